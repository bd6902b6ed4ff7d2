"""Batched forward kinematics and twist Jacobians, whatever the convention.

End pose ``T = Base · A_1 ⋯ A_n · Tool``; the measured point is the origin of Tool.
Shapes: geometry (..., n, K), joint values (..., m, n) in rad, base (..., 4, 4),
tool (..., m, 4, 4) or (..., 1, 4, 4) (one tool per pose allows several reflectors on
one flange).  Lengths in mm, in the measuring frame.
"""

from __future__ import annotations

import numpy as np

from . import dh, urdf

CONVENTIONS: tuple[str, ...] = dh.CONVENTIONS + ("urdf",)


def check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise ValueError(f"unknown convention {convention!r}; expected one of {', '.join(CONVENTIONS)}")


def joint_kinds(convention: str) -> tuple[str, ...]:
    """Kinds of the geometric parameters of one joint of a convention, in geometry-column order
    (the urdf offset is named per joint: see :func:`joint_parameter_names`)."""
    check_convention(convention)
    return urdf.KINDS if convention == "urdf" else dh.joint_kinds(convention)


def geometry_width(convention: str) -> int:
    """Columns of a joint's geometry row: the parameters first, then fixed descriptors."""
    check_convention(convention)
    return urdf.WIDTH if convention == "urdf" else dh.WIDTH


def prismatic_mask(convention: str, geom: np.ndarray) -> np.ndarray:
    """(n,) True where a joint slides (its value in mm) rather than turns (rad)."""
    col = urdf.PRISMATIC if convention == "urdf" else dh.PRISMATIC
    return np.asarray(geom)[..., col] > 0.5


def joint_parameter_names(convention: str, geom: np.ndarray) -> list[list[str]]:
    """Each joint's parameter names (1-based), in geometry-column order: ``a1, alpha1, …`` or,
    for urdf, ``x1, y1, z1, rx1, ry1, rz1`` and ``theta1`` (``d1`` for a prismatic joint)."""
    if convention == "urdf":
        return urdf.joint_names(prismatic_mask(convention, geom))
    kinds = joint_kinds(convention)
    return [[f"{k}{i + 1}" for k in kinds] for i in range(np.asarray(geom).shape[-2])]


def joint_value_columns(convention: str, geom: np.ndarray) -> np.ndarray:
    """(n,) index, among a joint's parameter kinds, of the parameter its joint value adds to
    (θ, or d for a prismatic DH joint; the offset for urdf): its Jacobian column is the joint's."""
    if convention == "urdf":
        return np.full(np.asarray(geom).shape[-2], urdf.OFFSET)
    return np.where(prismatic_mask(convention, geom), dh.D, dh.THETA)


def reach(convention: str, geom: np.ndarray) -> float:
    """A length scale of the arm (mm), at least 1."""
    if convention == "urdf":
        return urdf.reach(geom)
    return float(max(1.0, np.abs(geom[:, dh.A]).sum() + np.abs(geom[:, dh.D]).sum()))


def _inputs(convention: str, geom, q):
    check_convention(convention)
    geom = np.asarray(geom, dtype=float)
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != geom.shape[-2]:
        raise ValueError(f"joint values have {q.shape[-1]} columns but the robot has {geom.shape[-2]} joints")
    return geom, q


def _tool_vectors(tool, columns: slice) -> np.ndarray:
    if tool is None:
        tool = np.eye(4)[None]
    return np.asarray(tool, dtype=float)[..., :3, columns]


def _to_base(V: np.ndarray, base) -> np.ndarray:
    if base is None:
        return V
    base = np.asarray(base, dtype=float)
    out = base[..., None, :3, :3] @ V
    out[..., 3 if V.shape[-1] == 4 else 0] += base[..., None, :3, 3]
    return out


def _apply(convention: str, geom, q, V):
    return urdf.apply_chain(geom, q, V) if convention == "urdf" else dh.apply_chain(convention, geom, q, V)


def chain_pose(convention: str, geom, q, base=None, tool=None):
    """End rotation (..., m, 3, 3) and position (..., m, 3) mm; tool None means the flange."""
    geom, q = _inputs(convention, geom, q)
    V = _to_base(_apply(convention, geom, q, _tool_vectors(tool, slice(0, 4))), base)
    return V[..., :3], V[..., 3]


def chain_points(convention: str, geom, q, base=None, tool=None) -> np.ndarray:
    """Positions (..., m, 3) mm of the measured point only: the cheap path of swarms."""
    geom, q = _inputs(convention, geom, q)
    V = _to_base(_apply(convention, geom, q, _tool_vectors(tool, slice(3, 4))), base)
    return V[..., 0]


def chain_frames(convention: str, geom, q, base=None):
    """Frames after each joint: lists of rotations (..., m, 3, 3) and origins (..., m, 3), n+1 long."""
    geom, q = _inputs(convention, geom, q)
    base = None if base is None else np.asarray(base, dtype=float)
    if convention == "urdf":
        return urdf.chain_frames(geom, q, base)
    return dh.chain_frames(convention, geom, q, base)


def joint_axes(convention: str, geom, q, base=None):
    """Each joint's axis (..., m, n, 3) and a point on it (..., m, n, 3) mm, in the base frame."""
    geom, q = _inputs(convention, geom, q)
    base = None if base is None else np.asarray(base, dtype=float)
    if convention == "urdf":
        return urdf.joint_axes(geom, q, base)
    Rs, origins = dh.chain_frames(convention, geom, q, base)
    n = geom.shape[-2]
    if convention == "craig":  # Rx(α) Tx(a) Rz(q): the joint turns about z of its own frame
        axes = [Rs[i + 1][..., :, 2] for i in range(n)]
        points = [origins[i + 1] for i in range(n)]
    else:  # Rz(q) first: the joint turns about z of the frame before it
        axes = [np.broadcast_to(Rs[i], Rs[-1].shape)[..., :, 2] for i in range(n)]
        points = [np.broadcast_to(origins[i], origins[-1].shape) for i in range(n)]
    return np.stack(axes, -2), np.stack(points, -2)


def chain_twist_jacobian(convention: str, geom, q, base=None, tool=None):
    """``(J, R_e, p_e, R_flange)``, J (n, K, ..., m, 6): see :func:`robocal.model.dh.twist_jacobian`."""
    geom, q = _inputs(convention, geom, q)
    base = None if base is None else np.asarray(base, dtype=float)
    tool = None if tool is None else np.asarray(tool, dtype=float)
    if convention == "urdf":
        return urdf.twist_jacobian(geom, q, base, tool)
    return dh.twist_jacobian(convention, geom, q, base, tool)
