"""Robot and measurement files: round trips, validation, one-line errors with exit code 2."""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.measurements import Measurements, load_measurements, parse_measurements, save_measurements
from robocal.robotfile import builtin_names, load_robot, parse_robot, robot_to_toml, save_robot
from robocal.transforms import xyz_rpy_to_transform

GOOD = """
name = "test arm"
convention = "hayati"
[[joint]]
a = 170.0
alpha = -90.0
d = 0.0
theta = 0.0
limits = [-170.0, 170.0]
[[joint]]
a = 780.0
alpha = 0.0
d = 0.0
theta = -90.0
beta = 0.1
[base]
xyz = [1000.0, -2000.0, 50.0]
rpy = [10.0, -20.0, 130.0]
[tool]
xyz = [0.0, 0.0, 125.0]
"""


def test_builtins_load():
    names = builtin_names()
    for required in ("er10l-c10", "kr5-arc", "irb120", "ur10", "puma560"):
        assert required in names
    for name in names:
        r = load_robot(name)
        assert r.n_joints == 6


def test_robot_file_round_trip_is_exact(tmp_path, rng):
    r = parse_robot(GOOD)
    # random, not representable-in-few-digits values exercise the degree conversion
    g = r.geometry.copy()
    g[:, 1:3] += rng.normal(size=(2, 2)) * 0.01
    r = r.replace(geometry=g, targets={"B": xyz_rpy_to_transform([1, 2, 3], [0.1, 0.2, 0.3])})
    path = tmp_path / "r.toml"
    save_robot(r, path)
    back = load_robot(path)
    assert back.convention == r.convention and back.name == r.name
    np.testing.assert_array_equal(back.geometry, r.geometry)
    np.testing.assert_array_equal(back.limits, r.limits)
    np.testing.assert_allclose(back.base, r.base, atol=1e-12)
    np.testing.assert_allclose(back.tool, r.tool, atol=1e-12)
    np.testing.assert_allclose(back.targets["B"], r.targets["B"], atol=1e-12)
    # saving the reloaded robot gives the same text again
    assert robot_to_toml(back) == robot_to_toml(r)


BAD_ROBOTS = [
    ("convention = 'dh'\n", "needs at least one [[joint]]"),
    ("[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n", "missing key 'convention'"),
    ("convention = 'dhh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n", "unknown convention"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\n", "joint 1: missing key 'theta'"),
    ("convention = 'dh'\n[[joint]]\na='x'\nalpha=0\nd=0\ntheta=0\n", "joint 1, key 'a': expected a number"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nbeta=0\n", "only allowed with convention 'hayati'"),
    ("convention = 'dh'\n[[joint]]\na=0\nalhpa=0\nalpha=0\nd=0\ntheta=0\n", "joint 1: unknown key 'alhpa'"),
    ("convention = 'dh'\n[[joint]]\na=nan\nalpha=0\nd=0\ntheta=0\n", "must be finite"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=-1.5708\nd=0\ntheta=0\n", "looks like radians"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nlimits=[5, -5]\n", "low < high"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n[base]\nxyz=[1,2]\n", "[base] xyz"),
    ("convention = 'dh'\nreach = 3\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n", "unknown key 'reach'"),
    ("convention = 'dh'\n[[joint]\na=0\n", "not valid TOML"),
]


@pytest.mark.parametrize("text,message", BAD_ROBOTS)
def test_malformed_robot_files_give_one_line_and_exit_2(tmp_path, run_cli, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=None) as info:
        load_robot(path)
    assert message in str(info.value)
    assert str(path) in str(info.value)
    code, out, err = run_cli("evaluate", path, "whatever.csv")
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err and message in err


def test_radian_limits_are_rejected():
    text = "convention='dh'\n" + "[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nlimits=[-3.14, 3.14]\n" * 3
    with pytest.raises(InputError, match="look like radians"):
        parse_robot(text)


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
    ("q1;q2;x;y;z\n10;20;1;2;3\n", "separated by ;"),
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
