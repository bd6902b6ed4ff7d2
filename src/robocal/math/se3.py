"""Rigid transforms: homogeneous (..., 4, 4) matrices with lengths in mm and angles in rad."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .so3 import matrix_to_rpy, rpy_to_matrix


def homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) and translation (..., 3) mm → (..., 4, 4)."""
    R = np.asarray(R, dtype=float)
    p = np.asarray(p, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def xyz_rpy_to_transform(xyz, rpy) -> np.ndarray:
    """Translation (..., 3) mm and rpy (..., 3) rad → (..., 4, 4)."""
    return homogeneous(rpy_to_matrix(np.asarray(rpy, dtype=float)), np.asarray(xyz, dtype=float))


def transform_to_xyz_rpy(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., 4, 4) → translation (..., 3) mm and rpy (..., 3) rad."""
    T = np.asarray(T, dtype=float)
    return T[..., :3, 3].copy(), matrix_to_rpy(T[..., :3, :3])


def frame_from_values(values: Sequence[float]) -> np.ndarray:
    """A frame from 3 numbers (x, y, z mm) or 6 (x, y, z mm, rx, ry, rz rad as rpy) → (4, 4).

    The one frame parser of robocal: robot files, simulation and the command line
    all build frames through it.
    """
    v = [float(x) for x in values]
    if len(v) not in (3, 6):
        raise ValueError(f"a frame is x,y,z or x,y,z,rx,ry,rz, got {len(v)} numbers")
    return xyz_rpy_to_transform(v[:3], v[3:] if len(v) == 6 else (0.0, 0.0, 0.0))


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4)."""
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    return homogeneous(Rt, -(Rt @ T[..., :3, 3:])[..., 0])


def end_frame(R_f: np.ndarray, o_f: np.ndarray, tool: np.ndarray | None):
    """The tool frame (R_e (..., 3, 3), p_e (..., 3)) at a flange (R_f, o_f), or the flange
    itself without a tool; and the broadcast shape of the chain's poses (..., m)."""
    if tool is None:
        p_e, R_e = o_f, R_f
    else:
        p_e = o_f + (R_f @ tool[..., :3, 3:])[..., 0]
        R_e = R_f @ tool[..., :3, :3]
    return R_e, p_e, np.broadcast_shapes(p_e.shape, R_f.shape[:-1])[:-1]
