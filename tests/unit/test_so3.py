"""Rotations: the exponential map, its Jacobians and the rpy convention against independent forms."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.math.so3 import (
    apply_right_jacobian_inv,
    exp_so3,
    left_jacobian,
    log_so3,
    matrix_to_rpy,
    orientation_error,
    rpy_to_matrix,
)


def test_exp_and_log_agree_with_scipy(rng):
    axes = rng.normal(size=(200, 3))
    w = axes / np.linalg.norm(axes, axis=1, keepdims=True) * np.logspace(-8, np.log10(3.1), 200)[:, None]
    np.testing.assert_allclose(exp_so3(w), Rotation.from_rotvec(w).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(log_so3(exp_so3(w)), w, atol=1e-12)
    near_pi = np.array([[np.pi - 1e-5, 0.0, 0.0], [0.0, 0.0, np.pi - 1e-9]])
    np.testing.assert_allclose(log_so3(exp_so3(near_pi)), near_pi, atol=1e-7)


def test_rpy_is_rz_ry_rx(rng):
    rpy = rng.uniform(-1.5, 1.5, (50, 3))
    ref = Rotation.from_euler("ZYX", rpy[:, ::-1]).as_matrix()
    np.testing.assert_allclose(rpy_to_matrix(rpy), ref, atol=1e-14)
    np.testing.assert_allclose(matrix_to_rpy(ref), rpy, atol=1e-12)


def test_orientation_error_is_log_of_measured_times_model_transposed(rng):
    Rm, R = exp_so3(rng.normal(size=(10, 3))), exp_so3(rng.normal(size=(10, 3)))
    ref = Rotation.from_matrix(Rm @ np.swapaxes(R, -1, -2)).as_rotvec()
    np.testing.assert_allclose(orientation_error(Rm, R), ref, atol=1e-12)


def test_right_jacobian_inverse_matches_finite_differences(rng):
    axes = rng.normal(size=(5, 3))
    phi = axes / np.linalg.norm(axes, axis=1, keepdims=True) * np.array([[1e-6], [1e-3], [0.3], [1.5], [2.8]])
    w = rng.normal(size=(2, 5, 3))
    h = 1e-7
    fd = (log_so3(exp_so3(phi) @ exp_so3(h * w)) - log_so3(exp_so3(phi) @ exp_so3(-h * w))) / (2 * h)
    np.testing.assert_allclose(apply_right_jacobian_inv(phi, w), fd, atol=1e-6)


@pytest.mark.parametrize("scale", [1e-6, 0.3, 2.5])
def test_left_jacobian_matches_finite_differences(rng, scale):
    phi = rng.normal(size=3)
    phi *= scale / np.linalg.norm(phi)
    eps = rng.normal(size=3)
    h = 1e-7
    # Exp(φ + hε) Exp(φ)ᵀ ≈ Exp(h J_l ε)
    fd = (log_so3(exp_so3(phi + h * eps) @ exp_so3(phi).T) - log_so3(exp_so3(phi - h * eps) @ exp_so3(phi).T)) / (2 * h)
    np.testing.assert_allclose(left_jacobian(phi) @ eps, fd, atol=1e-7)


def test_quaternions_to_matrices_batched_match_scipy():
    from robocal.math.so3 import matrix_quaternion, quaternion_matrix

    rng = np.random.default_rng(4)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    want = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()  # scipy: scalar last
    np.testing.assert_allclose(quaternion_matrix(q), want, atol=1e-14)
    np.testing.assert_allclose(quaternion_matrix(q[7]), want[7], atol=1e-14)
    back = np.array([matrix_quaternion(R) for R in want])
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-12)
