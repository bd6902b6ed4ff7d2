"""Implausible deviations are named with their likely cause, and make the verdict: not physical."""

import math

import numpy as np

from robocal.calibration.judge.diagnostics import physicality


def test_implausible_deviations_name_parameters_and_cause():
    names = ["d2", "d3", "alpha2", "base_x"]
    x = np.array([159000.0, -159000.0, 0.01, 2500.0])  # a base metres away is normal
    corr = np.eye(4)
    corr[0, 1] = corr[1, 0] = -0.99999
    verdict = physicality(names, x, np.ones(4), corr)
    text = verdict.sentence()
    assert not verdict.physical
    assert text.startswith("implausible deviations") and "d2 +1.59e+05 mm" in text and "base_x" not in text
    assert "nearly dependent" in text and "parallel axes" in text
    assert physicality(names, np.array([5.0, 1.0, 0.05, 9000.0]), None, None).physical


def test_a_joint_term_is_judged_by_how_far_it_turns_its_joint():
    """A harmonic's amplitude of 48.9 rad is not physical; one of 0.02° is, whatever its value in rad."""
    names = ["harmonic6_cos1", "harmonic6_sin1"]
    verdict = physicality(names, np.array([48.9, 0.0]), None, None,
                          {"harmonic6_cos1": 48.9, "harmonic6_sin1": 0.0})
    assert not verdict.physical and verdict.implausible[0][0] == "harmonic6_cos1"
    assert "° of turn" in verdict.sentence()
    small = math.radians(0.02)
    assert physicality(names, np.array([small, small]), None, None,
                       {"harmonic6_cos1": small, "harmonic6_sin1": small}).physical
