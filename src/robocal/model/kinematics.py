"""Batched forward kinematics and twist Jacobians, whatever the convention.

End pose ``T = Base · A_1 ⋯ A_n · Tool``; the measured point is the origin of Tool.
Shapes: geometry (..., n, K), joint values (..., m, n) in rad, base (..., 4, 4),
tool (..., m, 4, 4) or (..., 1, 4, 4) (one tool per pose allows several reflectors on
one flange).  Lengths in mm, in the measuring frame.
"""

from __future__ import annotations

import numpy as np

from . import dh

CONVENTIONS: tuple[str, ...] = dh.CONVENTIONS


def check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise ValueError(f"unknown convention {convention!r}; expected one of {', '.join(CONVENTIONS)}")


def joint_kinds(convention: str) -> tuple[str, ...]:
    """Names of the geometric parameters of one joint of a convention."""
    check_convention(convention)
    return dh.joint_kinds(convention)


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


def chain_pose(convention: str, geom, q, base=None, tool=None):
    """End rotation (..., m, 3, 3) and position (..., m, 3) mm; tool None means the flange."""
    geom, q = _inputs(convention, geom, q)
    V = _to_base(dh.apply_chain(convention, geom, q, _tool_vectors(tool, slice(0, 4))), base)
    return V[..., :3], V[..., 3]


def chain_points(convention: str, geom, q, base=None, tool=None) -> np.ndarray:
    """Positions (..., m, 3) mm of the measured point only: the cheap path of swarms."""
    geom, q = _inputs(convention, geom, q)
    V = _to_base(dh.apply_chain(convention, geom, q, _tool_vectors(tool, slice(3, 4))), base)
    return V[..., 0]


def chain_frames(convention: str, geom, q, base=None):
    """Frames after each joint: lists of rotations (..., m, 3, 3) and origins (..., m, 3), n+1 long."""
    geom, q = _inputs(convention, geom, q)
    return dh.chain_frames(convention, geom, q, None if base is None else np.asarray(base, dtype=float))


def chain_twist_jacobian(convention: str, geom, q, base=None, tool=None):
    """``(J, R_e, p_e, R_flange)``, J (n, K, ..., m, 6): see :func:`robocal.model.dh.twist_jacobian`."""
    geom, q = _inputs(convention, geom, q)
    base = None if base is None else np.asarray(base, dtype=float)
    tool = None if tool is None else np.asarray(tool, dtype=float)
    return dh.twist_jacobian(convention, geom, q, base, tool)
