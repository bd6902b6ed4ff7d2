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


def _shepperd_numpy(R):
    """Shepperd's quaternion of R on numpy's scalars: the form a program's quaternions were written
    with before the Python-float one, which must give the same bits (a filtered program's digits)."""
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    k = int(np.argmax([trace, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[m, m])
        q = np.empty(4)
        q[0] = (R[m, j] - R[j, m]) / s
        q[1 + i] = s / 4
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + m] = (R[m, i] + R[i, m]) / s
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def test_matrix_quaternion_in_python_floats_is_numpys_to_the_bit():
    from robocal.math.so3 import matrix_quaternion

    rng = np.random.default_rng(8)
    R = Rotation.random(4000, random_state=rng).as_matrix()
    turns = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]),
             Rotation.from_euler("z", 90, degrees=True).as_matrix()]
    for M in [*R, *turns]:
        assert np.array_equal(matrix_quaternion(M), _shepperd_numpy(M))


def test_one_rotations_angles_are_the_batched_ones_to_the_bit():
    """matrix_to_rpy of one matrix (numpy's scalars) against the same matrices batched (its arrays):
    random rotations, pitch at ±90° (gimbal lock) and within 1e-12 rad of it."""
    from robocal.math.so3 import matrix_to_rpy, rpy_to_matrix

    rng = np.random.default_rng(9)
    angles = rng.uniform(-3.2, 3.2, (6000, 3))
    angles[:500, 1] = np.pi / 2 * np.sign(rng.normal(size=500))
    angles[500:1000, 1] = np.pi / 2 + rng.normal(size=500) * 1e-12
    R = rpy_to_matrix(angles)
    batched = matrix_to_rpy(R)
    one = np.array([matrix_to_rpy(M) for M in R])
    assert np.array_equal(one, batched)
    np.testing.assert_allclose(rpy_to_matrix(one), R, atol=1e-9)
