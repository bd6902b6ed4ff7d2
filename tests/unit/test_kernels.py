"""The compiled kernels (numba backend) agree with the numpy path."""

import numpy as np
import pytest

from robocal.backend import numba_installed
from robocal.calibration.fit.problem import Setup
from robocal.math.se3 import xyz_rpy_to_transform
from robocal.model.dh import CONVENTIONS  # the DH family: the kernels chain these
from robocal.model.kinematics import chain_points
from robocal.model.measurements import Measurements
from robocal.model.parameters import ParameterSpace
from robocal.model.robot import Robot

pytestmark = pytest.mark.skipif(not numba_installed(), reason="numba (fast extra) not installed")


def _robot(convention, rng):
    g = rng.normal(size=(6, 5)) * [300, 1, 1, 300, 0.1]
    if convention != "hayati":
        g[:, 4] = 0
    return Robot(convention, g, base=xyz_rpy_to_transform([1000, -500, 200], [0.2, -0.1, 1.0]),
                 tool=xyz_rpy_to_transform([10, 20, 120], [0.1, 0.0, 0.3]),
                 targets={"B": xyz_rpy_to_transform([50, 0, 80], [0, 0.2, 0])})


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("full_pose", [True, False])
@pytest.mark.parametrize("frames", [False, True])
def test_objective_kernel_equals_numpy(convention, full_pose, frames, rng):
    robot = _robot(convention, rng)
    q = rng.uniform(-3, 3, (25, 6))
    targets = tuple(rng.choice(["", "B"], 25))
    T = robot.fk(q, targets)
    meas = Measurements(q=q, position=T[:, :3, 3] + rng.normal(size=(25, 3)),
                        rotation=T[:, :3, :3] if full_pose else None, targets=targets)
    space = ParameterSpace.of(robot)
    names = [n for n in space.names if frames or not n.startswith(("base", "tool"))]
    prob = Setup(space, meas, sigma_position=0.02, sigma_orientation=0.02 / 3e3**0.5).problem(names)
    X = rng.normal(size=(17, len(names))) * 1e-2
    for kind in ("sum_squares", "sum_norms"):
        a = prob.objective(X, kind, backend="numpy")
        b = prob.objective(X, kind, backend="numba")
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-9)


def test_residual_jacobian_is_the_same_on_both_backends(rng):
    robot = _robot("hayati", rng)
    q = rng.uniform(-3, 3, (40, 6))
    T = robot.fk(q)
    meas = Measurements(q=q, position=T[:, :3, 3], rotation=T[:, :3, :3])
    space = ParameterSpace.of(robot)
    x = rng.normal(size=space.size) * 1e-2
    a = Setup(space, meas, backend="numpy").problem(space.names).residual_jacobian(x)
    b = Setup(space, meas, backend="numba").problem(space.names).residual_jacobian(x)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_points_kernel_equals_numpy(convention, rng):
    from robocal.model import kernels

    robot = _robot(convention, rng)
    space = ParameterSpace.of(robot)
    geom, base, tools = space.expand(rng.normal(size=(40, space.size)) * 1e-2)
    q = rng.uniform(-3, 3, (60, 6))
    got = kernels.points(kernels.CONVENTION_CODE[convention], kernels.chain_constants(geom), base,
                         np.ascontiguousarray(robot.tool), kernels.joint_trig(q))
    ref = chain_points(convention, geom, q, base, robot.tool[None, None])
    assert np.abs(got - ref).max() < 1e-9


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_each_parallel_twin_gives_its_serial_kernels_numbers_to_the_bit(convention, rng):
    """The twins share one chain: the parallel one (called directly, as a large call runs it) gives, particle
    by particle, what the serial one gives, with and without orientations, both objectives, joints alone or
    frames."""
    from robocal.model import kernels

    robot = _robot(convention, rng)
    space = ParameterSpace.of(robot)
    geom, base, tools = space.expand(rng.normal(size=(9, space.size)) * 1e-2)
    m = 301  # not a multiple of any vector width
    q, tidx = kernels.joint_trig(rng.uniform(-3, 3, (m, 6))), rng.integers(0, tools.shape[1], m).astype(np.int64)
    pm = np.ascontiguousarray(rng.normal(size=(m, 3)) * 500)
    Rm = np.ascontiguousarray(np.stack([xyz_rpy_to_transform([0, 0, 0], r)[:3, :3] for r in rng.normal(size=(m, 3))]))
    conv = kernels.CONVENTION_CODE[convention]
    cols = np.array([0, 3, 7, 12, 16, 22], np.int64)
    X = rng.normal(size=(9, len(cols))) * 1e-2
    for use_rot in (True, False):
        for kind in (0, 1):
            args = (q, tidx, pm, Rm, use_rot, 0.7, kind)
            serial = kernels.objective(conv, geom, base, tools, *args)
            assert np.array_equal(kernels.objective_parallel(conv, geom, base, tools, *args), serial)
            shared = (conv, np.ascontiguousarray(robot.geometry), cols, X, base[0], tools[0])
            assert np.array_equal(kernels.objective_joints_parallel(*shared, *args),
                                  kernels.objective_joints(*shared, *args))
