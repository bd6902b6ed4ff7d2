"""Kinematic trees (robocal.model.kinematic_tree): read from a robot file in every convention, moved
as an independent URDF reader moves the URDF robocal writes of them, differentiated as finite
differences say, and split into chains that move as the tree does."""

import independent_urdf as ind
import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.io.robotfile import parse_robot, robot_to_toml
from robocal.io.urdf import urdf_text
from robocal.math.se3 import xyz_rpy_to_transform
from robocal.math.so3 import orientation_error
from robocal.model.kinematic_tree import TreeSpec
from robocal.model.parameters import ParameterSpace

#: a torso joint carrying two 3-joint arms, as URDF origins (xyz mm, rpy deg, axis)
TREE = """
name = "two arms on a torso"
convention = "urdf"
[[joint]]
xyz = [0, 0, 300]
rpy = [0, 0, 0]
axis = [0, 0, 1]
[[joint]]
parent = 1
xyz = [50, 200, 200]
rpy = [-90, 0, 10]
axis = [0, 0, 1]
[[joint]]
xyz = [0, 0, 150]
rpy = [0, 0, 0]
axis = [0, 1, 0]
[[joint]]
xyz = [0, 0, 350]
rpy = [0, 5, 0]
axis = [0, 1, 0]
[[joint]]
parent = 1
xyz = [50, -200, 200]
rpy = [90, 0, -10]
axis = [0, 0, 1]
[[joint]]
xyz = [0, 0, 150]
rpy = [0, 0, 0]
axis = [0, 1, 0]
[[joint]]
xyz = [0, 0, 350]
rpy = [0, 0, 3]
axis = [1, 0, 0]
[chains.left]
tip = 4
[chains.left.tool]
xyz = [0, 0, 80]
rpy = [0, 0, 0]
[chains.right]
tip = 7
[chains.right.tool]
xyz = [10, 0, 80]
rpy = [0, 20, 0]
"""


def _robot(text=TREE):
    robot = parse_robot(text)
    return robot.replace(base=xyz_rpy_to_transform([1200, -300, 50], [0.02, -0.01, 1.2]))


def test_the_shape_of_a_tree():
    robot = _robot()
    assert robot.tree.chains == {"left": (0, 1, 2, 3), "right": (0, 4, 5, 6)}
    assert robot.tree.shared() == (0,)
    assert robot.tree.describe() == "1 joint 1 (left, right); 2–4 joint 2…joint 4 (left); 5–7 joint 5…joint 7 (right)"
    with pytest.raises(ValueError, match="hangs from joint 1, not from 2"):
        TreeSpec((-1, 0, 0), {"a": (0, 1, 2)})


def test_a_tree_file_round_trips(rng):
    robot = _robot()
    again = parse_robot(robot_to_toml(robot))
    q = rng.uniform(-1, 1, (10, 7))
    for chain in ("left", "right"):
        assert np.abs(again.fk(q, chains=[chain] * 10) - robot.fk(q, chains=[chain] * 10)).max() < 1e-9


@pytest.mark.parametrize("read_back", [False, True])
def test_the_urdf_written_of_a_tree_moves_every_branch_as_an_independent_reader_says(read_back, rng):
    robot = _robot()
    robot = robot.replace(geometry=robot.geometry + np.pad(rng.normal(0, 1e-3, (7, 7)), ((0, 0), (0, 7))))
    if read_back:  # the same tree read back from its own URDF, and written again
        from robocal.io.urdf_tree import parse_urdf_tree

        robot = parse_urdf_tree(urdf_text(robot), tips=["target_left", "target_right"])
        assert robot.tree.names == ("target_left", "target_right")
    text = urdf_text(robot)
    reader = ind.Urdf(text)
    q = rng.uniform(-1, 1, (8, 7))
    names = [f"joint_{i + 1}" for i in range(7)] if robot.joint_names is None else list(robot.joint_names)
    for chain in robot.tree.names:
        mine = robot.fk(q, chains=[chain] * len(q))
        for row, T in zip(q, mine):
            M = reader.transform("measuring_frame", f"target_{chain}", dict(zip(names, row)))
            M[:3, 3] *= 1000.0
            assert np.abs(M - T).max() < 1e-9


def test_a_chain_of_the_tree_is_a_serial_robot_that_moves_as_its_branch(rng):
    robot = _robot()
    q = rng.uniform(-1, 1, (10, 7))
    for chain, path in robot.tree.chains.items():
        arm = robot.chain(chain)
        assert arm.tree is None and arm.n_joints == 4
        assert np.abs(arm.fk(q[:, list(path)]) - robot.fk(q, chains=[chain] * 10)).max() < 1e-12
    with pytest.raises(ValueError, match="not one of left, right"):
        robot.chain("head")


def test_the_tree_jacobian_matches_finite_differences(rng):
    robot = _robot()
    robot = robot.replace(targets={"left": robot.targets["left"], "right": robot.targets["right"]})
    space = ParameterSpace.of(robot)
    q = rng.uniform(-1, 1, (12, 7))
    chains = ["left", "right"] * 6
    chain, target = robot.tree.index(chains), space.target_index(chains)
    deviation = rng.normal(size=space.size) * 0.01
    J, R, _ = space.jacobian(deviation, q, target, chain=chain)
    h = 1e-6
    Jfd = np.zeros_like(J)
    for k in range(space.size):
        e = np.zeros(space.size)
        e[k] = h
        Rp, pp = space.pose(deviation + e, q, target, chain=chain)
        Rm, pm = space.pose(deviation - e, q, target, chain=chain)
        Jfd[:, :3, k] = (pp - pm) / (2 * h)
        Jfd[:, 3:, k] = (orientation_error(Rp, R) - orientation_error(Rm, R)) / (2 * h)
    assert np.abs(J - Jfd).max() < 1e-5 * max(1.0, np.abs(Jfd).max())
    # a joint off a row's chain moves none of its pose
    left = np.array(chains) == "left"
    assert np.all(J[left][:, :, space.index(["x5", "theta6", "rz7"])] == 0)


@pytest.mark.parametrize("text, message", [
    (TREE.replace("[chains.left]\ntip = 4", "[chains.left]\ntip = 9"), "tip must be a joint 1…7"),
    (TREE.replace("parent = 1\nxyz = [50, -200", "parent = 7\nxyz = [50, -200"),
     "parent must be a joint before this one"),
    ('convention = "hayati"\n' + "".join(f"[[joint]]\n{p}a = 100\nalpha = 0\nd = 0\ntheta = 0\n" for p in
                                          ("", "parent = 1\n", "parent = 1\n"))
     + "[chains.a]\ntip = 2\n[chains.b]\ntip = 3\n", "tree's joints are urdf origins"),
    (TREE.split("[chains.left]")[0], "names its chains: tables"),
    (TREE.replace("tip = 4\n", "tip = 4\nfoo = 1\n"), "foo"),
])
def test_a_malformed_tree_is_said_on_one_line(text, message):
    with pytest.raises(InputError, match=message) as info:
        parse_robot(text)
    assert "\n" not in str(info.value)


def test_a_tree_s_compliance_jacobian_matches_finite_differences_and_loads_a_joint_with_its_own_branch(rng):
    from robocal.model.terms import TermSpec, gravity_basis

    robot = _robot()
    robot = robot.replace(targets={"left": robot.targets["left"], "right": robot.targets["right"]})
    space = ParameterSpace.of(robot, terms=TermSpec({"compliance": ("gravity", False)}))
    q = rng.uniform(-1, 1, (10, 7))
    chains = ["left", "right"] * 5
    chain, target = robot.tree.index(chains), space.target_index(chains)
    joints = space.joint_data(q)
    deviation = rng.normal(size=space.size) * 0.01
    J, R, _ = space.jacobian(deviation, q, target, joints=joints, chain=chain)
    h = 1e-6
    terms = np.flatnonzero([n.startswith("gravity") for n in space.names])
    for k in terms:
        e = np.zeros(space.size)
        e[k] = h
        pp = space.points(deviation + e, q, target, joints=joints, chain=chain)
        pm = space.points(deviation - e, q, target, joints=joints, chain=chain)
        assert np.abs(J[:, :3, k] - (pp - pm) / (2 * h)).max() < 1e-5 * max(1.0, np.abs(J[:, :3, k]).max())
    # gravity askew to the torso's axis (a robot on a slope), so that it loads joint 1 too
    phi = gravity_basis("urdf", robot.geometry, q, np.array([0.6, 0.0, -0.8]), robot.tree.parents)
    # joint 1 (the torso) carries both arms; the left shoulder (2) its own arm (2–4), never the right (5–7)
    assert np.abs(phi[:, 0, 1:]).max() > 1.0
    assert np.all(phi[:, 1, 4:] == 0) and np.abs(phi[:, 1, 1:4]).max() > 1.0
    # the moment about joint 2's axis of a unit first mass moment of link 3, composed here from the file's
    # origins with scipy's rotations (the URDF rpy: extrinsic x, y, z)
    from scipy.spatial.transform import Rotation

    def turn(rpy_deg, axis, angle):
        return Rotation.from_euler("xyz", rpy_deg, degrees=True) * Rotation.from_rotvec(np.multiply(axis, angle))

    g = 9.80665 * np.array([0.6, 0.0, -0.8])
    for row, qm in enumerate(q):
        first = turn([0, 0, 0], [0, 0, 1], qm[0])
        axis2 = (first * Rotation.from_euler("xyz", [-90, 0, 10], degrees=True)).apply([0, 0, 1])
        R3 = (first * turn([-90, 0, 10], [0, 0, 1], qm[1]) * turn([0, 0, 0], [0, 1, 0], qm[2])).as_matrix()
        for a in range(3):
            expected = axis2 @ np.cross(R3 @ np.eye(3)[a], g)
            assert phi[row, 1, 2, a] == pytest.approx(expected, abs=1e-9)
