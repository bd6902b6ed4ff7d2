"""Joint terms: the gravity basis spans any mass distribution's torques, the term Jacobian
matches finite differences, and values round-trip through their vector form."""

import numpy as np
import pytest

from robocal.io.robotfile import load_robot
from robocal.math.so3 import orientation_error
from robocal.model.kinematics import chain_frames
from robocal.model.parameters import ParameterSpace
from robocal.model.terms import (
    G,
    JointInputs,
    JointTerms,
    TermSpec,
    basis,
    gravity_basis,
    joint_axes_and_links,
    payload_torque,
)


def _explicit_gravity_torques(robot, q, masses, points, direction):
    """Torque of point masses (per link: masses (n, k) kg at points (n, k, 3) mm in the link frame)
    about every joint axis, summed particle by particle."""
    Rs, origins = chain_frames(robot.convention, robot.geometry, q)
    axes, on_axis, _ = joint_axes_and_links(robot.convention, robot.geometry, q)
    g = G * np.asarray(direction) / np.linalg.norm(direction)
    tau = np.zeros(q.shape)
    n = robot.n_joints
    for j in range(n):
        world = origins[j + 1][:, None, :] + np.einsum("mab,kb->mka", Rs[j + 1], points[j])  # (m, k, 3)
        for i in range(j + 1):  # joint i moves link j when i ≤ j
            arm = (world - on_axis[:, i, None, :]) / 1000.0
            tau[:, i] += np.einsum("ma,mka->m", axes[:, i], np.cross(arm, masses[j][None, :, None] * g))
    return tau


@pytest.mark.parametrize("name", ["kr5-arc", "ur10", "er10l-c10"])
@pytest.mark.parametrize("convention", ["dh", "craig"])
def test_gravity_basis_spans_the_torques_of_any_mass_distribution(name, convention, rng):
    robot = load_robot(name)
    if convention == "craig":
        robot = robot.replace(convention="craig")
    q = rng.uniform(-3, 3, (80, 6))
    masses = rng.uniform(1, 20, (6, 4))
    points = rng.normal(size=(6, 4, 3)) * 200
    direction = np.array([0.1, -0.2, -1.0])
    tau = _explicit_gravity_torques(robot, q, masses, points, direction)
    phi = gravity_basis(robot.convention, robot.geometry, q, direction)
    for i in range(6):
        A = phi[:, i, i:].reshape(len(q), -1)
        coef, *_ = np.linalg.lstsq(A, tau[:, i], rcond=None)
        assert np.abs(A @ coef - tau[:, i]).max() < 1e-8 * max(np.abs(tau[:, i]).max(), 1.0), i


def test_payload_torque_is_a_point_mass_at_the_flange(rng):
    robot = load_robot("kr5-arc")
    q = rng.uniform(-2, 2, (20, 6))
    com = np.array([10.0, -20.0, 80.0])
    masses = np.zeros((6, 1))
    masses[5, 0] = 3.0
    points = np.zeros((6, 1, 3))
    points[5, 0] = com
    direction = np.array([0.0, 0.0, -1.0])
    ref = _explicit_gravity_torques(robot, q, masses, points, direction)
    got = payload_torque("dh", robot.geometry, q, direction, np.full(20, 3.0), com)
    np.testing.assert_allclose(got, ref, atol=1e-9)


@pytest.mark.parametrize("spec", [TermSpec({"compliance": ("torque", False)}),
                                  TermSpec({"compliance": ("gravity", True)}), TermSpec({"harmonics": 2}),
                                  TermSpec({"compliance": ("gravity", False), "harmonics": 1})])
def test_term_jacobian_matches_finite_differences(spec, rng):
    robot = load_robot("ur10")
    q = rng.uniform(-3, 3, (7, 6))
    torques = rng.normal(size=(7, 6)) * 50
    payload = rng.uniform(0, 5, 7)
    space = ParameterSpace.of(robot, terms=spec)
    joints = space.joint_data(q, JointInputs(torques, payload))
    dev = rng.normal(size=space.size) * 1e-3
    J, R, _ = space.jacobian(dev, q, joints=joints)
    t0 = space.size - space.n_term_params
    for k in range(t0, space.size):
        h = 1e-6 if space.names[k].startswith("compliance") else 1e-5  # Δq of 1e-5 to 1e-4 rad either way
        e = np.zeros(space.size)
        e[k] = h
        Rp, pp = space.pose(dev + e, q, joints=joints)
        Rm, pm = space.pose(dev - e, q, joints=joints)
        fd_p = (pp - pm) / (2 * h)
        fd_r = (orientation_error(Rp, R) - orientation_error(Rm, R)) / (2 * h)
        assert np.abs(J[:, :3, k] - fd_p).max() < 1e-5 * np.abs(fd_p).max() + 1e-8, space.names[k]
        assert np.abs(J[:, 3:, k] - fd_r).max() < 1e-5 * np.abs(fd_r).max() + 1e-11, space.names[k]


def test_values_round_trip_and_apply_moves_the_joints(rng):
    robot = load_robot("kr5-arc")
    spec = TermSpec({"compliance": ("gravity", True), "harmonics": 2})
    names = spec.names(6)
    values = rng.normal(size=len(names)) * 1e-4
    terms = JointTerms().with_vector(spec, 6, values)
    np.testing.assert_array_equal(terms.vector(spec, 6), values)
    assert terms.spec() == spec
    space = ParameterSpace.of(robot, terms=spec)
    calibrated = space.apply(np.concatenate([np.zeros(space.size - len(names)), values]))
    q = rng.uniform(-2, 2, (10, 6))
    load = JointInputs(payload=np.full(10, 2.0))
    B = basis(spec, "dh", robot.geometry, q, load, calibrated.terms)
    np.testing.assert_allclose(calibrated.effective_joints(q, load), q + B @ values, atol=1e-15)
    # harmonic 1 of joint 4 is exactly a cos(q4) + b sin(q4)
    h = JointTerms({"harmonics": np.zeros((6, 1, 2))})
    h.get("harmonics")[3, 0] = (2e-3, -1e-3)
    dq = robot.replace(terms=h).effective_joints(q) - q
    np.testing.assert_allclose(dq[:, 3], 2e-3 * np.cos(q[:, 3]) - 1e-3 * np.sin(q[:, 3]), atol=1e-15)
    assert np.abs(dq[:, [0, 1, 2, 4, 5]]).max() == 0


def test_mass_torques_are_the_derivative_of_the_potential_energy(rng):
    """robocal's torques of point masses against the independent simulator's central differences
    of the potential energy (its own 4×4 products)."""
    import independent as ind

    from robocal.model.terms import mass_torques

    robot = load_robot("kr5-arc")
    g = ind.geometry("kr5-arc")
    masses = rng.uniform(0.5, 20, 6)
    centres = rng.normal(0, 150, (6, 3))
    q = rng.uniform(-2.5, 2.5, (12, 6))
    ref = np.array([ind.gravity_torques(g, qi, masses, centres) for qi in q])
    got = mass_torques("dh", robot.geometry, q, np.array([0.0, 0.0, -1.0]), masses, centres)
    np.testing.assert_allclose(got, ref, atol=1e-6 * np.abs(ref).max())


@pytest.mark.parametrize("name", ["kr5-arc", "ur10"])
def test_the_simulated_mass_model_loads_the_joints_as_an_arm_does(name, rng):
    """Nominal masses give zero torque on a vertical first axis and the largest on the shoulder."""
    from robocal.model.terms import mass_torques, nominal_masses

    robot = load_robot(name)
    masses, centres = nominal_masses(robot.convention, robot.geometry)
    q = rng.uniform(-2, 2, (100, 6))
    tau = mass_torques(robot.convention, robot.geometry, q, np.array([0.0, 0.0, -1.0]), masses, centres)
    rms = np.sqrt(np.mean(tau**2, axis=0))
    assert rms[0] < 1e-9 and rms[1] == rms.max() and rms[1] > 20
