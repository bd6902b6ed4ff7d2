"""URDF robots: the urdf convention's Jacobian against finite differences, the reader against an
independent URDF forward kinematics, DH robots written as URDF, and one-line errors."""

import math
import warnings
from pathlib import Path

import independent_urdf as ind
import numpy as np
import pytest

from robocal.exceptions import InputError, RobocalWarning
from robocal.io.robotfile import load_robot
from robocal.io.urdf import parse_urdf, urdf_text
from robocal.math.se3 import xyz_rpy_to_transform
from robocal.math.so3 import orientation_error
from robocal.model.parameters import ParameterSpace

DATA = Path(__file__).parents[1] / "data"

#: arbitrary axes, rotated origins, a prismatic joint, fixed joints inside the chain, a side branch
ARM = """<?xml version="1.0"?>
<!-- a test arm: nothing in it is unit-aligned -->
<robot name="odd arm">
  <link name="world"/>
  <link name="base"><inertial><mass value="3"/></inertial></link>
  <link name="l1"/><link name="l2"/><link name="l2b"/><link name="l3"/><link name="l4"/>
  <link name="camera"/><link name="tool0"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/>
    <origin xyz="0.1 -0.2 0.05" rpy="0.1 0.2 0.3"/></joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0.01 0.02 0.3" rpy="0.05 -0.1 0.7"/><axis xyz="0.1 0.2 0.97"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="track" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.2 0 0.05" rpy="0 1.2 0"/><axis xyz="1 1 0"/>
    <limit lower="-0.4" upper="0.6" effort="1" velocity="1"/></joint>
  <joint name="spacer" type="fixed"><parent link="l2"/><child link="l2b"/>
    <origin xyz="0 0.05 0.1" rpy="-0.4 0 0.2"/></joint>
  <joint name="j3" type="continuous"><parent link="l2b"/><child link="l3"/>
    <origin xyz="0.3 0.1 0" rpy="1.5707963 0 0"/><axis xyz="0 -1 0.2"/></joint>
  <joint name="side" type="revolute"><parent link="l2b"/><child link="camera"/>
    <origin xyz="0.05 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.25 -0.02 0.01" rpy="0.3 0.3 -0.3"/><axis xyz="-0.6 0.8 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l4"/><child link="tool0"/>
    <origin xyz="0 0 0.08" rpy="0 1.5707963267948966 0"/></joint>
</robot>
"""


def _load(text, **kw):
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        robot = parse_urdf(text, source="arm.urdf", **kw)
    return robot, [str(w.message) for w in said if issubclass(w.category, RobocalWarning)]


def _compare(robot, reference: ind.Urdf, base: str, tip: str, rng, n=40):
    names = reference.movable(base, tip)
    assert list(robot.joint_names) == names
    lo = np.where(np.isfinite(robot.limits[:, 0]), robot.limits[:, 0], -math.pi)
    hi = np.where(np.isfinite(robot.limits[:, 1]), robot.limits[:, 1], math.pi)
    q = rng.uniform(lo, hi, (n, robot.n_joints))
    T = robot.fk(q)
    for k in range(n):
        values = {name: q[k, i] / (1000.0 if robot.prismatic[i] else 1.0) for i, name in enumerate(names)}
        ref = reference.transform(base, tip, values)
        np.testing.assert_allclose(T[k, :3, 3], 1000.0 * ref[:3, 3], atol=1e-6)
        assert np.degrees(np.linalg.norm(orientation_error(ref[:3, :3], T[k, :3, :3]))) < 1e-6


def test_forward_kinematics_equals_an_independent_urdf_reader(rng):
    robot, said = _load(ARM)
    assert said == ["URDF tip link 'tool0' chosen (4 movable joints from 'world'); other leaves: camera "
                    "(choose with --tip-link)"]
    assert robot.prismatic.tolist() == [False, True, False, False]
    np.testing.assert_allclose(robot.limits[1], [-400.0, 600.0])  # mm
    assert np.all(np.isinf(robot.limits[2]))  # continuous
    _compare(robot, ind.Urdf(ARM), "world", "tool0", rng)
    # the side branch, from an inner base link
    side, said = _load(ARM, base_link="l1", tip_link="camera")
    assert not said
    _compare(side, ind.Urdf(ARM), "l1", "camera", rng)


@pytest.mark.parametrize("blank", ["", "\n"])
def test_the_ros_industrial_irb120_loads_as_published(blank, rng, tmp_path):
    text = (DATA / "irb120_ros_industrial.urdf").read_text()
    path = tmp_path / "irb120.urdf"
    path.write_text(blank + text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_robot(path)
    assert robot.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    _compare(robot, ind.Urdf(text), "base_link", "tool0", rng)


def test_identification_jacobian_matches_finite_differences(rng):
    robot, _ = _load(ARM)
    robot = robot.replace(base=xyz_rpy_to_transform([1500, -2000, 300], [0.4, -0.3, 2.0]),
                          tool=xyz_rpy_to_transform([10, 20, 150], [0.1, 0.2, 0.3]))
    space = ParameterSpace.of(robot)
    assert space.names[:14] == ("x1", "y1", "z1", "rx1", "ry1", "rz1", "theta1", "x2", "y2", "z2", "rx2", "ry2",
                                "rz2", "d2")
    q = rng.uniform(-1, 1, size=(6, 4)) * [1, 300, 1, 1]
    deviation = rng.normal(size=space.size) * 0.05  # away from the reference: the SO(3) Jacobians too
    J, R, _ = space.jacobian(deviation, q)
    h = 1e-6
    Jfd = np.zeros_like(J)
    for k in range(space.size):
        e = np.zeros(space.size)
        e[k] = h
        Rp, pp = space.pose(deviation + e, q)
        Rm, pm = space.pose(deviation - e, q)
        Jfd[:, :3, k] = (pp - pm) / (2 * h)
        Jfd[:, 3:, k] = (orientation_error(Rp, R) - orientation_error(Rm, R)) / (2 * h)
    rel = np.abs(J - Jfd).max(axis=(0, 1)) / (np.abs(Jfd).max(axis=(0, 1)) + 1e-12)
    assert rel.max() < 1e-6, dict(zip(space.names, rel))


@pytest.mark.parametrize("name", ["er10l-c10", "kr5-arc", "irb120", "ur10", "puma560"])
def test_built_in_robots_written_as_urdf_keep_their_kinematics(name, rng):
    robot = load_robot(name).replace(tool=xyz_rpy_to_transform([5, 10, 150], [0.2, 0.1, 0.3]))
    text = urdf_text(robot)
    back, _ = _load(text)
    assert back.convention == "urdf" and back.n_joints == robot.n_joints
    q = rng.uniform(-np.pi, np.pi, size=(50, robot.n_joints))
    np.testing.assert_allclose(back.fk(q), robot.fk(q), atol=1e-9)
    # and an independent reader agrees, from the measuring frame to the target
    ref = ind.Urdf(text)
    for k in range(5):
        values = dict(zip(ref.movable("measuring_frame", "target"), q[k]))
        np.testing.assert_allclose(1000 * ref.transform("measuring_frame", "target", values)[:3, 3],
                                   robot.fk(q[k:k + 1])[0, :3, 3], atol=1e-6)


BAD = [
    ("<robot><link name='a'/>", "not valid XML"),
    ("<robotx/>", "not a URDF"),
    ("<robot><link name='a'/><link name='b'/></robot>", "one root link"),
    ("<robot><link name='a'/><link name='b'/><joint name='j' type='floating'><parent link='a'/>"
     "<child link='b'/></joint></robot>", "joint 'j': floating joints are not supported"),
    ("<robot><link name='a'/><link name='b'/><joint name='j' type='revolute'><parent link='a'/>"
     "<child link='c'/></joint></robot>", "joint 'j': link 'c' is not defined"),
    ("<robot><link name='a'/><link name='b'/><joint name='j' type='revolute'><parent link='a'/>"
     "<child link='b'/><origin xyz='0 0'/></joint></robot>", "joint 'j', <origin xyz>: expected 3"),
    ("<robot><link name='a'/><link name='b'/><joint name='j' type='fixed'><parent link='a'/>"
     "<child link='b'/></joint></robot>", "no movable joint"),
]


@pytest.mark.parametrize("text,message", BAD)
def test_malformed_urdf_files_give_one_line_and_exit_2(tmp_path, run_cli, text, message):
    path = tmp_path / "bad.urdf"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            load_robot(path)
    assert message in str(info.value) and str(path) in str(info.value)
    code, out, err = run_cli("evaluate", path, "whatever.csv")
    assert code == 2 and err.count("\n") == 1 and message in err


def test_unknown_links_are_named(tmp_path, run_cli):
    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    code, out, err = run_cli("evaluate", path, "whatever.csv", "--tip-link", "tool1")
    assert code == 2 and "--tip-link" in err and "no link named 'tool1'" in err
    code, out, err = run_cli("evaluate", "kr5-arc", "whatever.csv", "--base-link", "base")
    assert code == 2 and "applies to URDF robots only" in err


def test_a_prismatic_dh_joint_is_a_slide_along_z(rng, tmp_path):
    """A linear track under a DH arm: the file's ``type = "prismatic"``, its values in mm in
    measurement files, its FK against a plain product of 4×4 transforms, and its Jacobian."""
    from robocal.io.measurements import load_measurements, save_measurements
    from robocal.io.robotfile import parse_robot, robot_to_toml
    from robocal.math.se3 import homogeneous
    from robocal.math.so3 import rot_x, rot_z
    from robocal.simulation import simulate

    arm = robot_to_toml(load_robot("kr5-arc")).split("[[joint]]", 1)[1]  # the KR5's joints, base and tool
    robot = parse_robot("convention = 'dh'\n[[joint]]\ntype = 'prismatic'\na = 0\nalpha = -90\nd = 300\n"
                        "theta = 90\nlimits = [0, 2500]\n[[joint]]" + arm)
    assert robot.prismatic.tolist() == [True] + [False] * 6
    np.testing.assert_allclose(robot.limits[0], [0, 2500])  # mm
    assert parse_robot(robot_to_toml(robot)).prismatic[0]
    q = np.column_stack([rng.uniform(0, 2500, 20), rng.uniform(-2, 2, (20, 6))])
    T = robot.fk(q)
    for k in range(20):
        ref = np.eye(4)
        for (a, al, th, d, _, slide), qi in zip(robot.geometry, q[k]):
            turn, length = (th, d + qi) if slide else (th + qi, d)
            ref = ref @ homogeneous(rot_z(turn), [0, 0, length]) @ homogeneous(rot_x(al), [a, 0, 0])
        np.testing.assert_allclose(T[k], ref @ robot.tool, atol=1e-9)
    # measurement files keep the slide in mm, the arm's joints in degrees
    sim = simulate(robot, 30, measure="position", seed=2)
    save_measurements(sim.measurements, tmp_path / "d.csv", prismatic=robot.prismatic)
    row = (tmp_path / "d.csv").read_text().splitlines()[1].split(",")
    assert 0 <= float(row[0]) <= 2500
    back = load_measurements(tmp_path / "d.csv", n_joints=7, prismatic=tuple(robot.prismatic))
    np.testing.assert_allclose(back.q, sim.measurements.q, atol=1e-9)
    # the Jacobian of the slide's d is its joint value's column
    space = ParameterSpace.of(robot)
    J, R, _ = space.jacobian(np.zeros(space.size), q[:5])
    h = 1e-4
    e = np.zeros(space.size)
    e[space.names.index("d1")] = h
    _, pp = space.pose(e, q[:5])
    _, pm = space.pose(-e, q[:5])
    np.testing.assert_allclose(J[:, :3, space.names.index("d1")], (pp - pm) / (2 * h), atol=1e-6)


@pytest.mark.parametrize("which", ["arm", "irb120"])
def test_evaluate_agrees_with_the_independent_reader_from_the_command_line(which, tmp_path, run_cli, rng):
    """`robocal evaluate FILE.urdf data.csv --json` on poses the independent reader computed:
    nothing left but rounding (1e-6 mm, 1e-6°)."""
    text = ARM if which == "arm" else "\n" + (DATA / "irb120_ros_industrial.urdf").read_text()
    path = tmp_path / f"{which}.urdf"
    path.write_text(text)
    ref = ind.Urdf(text)
    base, tip = ("world", "tool0") if which == "arm" else ("base_link", "tool0")
    names = ref.movable(base, tip)
    slide = [ref.joints[link]["type"] == "prismatic" for link in ref._path(base, tip)
             if ref.joints[link]["type"] != "fixed"]
    q = rng.uniform(-1.5, 1.5, (30, len(names)))
    q[:, slide] = rng.uniform(-0.3, 0.5, (30, sum(slide)))  # m
    rows = ["," .join([f"q{i + 1}" for i in range(len(names))] + ["x", "y", "z", "rx", "ry", "rz"])]
    from scipy.spatial.transform import Rotation

    for qi in q:
        T = ref.transform(base, tip, dict(zip(names, qi)))
        rz, ry, rx = Rotation.from_matrix(T[:3, :3]).as_euler("ZYX", degrees=True)
        values = [v * 1000 if s else math.degrees(v) for v, s in zip(qi, slide)]
        rows.append(",".join(repr(float(v)) for v in [*values, *(1000 * T[:3, 3]), rx, ry, rz]))
    (tmp_path / "data.csv").write_text("\n".join(rows) + "\n")
    code, out, err = run_cli("evaluate", path, tmp_path / "data.csv", "--json")
    assert code == 0, err
    import json

    metrics = json.loads(out)
    assert metrics["position"]["max"] < 1e-6
    assert max(metrics["orientation"][a]["max"] for a in "xyz") < 1e-6


def test_a_urdf_robot_round_trips_through_a_robot_file(rng):
    from robocal.io.robotfile import parse_robot, robot_to_toml

    robot, _ = _load(ARM)
    space = ParameterSpace.of(robot)
    calibrated = space.apply(rng.normal(size=space.size) * 0.01)  # identified rotations and zeros too
    back = parse_robot(robot_to_toml(calibrated))
    assert back.convention == "urdf" and back.joint_names == robot.joint_names
    q = rng.uniform(-1, 1, (30, 4)) * [1, 300, 1, 1]
    np.testing.assert_allclose(back.fk(q), calibrated.fk(q), atol=1e-9)
    np.testing.assert_allclose(back.limits, robot.limits)


def test_a_chain_s_origin_rotations_made_at_once_are_each_joint_s_own(rng):
    """A chain's walk makes every joint's origin rotation in one call (and the Jacobian every
    J_l(−r)): to the bit each joint's own, with particles and poses batched, identified rotations
    and prismatic joints among them."""
    from robocal.math.so3 import left_jacobian
    from robocal.model import urdf

    for lead in [(), (4,), (2, 3)]:
        geom = np.zeros(lead + (6, urdf.WIDTH))
        geom[..., :7] = rng.normal(0, 1, lead + (6, 7)) * [100, 100, 100, 0.01, 0.01, 0.01, 0.02]
        geom[..., urdf.ROLL:urdf.YAW + 1] = rng.uniform(-3, 3, lead + (6, 3))
        axes = rng.normal(size=lead + (6, 3))
        geom[..., urdf.AX:urdf.AZ + 1] = axes / np.linalg.norm(axes, axis=-1, keepdims=True)
        geom[..., urdf.PRISMATIC] = rng.uniform(size=lead + (6,)) < 0.3
        q = rng.uniform(-2, 2, lead + (9, 6))
        together, own = urdf.origin_rotation(geom), left_jacobian(-geom[..., urdf.RX:urdf.RZ + 1])
        for i in range(6):
            np.testing.assert_array_equal(urdf.origin_rotation(geom[..., None, i, :]),
                                          urdf.joint_transforms(geom, q, i, together)[0])
            np.testing.assert_array_equal(left_jacobian(-geom[..., None, i, urdf.RX:urdf.RZ + 1]),
                                          own[..., None, i, :, :])
