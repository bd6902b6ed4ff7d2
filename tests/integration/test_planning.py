"""Calibration pose planning."""

import math
import warnings

import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.plan import plan_poses
from robocal.simulation import random_joints, simulate


@pytest.mark.parametrize(
    "name,measure,errors", [("er10l-c10", "pose", "paper"), ("kr5-arc", "position", "uniform:0.25,0.05")]
)
def test_planned_poses_beat_random_sets_in_prediction_and_in_simulation(name, measure, errors):
    robot = load_robot(name)
    plan = plan_poses(robot, 30, candidates=2000, measure=measure, seed=0)
    assert plan.predicted_rms < np.median(plan.random_rms)
    assert plan.value > np.median(plan.random_values)
    # confirm by simulation: plant errors, measure with the planned noise, calibrate, validate on 500 poses
    truth = simulate(robot, 1, deviations=errors, seed=11).truth
    val = simulate(truth, 500, seed=12, measure=measure).measurements
    k = (0.02 / math.radians(0.001)) ** 2  # weigh orientation as the plan assumed

    def validation_rms(q, seed):
        sim = simulate(truth, len(q), q=q, noise=0.02, angle_noise=math.radians(0.001), seed=seed, measure=measure)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = calibrate(robot, sim.measurements, "lm", validate=val, k=k)
        return res.metrics["validation_after"].position["rms"]

    planned = np.mean([validation_rms(plan.q, s) for s in range(8)])
    rng = np.random.default_rng(7)
    random = np.median([validation_rms(random_joints(robot, 30, rng), 100 + s) for s in range(12)])
    assert planned < random


def test_limits_and_reproducibility(run_cli, tmp_path):
    robot = load_robot("kr5-arc")
    lim = np.radians([[-30, 30], [-90, -10], [20, 90], [-90, 90], [-60, 60], [-90, 90]])
    a = plan_poses(robot, 12, candidates=300, measure="position", joint_range=lim, seed=3, random_sets=3)
    b = plan_poses(robot, 12, candidates=300, measure="position", joint_range=lim, seed=3, random_sets=3)
    c = plan_poses(robot, 12, candidates=300, measure="position", joint_range=lim, seed=4, random_sets=3)
    assert np.all(a.q >= lim[:, 0]) and np.all(a.q <= lim[:, 1])
    np.testing.assert_array_equal(a.q, b.q)
    assert not np.array_equal(a.q, c.q)
    for crit in ("O2", "O3", "O4"):
        p = plan_poses(robot, 12, candidates=200, measure="position", criterion=crit, seed=1, random_sets=3)
        assert p.value >= np.median(p.random_values)
    out = tmp_path / "plan.csv"
    code, _, err = run_cli(
        "plan",
        "kr5-arc",
        "--poses",
        12,
        "--candidates",
        300,
        "--measure",
        "position",
        "--limits",
        "-30:30,-90:-10,20:90,-90:90,-60:60,-90:90",
        "--out",
        out,
        "--quiet",
    )
    assert code == 0, err
    rows = out.read_text().splitlines()
    assert rows[0] == "pose_id,q1,q2,q3,q4,q5,q6" and len(rows) == 13
    for bad in (
        ["--limits", "10:5,0:1,0:1,0:1,0:1,0:1"],
        ["--criterion", "E"],
        ["--poses", "0"],
        ["--limits", "-30:30"],
    ):
        code, _, err = run_cli("plan", "kr5-arc", *bad, "--out", tmp_path / "x.csv")
        assert code == 2 and err.count("\n") == 1, (bad, err)
        assert not (tmp_path / "x.csv").exists()


def test_plan_and_calibration_weigh_alike(quiet):
    """Stating the plan's noise to the calibration gives the uncertainties the plan predicted."""
    robot = load_robot("er10l-c10")
    plan = plan_poses(robot, 30, candidates=300, measure="pose", noise=0.02, angle_noise=math.radians(0.002),
                      seed=2, random_sets=2)
    sim = simulate(robot, len(plan.q), q=plan.q, measure="pose")  # the nominal robot, no noise
    # the plan predicts what the poses alone tell (no prior): so does a calibration without one
    res = calibrate(robot, sim.measurements, "lm", noise=0.02, angle_noise=math.radians(0.002), prior="all=free")
    assert res.k == pytest.approx((0.02 / math.radians(0.002)) ** 2)
    predicted = dict(zip(plan.names, plan.predicted_std))
    for name, u in zip(res.names, res.uncertainty):
        assert u == pytest.approx(predicted[name], rel=1e-6), name


def test_a_cell_plan_keeps_the_tool_in_the_workspace_facing_the_tracker_and_moves_short():
    import math

    from robocal.plan.design import plan_poses

    robot = load_robot("kr5-arc")
    box = np.array([[300.0, 900.0], [-400.0, 400.0], [100.0, 900.0]])
    tracker = np.array([3000.0, 0.0, 500.0])
    p = plan_poses(robot, 20, candidates=300, frames="base+tool", workspace=box, tracker=tracker, fov=120.0,
                   model_error=0.2, seed=2)
    T = robot.fk(p.q)
    assert np.all((T[:, :3, 3] >= box[:, 0]) & (T[:, :3, 3] <= box[:, 1]))
    to = tracker - T[:, :3, 3]
    cos = np.einsum("mi,mi->m", T[:, :3, 2], to / np.linalg.norm(to, axis=1, keepdims=True))
    assert np.all(cos >= math.cos(math.radians(60.0)) - 1e-12)
    # the order is the nearest-neighbour one: never longer in total than the plan's poses taken as drawn
    moves = np.max(np.abs(np.diff(p.q, axis=0)), axis=1).sum()
    shuffled = p.q[np.random.default_rng(0).permutation(len(p.q))]
    assert moves <= np.max(np.abs(np.diff(shuffled, axis=0)), axis=1).sum()
    assert p.expected_rms == pytest.approx(math.sqrt(p.predicted_rms ** 2 + 3 * 0.2 ** 2))
