"""The ``urdf`` convention: each joint is an origin (xyz, rpy) followed by motion about its axis.

``A_i = Trans(p_i) · R_i · Exp(r_i) · M_i(q_i + offset_i)``

with p_i the origin's translation (mm, in the parent's frame), R_i = Rz(yaw) Ry(pitch) Rx(roll)
its nominal rotation, r_i a rotation vector about the origin's own axes (zero in a file;
what a calibration identifies), and M_i a rotation about the unit axis a_i (revolute) or a
translation along it (prismatic, mm).  Fixed joints are folded into their neighbours when
a chain is read (:mod:`robocal.io.urdf`).

Geometry (..., n, 14), last axis :data:`COLUMNS`: the seven error parameters of a joint
(x, y, z, rx, ry, rz, offset: the six of its origin, as FIGAROH parametrises a full pose,
and the joint's zero) come first, so that a deviation vector adds to them; then roll,
pitch, yaw, the axis, and 1.0 for a prismatic joint.  The offset is named ``theta{i}`` (rad)
for a revolute joint and ``d{i}`` (mm) for a prismatic one, as in the DH family.
"""

from __future__ import annotations

import numpy as np

from ..math.se3 import end_frame
from ..math.so3 import exp_so3, left_jacobian, rpy_to_matrix

COLUMNS: tuple[str, ...] = ("x", "y", "z", "rx", "ry", "rz", "offset", "roll", "pitch", "yaw", "ax", "ay", "az",
                            "prismatic")
X, Y, Z, RX, RY, RZ, OFFSET, ROLL, PITCH, YAW, AX, AY, AZ, PRISMATIC = range(14)
#: the error parameters of one joint, in column order
KINDS: tuple[str, ...] = COLUMNS[:7]
WIDTH = len(COLUMNS)


def joint_names(prismatic: np.ndarray) -> list[list[str]]:
    """Parameter names of each joint (1-based): x, y, z, rx, ry, rz and theta (or d)."""
    return [[*(f"{k}{i + 1}" for k in KINDS[:6]), f"{'d' if p else 'theta'}{i + 1}"] for i, p in enumerate(prismatic)]


def origin_rotation(geom: np.ndarray) -> np.ndarray:
    """R_i Exp(r_i), (..., n, 3, 3): each joint's origin rotation, identified part included."""
    return rpy_to_matrix(geom[..., ROLL:YAW + 1]) @ exp_so3(geom[..., RX:RZ + 1])


def _motion(axis: np.ndarray, t: np.ndarray, prismatic: np.ndarray):
    """Rotation (..., 3, 3) and translation (..., 3) of the joint motion by t about / along axis."""
    c, s = np.cos(t * (1 - prismatic)), np.sin(t * (1 - prismatic))
    k = axis
    K = np.zeros(k.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    R = np.eye(3) + s[..., None, None] * K + (1 - c)[..., None, None] * (K @ K)
    return R, k * (t * prismatic)[..., None]


def joint_transforms(geom: np.ndarray, q: np.ndarray, i: int, origins: np.ndarray):
    """Origin (R_o (..., 1, 3, 3), p (..., 1, 3)) and motion (R_m, p_m (..., m, …)) of joint i;
    ``origins``: every joint's :func:`origin_rotation` (..., n, 3, 3), made once for a chain's walk
    (the same numbers as joint i's own: each is its own products)."""
    g = geom[..., None, i, :]
    R_o = origins[..., None, i, :, :]
    p = g[..., X:Z + 1]
    R_m, p_m = _motion(g[..., AX:AZ + 1], q[..., i] + g[..., OFFSET], g[..., PRISMATIC])
    return R_o, p, R_m, p_m


def chain_frames(geom: np.ndarray, q: np.ndarray, base: np.ndarray | None = None, pre: bool = False):
    """Frames after each joint (and, with ``pre``, after each origin, before its motion):
    lists of rotations (..., m, 3, 3) and origins (..., m, 3) mm from the base frame on."""
    n = geom.shape[-2]
    if base is None:
        R, o = np.eye(3), np.zeros(3)
    else:
        R, o = base[..., None, :3, :3], base[..., None, :3, 3]
    Rs, origins, Rp, op = [R], [o], [], []
    rotations = origin_rotation(geom)
    for i in range(n):
        R_o, p, R_m, p_m = joint_transforms(geom, q, i, rotations)
        o = o + (R @ p[..., None])[..., 0]
        R = R @ R_o
        Rp.append(R)
        op.append(o)
        o = o + (R @ p_m[..., None])[..., 0]
        R = R @ R_m
        Rs.append(R)
        origins.append(o)
    return (Rs, origins, Rp, op) if pre else (Rs, origins)


def apply_chain(geom: np.ndarray, q: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Apply A_1 ⋯ A_n to the columns of V (..., m, 3, c), flange to base; the last column is a
    point (translations act on it), the others directions."""
    n = geom.shape[-2]
    e = np.zeros(V.shape[-1])
    e[-1] = 1.0
    rotations = origin_rotation(geom)
    for i in range(n - 1, -1, -1):
        R_o, p, R_m, p_m = joint_transforms(geom, q, i, rotations)
        V = R_m @ V + p_m[..., :, None] * e
        V = R_o @ V + p[..., :, None] * e
    return V


def twist_jacobian(geom: np.ndarray, q: np.ndarray, base=None, tool=None):
    """``(J, R_e, p_e, R_flange)``, J (n, 7, ..., m, 6) in the layout of
    :func:`robocal.model.dh.twist_jacobian`: x, y, z move the origin along its parent's axes;
    rx, ry, rz turn it about its own axes through its origin, R Exp(r + ε) = R Exp(r)
    Exp(J_r(r) ε); the offset moves the joint (its column is the joint value's column)."""
    Rs, origins, Rp, op = chain_frames(geom, q, base, pre=True)
    R_f = Rs[-1]
    R_e, p_e, shape = end_frame(R_f, origins[-1], tool)
    n = geom.shape[-2]
    J = np.zeros((n, len(KINDS)) + shape + (6,))
    # J_r(r) = J_l(−r): the origin's own axes, as the perturbation sees them (every joint's at once)
    own = left_jacobian(-geom[..., RX:RZ + 1])
    for i in range(n):
        g = geom[..., None, i, :]
        for k in range(3):
            J[i, X + k, ..., :3] = Rs[i][..., :, k]
        W = Rp[i] @ own[..., None, i, :, :]
        r = p_e - op[i]
        for k in range(3):
            w = W[..., :, k]
            J[i, RX + k, ..., :3] = np.cross(w, r)
            J[i, RX + k, ..., 3:] = w
        axis = (Rp[i] @ g[..., AX:AZ + 1, None])[..., 0]
        prismatic = g[..., PRISMATIC, None]
        J[i, OFFSET, ..., :3] = prismatic * axis + (1 - prismatic) * np.cross(axis, r)
        J[i, OFFSET, ..., 3:] = (1 - prismatic) * axis
    return J, R_e, p_e, R_f


def joint_axes(geom: np.ndarray, q: np.ndarray, base=None):
    """Each joint's axis (..., m, n, 3) and a point on it (..., m, n, 3) mm, in the base frame."""
    _, _, Rp, op = chain_frames(geom, q, base, pre=True)
    axes = [(Rp[i] @ geom[..., None, i, AX:AZ + 1, None])[..., 0] for i in range(geom.shape[-2])]
    shape = np.broadcast_shapes(*(a.shape for a in axes), *(o.shape for o in op))
    return (np.stack([np.broadcast_to(a, shape) for a in axes], -2),
            np.stack([np.broadcast_to(o, shape) for o in op], -2))


def reach(geom: np.ndarray) -> float:
    """A length scale of the arm (mm): the summed lengths of the joint origins."""
    return float(max(1.0, np.linalg.norm(geom[:, X:Z + 1], axis=1).sum()))
