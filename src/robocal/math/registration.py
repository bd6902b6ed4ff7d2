"""Closed-form rigid registration of corresponding point sets."""

from __future__ import annotations

import numpy as np

from .se3 import homogeneous


def rigid_registration(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares rigid transform T with dst ≈ T · src (Kabsch/Umeyama, no scale), (4, 4).

    src, dst: (m, 3) corresponding points in mm.  Needs three non-collinear points.
    """
    cs, cd = src.mean(0), dst.mean(0)
    H = (src - cs).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return homogeneous(R, cd - R @ cs)
