"""Where a model was calibrated: the range of each joint over the calibration poses, and how well
the model knew its TCP there.

The whole model is used everywhere: its geometry, and each physical term as its physics says
(a joint compliance wherever its torque model holds, a backlash by the direction of approach,
a drift by time, harmonics periodic in their joint's angle).  What a model knows less well
outside its data is said by its predicted uncertainty (:mod:`robocal.model.uncertainty`), which
grows there as the parameters' covariance and the residual process's variance say.  The region
keeps the median of that uncertainty at the calibration poses (``sigma_mm``): a pose whose
predicted uncertainty exceeds :data:`SIGMA_FACTOR` times it is named.  Without a covariance, a
pose more than :data:`TRUST_RAD` (:data:`TRUST_MM` for a sliding joint) beyond the ranges is.
A revolute joint whose range spans a whole turn has no outside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: how far outside the ranges a pose is still as well known as their fringe: 2° (2 mm for a slide)
TRUST_RAD, TRUST_MM = math.radians(2.0), 2.0
#: a pose whose predicted uncertainty exceeds this multiple of the median at the calibration poses is named
SIGMA_FACTOR = 3.0
#: how far past a range (rad or mm) still counts as inside it: the ranges are written rounded
TOLERANCE = 1e-7


@dataclass(frozen=True, eq=False)
class Region:
    """lo, hi (n,): each joint's smallest and largest value over the calibration poses, rad (mm
    for a sliding joint); n_poses: how many poses; prismatic (n,): True where a joint slides;
    sigma_mm: the median predicted position uncertainty at the calibration poses (mm), or None."""

    lo: np.ndarray
    hi: np.ndarray
    n_poses: int
    prismatic: np.ndarray | None = None
    sigma_mm: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "lo", np.asarray(self.lo, float))
        object.__setattr__(self, "hi", np.asarray(self.hi, float))
        slide = np.zeros(len(self.lo), bool) if self.prismatic is None else np.asarray(self.prismatic, bool)
        object.__setattr__(self, "prismatic", slide)

    @classmethod
    def of(cls, q: np.ndarray, prismatic: np.ndarray | None = None) -> Region:
        q = np.atleast_2d(np.asarray(q, float))
        return cls(q.min(axis=0), q.max(axis=0), len(q), prismatic)

    def with_sigma(self, sigma_mm: float | None) -> Region:
        return Region(self.lo, self.hi, self.n_poses, self.prismatic, sigma_mm)

    def outside(self, q: np.ndarray) -> np.ndarray:
        """How far each joint of each pose lies outside its range, (m, n), rad or mm (0 inside,
        within :data:`TOLERANCE` of the range, which files round to, and for a revolute joint
        whose range spans a whole turn)."""
        q = np.atleast_2d(np.asarray(q, float))
        d = np.maximum(self.lo - q, q - self.hi)
        whole = ~self.prismatic & (self.hi - self.lo >= 2.0 * math.pi - TOLERANCE)
        return np.where((d > TOLERANCE) & ~whole, d, 0.0)

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

    def describe_sigma(self, sigma: np.ndarray) -> str | None:
        """The poses whose predicted uncertainty σ (m,) mm exceeds SIGMA_FACTOR × ``sigma_mm``, or None."""
        bar = SIGMA_FACTOR * self.sigma_mm
        far = np.flatnonzero(sigma > bar)
        if far.size == 0:
            return None
        worst = far[np.argsort(-sigma[far])][:3]
        listed = ", ".join(f"{sigma[i]:.3g} mm at pose {i + 1}" for i in worst)
        return (f"{far.size} of {len(sigma)} poses have a predicted position uncertainty above {SIGMA_FACTOR:g}× its "
                f"median at the calibration poses ({self.sigma_mm:.3g} mm): up to {listed}; the model knows them "
                "less well (outside its data), by that much")

    def to_dict(self) -> dict:
        """Joint ranges as files hold them (deg; mm for a sliding joint)."""
        scale = np.where(self.prismatic, 1.0, 180.0 / math.pi)
        return {"joints": [[float(a), float(b)] for a, b in zip(self.lo * scale, self.hi * scale)],
                "poses": int(self.n_poses), **({} if self.sigma_mm is None else {"sigma_mm": float(self.sigma_mm)})}

    @classmethod
    def from_dict(cls, d: dict, prismatic: np.ndarray | None = None) -> Region:
        ranges = np.array(d["joints"], float)
        if ranges.ndim != 2 or ranges.shape[1] != 2:
            raise ValueError("joints must be a list of [low, high] pairs")
        slide = np.zeros(len(ranges), bool) if prismatic is None else np.asarray(prismatic, bool)
        scale = np.where(slide, 1.0, math.pi / 180.0)
        sigma = d.get("sigma_mm")
        return cls(ranges[:, 0] * scale, ranges[:, 1] * scale, int(d.get("poses", 0)), slide,
                   None if sigma is None else float(sigma))
