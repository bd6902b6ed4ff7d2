"""UR controller calibrations: the kinematics YAML and the DH deltas, read, written and read again.
The chains are checked against products of 4×4 matrices written here (scipy rotations)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import independent as ind
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.calibration import calibrate
from robocal.exceptions import InputError
from robocal.io.robotfile import load_robot
from robocal.io.ur import joint_origins, parse_ur_deltas, parse_ur_kinematics, ur_kinematics_yaml
from robocal.simulation import simulate

YAML = Path(__file__).parents[1] / "data" / "ur" / "ur10_kinematics.yaml"
SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def _yaml_chain(path: Path, q: np.ndarray) -> np.ndarray:
    """Flange positions (m, 3) mm: Π Trans(x, y, z) · RPY(roll, pitch, yaw) · Rz(q_i), from the file's numbers."""
    values, seg = {}, None
    for line in path.read_text().splitlines():
        key, _, value = line.strip().partition(":")
        if key in SEGMENTS:
            seg, values[key] = key, {}
        elif seg and key in ("x", "y", "z", "roll", "pitch", "yaw"):
            values[seg][key] = float(value)
    out = []
    for qi in q:
        T = np.eye(4)
        for i, s in enumerate(SEGMENTS):
            v = values[s]
            O = np.eye(4)
            O[:3, :3] = Rotation.from_euler("xyz", [v["roll"], v["pitch"], v["yaw"]]).as_matrix()
            O[:3, 3] = [1000 * v["x"], 1000 * v["y"], 1000 * v["z"]]
            J = np.eye(4)
            J[:3, :3] = Rotation.from_euler("z", qi[i]).as_matrix()
            T = T @ O @ J
        out.append(T[:3, 3])
    return np.array(out)


Q = np.radians(np.random.default_rng(0).uniform(-180, 180, (20, 6)))


def test_the_kinematics_yaml_is_read_as_its_chain_and_round_trips_exactly():
    robot = load_robot(YAML)
    assert robot.convention == "urdf" and robot.joint_names[0] == "shoulder_pan_joint"
    assert robot.positions(Q) == pytest.approx(_yaml_chain(YAML, Q), abs=1e-9)
    text, notes = ur_kinematics_yaml(robot)
    again = parse_ur_kinematics(text)
    assert notes == [] and np.array_equal(again.geometry, robot.geometry)
    # the published UR10 kinematics are the built-in UR10's DH table
    assert robot.fk(Q) == pytest.approx(load_robot("ur10").fk(Q), abs=1e-6)


def test_a_calibrated_dh_model_goes_to_the_yaml_and_back_with_its_geometry(tmp_path):
    sim = simulate(load_robot("ur10"), 120, deviations="uniform:0.3,0.003", noise=0.01, angle_noise=1e-5, seed=2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate("ur10", sim.measurements, "lm", frames="none")
        written = result.export(tmp_path / "cal.yaml")
    assert [p.name for p in written][:2] == ["cal.yaml", "cal.robocal.toml"]
    back = load_robot(tmp_path / "cal.yaml")
    flange = result.robot.replace(base=np.eye(4), tool=np.eye(4))
    # the YAML ends at the last joint's frame; what the model puts after it (a6, α6) is said, for the TCP
    _, leftover = joint_origins(result.robot)
    assert back.fk(Q) @ leftover == pytest.approx(flange.fk(Q), abs=1e-9)
    said = [str(w.message) for w in caught]
    assert np.allclose(leftover, np.eye(4)) or any("add this offset to the controller's TCP" in s for s in said)
    # what the YAML cannot hold (the frames) is in the robot file beside it
    assert load_robot(tmp_path / "cal.robocal.toml").fk(Q) == pytest.approx(result.robot.fk(Q), abs=1e-9)


def test_dh_deltas_are_added_to_the_nominal_model(tmp_path):
    deltas = {"delta_a": [0, 0.0003, -0.0002, 0, 0, 0], "delta_d": [0.0001, 0, 0, 0.0002, -0.0001, 0],
              "delta_alpha": [0, 0.001, 0, -0.0005, 0, 0], "delta_theta": [0.002, -0.001, 0.0005, 0, 0.001, 0]}
    text = "[mounting]\n" + "".join(f"{k} = [ {', '.join(map(str, v))} ]\n" for k, v in deltas.items())
    robot = parse_ur_deltas(text, load_robot("ur10"), source="calibration.conf")
    # the independent simulator's DH product with the same deltas (m → mm)
    nominal = {"a": [0, -612.0, -572.3, 0, 0, 0], "alpha": np.radians([90, 0, 0, 90, -90, 0]),
               "theta": np.zeros(6), "d": [127.3, 0, 0, 163.941, 115.7, 92.2], "beta": np.zeros(6)}
    g = {k: np.array(v, float) for k, v in nominal.items()}
    g["a"] += 1000 * np.array(deltas["delta_a"])
    g["d"] += 1000 * np.array(deltas["delta_d"])
    g["alpha"] += deltas["delta_alpha"]
    g["theta"] += deltas["delta_theta"]
    expected = np.array([ind.pose(g, q)[:3, 3] for q in Q])
    assert robot.positions(Q) == pytest.approx(expected, abs=1e-9)


def test_the_command_line_reads_both_forms(tmp_path, run_cli):
    code, out, err = run_cli("robots", "--from-ur", YAML, "--out", tmp_path / "ur.toml")
    assert code == 0, err
    assert load_robot(tmp_path / "ur.toml").positions(Q) == pytest.approx(_yaml_chain(YAML, Q), abs=1e-9)
    conf = tmp_path / "calibration.conf"
    conf.write_text("delta_a = [0, 0, 0, 0, 0, 0]\ndelta_d = [0, 0, 0, 0, 0, 0]\n")
    code, _, err = run_cli("robots", "--from-ur", conf)
    assert code == 2 and "--nominal" in err
    code, _, err = run_cli("robots", "--from-ur", conf, "--nominal", "ur10")
    assert code == 2 and "missing delta_alpha" in err
    bad = tmp_path / "bad.yaml"
    bad.write_text(YAML.read_text().replace("  forearm:", "  elbow:"))
    code, _, err = run_cli("evaluate", bad, tmp_path / "none.csv")
    assert code == 2 and "unknown segment 'elbow'" in err


def test_deltas_with_cancelling_offsets_are_read_and_wrong_units_refused():
    """A controller's deltas may hold offsets of hundreds of metres on the parallel axes 2–4 that
    cancel (d along axes that stay parallel adds up): read as they are.  The same deltas in mm
    or degrees move the flange by metres: refused, naming the units."""
    nominal = load_robot("ur10")
    deltas = {"delta_a": [0, 0.0003, -0.0002, 0, 0, 0], "delta_d": [0.0001, 300.0, -300.0004, 0.0002, -0.0001, 0],
              "delta_alpha": [0.001, 0, 0, -0.0005, 0, 0], "delta_theta": [0.002, -0.001, 0.0005, 0, 0.001, 0]}

    def text(d):
        return "".join(f"{k} = [ {', '.join(map(str, v))} ]\n" for k, v in d.items())

    robot = parse_ur_deltas(text(deltas), nominal, source="calibration.conf")
    moved = np.linalg.norm(robot.positions(Q) - nominal.positions(Q), axis=1)
    assert 0.05 < moved.max() < 5.0  # millimetres: the offsets cancel
    for wrong in ({**deltas, "delta_a": [1000 * v for v in deltas["delta_a"]],
                   "delta_d": [1000 * v for v in deltas["delta_d"]]},
                  {**deltas, "delta_theta": list(np.degrees(deltas["delta_theta"]))}):
        with pytest.raises(InputError, match="not a calibration of it in m and rad"):
            parse_ur_deltas(text(wrong), nominal, source="calibration.conf")


def test_kinematics_yaml_in_millimetres_or_degrees_is_refused(tmp_path, run_cli):
    mm = tmp_path / "mm.yaml"
    mm.write_text(YAML.read_text().replace("z: 0.1273", "z: 127.3").replace("x: -0.612", "x: -612"))
    code, _, err = run_cli("robots", "--from-ur", mm, "--out", tmp_path / "x.toml")
    assert code == 2 and "metres, not millimetres" in err and "kinematics.shoulder.z" in err
    deg = tmp_path / "deg.yaml"
    deg.write_text(re.sub(r"roll: 1\.570796\d*", "roll: 90", YAML.read_text(), count=1))
    code, _, err = run_cli("robots", "--from-ur", deg, "--out", tmp_path / "x.toml")
    assert code == 2 and "radians, not degrees" in err and not (tmp_path / "x.toml").exists()
