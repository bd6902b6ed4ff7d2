"""The tree correction against planted truths of the independent simulator (tests/independent.py).

- A step-like error of the TCP (steps in joints 1 and 3) that no joint term and no smooth
  kernel follows: ``--model auto`` chooses trees and new poses reach near the noise floor.
- A smooth cross-joint error: a learned correction is chosen, and fresh poses gain from it.
- None at all: geometry alone (``test_model_terms.test_auto_keeps_geometry_alone_on_geometric_data``
  runs the same ladder, trees included).
- The predicted σ matches the real error of the model inside its data and beyond them, where
  the trees fade out.
- The model travels: its sidecar file gives ``evaluate`` the calibration's own figure, and
  compensation through it lands the simulated true robot.
"""

import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.compensation import compensate
from robocal.evaluation import evaluate
from robocal.io.goals import Goals
from robocal.io.robotfile import load_robot
from robocal.model.measurements import Measurements
from robocal.model.uncertainty import predicted_sigma, region_note

NOISE = 0.02


def _step(q):
    """What the arm's TCP does beyond its joints (mm), stepping with joints 1 and 3: a cable's pull
    that sets in past an angle, a cam, a sensor's sector."""
    on = (np.cos(2.5 * q[:, 0]) > 0) & (q[:, 2] > 0.2)  # sectors of joint 1, the same everywhere in its range
    return np.column_stack([0.3 * on - 0.15 * (q[:, 2] < -0.8), -0.2 * on, 0.25 * on])


def _smooth(q):
    dq = np.zeros_like(q)
    dq[:, 1] = 4e-4 * np.sin(q[:, 0]) * np.cos(q[:, 2])
    dq[:, 4] = 5e-4 * np.cos(q[:, 3] + q[:, 0])
    return dq


def _campaign(error, n, seed, noise=NOISE):
    """KR5 positions with ``error``: _step (mm, added to the TCP) or _smooth (rad, at the joints)."""
    c = ind.campaign("kr5-arc", {"a2": 0.2, "theta3": 0.002}, n, np.random.default_rng(seed), noise=noise,
                     measure="position", joint_error=None if error is _step else error)
    offset = _step(c["q"]) if error is _step else 0.0
    return Measurements(q=c["q"], position=c["position"] + offset)


def _calibrate(meas, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate("kr5-arc", meas, "lm", frames="none", **kw)
    return result, [str(w.message) for w in caught] + result.notes  # what it said: warnings and notes


@pytest.fixture(scope="module")
def steps():
    return _campaign(_step, 500, 11), _campaign(_step, 300, 12)


def test_auto_chooses_trees_for_a_step_like_error_and_fresh_poses_near_the_floor(steps):
    meas, fresh = steps
    res, said = _calibrate(meas, model="auto", validate=fresh)
    rows = {r.model: r for r in res.model_selection}
    assert "trees" in res.model.split("+"), rows
    validation = res.metrics["validation_after"].position["rms"]
    geometric = rows["geometric"].validation_rms_mm
    assert validation < 0.5 * geometric
    # the process is in the ladder and the trees beat it on held-out poses (clearly enough that its
    # screen was all it took)
    chosen = res.model_selection[[r.model for r in rows.values()].index(res.model)]
    assert rows["residual"].cv_rms_mm > 1.2 * chosen.cv_rms_mm
    assert rows["residual"].screened == any("not tuned in full" in s for s in said)
    summary = res.to_dict()["residual_model"]
    assert summary["kind"].startswith("gradient-boosted trees")
    # they split on the joints that step, 1 and 3, more than on the others
    importance = np.mean([summary["joint_importance"][a] for a in "xyz"], axis=0)
    assert set(np.argsort(-importance)[:2]) == {0, 2}
    budget = {r.model: r for r in res.error_budget}
    trees, geometric = budget["+ trees"], budget["geometric calibration"]
    assert trees.removed_mm > 0 and all(a < b for a, b in zip(trees.axes_mm, geometric.axes_mm))


def test_a_smooth_error_gets_a_learned_correction_that_helps(quiet):
    res, _ = _calibrate(_campaign(_smooth, 400, 21), model="auto", validate=_campaign(_smooth, 300, 22))
    rows = {r.model: r for r in res.model_selection}
    assert {"trees", "residual"} & set(res.model.split("+")), rows
    assert res.metrics["validation_after"].position["rms"] < 0.6 * rows["geometric"].validation_rms_mm
    assert not rows["residual"].screened  # a process that wins is tuned in full, never judged by its screen


def _inside(q):
    """The calibration's joint 1 range (and beyond it, > 1.7 rad, the error is alike: its sectors repeat)."""
    return q[:, 0] < 1.0


def test_the_predicted_sigma_matches_the_real_error_inside_and_beyond_the_data(quiet):
    pool = _campaign(_step, 1600, 31)
    meas = pool.subset(np.flatnonzero(_inside(pool.q))[:450])
    res, _ = _calibrate(meas, model="trees")
    truth = _campaign(_step, 1500, 32, noise=0.0)  # where the real robot goes, without the tracker's noise
    ratios = {}
    for name, keep in (("inside", _inside(truth.q)), ("outside", truth.q[:, 0] > 1.7)):
        q = truth.q[keep][:300]
        error = np.linalg.norm(res.robot.positions(q) - truth.position[keep][:300], axis=1)
        sigma = predicted_sigma(res.robot, q)
        ratios[name] = float(np.sqrt(np.mean(error ** 2) / np.mean(sigma ** 2)))
    model = res.robot.residual
    assert np.mean(model.weight(truth.q[truth.q[:, 0] > 1.7][:300])) < 0.2  # beyond the data it fades
    note = region_note(res.robot, truth.q[truth.q[:, 0] > 1.7][:300])
    assert "beyond the data of the learned correction (trees)" in note  # and evaluate/compensate say so
    for ratio in ratios.values():
        assert 0.5 < ratio < 2.0, ratios


def test_the_exported_trees_evaluate_to_the_calibration_figure_and_compensate(steps, tmp_path):
    meas, fresh = steps
    res, _ = _calibrate(meas, model="trees", validate=fresh)
    written = res.export(tmp_path / "cal.toml")
    assert [p.name for p in written] == ["cal.toml", "cal.residual.json"]
    figure = res.metrics["validation_after"].position["rms"]
    assert evaluate(tmp_path / "cal.toml", fresh).metrics.position["rms"] == pytest.approx(figure, rel=1e-9)
    calibrated = load_robot(tmp_path / "cal.toml")
    truth = ind.geometry("kr5-arc", {"a2": 0.2, "theta3": 0.002})
    goals_q = fresh.q[:25]

    def real(q):  # where the real robot's TCP goes (mm)
        return np.array([ind.pose(truth, qi)[:3, 3] for qi in q]) + _step(q)

    goal = real(goals_q)
    out = compensate(load_robot("kr5-arc"), calibrated, Goals(q=goals_q, position=goal, rotation=None,
                                                              ids=[str(i) for i in range(25)]), position_only=True)
    miss = np.linalg.norm(real(out.q) - goal, axis=1)
    before = np.linalg.norm(real(out.q_nominal) - goal, axis=1)
    assert np.sqrt(np.mean(miss ** 2)) < 0.3 * np.sqrt(np.mean(before ** 2))
