"""Where a model was calibrated: the range of each joint over the calibration poses.

A model beyond geometry (joint terms, a residual process) is only known where its data were:
harmonics of a joint that turned through part of a circle are nearly collinear with the
geometry over that arc, and their large, cancelling amplitudes can explode outside it; a
gravity compliance fitted with its geometry can carry that geometry's compromise elsewhere.
So a calibrated model records its region, every command that uses it says how many poses lie
outside and by how much, and a model beyond geometry carries its geometric fit as a fallback:
a little outside the region (up to :data:`TRUST_RAD`, :data:`TRUST_MM` for a sliding joint) it
stays itself, as a fit of a smooth effect is good a few degrees past its last pose; further
out it blends into that fit, and beyond :data:`FALLBACK_RAD` (:data:`FALLBACK_MM`) it *is*
that fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: how far outside the region the full model is kept as it is: 2° (2 mm for a sliding joint)
TRUST_RAD, TRUST_MM = math.radians(2.0), 2.0
#: how far outside it the model has become its geometric fallback: 10° (10 mm)
FALLBACK_RAD, FALLBACK_MM = math.radians(10.0), 10.0
#: how far past a range (rad or mm) still counts as inside it: the ranges are written rounded
TOLERANCE = 1e-7


def describe_margin() -> str:
    return (f"{math.degrees(TRUST_RAD):g}° ({TRUST_MM:g} mm for a sliding joint) it blends into its geometric fit, "
            f"which it is beyond {math.degrees(FALLBACK_RAD):g}° ({FALLBACK_MM:g} mm)")


@dataclass(frozen=True, eq=False)
class Region:
    """lo, hi (n,): each joint's smallest and largest value over the calibration poses, rad (mm
    for a sliding joint); n_poses: how many poses; prismatic (n,): True where a joint slides."""

    lo: np.ndarray
    hi: np.ndarray
    n_poses: int
    prismatic: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "lo", np.asarray(self.lo, float))
        object.__setattr__(self, "hi", np.asarray(self.hi, float))
        slide = np.zeros(len(self.lo), bool) if self.prismatic is None else np.asarray(self.prismatic, bool)
        object.__setattr__(self, "prismatic", slide)

    @classmethod
    def of(cls, q: np.ndarray, prismatic: np.ndarray | None = None) -> Region:
        q = np.atleast_2d(np.asarray(q, float))
        return cls(q.min(axis=0), q.max(axis=0), len(q), prismatic)

    def outside(self, q: np.ndarray) -> np.ndarray:
        """How far each joint of each pose lies outside its range, (m, n), rad or mm (0 inside,
        and within :data:`TOLERANCE` of the range, which files round to)."""
        q = np.atleast_2d(np.asarray(q, float))
        d = np.maximum(self.lo - q, q - self.hi)
        return np.where(d > TOLERANCE, d, 0.0)

    def weight(self, q: np.ndarray) -> np.ndarray:
        """Per pose, the share of the full model (1 up to TRUST outside the region, 0 beyond
        FALLBACK): a product over joints of a cos² step between the two, smooth for the IK."""
        trust = np.where(self.prismatic, TRUST_MM, TRUST_RAD)
        width = np.where(self.prismatic, FALLBACK_MM - TRUST_MM, FALLBACK_RAD - TRUST_RAD)
        t = np.clip((self.outside(q) - trust) / width, 0.0, 1.0)
        return np.prod(np.where(t < 1.0, np.cos(0.5 * np.pi * t) ** 2, 0.0), axis=1)

    def describe(self, q: np.ndarray) -> str | None:
        """"N of M poses lie outside …, joint 1 by up to 135°, …", or None when none lies further
        outside than TRUST (the fringe of a range is as well known as its inside)."""
        d = self.outside(q)
        out = np.any(d > np.where(self.prismatic, TRUST_MM, TRUST_RAD), axis=1)
        if not out.any():
            return None
        worst = [(j, d[:, j].max()) for j in np.argsort(-d.max(axis=0)) if d[:, j].max() > 0][:3]
        parts = [f"joint {j + 1} by up to {v:.4g} mm" if self.prismatic[j] else
                 f"joint {j + 1} by up to {math.degrees(v):.4g}°" for j, v in worst]
        return (f"{int(out.sum())} of {len(q)} poses lie more than {math.degrees(TRUST_RAD):g}° outside the joint "
                f"ranges the model was calibrated on ({', '.join(parts)})")

    def to_dict(self) -> dict:
        """Joint ranges as files hold them (deg; mm for a sliding joint)."""
        scale = np.where(self.prismatic, 1.0, 180.0 / math.pi)
        return {"joints": [[float(a), float(b)] for a, b in zip(self.lo * scale, self.hi * scale)],
                "poses": int(self.n_poses)}

    @classmethod
    def from_dict(cls, d: dict, prismatic: np.ndarray | None = None) -> Region:
        ranges = np.array(d["joints"], float)
        if ranges.ndim != 2 or ranges.shape[1] != 2:
            raise ValueError("joints must be a list of [low, high] pairs")
        slide = np.zeros(len(ranges), bool) if prismatic is None else np.asarray(prismatic, bool)
        scale = np.where(slide, 1.0, math.pi / 180.0)
        return cls(ranges[:, 0] * scale, ranges[:, 1] * scale, int(d.get("poses", 0)), slide)
