"""Geometry of the 2TPR&2TPS mechanism: joint points, rod zero lengths, platform poses.

Frames and conventions (MODEL §7).  The fixed frame o sits at the midpoint of T3T4, the
moving frame o1 at the midpoint of R1R2; lengths in mm, angles in rad.  A platform pose
is (x, y, z, α, β, γ) with ``R = Rz(γ) Ry(β) Rx(α)`` and o1 = (x, y, z).  Limbs 1, 2 are
T–P–S from T1, T2 to B1 = S1, B2 = S2; limbs 3, 4 are T–P–R from T3, T4 to B3 = R2,
B4 = R1.  Rod i has length ``|u_i|`` with ``u_i = R B_i + o1 − T_i``.  Commanded rod
lengths are what the controller believes: the real length is the commanded one plus the
rod's zero-length error ΔL_i.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..math.so3 import rot_x, rot_y, rot_z
from ..presets import chen2023 as paper

AXES = ("x", "y", "z")
#: the 28 error parameters: fixed points, moving points, rod zero lengths (all mm)
PARAM_NAMES = tuple(
    [f"T{i}{a}" for i in range(1, 5) for a in AXES]
    + [f"B{i}{a}" for i in range(1, 5) for a in AXES]
    + [f"dL{i}" for i in range(1, 5)]
)


@dataclass(frozen=True)
class PKMGeometry:
    """Joint points (4, 3) of the fixed (T) and moving (B) platforms in mm, rod zero-length
    errors (4,) mm, rod length limits (mm) and the Hooke-joint swing limit (rad), measured
    between a rod and the fixed platform's normal (the paper gives ±60° without its axis)."""

    T: np.ndarray
    B: np.ndarray
    rod_zero: np.ndarray = field(default_factory=lambda: np.zeros(4))
    rod_limits: tuple[float, float] = paper.ROD_LIMITS
    hooke_limit: float = math.radians(paper.HOOKE_LIMIT_DEG)
    name: str = "2TPR&2TPS"

    def __post_init__(self) -> None:
        for key, shape in (("T", (4, 3)), ("B", (4, 3)), ("rod_zero", (4,))):
            v = np.array(getattr(self, key), dtype=float)
            if v.shape != shape:
                raise ValueError(f"{key} must have shape {shape}")
            object.__setattr__(self, key, v)

    def vector(self) -> np.ndarray:
        """The 28 parameters in :data:`PARAM_NAMES` order."""
        return np.concatenate([self.T.ravel(), self.B.ravel(), self.rod_zero])

    def with_errors(self, delta) -> PKMGeometry:
        """This geometry with errors (28,) added (mm)."""
        delta = np.asarray(delta, dtype=float)
        if delta.shape != (28,):
            raise ValueError("a PKM error vector has 28 entries")
        return replace(self, T=self.T + delta[:12].reshape(4, 3), B=self.B + delta[12:24].reshape(4, 3),
                       rod_zero=self.rod_zero + delta[24:])


def chen2023() -> PKMGeometry:
    """The mechanism of Chen et al. Table 2 (see :mod:`robocal.presets.chen2023`)."""
    return PKMGeometry(np.array(paper.FIXED_POINTS), np.array(paper.MOVING_POINTS))


def rotate(R: np.ndarray, P: np.ndarray) -> np.ndarray:
    """R (…, 3, 3) applied to the four points P (4, 3) → (…, 4, 3)."""
    return np.swapaxes(R @ P.T, -1, -2)


def reduced_to_pose(q) -> np.ndarray:
    """(…, 4) (y, z, α, β) → (…, 6) pose with x = z tan β, γ = 0 (the nominal constraints)."""
    q = np.asarray(q, dtype=float)
    y, z, a, b = (q[..., k] for k in range(4))
    return np.stack([z * np.tan(b), y, z, a, b, np.zeros_like(y)], -1)


def rotation(pose) -> np.ndarray:
    """Platform rotation R = Rz(γ) Ry(β) Rx(α) of poses (…, 6)."""
    pose = np.asarray(pose, dtype=float)
    return rot_z(pose[..., 5]) @ rot_y(pose[..., 4]) @ rot_x(pose[..., 3])


def rotation_derivatives(pose):
    """R and ∂R/∂α, ∂R/∂β, ∂R/∂γ, each (…, 3, 3)."""
    a, b, g = pose[..., 3], pose[..., 4], pose[..., 5]
    Rx, Ry, Rz = rot_x(a), rot_y(b), rot_z(g)
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    z = np.zeros_like(a)
    dRx = np.stack([np.stack([z, z, z], -1), np.stack([z, -sa, -ca], -1), np.stack([z, ca, -sa], -1)], -2)
    dRy = np.stack([np.stack([-sb, z, cb], -1), np.stack([z, z, z], -1), np.stack([-cb, z, -sb], -1)], -2)
    dRz = np.stack([np.stack([-sg, -cg, z], -1), np.stack([cg, -sg, z], -1), np.stack([z, z, z], -1)], -2)
    return Rz @ Ry @ Rx, (Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx)


def leg_vectors(geom: PKMGeometry, pose) -> np.ndarray:
    """u_i = R B_i + o1 − T_i, (…, 4, 3) in mm."""
    pose = np.asarray(pose, dtype=float)
    return rotate(rotation(pose), geom.B) + pose[..., None, :3] - geom.T
