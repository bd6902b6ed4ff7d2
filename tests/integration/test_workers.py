"""``--model auto`` on forked workers: the numbers of the same work done in this process, and
no worker lost on the way (numba's OpenMP kernels abort in a forked child that runs them)."""

import sys
import warnings

import numpy as np
import pytest

import robocal.backend as backend
from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.simulation import simulate


def _auto(meas):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate("kr5-arc", meas, "lm", frames="base+tool", model="auto", seed=4)
    return result, [str(w.message) for w in caught]


@pytest.mark.skipif(sys.platform != "linux", reason="workers are forked on Linux only")
def test_auto_on_workers_equals_auto_here(monkeypatch):
    meas = simulate(load_robot("kr5-arc"), 60, deviations="uniform:0.2,0.001", noise=0.02, angle_noise=2e-5,
                    harmonics={2: [[0.01, 0.005]]}, seed=3).measurements
    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 1)
    here, _ = _auto(meas)
    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 2)
    there, said = _auto(meas)
    assert not [s for s in said if "worker" in s]
    assert [r.model for r in there.model_selection] == [r.model for r in here.model_selection]
    assert any(r.model.endswith("residual") for r in here.model_selection)
    np.testing.assert_allclose([r.cv_rms_mm for r in there.model_selection],
                               [r.cv_rms_mm for r in here.model_selection], rtol=1e-9)
    assert there.model == here.model
    assert there.metrics["after"].position["rms"] == pytest.approx(here.metrics["after"].position["rms"], rel=1e-9)
