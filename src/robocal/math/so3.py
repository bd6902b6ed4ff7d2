"""Rotations: elementary rotations, rpy angles, the exponential map and its Jacobians.

All functions are batched over any leading shape: (..., 3) vectors, (..., 3, 3) matrices.
Angles in rad.
"""

from __future__ import annotations

import math

import numpy as np

#: below this angle (rad) the closed forms cancel catastrophically; series keep full precision
SERIES_ANGLE = 1e-4


def skew(w: np.ndarray) -> np.ndarray:
    """Cross-product matrix [w]× of vectors (..., 3) → (..., 3, 3)."""
    w = np.asarray(w, dtype=float)
    z = np.zeros(w.shape[:-1])
    return np.stack(
        [
            np.stack([z, -w[..., 2], w[..., 1]], -1),
            np.stack([w[..., 2], z, -w[..., 0]], -1),
            np.stack([-w[..., 1], w[..., 0], z], -1),
        ],
        -2,
    )


def rot_x(t: np.ndarray) -> np.ndarray:
    """Rotation about x by t (rad), batched: (...) → (..., 3, 3)."""
    t = np.asarray(t, dtype=float)
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(t: np.ndarray) -> np.ndarray:
    """Rotation about y by t (rad), batched: (...) → (..., 3, 3)."""
    t = np.asarray(t, dtype=float)
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(t: np.ndarray) -> np.ndarray:
    """Rotation about z by t (rad), batched: (...) → (..., 3, 3)."""
    t = np.asarray(t, dtype=float)
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """(..., 3) roll, pitch, yaw in rad → R = Rz(yaw) Ry(pitch) Rx(roll), (..., 3, 3)."""
    rpy = np.asarray(rpy, dtype=float)
    return rot_z(rpy[..., 2]) @ rot_y(rpy[..., 1]) @ rot_x(rpy[..., 0])


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`; pitch in [−π/2, π/2], yaw = 0 chosen at gimbal lock."""
    R = np.asarray(R, dtype=float)
    if R.shape == (3, 3):
        return _rpy_one(R)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    cp = np.sqrt(R[..., 2, 1] ** 2 + R[..., 2, 2] ** 2)
    lock = cp < 1e-9
    roll = np.where(lock, np.arctan2(-R[..., 1, 2], R[..., 1, 1]), np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.where(lock, 0.0, np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    return np.stack([roll, pitch, yaw], -1)


def _rpy_one(R: np.ndarray) -> np.ndarray:
    """:func:`matrix_to_rpy` of one rotation on numpy's scalars (the same ufuncs, so the same bits; a
    program's ten thousand targets one at a time, without the arrays' overhead)."""
    r = R.tolist()
    pitch = np.arcsin(np.float64(min(max(-r[2][0], -1.0), 1.0)))
    cp = math.sqrt(r[2][1] * r[2][1] + r[2][2] * r[2][2])
    if cp < 1e-9:
        roll, yaw = np.arctan2(np.float64(-r[1][2]), np.float64(r[1][1])), 0.0
    else:
        roll, yaw = np.arctan2(np.float64(r[2][1]), np.float64(r[2][2])), np.arctan2(np.float64(r[1][0]),
                                                                                     np.float64(r[0][0]))
    return np.array([roll, pitch, yaw], dtype=float)


def _rodrigues_coefficients(w: np.ndarray):
    """sin θ/θ, (1 − cos θ)/θ², (θ − sin θ)/θ³ of rotation vectors (..., 3), θ = |w|, each (...)."""
    th2 = np.sum(w * w, -1)
    th = np.sqrt(th2)
    small = th < SERIES_ANGLE
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    c = np.where(small, 1.0 / 6.0 - th2 / 120.0, (ths - np.sin(ths)) / ths**3)
    return a, b, c


def _quadratic_in_skew(w: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """I + b [w]× + c [w]×², batched."""
    K = skew(w)
    return np.broadcast_to(np.eye(3), K.shape) + b[..., None, None] * K + c[..., None, None] * (K @ K)


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) in rad → rotation matrices (..., 3, 3) (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    a, b, _ = _rodrigues_coefficients(w)
    return _quadratic_in_skew(w, a, b)


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) → rotation vectors (..., 3) in rad, angle in [0, π]."""
    R = np.asarray(R, dtype=float)
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    th = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    small = th < SERIES_ANGLE
    factor = np.where(small, 0.5 + th**2 / 12.0, th / (2.0 * np.where(small, 1.0, np.sin(th))))
    w = factor[..., None] * v
    near_pi = th > np.pi - 1e-3
    if np.any(near_pi):
        # sin θ → 0 makes the antisymmetric part useless; take the axis from the
        # symmetric part instead (scipy does this carefully).
        from scipy.spatial.transform import Rotation

        w[near_pi] = Rotation.from_matrix(R[near_pi]).as_rotvec()
    return w


def orientation_error(R_measured: np.ndarray, R_model: np.ndarray) -> np.ndarray:
    """δ = log(R_measured · R_modelᵀ) (MODEL §2): rotation vectors (..., 3) in rad about the
    axes of the frame both rotations are expressed in (the measuring frame)."""
    return log_so3(np.asarray(R_measured) @ np.swapaxes(np.asarray(R_model), -1, -2))


def _jr_inv_coefficient(th: np.ndarray) -> np.ndarray:
    """c(θ) of J_r⁻¹(φ) = I + ½[φ]× + c(θ)[φ]×², with its series below SERIES_ANGLE."""
    small = th < SERIES_ANGLE
    ths = np.where(small, 1.0, th)
    return np.where(small, 1.0 / 12.0 + th**2 / 720.0, 1.0 / ths**2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths)))


def apply_right_jacobian_inv(phi: np.ndarray, w: np.ndarray) -> np.ndarray:
    """J_r⁻¹(φ) applied to vectors: log(Exp(φ)·Exp(ε)) ≈ φ + J_r⁻¹(φ) ε.

    phi: (m, 3) rotation vectors; w: (..., m, 3) vectors, one batch per leading index.
    Uses J_r⁻¹(φ) w = w + ½ φ×w + c(θ) φ×(φ×w), component by component: cross products
    on contiguous (…, m) arrays instead of 3×3 products or strided (…, m, 3) ones.
    """
    phi = np.asarray(phi, dtype=float)
    c = _jr_inv_coefficient(np.linalg.norm(phi, axis=-1))
    a0, a1, a2 = phi[:, 0], phi[:, 1], phi[:, 2]
    b0, b1, b2 = (np.ascontiguousarray(w[..., i]) for i in range(3))
    p0, p1, p2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0  # φ × w
    q0, q1, q2 = a1 * p2 - a2 * p1, a2 * p0 - a0 * p2, a0 * p1 - a1 * p0  # φ × (φ × w)
    out = np.empty(np.broadcast_shapes(phi.shape, w.shape))
    out[..., 0] = b0 + 0.5 * p0 + c * q0
    out[..., 1] = b1 + 0.5 * p1 + c * q1
    out[..., 2] = b2 + 0.5 * p2 + c * q2
    return out


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_l(φ): Exp(φ + ε) ≈ Exp(J_l(φ) ε) · Exp(φ).  (..., 3) → (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    _, b, c = _rodrigues_coefficients(phi)
    return _quadratic_in_skew(phi, b, c)


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """Nearest rotation (Frobenius) to each (..., 3, 3) matrix; with M a sum of rotations this
    is their chordal mean."""
    U, _, Vt = np.linalg.svd(M)
    D = np.ones(M.shape[:-1])
    D[..., 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """R (..., 3, 3) of unit quaternions (..., 4) (w, x, y, z), scalar first."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    R = np.empty(np.shape(w) + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return R


def matrix_quaternion(R: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of R (3, 3), w ≥ 0, from its largest diagonal term (Shepperd).
    (In Python floats, a program's ten thousand targets one at a time: the same operations as on
    numpy's scalars, the norm numpy's own.)"""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(R, float).tolist()
    trace = r00 + r11 + r22
    k, largest = 0, trace
    for i, v in enumerate((r00, r11, r22), 1):  # the first largest, as argmax
        if v > largest:
            k, largest = i, v
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = [s / 4, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s]
    else:
        M = ((r00, r01, r02), (r10, r11, r12), (r20, r21, r22))
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = 2.0 * math.sqrt(1.0 + M[i][i] - M[j][j] - M[m][m])
        q = [0.0] * 4
        q[0] = (M[m][j] - M[j][m]) / s
        q[1 + i] = s / 4
        q[1 + j] = (M[j][i] + M[i][j]) / s
        q[1 + m] = (M[m][i] + M[i][m]) / s
    out = np.array(q)
    out /= np.linalg.norm(out)
    return -out if out[0] < 0 else out
