"""The predicted TCP position's uncertainty (MODEL §8) against the spread of the predictions
over many noise draws of a truth planted by the independent simulator (tests/independent.py)."""

from __future__ import annotations

import json
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot, save_robot
from robocal.model.measurements import Measurements
from robocal.model.uncertainty import point_sigma

DEVIATIONS = {"a2": 0.3, "d4": -0.2, "theta3": 0.002, "alpha2": -0.001, "a3": 0.15}
NOISE = 0.05


def _fit(seed: int, n: int = 50):
    c = ind.campaign("kr5-arc", DEVIATIONS, n, np.random.default_rng(seed), noise=NOISE, measure="position")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate("kr5-arc", Measurements(q=c["q"], position=c["position"]), "lm", frames="none",
                         noise=NOISE)


@pytest.mark.slow
def test_predicted_uncertainty_matches_the_spread_of_predictions_over_draws():
    rng = np.random.default_rng(0)
    lim = np.radians(ind.LIMITS_DEG["kr5-arc"])
    q_test = rng.uniform(lim[:, 0], lim[:, 1], (12, 6))
    g = ind.geometry("kr5-arc", DEVIATIONS)
    truth = np.array([ind.pose(g, q)[:3, 3] for q in q_test])
    errors, sigmas = [], []
    for draw in range(60):
        r = _fit(500 + draw)
        errors.append(r.robot.positions(q_test) - truth)
        sigmas.append(point_sigma(r.robot, r.robot.uncertainty, q_test))
    errors, sigmas = np.array(errors), np.array(sigmas)
    spread = np.sqrt(np.mean(np.sum(errors**2, axis=2), axis=0))  # rms radius per test pose over the draws
    predicted = np.sqrt(np.mean(sigmas**2, axis=0))
    ratio = spread / predicted
    # 60 draws: the rms of a 3-D error is known to about ±10 %
    assert np.all((ratio > 0.7) & (ratio < 1.35)), ratio
    assert 0.85 < np.median(ratio) < 1.15, ratio
    # and the poses differ: the map is not one number
    assert predicted.max() > 1.3 * predicted.min()


def test_the_covariance_travels_with_the_robot_file_and_evaluate_gives_it_per_pose(tmp_path, run_cli):
    result = _fit(1, 60)
    save_robot(result.robot, tmp_path / "cal.toml")
    robot = load_robot(tmp_path / "cal.toml")
    assert robot.uncertainty.names == tuple(result.names)
    assert np.allclose(robot.uncertainty.matrix, result.covariance, rtol=1e-12, atol=0)
    summary = result.to_dict()["tcp_uncertainty"]
    assert summary["points"] == 2000 and summary["at_calibration_poses"]["median_mm"] > 0
    from robocal.io.measurements import save_measurements

    save_measurements(result.measurements.subset(np.arange(8)), tmp_path / "d.csv")
    code, out, err = run_cli("evaluate", tmp_path / "cal.toml", tmp_path / "d.csv", "--uncertainty", "--json")
    assert code == 0, err
    per_pose = json.loads(out)["uncertainty"]["per_pose"]
    expected = point_sigma(result.robot, result.robot.uncertainty, result.measurements.q[:8])
    assert [p["sigma_mm"] for p in per_pose] == pytest.approx(expected, rel=1e-6)
    code, out, err = run_cli("evaluate", "kr5-arc", tmp_path / "d.csv", "--uncertainty")
    assert code == 2 and "no parameter covariance" in err


@pytest.mark.slow
def test_predicted_uncertainty_is_calibrated_inside_and_outside_the_sampled_joint_box():
    """A compliant KR5 calibrated on poses from the middle 60 % of its joint ranges and judged on
    fresh poses inside that box and beyond it (up to the limits): the whole model is used in both,
    and its predicted σ matches the actual error there, z = |error| / σ with rms near 1."""
    from robocal.model.uncertainty import predicted_sigma

    g = ind.geometry("kr5-arc", DEVIATIONS)
    masses, centres = [25.0, 18.0, 9.0, 4.0, 2.0, 0.5], [(-90, 30, 0), (-300, 0, 60), (-40, -20, 10), (0, 80, 0),
                                                        (0, 0, 20), (0, 0, 0)]
    compliance = np.array([0.0, 5e-6, 8e-6, 0.0, 0.0, 0.0])
    lim = np.radians(ind.LIMITS_DEG["kr5-arc"])
    box = lim.mean(axis=1)[:, None] + 0.3 * (lim - lim.mean(axis=1)[:, None])

    def torques(q):
        return np.array([ind.gravity_torques(ind.geometry("kr5-arc"), qi, masses, centres) for qi in q])

    def truth(q, tau):
        return np.array([ind.pose(g, qi)[:3, 3] for qi in q + tau * compliance])

    rng = np.random.default_rng(3)
    inside = rng.uniform(box[:, 0], box[:, 1], (15, 6))
    outside = rng.uniform(lim[:, 0], lim[:, 1], (60, 6))
    outside = outside[np.any((outside < box[:, 0] - 0.2) | (outside > box[:, 1] + 0.2), axis=1)][:15]
    fresh = np.vstack([inside, outside])
    tau_fresh = torques(fresh)
    z = []
    for draw in range(30):
        r = np.random.default_rng(100 + draw)
        q = r.uniform(box[:, 0], box[:, 1], (60, 6))
        tau = torques(q)
        meas = Measurements(q=q, position=truth(q, tau) + r.normal(0, NOISE, (60, 3)), torques=tau)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = calibrate("kr5-arc", meas, "lm", frames="none", model="compliance", noise=NOISE)
        from robocal.model.terms import JointInputs

        inputs = JointInputs(torques=tau_fresh)
        error = np.linalg.norm(res.robot.positions(fresh, inputs=inputs) - truth(fresh, tau_fresh), axis=1)
        z.append(error / predicted_sigma(res.robot, fresh, inputs=inputs))
    z = np.array(z)
    rms_in, rms_out = np.sqrt(np.mean(z[:, :15] ** 2)), np.sqrt(np.mean(z[:, 15:] ** 2))
    assert 0.7 < rms_in < 1.4 and 0.7 < rms_out < 1.4, (rms_in, rms_out)  # 30 draws × 15 poses each


def test_the_map_samples_the_measured_workspace_by_default_and_its_colours_tell_its_values_apart():
    """The UR10's real poses span a box of about 800 × 500 × 500 mm, its joints far more: the default map
    keeps joint sets whose TCP lies in that box (grown by a tenth); --map-over joints draws anywhere in
    the joint ranges, mostly outside it, where the model knows its TCP less well."""
    from pathlib import Path

    from robocal.calibration.config import CalibrationConfig
    from robocal.exceptions import InputError
    from robocal.io.measurements import load_measurements
    from robocal.model.uncertainty import BOX_MARGIN, tcp_map

    meas = load_measurements(Path(__file__).parents[2] / "examples" / "ur10-ipa" / "series_c.csv", n_joints=6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate("ur10", meas.subset(np.arange(300)), "lm", frames="base+tool")
    m = tcp_map(result.robot, result.measurements, 0)
    wide = tcp_map(result.robot, result.measurements, 0, over="joints")
    B = np.linalg.inv(result.robot.base)  # the box is the base frame's, where the report draws the map

    def base(p):
        return p @ B[:3, :3].T + B[:3, 3]

    tcp = base(result.robot.positions(result.measurements.q))
    lo, hi = tcp.min(axis=0), tcp.max(axis=0)
    grown = BOX_MARGIN * (hi - lo) + 1e-6
    assert m.over == "workspace" and len(m.sigma) == 2000 and result.to_dict()["tcp_uncertainty"]["over"] == \
        "workspace"
    assert np.all(base(m.position) >= lo - grown) and np.all(base(m.position) <= hi + grown)
    outside = np.any((base(wide.position) < lo - grown) | (base(wide.position) > hi + grown), axis=1)
    assert outside.mean() > 0.5  # the joint ranges reach far beyond the measured box
    assert np.median(m.sigma) < np.median(wide.sigma)
    bright = base(m.brightest()[None])[0]
    assert np.all(bright >= lo - grown) and np.all(bright <= hi + grown)
    with pytest.raises(InputError, match="map_over"):
        CalibrationConfig(map_over="everywhere")
