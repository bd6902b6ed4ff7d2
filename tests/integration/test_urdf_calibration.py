"""Calibrating through a URDF, against a truth planted by the independent URDF reader
(tests/independent_urdf.py): a 7-axis arm on a linear track, origin errors of 0.3 mm and
0.003 rad on every axis of every joint, measured from an unknown tracker frame.  The exported
URDF, read independently from ``measuring_frame`` to ``target``, predicts fresh poses; the
input's links, joint names and limits survive."""

import json
import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import independent_urdf as ind
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.calibration import calibrate
from robocal.io.measurements import save_measurements
from robocal.model.measurements import Measurements

TRACK_ARM = (Path(__file__).parents[1] / "data" / "track_arm.urdf").read_text()
NOISE = 0.02  # mm per axis


def _planted(text: str, rng) -> str:
    """The true arm: every movable joint's origin moved by up to 0.3 mm and 0.003 rad per axis."""
    root = ET.fromstring(text)
    for j in root.findall("joint"):
        if j.get("type") == "fixed":
            continue
        o = j.find("origin")
        xyz = np.array([float(v) for v in o.get("xyz").split()]) + rng.uniform(-3e-4, 3e-4, 3)
        rpy = np.array([float(v) for v in o.get("rpy").split()]) + rng.uniform(-3e-3, 3e-3, 3)
        o.set("xyz", " ".join(repr(float(v)) for v in xyz))
        o.set("rpy", " ".join(repr(float(v)) for v in rpy))
    return ET.tostring(root, encoding="unicode")


def _campaign(truth: ind.Urdf, tracker: np.ndarray, n: int, rng, noise: float):
    names = truth.movable("world", "tool0")
    lo = np.array([0.0] + [-2.0] * 7)
    hi = np.array([2.0] + [2.0] * 7)
    q = rng.uniform(lo, hi, (n, 8))
    points = np.array([(tracker @ truth.transform("world", "tool0", dict(zip(names, qi))))[:3, 3] for qi in q])
    exact = 1000.0 * points
    q_file = q.copy()
    q_file[:, 0] *= 1000.0  # the track in mm
    return Measurements(q=q_file, position=exact + rng.normal(0, noise, exact.shape)), exact


@pytest.mark.slow
def test_calibrated_urdf_predicts_fresh_poses_read_independently(tmp_path, rng):
    truth = ind.Urdf(_planted(TRACK_ARM, rng))
    tracker = np.eye(4)
    tracker[:3, :3] = Rotation.from_rotvec([0.2, -0.4, 2.1]).as_matrix()
    tracker[:3, 3] = [2.1, -3.4, 0.8]  # m
    meas, _ = _campaign(truth, tracker, 400, rng, NOISE)
    fresh, exact = _campaign(truth, tracker, 200, rng, NOISE)
    robot_file = tmp_path / "arm.urdf"
    robot_file.write_text(TRACK_ARM)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        res = calibrate(robot_file, meas, "lm", validate=fresh)
    messages = [str(w.message) for w in said] + res.notes
    assert res.frames in ("base", "base+tool") and any(m.startswith("frames auto") for m in messages)
    assert res.metrics["validation_before"].position["rms"] > 1.0
    out = tmp_path / "calibrated.urdf"
    assert res.export(out) == [out]
    text = out.read_text()
    # the input's links, joint names and limits survive, with robocal's frames added
    for name in ("world", "carriage", "l7", "flange", "tool0", "measuring_frame", "target"):
        assert f'<link name="{name}"' in text
    assert '<visual><geometry><box size="0.4 0.4 0.1" /></geometry></visual>' in text
    assert re.search(r'<joint name="a2" type="revolute">', text)
    assert '<limit lower="-2.09" upper="2.09" effort="1" velocity="1" />' in text
    # an independent reader, from measuring_frame to target, predicts the fresh poses
    exported = ind.Urdf(text)
    names = exported.movable("measuring_frame", "target")
    assert names == ["track", "a1", "a2", "a3", "a4", "a5", "a6", "a7"]
    predicted = np.array([1000.0 * exported.transform("measuring_frame", "target", dict(zip(
        names, [qi[0] / 1000.0, *qi[1:]])))[:3, 3] for qi in fresh.q])
    error = np.sqrt(np.mean(np.sum((predicted - exact) ** 2, axis=1)))
    assert error < 0.035, error
    # and robocal reads its own export back to the same figure
    save_measurements(fresh, tmp_path / "fresh.csv", prismatic=[True] + [False] * 7)
    from robocal.evaluation import evaluate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = evaluate(out, tmp_path / "fresh.csv")
    assert again.metrics.position["rms"] == pytest.approx(res.metrics["validation_after"].position["rms"], rel=1e-6)


def test_the_command_line_round_trip_of_a_urdf_with_joint_terms(tmp_path, run_cli):
    urdf_file, data, out = tmp_path / "kr5.urdf", tmp_path / "d.csv", tmp_path / "cal.urdf"
    code, text, err = run_cli("robots", "--urdf", "kr5-arc")
    assert code == 0 and text.startswith("<?xml")
    urdf_file.write_text(text)
    code, _, err = run_cli("simulate", urdf_file, "--poses", "120", "--measure", "position", "--noise", "0.01",
                           "--compliance", "2=5e-6,3=8e-6", "--seed", "3", "--out", data,
                           "--truth", tmp_path / "t.toml")
    assert code == 0, err
    assert "URDF tip link 'target' chosen" in err  # said, on one line
    validation = tmp_path / "v.csv"
    code, _, err = run_cli("simulate", tmp_path / "t.toml", "--poses", "80", "--measure", "position", "--noise",
                           "0.01", "--seed", "4", "--out", validation)
    assert code == 0, err
    code, stdout, err = run_cli("calibrate", urdf_file, data, "--frames", "none", "--model", "compliance",
                                "--export", out, "--out", tmp_path / "r.json", "--validate", validation)
    assert code == 0, err
    sidecar = tmp_path / "cal.robocal.toml"
    # what the URDF hands ROS, and what the whole model would: said where the file is written
    note = next(line for line in err.splitlines() if line.startswith("robocal: note: wrote"))
    # the model's own geometry was fitted beside its compliance: ROS gets the geometric calibration's instead
    assert f"wrote {out}: the geometric calibration's geometry and frames (the whole model is in {sidecar})" in note
    assert "reach the robot only through robocal filter and compensate" in note
    assert 'convention = "urdf"' in sidecar.read_text() and "compliance = " in sidecar.read_text()
    after = json.loads((tmp_path / "r.json").read_text())["metrics"]["after"]["position"]["rms"]
    code, whole, _ = run_cli("evaluate", sidecar, data, "--json")
    assert json.loads(whole)["position"]["rms"] == pytest.approx(after, rel=1e-9)
    code, through_urdf, err = run_cli("evaluate", out, data, "--json")  # the URDF names its whole model
    assert code == 0 and json.loads(through_urdf)["position"]["rms"] == pytest.approx(after, rel=1e-9)
    assert "the whole model is read from" in err and "cal.robocal.toml" in err
    sidecar.rename(tmp_path / "elsewhere.toml")  # the URDF alone would lack the compliance: refused
    code, _, err = run_cli("evaluate", out, data, "--json")
    assert code == 2 and "'cal.robocal.toml', which is missing" in err and err.count("\n") == 1
    text = out.read_text()  # without robocal's element the URDF is read as the geometry it holds
    out.write_text(text.replace('<robocal whole_model="cal.robocal.toml" />', ""))
    code, geometry_only, _ = run_cli("evaluate", out, data, "--json")
    assert json.loads(geometry_only)["position"]["rms"] > 3 * after  # the geometry alone lacks the compliance
    # the figures the calibration stated for each export are what each gives on the validation poses
    exports = json.loads((tmp_path / "r.json").read_text())["exports"]
    assert exports["figure"] == "validation"
    assert exports["geometry_and_frames"]["geometry_of"] == "the geometric calibration's"
    code, urdf_alone, _ = run_cli("evaluate", out, validation, "--json")
    assert exports["geometry_and_frames"]["position_rms_mm"] == pytest.approx(
        json.loads(urdf_alone)["position"]["rms"], rel=1e-9)
    code, whole, _ = run_cli("evaluate", tmp_path / "elsewhere.toml", validation, "--json")
    assert exports["whole_model"]["position_rms_mm"] == pytest.approx(json.loads(whole)["position"]["rms"], rel=1e-9)
    assert f"{exports['geometry_and_frames']['position_rms_mm']:.4f} mm RMS on the validation poses" in note


def test_the_target_hangs_from_the_tip_link(tmp_path):
    """MODEL §5: the target link's fixed joint starts at the tip link, and the chain read to it
    is the calibrated robot's (here the tip is tool0, below the flange by fixed joints)."""
    from robocal.io.urdf import parse_urdf, urdf_text
    from robocal.math.se3 import xyz_rpy_to_transform

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = parse_urdf(TRACK_ARM, source="arm.urdf")
    assert robot.urdf.tip_link == "tool0"
    robot = robot.replace(tool=xyz_rpy_to_transform([5, -7, 180], [0.1, 0.2, 0.3]),
                          base=xyz_rpy_to_transform([1000, 200, -50], [0, 0, 0.5]))
    text = urdf_text(robot)
    joint = ET.fromstring(text).find("joint[@name='target_joint']")
    assert joint.find("parent").get("link") == "tool0"
    reader = ind.Urdf(text)
    q = np.array([[300.0, 0.1, -0.4, 0.3, 1.0, -0.5, 0.7, 0.2]])
    names = reader.movable("measuring_frame", "target")
    T = reader.transform("measuring_frame", "target", dict(zip(names, [q[0, 0] / 1000, *q[0, 1:]])))
    np.testing.assert_allclose(1000 * T[:3, 3], robot.fk(q)[0, :3, 3], atol=1e-6)
