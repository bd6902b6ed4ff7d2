"""Measurement files: round trips, averaging, column mapping, one-line errors."""

import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.io.measurements import load_measurements, parse_measurements, save_measurements
from robocal.math.se3 import xyz_rpy_to_transform
from robocal.model.measurements import Measurements


def _meas(rng, n=5, full=True):
    q = rng.uniform(-2, 2, size=(n, 6))
    pos = rng.normal(size=(n, 3)) * 500
    rot = xyz_rpy_to_transform(np.zeros((n, 3)), rng.normal(size=(n, 3)))[:, :3, :3] if full else None
    return Measurements(q=q, position=pos, rotation=rot)


def test_measurement_round_trip(tmp_path, rng):
    m = _meas(rng)
    save_measurements(m, tmp_path / "m.csv")
    back = load_measurements(tmp_path / "m.csv", n_joints=6)
    np.testing.assert_allclose(back.q, m.q, atol=1e-14)
    np.testing.assert_allclose(back.position, m.position, atol=1e-12)
    np.testing.assert_allclose(back.rotation, m.rotation, atol=1e-12)
    assert list(back.rows) == [2, 3, 4, 5, 6]


def test_rpy_columns_follow_spec_convention():
    text = "q1,q2,x,y,z,rx,ry,rz\n10,20,1,2,3,30,-40,50\n"
    m = parse_measurements(text)
    Rx = np.array([[1, 0, 0], [0, np.cos(0.5236), -np.sin(0.5236)], [0, np.sin(0.5236), np.cos(0.5236)]])
    r, p, y = np.radians([30, -40, 50])
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    np.testing.assert_allclose(m.rotation[0], Rz @ Ry @ Rx, atol=1e-15)


def test_repeated_rows_are_averaged_by_pose_id_and_target():
    text = (
        "pose_id,target,q1,q2,x,y,z\n"
        "p1,A,10,20,1.0,2.0,3.0\n"
        "p1,A,10,20,1.2,2.0,3.0\n"
        "p1,B,10,20,5.0,5.0,5.0\n"
        "p2,A,30,40,7.0,8.0,9.0\n"
    )
    m = parse_measurements(text)
    assert m.n_poses == 3 and m.n_raw == 4
    assert m.targets == ("A", "B", "A") and m.pose_ids == ("p1", "p1", "p2")
    np.testing.assert_allclose(m.position[0], [1.1, 2.0, 3.0])
    assert list(m.rows) == [2, 4, 5]


BAD_CSV = [
    ("", "file is empty"),
    ("q1,q2,x,y,z\n", "header but no data rows"),
    ("q1,q2,x,y\n10,20,1,2\n", "missing column 'z'"),
    ("q1,q3,x,y,z\n10,20,1,2,3\n", "'q2' is missing"),
    ("q1,q2,x,y,z,w\n10,20,1,2,3,4\n", "unknown column 'w'"),
    ("q1,q2,x,x,y,z\n10,20,1,1,2,3\n", "column 'x' appears twice"),
    ("q1,q2,x,y,z\n10,20,1,abc,3\n", "row 2, column 'y': 'abc' is not a number"),
    ("q1,q2,x,y,z\n10,20,1,2,3\n10,20,1,nan,3\n", "row 3, column 'y': value is not finite"),
    ("q1,q2,x,y,z\n10,20,1,inf,3\n", "value is not finite"),
    ("q1,q2,x,y,z\n10,20,1,5,2,3\n", "row 2: has 6 cells"),
    ("q1;q2;x;y;z\n10;20;1;2;3\n", "separated by ';'"),
    ("q1,q2,x,y,z,rx,ry\n10,20,1,2,3,4,5\n", "'rz' is missing"),
    ("q1,q2,x,y,z\n0.1,0.2,1,2,3\n0.3,0.1,1,2,3\n-1,2,1,2,3\n", "look like radians"),
    ("pose_id,q1,q2,x,y,z\np1,10,20,1,2,3\np1,10,20,9,2,3\n", "disagree by"),
    ("pose_id,q1,q2,x,y,z\np1,10,20,1,2,3\np1,11,20,1,2,3\n", "different joint values"),
    ("q1,q2,q3,x,y,z\n10,20,30,1,2,3\n", "robot has 2 joints"),
]


@pytest.mark.parametrize("text,message", BAD_CSV)
def test_malformed_measurement_files(tmp_path, run_cli, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_measurements(path, n_joints=2)
    assert message in str(info.value) and str(path) in str(info.value)
    robot = tmp_path / "two.toml"
    robot.write_text("convention='dh'\n" + "[[joint]]\na=100\nalpha=0\nd=0\ntheta=0\n" * 2)
    code, out, err = run_cli("evaluate", robot, path)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err


def test_column_mapping(tmp_path):
    m = parse_measurements("A1,A2,X,y,z\n10,20,1,2,3\n", columns={"A1": "q1", "A2": "q2", "X": "x"})
    np.testing.assert_allclose(m.position, [[1, 2, 3]])
    with pytest.raises(InputError, match="not in the file"):
        parse_measurements("q1,x,y,z\n10,1,2,3\n", columns={"Q": "q1"})


def test_header_less_or_space_separated_exports_are_named():
    for text in ("2.64e+03 1.62e+02 9.1e+02\n2.1e+03 1.1e+02 9.0e+02\n", "10,20,1,2,3\n11,21,1,2,3\n"):
        with pytest.raises(InputError, match="no header row, or not comma-separated"):
            parse_measurements(text)


def test_byte_order_mark_crlf_and_trailing_blank_lines_load():
    text = "\ufeffq1,q2,x,y,z\r\n10,20,1,2,3\r\n30,40,4,5,6\r\n\r\n\r\n"
    m = parse_measurements(text)
    assert m.n_poses == 2 and list(m.rows) == [2, 3]
