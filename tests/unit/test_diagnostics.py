"""Implausible deviations are named with their likely cause."""

import numpy as np

from robocal.calibration.diagnostics import implausible_deviations


def test_implausible_deviations_name_parameters_and_cause():
    names = ["d2", "d3", "alpha2", "base_x"]
    x = np.array([159000.0, -159000.0, 0.01, 2500.0])  # a base metres away is normal
    corr = np.eye(4)
    corr[0, 1] = corr[1, 0] = -0.99999
    text = implausible_deviations(names, x, np.ones(4), corr)
    assert text.startswith("implausible deviations") and "d2 +1.59e+05 mm" in text and "base_x" not in text
    assert "nearly dependent" in text and "parallel axes" in text
    assert implausible_deviations(names, np.array([5.0, 1.0, 0.05, 9000.0]), None, None) is None
