"""The compiled kernels (fast extra) agree with the numpy path."""

import numpy as np
import pytest

from robocal import _fast
from robocal.kinematics import CONVENTIONS, Robot, chain_points
from robocal.measurements import Measurements
from robocal.objectives import Problem
from robocal.parameters import ParameterSpace
from robocal.transforms import xyz_rpy_to_transform

pytestmark = pytest.mark.skipif(not _fast.AVAILABLE, reason="numba (fast extra) not installed")


def _robot(convention, rng):
    g = rng.normal(size=(6, 5)) * [300, 1, 1, 300, 0.1]
    if convention != "hayati":
        g[:, 4] = 0
    return Robot(
        convention,
        g,
        base=xyz_rpy_to_transform([1000, -500, 200], [0.2, -0.1, 1.0]),
        tool=xyz_rpy_to_transform([10, 20, 120], [0.1, 0.0, 0.3]),
        targets={"B": xyz_rpy_to_transform([50, 0, 80], [0, 0.2, 0])},
    )


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("full_pose", [True, False])
@pytest.mark.parametrize("frames", [False, True])
def test_objective_kernel_equals_numpy(convention, full_pose, frames, rng):
    robot = _robot(convention, rng)
    q = rng.uniform(-3, 3, (25, 6))
    targets = tuple(rng.choice(["", "B"], 25))
    T = robot.fk(q, targets)
    meas = Measurements(
        q=q,
        position=T[:, :3, 3] + rng.normal(size=(25, 3)),
        rotation=T[:, :3, :3] if full_pose else None,
        targets=targets,
    )
    space = ParameterSpace.of(robot)
    names = [n for n in space.names if frames or not n.startswith(("base", "tool"))]
    prob = Problem(space, space.index(names), meas, k=3e3)
    X = rng.normal(size=(17, len(names))) * 1e-2
    for kind in ("sum_squares", "sum_norms"):
        a = prob.objective(X, kind, fast=False)
        b = prob.objective(X, kind, fast=True)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_points_kernel_equals_numpy(convention, rng):
    robot = _robot(convention, rng)
    space = ParameterSpace.of(robot)
    geom, base, tools = space.expand(rng.normal(size=(40, space.size)) * 1e-2)
    q = rng.uniform(-3, 3, (60, 6))
    got = _fast.points(
        _fast.CONVENTION_CODE[convention], _fast.trig(geom), base, np.ascontiguousarray(robot.tool), _fast.joint_trig(q)
    )
    # the kernel takes one shared tool: compare with the numpy path given the same one
    ref = chain_points(convention, geom, q, base, robot.tool[None, None])
    assert np.abs(got - ref).max() < 1e-9


def test_right_jacobian_inverse_kernel_equals_numpy(rng):
    from robocal.transforms import apply_right_jacobian_inv

    phi = rng.normal(size=(50, 3)) * np.logspace(-7, 0, 50)[:, None]
    w = rng.normal(size=(7, 50, 3))
    np.testing.assert_allclose(
        _fast.apply_right_jacobian_inv(phi, w), apply_right_jacobian_inv(phi, w), rtol=1e-13, atol=1e-13
    )
