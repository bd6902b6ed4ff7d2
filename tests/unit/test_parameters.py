"""The parameter space: its exact Jacobian against finite differences, and batched poses."""

import numpy as np

from robocal.io.robotfile import load_robot
from robocal.math.se3 import xyz_rpy_to_transform
from robocal.math.so3 import orientation_error
from robocal.model.dh import CONVENTIONS  # the DH family (urdf: tests/unit/test_urdf.py)
from robocal.model.parameters import ParameterSpace, is_angle
from robocal.model.robot import Robot


def test_identification_jacobian_matches_finite_differences(rng):
    for convention in CONVENTIONS:
        g = rng.normal(size=(6, 5)) * [300, 1, 1, 300, 0.2]
        if convention != "hayati":
            g[:, 4] = 0
        robot = Robot(convention, g, base=xyz_rpy_to_transform([1500, -2000, 300], [0.4, -0.3, 2.0]),
                      tool=xyz_rpy_to_transform([10, 20, 150], [0.1, 0.2, 0.3]),
                      targets={"B": xyz_rpy_to_transform([-30, 0, 100], [0, 0.5, 0])})
        space = ParameterSpace.of(robot)
        q = rng.uniform(-np.pi, np.pi, size=(6, 6))
        tidx = np.array([0, 1, 0, 1, 1, 0])
        deviation = rng.normal(size=space.size) * 0.05  # away from the reference: tests the SO(3) Jacobians too
        J, R, _ = space.jacobian(deviation, q, tidx)
        h = 1e-6
        Jfd = np.zeros_like(J)
        for k in range(space.size):
            e = np.zeros(space.size)
            e[k] = h
            Rp, pp = space.pose(deviation + e, q, tidx)
            Rm, pm = space.pose(deviation - e, q, tidx)
            Jfd[:, :3, k] = (pp - pm) / (2 * h)
            Jfd[:, 3:, k] = (orientation_error(Rp, R) - orientation_error(Rm, R)) / (2 * h)
        rel = np.abs(J - Jfd).max(axis=(0, 1)) / (np.abs(Jfd).max(axis=(0, 1)) + 1e-12)
        assert rel.max() < 1e-6, (convention, dict(zip(space.names, rel)))


def test_apply_matches_batched_pose(rng):
    robot = load_robot("er10l-c10")
    space = ParameterSpace.of(robot)
    deviations = rng.normal(size=(20, space.size)) * 0.01
    q = rng.uniform(-np.pi, np.pi, size=(32, 6))
    R, p = space.pose(deviations, q)  # 20 particles × 32 poses in one call
    assert p.shape == (20, 32, 3)
    for i in (0, 7, 19):
        T = space.apply(deviations[i]).fk(q)
        np.testing.assert_allclose(p[i], T[:, :3, 3], atol=1e-9)
        np.testing.assert_allclose(R[i], T[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(space.points(deviations, q), p, atol=1e-12)


def test_names_and_units():
    space = ParameterSpace.of(load_robot("er10l-c10"), targets=("", "B"))
    assert space.names[:5] == ("a1", "alpha1", "theta1", "d1", "beta1")
    assert "tool[B]_rz" in space.names and "base_x" in space.names
    assert [is_angle(n) for n in ("a1", "alpha2", "beta3", "base_x", "base_rz", "tool[B]_y", "tool_rx")] == [
        False, True, True, False, True, False, True]
