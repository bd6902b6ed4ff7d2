"""The newest features meet each other: no hang, and no silent wrong number.

One test (or a few) per class of what must hold: outputs written together, studies that know
which spec made them, schedulers that do not answer, reflectors in evaluate and compensate,
too little data for a model, a joint that never moved, the final guard, extrapolation
outside the calibrated region, tools that do not match, repeated poses, Ctrl-C.  The bad
inputs that end in one line and exit code 2 live in the corpus (data/bad/manifest.json).
"""

from __future__ import annotations

import csv
import http.server
import io
import json
import math
import signal
import subprocess
import sys
import threading
import time
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.io.measurements import measurements_to_csv, parse_measurements
from robocal.io.robotfile import load_robot, save_robot
from robocal.math.se3 import frame_from_values
from robocal.model.measurements import Measurements
from robocal.study.driver import run_study
from robocal.study.spec import parse_study

STUDY = "robot = 'kr5-arc'\nmethods = ['lm']\nposes = [20]\nseeds = 2\nvalidate = 20\n"


def _said(fn, *args, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kw)
    return out, [str(w.message) for w in caught]


def _kr5_campaign(n, seed, deviations=None, q=None, noise=0.02, base=None, tool=None, measure="position"):
    """Joints (given, or uniform in the KR5's limits) and what the independent simulator measures."""
    rng = np.random.default_rng(seed)
    lim = np.radians(ind.LIMITS_DEG["kr5-arc"])
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 6)) if q is None else q
    g = ind.geometry("kr5-arc", deviations or {"a2": 0.2, "theta3": 0.003, "d4": -0.15, "alpha5": 0.002})
    T = np.array([ind.pose(g, qi, np.eye(4) if base is None else base, np.eye(4) if tool is None else tool)
                  for qi in q])
    position = T[:, :3, 3] + rng.normal(0.0, noise, (len(q), 3))
    return Measurements(q=q, position=position, rotation=T[:, :3, :3] if measure == "pose" else None)


# --- outputs ------------------------------------------------------------------------------

def test_a_failure_while_writing_leaves_every_earlier_output_as_it_was(tmp_path, run_cli):
    data = tmp_path / "d.csv"
    data.write_text(measurements_to_csv(_kr5_campaign(40, 1)))
    out, export = tmp_path / "r.json", tmp_path / "m.toml"
    out.write_text("earlier result\n")
    (tmp_path / "m.residual.json").mkdir()  # the export's sidecar cannot be written
    code, _, err = run_cli("calibrate", "kr5-arc", data, "--model", "residual", "--out", out, "--export", export,
                           "--quiet")
    assert code == 2 and err.count("\n") == 1 and "m.residual.json" in err and "is a folder" in err
    assert out.read_text() == "earlier result\n" and not export.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_ctrl_c_writes_nothing_and_exits_130(tmp_path):
    out = tmp_path / "r.json"
    out.write_text("earlier\n")
    proc = subprocess.Popen([sys.executable, "-m", "robocal", "calibrate", "kr5-arc", str(_kr5_file(tmp_path)),
                             "--method", "ipso", "--iterations", "1000000", "--backend", "numpy", "--quiet",
                             "--out", str(out)], stderr=subprocess.PIPE, text=True)
    time.sleep(6)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and err == "robocal: interrupted; nothing written\n"
    assert out.read_text() == "earlier\n"


def _kr5_file(tmp_path):
    path = tmp_path / "kr5.csv"
    path.write_text(measurements_to_csv(_kr5_campaign(30, 2)))
    return path


# --- studies ------------------------------------------------------------------------------

def test_a_study_resumed_under_another_spec_refuses_naming_the_keys(tmp_path, run_cli):
    first, second = tmp_path / "a.toml", tmp_path / "b.toml"
    first.write_text(STUDY)
    second.write_text(STUDY + "errors = 'none'\nframes = 'base'\n")
    assert run_cli("study", first, "--out", tmp_path / "o", "--workers", "1", "-q")[0] == 0
    before = (tmp_path / "o" / "runs.csv").read_text()
    code, _, err = run_cli("study", second, "--out", tmp_path / "o", "--workers", "1", "-q")
    assert code == 2 and "different study" in err and "errors 'uniform:0.25,0.05' there, 'none' here" in err
    assert "frames 'none' there, 'base' here" in err
    assert (tmp_path / "o" / "runs.csv").read_text() == before
    # more seeds of the same spec resume
    (tmp_path / "c.toml").write_text(STUDY.replace("seeds = 2", "seeds = 3"))
    code, out, _ = run_cli("study", tmp_path / "c.toml", "--out", tmp_path / "o", "--workers", "1")
    assert code == 0 and "1 runs done, 2 already" in " ".join(out.split())


def test_a_scheduler_that_is_not_dask_is_one_line_within_seconds(tmp_path, run_cli):
    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    study = tmp_path / "s.toml"
    study.write_text(STUDY)
    try:
        start = time.perf_counter()
        code, _, err = run_cli("study", study, "--out", tmp_path / "o", "--scheduler",
                               f"tcp://127.0.0.1:{server.server_address[1]}")
        elapsed = time.perf_counter() - start
    finally:
        server.shutdown()
    assert code == 2 and "not a Dask scheduler" in err and err.count("\n") == 1 and elapsed < 30
    assert not (tmp_path / "o").exists()  # a failed start leaves nothing behind


def test_local_studies_run_without_dask(tmp_path, monkeypatch):
    from robocal.study import engine

    spec = parse_study(STUDY, source="s.toml")
    here = run_study(spec, tmp_path / "here", workers=1)
    monkeypatch.setattr(engine, "_has_dask", lambda: False)
    pool = run_study(spec, tmp_path / "pool", workers=2)
    strip = [{k: v for k, v in r.items() if k != "time_s"} for r in here.rows]
    assert [{k: v for k, v in r.items() if k != "time_s"} for r in pool.rows] == strip


# --- reflectors -----------------------------------------------------------------------------

def _reflector_data(n, seed):
    """Two reflectors on a KR5's flange, each pose measured at both, far from the robot's frame."""
    rng = np.random.default_rng(seed)
    lim = np.radians(ind.LIMITS_DEG["kr5-arc"]) * 0.8
    q = np.repeat(rng.uniform(lim[:, 0], lim[:, 1], (n, 6)), 2, axis=0)
    base = frame_from_values([2000.0, -500.0, 300.0, 0.1, 0.05, 1.0])
    g = ind.geometry("kr5-arc", {"a2": 0.2})
    tools = {"A": frame_from_values([30.0, 0.0, 50.0]), "B": frame_from_values([-30.0, 20.0, 50.0])}
    targets = ["A", "B"] * n
    pos = np.array([ind.pose(g, qi, base, tools[t])[:3, 3] for qi, t in zip(q, targets)])
    return Measurements(q=q, position=pos + rng.normal(0, 0.01, pos.shape), targets=tuple(targets),
                        pose_ids=tuple(f"P{i // 2}" for i in range(2 * n)))


def test_evaluate_and_compensate_with_a_target_column(tmp_path, run_cli):
    data = tmp_path / "d.csv"
    data.write_text(measurements_to_csv(_reflector_data(30, 3)))
    for frames in ((), ("--frames", "auto"), ("--frames", "base+tool")):
        code, out, err = run_cli("evaluate", "kr5-arc", data, "--json", *frames)
        assert code == 0, err
        assert json.loads(out)["position"]["rms"] < 1.0  # nominal joints, fitted frames: the a2 error remains
    cal = tmp_path / "cal.toml"
    assert run_cli("calibrate", "kr5-arc", data, "--export", cal, "-q")[0] == 0
    code, out, err = run_cli("evaluate", cal, data, "--json")
    assert code == 0 and json.loads(out)["position"]["rms"] < 0.03
    commands, goals = tmp_path / "c.csv", tmp_path / "goals.csv"
    lines = data.read_text().splitlines()  # the measured joints as goals: place each reflector where
    goals.write_text("\n".join(",".join(line.split(",")[:8]) for line in lines) + "\n")  # the nominal says
    code, _, err = run_cli("compensate", "kr5-arc", cal, goals, "--out", commands)
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(commands.read_text())))
    assert all(r["status"] == "ok" for r in rows) and max(float(r["residual_mm"]) for r in rows) < 1e-5


# --- models and data ----------------------------------------------------------------------------

def test_a_residual_process_that_spends_the_data_is_said_loudly():
    meas = _kr5_campaign(40, 4)
    res, said = _said(calibrate, "kr5-arc", meas, model="residual")
    assert any("degrees of freedom" in s and "fitted, not its accuracy" in s for s in said)
    assert res.robot.residual.dof > 0.5 * 3 * 40 - res.robot.n_joints * 4


def test_auto_never_keeps_a_rung_that_predicts_worse_than_geometry():
    from robocal.calibration.select.choice import Candidate, choose

    rng = np.random.default_rng(5)
    geometric = rng.normal(0, 0.3, (200, 3))
    noisy_but_lucky = geometric * rng.choice([0.2, 2.5], (200, 1))  # a rung that does worse on average
    best = geometric * 0.97
    rungs = [Candidate((), False, None, geometric), Candidate(("harmonics",), False, None, noisy_but_lucky),
             Candidate(("compliance",), False, None, best)]
    assert rungs[1].cv_rms > rungs[0].cv_rms
    chosen = choose(rungs, np.arange(200))
    assert chosen is not rungs[1] and chosen.cv_rms <= rungs[0].cv_rms


def _still_joint_campaign(jitter_deg: float):
    rng = np.random.default_rng(6)
    lim = np.radians(ind.LIMITS_DEG["kr5-arc"]) * 0.8
    q = rng.uniform(lim[:, 0], lim[:, 1], (300, 6))
    q[:, 0] = math.radians(30.0) + math.radians(jitter_deg) * rng.standard_normal(300)
    base = frame_from_values([2500.0, -800.0, 300.0, 0.1, -0.05, 1.2])
    tool = frame_from_values([40.0, 10.0, 120.0])
    meas = _kr5_campaign(300, 7, q=q, base=base, tool=tool)
    return meas.subset(np.arange(200)), meas.subset(np.arange(200, 300))


def test_a_joint_that_never_moved_has_its_parameters_dropped_with_the_reason():
    cal, val = _still_joint_campaign(0.002)  # read-back jitter only: it must not separate joint 1's geometry
    full, said = _said(calibrate, "kr5-arc", cal, frames="base+tool", validate=val)
    reasons = full.identifiability.reasons
    for name in ("a1", "alpha1", "theta2"):
        assert reasons[name].kind == "still_joint" and reasons[name].joints == (1,)
        assert "needs the motion of joint 1, which never moved" in reasons[name].text()
    assert not any(n in full.names for n in ("a1", "alpha1", "theta1", "d1", "theta2", "d2"))
    assert any("joint 1 never moves" in s for s in said)
    assert not any("ill-conditioned" in s or "implausible" in s for s in said)
    assert full.metrics["validation_after"].position["rms"] < 0.02 * math.sqrt(3) * 1.15


def test_a_joint_that_never_moved_gives_the_model_with_it_folded_into_the_base():
    cal, val = _still_joint_campaign(0.0)
    full, _ = _said(calibrate, "kr5-arc", cal, frames="base+tool")
    g = ind.geometry("kr5-arc")  # the same arm with joint 1 folded into its base: five joints
    folded_base = (ind._rz(math.radians(30.0) + g["theta"][0]) @ ind._trans(0, 0, g["d"][0])
                   @ ind._trans(g["a"][0], 0, 0) @ ind._rx(g["alpha"][0]) @ ind._rz(g["theta"][1]))
    robot = load_robot("kr5-arc")
    five = robot.replace(geometry=robot.geometry[1:].copy(), limits=robot.limits[1:], base=folded_base)
    five.geometry[0, 2] = 0.0  # θ2 now lives in the base
    folded, _ = _said(calibrate, five, Measurements(q=cal.q[:, 1:], position=cal.position), frames="base+tool")
    assert np.abs(full.robot.positions(val.q) - folded.robot.positions(val.q[:, 1:])).max() < 1e-4


def test_the_final_guard_keeps_geometry_over_a_rich_model_that_fits_worse():
    from dataclasses import replace

    from robocal.calibration.config import CalibrationConfig
    from robocal.calibration.fit.parametric import fit_parametric, term_spec
    from robocal.calibration.inputs import load_inputs
    from robocal.calibration.judge.guard import guard
    from robocal.calibration.select.selection import Chosen

    meas = _kr5_campaign(60, 8)
    cfg = CalibrationConfig(model="harmonics")
    inputs = load_inputs("kr5-arc", meas, None, cfg)
    rich = fit_parametric(inputs, cfg, term_spec(("harmonics",), meas, cfg))
    geometric = fit_parametric(inputs, cfg, term_spec((), meas, cfg))
    misled = replace(rich, estimate=rich.estimate.replace(x=rich.estimate.x + 1e-3))
    kept = guard(Chosen("harmonics", misled, geometric=geometric))
    assert kept.name == "geometric" and kept.fit is geometric
    assert any("worse than geometry alone" in n for n in kept.notes)
    # and a calibration that made things worse than the nominal joints returns those
    lost = replace(geometric, estimate=geometric.estimate.replace(x=geometric.estimate.x + 0.05))
    kept = guard(Chosen("geometric", lost, geometric=lost))
    assert not np.any(kept.fit.estimate.x) and any("nominal joint geometry is returned" in n for n in kept.notes)


def test_outside_its_region_the_whole_model_is_used_and_its_uncertainty_says_how_well(tmp_path, run_cli):
    """Harmonics of joint 2 identified over 40° of its range, used 80° further on: the model is
    used whole (no fallback), and its predicted uncertainty, grown as the covariance says, names
    those poses and accounts for their errors."""
    def gears(q):  # a transmission error of joint 2, which the geometry cannot take
        dq = np.zeros_like(q)
        dq[:, 1] = 0.004 * np.cos(q[:, 1]) + 0.003 * np.sin(2 * q[:, 1])
        return dq

    rng = np.random.default_rng(9)
    lim = np.radians(ind.LIMITS_DEG["kr5-arc"]) * 0.8
    narrow = rng.uniform(lim[:, 0], lim[:, 1], (300, 6))
    narrow[:, 1] = rng.uniform(math.radians(-90), math.radians(-50), 300)  # joint 2 over 40° only
    far = narrow.copy()
    far[:, 1] += math.radians(80)
    g = ind.geometry("kr5-arc", {"a2": 0.2, "d4": -0.15})

    def measure(q, noise=0.01):
        return Measurements(q=q, position=np.array([ind.pose(g, qi)[:3, 3] for qi in q + gears(q)])
                            + rng.normal(0, noise, (len(q), 3)))

    within = np.clip(narrow[200:], narrow[:200].min(axis=0), narrow[:200].max(axis=0))
    cal, inside, outside = measure(narrow[:200]), measure(within, 0.0), measure(far[200:], 0.0)
    # harmonics of 0.23° and 0.17°, several times a real gear's: the prior says so (with the default
    # 0.05°, poses over 40° of the joint could not tell the amplitudes from the geometry's, and the
    # prior would hold them, rightly, near a real robot's)
    res, _ = _said(calibrate, "kr5-arc", cal, model="harmonics", frames="none", harmonics=3, noise=0.01,
                   prior="harmonic=0.3")
    rich = res.robot
    assert rich.region is not None and rich.region.sigma_mm > 0 and rich.uncertainty is not None
    path = tmp_path / "rich.toml"
    save_robot(rich, path)
    code, out, err = run_cli("evaluate", path, _write(tmp_path / "far.csv", outside), "--json", "--uncertainty")
    assert code == 0 and "poses have a predicted position uncertainty above 3× its median" in err
    shown = json.loads(out)
    error = np.linalg.norm(outside.position - rich.positions(outside.q), axis=1)
    assert shown["position"]["rms"] == pytest.approx(np.sqrt(np.mean(error ** 2)), rel=1e-9)  # the model itself
    sigma = np.array([p["sigma_mm"] for p in shown["uncertainty"]["per_pose"]])
    assert np.median(sigma) > 3 * rich.region.sigma_mm  # far less known there, and it says so
    z = error / sigma
    assert 0.5 < np.sqrt(np.mean(z ** 2)) < 2.0, np.sqrt(np.mean(z ** 2))  # and by about as much as it errs
    code, out, err = run_cli("evaluate", path, _write(tmp_path / "in.csv", inside), "--json")
    assert code == 0 and "uncertainty above" not in err
    assert json.loads(out)["position"]["rms"] == pytest.approx(
        np.sqrt(np.mean(np.sum((inside.position - rich.positions(inside.q)) ** 2, axis=1))), rel=1e-9)
    legacy = 'fallback = "rich.geometric.toml"\n' + path.read_text()
    (tmp_path / "old.toml").write_text(legacy)  # an earlier file naming a geometric fallback: said, not used
    code, out, err = run_cli("evaluate", tmp_path / "old.toml", tmp_path / "in.csv", "--json")
    assert code == 0 and "key 'fallback'" in err and "is not used" in err, err


def _write(path, meas):
    path.write_text(measurements_to_csv(meas))
    return path


def test_compensating_with_a_tracker_target_tool_says_so_and_serves_the_tcp(tmp_path):
    from robocal.compensation import compensate
    from robocal.io.goals import Goals

    nominal = load_robot("kr5-arc")
    target = frame_from_values([60.0, 20.0, 90.0, 0.0, math.pi / 2, 0.0])
    calibrated = nominal.replace(tool=target)  # what a calibration on tracker data exports
    rng = np.random.default_rng(10)
    q = rng.uniform(np.radians([-60, -100, 20, -90, 20, -90]), np.radians([60, -40, 100, 90, 100, 90]), (20, 6))
    res = compensate(nominal, calibrated, Goals(q=q, position=None, rotation=None, ids=[str(i) for i in range(20)]))
    assert any("it is the point the calibration measured, not the TCP" in w for w in res.warnings)
    assert res.status == ["ok"] * 20 and res.residual_mm.max() < 1e-5
    np.testing.assert_allclose(res.q, q, atol=1e-9)  # the same arm: nothing to correct at the TCP


def test_a_solution_on_another_branch_is_named_so():
    from robocal.inverse.local import _statuses

    reached, moved = np.array([True, True]), np.radians([45.0, 1.0])
    status = _statuses(reached, moved, np.array([50.0, 50.0]), np.zeros(2, bool), np.zeros(2, bool))
    assert status == ["branch", "ok"]


def test_evaluate_frames_auto_shows_the_fit_it_speaks_of(run_cli, tmp_path):
    tool = frame_from_values([80.0, 0.0, 60.0, math.pi / 2, 0.0, 0.3])  # a target turned against the flange
    base = frame_from_values([2000.0, 500.0, -300.0, 0.0, 0.0, 2.0])
    meas = _kr5_campaign(80, 11, base=base, tool=tool, measure="pose", noise=0.01)
    code, out, err = run_cli("evaluate", "kr5-arc", _write(tmp_path / "d.csv", meas), "--frames", "auto", "--json")
    assert code == 0
    said = float(err.split(" mm after registering")[0].split()[-1])
    shown = json.loads(out)
    assert said == pytest.approx(shown["position"]["rms"], rel=1e-3)
    assert shown["orientation"]["x"]["max"] < 1.0  # the orientations fit too


# --- repeated poses --------------------------------------------------------------------------

def test_repeated_cycles_and_encoder_jitter_are_one_pose():
    head = "pose_id,q1,q2,x,y,z\n"
    jitter = head + "D466,10,20,1,2,3\nD466,10.005156,20,1.01,2,3\nD467,30,40,5,6,7\n"
    meas = parse_measurements(jitter, n_joints=2)
    assert meas.n_poses == 2 and meas.q[0, 0] == pytest.approx(math.radians(10.002578))
    cycles = head.replace("pose_id,", "pose_id,cycle,") + "P1,1,10,20,1,2,3\nP1,2,10.3,20,1.2,2,3\nP2,1,30,40,5,6,7\n"
    meas = parse_measurements(cycles, n_joints=2)
    assert meas.n_poses == 3 and meas.pose_ids == ("P1", "P1", "P2")  # cycles stay, grouped by their pose


def test_library_warnings_stay_off_the_terminal(capsys):
    from robocal.cli.app import _one_line_warnings
    from robocal.exceptions import RobocalWarning

    shown = []
    show = _one_line_warnings(lambda *a: shown.append(a))
    show(RuntimeWarning("overflow encountered in multiply"), RuntimeWarning, "x.py", 1)
    show(RobocalWarning("a thing\n  to say"), RobocalWarning, "x.py", 1)
    assert shown == [] and capsys.readouterr().err == "robocal: warning: a thing to say\n"
