"""The report's advice follows its figures: the gap between the model's held-out figure and the
instrument's floor, and the predicted uncertainty over the calibrated joint ranges."""

import re
import warnings
from pathlib import Path

import numpy as np

from robocal import calibrate
from robocal.report.advice import FLOOR_GAP, next_steps
from robocal.simulation import simulate

UR10 = Path(__file__).resolve().parents[2] / "examples" / "ur10-ipa" / "series_c.csv"


def _fit(*args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate(*args, **kw)


def test_a_figure_far_above_the_floor_is_said_with_both_numbers():
    from robocal.io.measurements import load_measurements

    meas = load_measurements(UR10, n_joints=6)
    cal, val = meas.subset(np.arange(0, meas.n_poses, 2)), meas.subset(np.arange(1, meas.n_poses, 2))
    res = _fit("ur10", cal, "lm", frames="base+tool", validate=val)
    advice = next_steps(res)
    assert not any(a.startswith("Nothing calls") for a in advice)
    gap = next(a for a in advice if "the instrument's own" in a)
    figure, floor = (float(x) for x in re.search(r"predicts ([\d.]+) mm RMS .*?own ([\d.]+) mm", gap).groups())
    assert figure == round(res.metrics["validation_after"].position["rms"], 3 - int(np.floor(np.log10(figure))) - 1)
    assert figure > FLOOR_GAP * floor and "--model auto" in gap


def test_a_model_at_its_floor_is_not_told_to_do_more():
    """A planted robot the geometric model holds exactly, measured with a stated 0.02 mm: its
    cross-validated figure is at the floor, and no advice says otherwise."""
    from robocal.calibration.fit.instrument import Instrument, with_instrument
    from robocal.io.robotfile import load_robot

    sim = simulate(load_robot("kr5-arc"), 120, deviations="uniform:0.3,0.003", seed=8, noise=0.02,
                   angle_noise=1e-5)
    res = _fit("kr5-arc", with_instrument(sim.measurements, Instrument.parse("0.02")), "lm", frames="none")
    figure = res.metrics["predicted"].position["rms"]
    assert figure < FLOOR_GAP * 0.02 * np.sqrt(3)
    advice = next_steps(res)
    assert not any("the difference is the model's" in a for a in advice), advice


def test_the_exports_paragraph_offers_a_ur_yaml_for_a_ur_arm_only():
    """A UR kinematics YAML is offered where a UR-type arm's joints fit it (the UR10), never for a KR5 or
    the Panda's seven joints; and it says the frames are in the TOML beside it."""
    from robocal.io.measurements import load_measurements
    from robocal.io.robotfile import load_robot
    from robocal.report.html import _exports

    meas = load_measurements(UR10, n_joints=6)
    ur = " ".join(_exports(_fit("ur10", meas.subset(np.arange(0, 300)), "lm", frames="base+tool")))
    assert "UR kinematics YAML holds the joints' geometry alone" in ur and "robot TOML written beside it" in ur
    sim = simulate(load_robot("kr5-arc"), 40, deviations="uniform:0.3,0.003", seed=1, noise=0.02)
    kr5 = " ".join(_exports(_fit("kr5-arc", sim.measurements, "lm")))
    assert "YAML" not in kr5

