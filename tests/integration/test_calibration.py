"""Calibration engine: recovery of planted errors, identifiability, frames, swarms, CLI."""

import json
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.calibration.judge.identifiability import analyse
from robocal.io.robotfile import load_robot
from robocal.model.measurements import Measurements
from robocal.model.metrics import Metrics
from robocal.model.parameters import ParameterSpace
from robocal.presets.wen2019 import PARAMETERS as WEN2019_PARAMS
from robocal.presets.wen2019 import TABLE2_DEVIATIONS as WEN2019_ERRORS
from robocal.simulation import simulate

pytestmark = pytest.mark.usefixtures("quiet")

#: the KR5's planted errors (±0.25 mm, ±0.05 rad, Kou et al.'s range), drawn once
KR5_ERRORS = ind.uniform_deviations("kr5-arc", 0.25, 0.05, np.random.default_rng(3))


def test_lm_recovers_wen2019_errors_exactly_from_full_pose_data():
    robot = load_robot("er10l-c10")
    meas = ind.measurements("er10l-c10", WEN2019_ERRORS, 32, 1, noise=0.0)
    res = calibrate(robot, meas, "lm")
    assert res.identifiability.dropped == ["d2"]  # axes 2 ∥ 3: beta2 carries the pair, as in the paper
    for name in res.names:
        assert abs(res.parameter(name) - WEN2019_ERRORS.get(name, 0.0)) < 1e-6, name
    assert res.metrics["after"].position["max"] < 1e-6
    assert res.metrics["after"].orientation["z"]["max"] < 1e-6
    assert res.metrics["before"].position["mean"] > 5


def test_noisy_full_pose_validation_is_at_the_true_parameter_set_floor():
    robot = load_robot("er10l-c10")
    meas = ind.measurements("er10l-c10", WEN2019_ERRORS, 32, 1, noise=0.02, angle_noise=np.radians(0.001))
    val = ind.measurements("er10l-c10", WEN2019_ERRORS, 200, 77, noise=0.0)
    auto = calibrate(robot, meas, "lm", validate=val)
    floor = calibrate(robot, meas, "lm", validate=val, params=WEN2019_PARAMS)  # exactly the planted set
    a = auto.metrics["validation_after"].position["rms"]
    f = floor.metrics["validation_after"].position["rms"]
    assert a <= 1.1 * f and a < 0.05
    # standard uncertainties are consistent with the actual estimation errors
    z = [(floor.parameter(n) - WEN2019_ERRORS[n]) / u for n, u in zip(floor.names, floor.uncertainty)]
    assert np.all(np.isfinite(z)) and np.max(np.abs(z)) < 5


def _fd_position_jacobian(robot, q, names, h=1e-6):
    """Position Jacobian by central differences of plain FK (independent of the analytic one)."""
    space = ParameterSpace.of(robot)
    cols = []
    for n in names:
        e = space.vector({n: h})
        cols.append(((space.apply(e).positions(q) - space.apply(-e).positions(q)) / (2 * h)).ravel())
    return np.column_stack(cols)


def test_kr5_dropped_set_is_exactly_the_unidentifiable_one_and_fit_is_exact():
    robot = load_robot("kr5-arc")
    meas = ind.measurements("kr5-arc", KR5_ERRORS, 30, 3, noise=0.0, measure="position")
    # the planted twists reach 0.05 rad (Kou et al.'s box), far beyond a real arm's: without a
    # prior, identifiability alone decides what is kept
    res = calibrate(robot, meas, "lm", params="kou2022", prior="all=free")
    assert res.metrics["after"].position["max"] < 1e-6
    assert res.metrics["before"].axis_max["x"] > 10
    candidates = res.names + res.identifiability.dropped
    # independent rank at the estimate, from finite differences, angles scaled to mm by the reach
    J = _fd_position_jacobian(res.robot, meas.q, candidates)
    J = J / np.linalg.norm(J, axis=0).clip(1e-300)
    rank = np.linalg.matrix_rank(J, tol=1e-7 * np.sqrt(J.shape[0]))
    assert rank == len(res.names)
    kept = J[:, : len(res.names)]
    assert np.linalg.matrix_rank(kept, tol=1e-7 * np.sqrt(J.shape[0])) == len(res.names)
    # at the nominal model the textbook dependencies show: θ6 and α6 with the point on axis 6,
    # d2 with d3 for parallel axes 2 ∥ 3
    space = ParameterSpace.of(robot)
    Jn, _, _ = space.jacobian(np.zeros(space.size), meas.q)
    idx = space.index(candidates)
    at_nominal = analyse(
        Jn[:, :3, idx].transpose(0, 1, 2).reshape(-1, len(idx)),
        candidates,
        np.array([n.startswith(("alpha", "theta")) for n in candidates]),
        30,
        robot.reach(),
    )
    assert {"theta6", "alpha6", "d2"} <= set(at_nominal.dropped)
    assert "alpha6" in res.identifiability.dropped


def test_kr5_noisy_keeps_the_nominal_identifiable_set():
    robot = load_robot("kr5-arc")
    meas = ind.measurements("kr5-arc", KR5_ERRORS, 30, 3, noise=0.02, measure="position")
    val = ind.measurements("kr5-arc", KR5_ERRORS, 200, 9, noise=0.0, measure="position")
    res = calibrate(robot, meas, "lm", validate=val)
    # axes 2 ∥ 3: β2 is offered (DH + β), and with it d2 stays dependent on d3
    assert set(res.identifiability.dropped) == {"d2", "a5", "alpha5", "alpha6", "theta6"}
    assert "beta2" in res.names and res.identifiability.reasons["d2"].kind == "dependent"
    assert res.identifiability.absorbed_by("d3") == [("d2", pytest.approx(1.0))]
    # in plain DH (the paper's 24), d2 separates to second order at the estimate; the F-test declines it
    dh = calibrate(robot, meas, "lm", validate=val, params="kou2022")
    assert dh.identifiability.reasons["d2"].kind == "second_order"
    assert "F-test" in dh.identifiability.reasons["d2"].text()
    assert res.metrics["validation_after"].position["rms"] < 0.05


@pytest.mark.parametrize(
    "name,measure,errors", [("er10l-c10", "pose", "paper"), ("kr5-arc", "position", "uniform:0.25,0.05")]
)
def test_unknown_measuring_frame_and_tool_need_no_initial_guess(name, measure, errors):
    from scipy.spatial.transform import Rotation

    robot = load_robot(name)
    deviations = WEN2019_ERRORS if errors == "paper" else KR5_ERRORS
    base, tool = np.eye(4), np.eye(4)
    base[:3, :3] = Rotation.from_euler("ZYX", [0.8, -0.2, 0.3]).as_matrix()  # rpy (0.3, −0.2, 0.8) rad
    base[:3, 3] = (2500.0, -1800.0, 400.0)
    tool[:3, :3] = Rotation.from_euler("ZYX", [0.3, 0.2, 0.1]).as_matrix()
    tool[:3, 3] = (20.0, -35.0, 110.0)
    frames = {"base": base, "tool": tool, "measure": measure, "noise": 0.0}
    meas = ind.measurements(name, deviations, 40, 2, **frames)
    res = calibrate(robot, meas, "lm", frames="base+tool")
    assert res.metrics["after"].position["max"] < 1e-6
    val = ind.measurements(name, deviations, 100, 5, **frames)
    assert Metrics.of(res.robot, val).position["max"] < 1e-6
    # base rotation and joint 1 share θ1 and d1: those fold into the frame
    assert {"theta1", "d1"} <= set(res.identifiability.dropped)


def test_several_targets_each_get_a_tool_offset():
    robot = load_robot("kr5-arc")
    sim = simulate(
        robot, 40, deviations="uniform:0.1,0.002", seed=4, measure="position", base=(1000.0, 500.0, 0.0, 0.0, 0.0, 0.5)
    )
    tools = {"A": (0.0, 0.0, 100.0), "B": (60.0, 0.0, 80.0), "C": (0.0, 70.0, 90.0)}
    q, pos, tg = [], [], []
    for t, xyz in tools.items():
        T = sim.truth.replace(tool=np.eye(4))
        T.tool[:3, 3] = xyz
        q.append(sim.measurements.q)
        pos.append(T.positions(sim.measurements.q))
        tg += [t] * sim.measurements.n_poses
    meas = Measurements(q=np.vstack(q), position=np.vstack(pos), targets=tuple(tg))
    res = calibrate(robot, meas, "lm", frames="base+tool")
    assert res.metrics["after"].position["max"] < 1e-6
    offsets = {t: res.robot.targets[t][:3, 3] for t in tools}
    # the reflectors' mutual distances come out as planted (the flange frame itself may turn with
    # errors of joint 6 folded into it, so compare rotation-invariant figures)
    for s, t in (("A", "B"), ("A", "C"), ("B", "C")):
        planted = np.linalg.norm(np.subtract(tools[s], tools[t]))
        assert np.linalg.norm(offsets[s] - offsets[t]) == pytest.approx(planted, abs=1e-6)




@pytest.mark.parametrize(
    "method,robot,measure,errors",
    [
        ("ipso", "er10l-c10", "pose", "paper"),
        ("pso", "kr5-arc", "position", "uniform:0.25,0.05"),
        ("ldpso-bt", "kr5-arc", "position", "uniform:0.25,0.05"),
    ],
)
@pytest.mark.slow
def test_swarms_reach_the_papers_regime_monotonically(method, robot, measure, errors, backend):
    r = load_robot(robot)
    sim = simulate(r, 32 if robot == "er10l-c10" else 30, deviations=errors, seed=1, measure=measure)
    params = "wen2019" if method == "ipso" else "kou2022"
    res = calibrate(r, sim.measurements, method, params=params, seed=0, backend=backend)
    h = res.optimization.history
    assert np.all(np.diff(h) <= 0) and h[-1] < h[0]
    assert res.metrics["before"].position["max"] > 30
    assert res.metrics["after"].position["max"] < 1.0
    assert res.optimization.nfev > 0 and res.optimization.nit == len(h) - 1


@pytest.mark.parametrize("method", ["pso", "ipso", "ldpso-bt", "hybrid", "lm"])
def test_fixed_seed_is_bit_for_bit_reproducible(method, backend):
    r = load_robot("kr5-arc")
    sim = simulate(r, 20, deviations="uniform:0.25,0.05", seed=1, measure="position")
    kw = {"backend": backend} if method == "lm" else {"iterations": 30, "particles": 30 if method != "ipso" else 20,
                                                      "backend": backend}
    a = calibrate(r, sim.measurements, method, seed=5, **kw).to_dict()
    b = calibrate(r, sim.measurements, method, seed=5, **kw).to_dict()
    for d in (a, b):
        d.pop("time_s")
        d.pop("timings")
        d["optimizer"].pop("time_s")
    assert json.dumps(a) == json.dumps(b)
    if method != "lm":
        c = calibrate(r, sim.measurements, method, seed=6, **kw).to_dict()
        assert c["history"] != a["history"]


def test_hybrid_reaches_lm_accuracy():
    r = load_robot("er10l-c10")
    sim = simulate(r, 32, deviations="paper", seed=1)
    res = calibrate(r, sim.measurements, "hybrid", iterations=100)
    assert res.metrics["after"].position["max"] < 1e-6
    assert res.uncertainty is not None


def test_cli_calibrate_end_to_end(tmp_path, run_cli):
    d, t, v = tmp_path / "d.csv", tmp_path / "t.toml", tmp_path / "v.csv"
    assert (
        run_cli(
            "simulate",
            "er10l-c10",
            "--errors",
            "paper",
            "--poses",
            32,
            "--seed",
            1,
            "--noise",
            0.02,
            "--out",
            d,
            "--truth",
            t,
        )[0]
        == 0
    )
    assert run_cli("simulate", t, "--poses", 100, "--seed", 2, "--out", v)[0] == 0
    out, cal = tmp_path / "result.json", tmp_path / "calibrated.toml"
    code, stdout, err = run_cli(
        "calibrate", "er10l-c10", d, "--method", "lm", "--validate", v, "--seed", 3, "--out", out, "--export", cal
    )
    assert code == 0, err
    assert "validation after" in stdout
    result = json.loads(out.read_text())
    for key in ("method", "seed", "parameters", "dropped", "metrics", "iterations", "evaluations", "time_s"):
        assert key in result
    assert result["dropped"][0]["name"] == "d2" and result["dropped"][0]["reason"]
    p = {x["name"]: x for x in result["parameters"]}
    assert p["a1"]["unit"] == "mm" and p["alpha1"]["unit"] == "rad" and p["a1"]["uncertainty"] > 0
    assert p["a1"]["value"] == pytest.approx(p["a1"]["nominal"] + p["a1"]["error"])
    m = result["metrics"]
    assert m["after"]["position"]["rms"] < 0.05 < m["before"]["position"]["rms"]
    assert m["validation_after"]["position"]["rms"] < 0.05
    # the exported robot evaluates to the reported "after" metrics
    code, stdout, _ = run_cli("evaluate", cal, d, "--json")
    assert json.loads(stdout)["position"] == pytest.approx(m["after"]["position"], rel=1e-9)
    # a swarm run with a progress-capable CLI, quiet
    code, _, err = run_cli(
        "calibrate", "er10l-c10", d, "--method", "ipso", "--iterations", 20, "--quiet", "--out", tmp_path / "r2.json"
    )
    assert code == 0, err


def test_cli_calibrate_bad_options_write_nothing(tmp_path, run_cli):
    d = tmp_path / "d.csv"
    run_cli("simulate", "kr5-arc", "--poses", 20, "--measure", "position", "--out", d)
    out = tmp_path / "r.json"
    for args in (
        ["--method", "sgd"],
        ["--frames", "tool"],
        ["--params", "a1,zz9"],
        ["--box", "0,1"],
        ["--objective", "max"],
        ["--halton", "sobol"],
        ["--particles", "0"],
    ):
        code, _, err = run_cli("calibrate", "kr5-arc", d, *args, "--out", out)
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, (args, err)
        assert not out.exists()


def test_a_swarms_prediction_is_its_own_not_lms():
    """A swarm's answer is not the data's optimum: its folds refitted by LM would predict LM's
    better model.  Its prediction is its own misfit plus its structure's optimism, never below
    its in-sample fit, and the folds' refits are model selection's time, not the method's."""
    robot = load_robot("kr5-arc")
    sim = simulate(robot, 40, deviations="uniform:0.5,0.002", noise=0.02, seed=3, measure="position")
    val = simulate(sim.truth, 300, noise=0.02, seed=4, measure="position").measurements
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(robot, sim.measurements, "pso", frames="none", validate=val, particles=40, iterations=150)
        lm = calibrate(robot, sim.measurements, "lm", frames="none", validate=val)
    fit, predicted = res.metrics["after"].position["rms"], res.metrics["predicted"].position["rms"]
    assert predicted > fit and predicted > lm.metrics["predicted"].position["rms"]
    assert predicted == pytest.approx(res.metrics["validation_after"].position["rms"], rel=0.35)
    assert res.time_s == res.timings["optimize_s"] and res.timings["model_s"] > 0
