"""Residuals and objectives of a calibration problem, batched over candidate solutions.

A :class:`Problem` ties a parameter space (around the initial robot), the subset of
parameters being estimated, and the measurements.  Its vector ``x`` holds the
estimated errors only (mm, rad); everything else stays at the initial robot.

Objectives (SPEC §3), all evaluated for a whole swarm (P, k) in one batched call:

- ``sum_squares`` — Wen et al. (2019) eq. 7: Σ_j k·|δ_j|² + |δp_j|² (k in mm²/rad²;
  position-only data reduce it to Σ|δp_j|²).  Also what least squares minimises.
- ``sum_norms`` — Kou et al. (2022) eq. 4: Σ_j |δp_j| (mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .measurements import Measurements
from .parameters import ParameterSpace
from .transforms import log_so3, right_jacobian_inv

OBJECTIVES = ("sum_squares", "sum_norms")

#: default orientation weight k of the pose objective, mm²/rad²: 1 rad counts as 100 mm,
#: so 0.01° weighs like 0.017 mm — about the ratio of a laser tracker's position noise to
#: its 6-DOF probe's orientation noise.  Wen et al. (2019) do not give their k.
DEFAULT_K = 1.0e4


@dataclass(eq=False)
class Problem:
    space: ParameterSpace
    active: np.ndarray
    meas: Measurements
    k: float = DEFAULT_K
    use_orientation: bool = True

    def __post_init__(self) -> None:
        self.active = np.asarray(self.active, dtype=int)
        self.target_idx = self.space.target_index(self.meas.targets)
        self.use_orientation = bool(self.use_orientation and self.meas.full_pose)
        self._Rm = self.meas.rotation if self.use_orientation else None
        self._sqrt_k = float(np.sqrt(self.k))

    @property
    def names(self) -> list[str]:
        return [self.space.names[i] for i in self.active]

    @property
    def n_params(self) -> int:
        return len(self.active)

    @property
    def n_residuals(self) -> int:
        return self.meas.n_poses * (6 if self.use_orientation else 3)

    def full(self, x: np.ndarray) -> np.ndarray:
        """Estimated errors (…, k_active) → full error vector (…, k_space)."""
        x = np.asarray(x, dtype=float)
        out = np.zeros(x.shape[:-1] + (self.space.size,))
        out[..., self.active] = x
        return out

    def errors(self, X: np.ndarray):
        """Position errors (…, m, 3) mm and orientation errors (…, m, 3) rad (or None)."""
        R, p = self.space.pose(self.full(X), self.meas.q, self.target_idx)
        dp = self.meas.position - p
        if self._Rm is None:
            return dp, None
        return dp, log_so3(self._Rm @ np.swapaxes(R, -1, -2))

    def objective(self, X: np.ndarray, kind: str = "sum_squares") -> np.ndarray:
        """Objective of each candidate in X (P, k_active) → (P,)."""
        dp, dr = self.errors(X)
        if kind == "sum_norms":
            return np.sqrt(np.sum(dp * dp, axis=-1)).sum(-1)
        if kind != "sum_squares":
            raise ValueError(f"unknown objective {kind!r}")
        f = np.sum(dp * dp, axis=(-1, -2))
        if dr is not None:
            f = f + self.k * np.sum(dr * dr, axis=(-1, -2))
        return f

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Stacked residual vector [δp (3m), √k·δ (3m)] of one solution (k_active,)."""
        dp, dr = self.errors(x)
        if dr is None:
            return dp.ravel()
        return np.concatenate([dp.ravel(), self._sqrt_k * dr.ravel()])

    def residual_jacobian(self, x: np.ndarray) -> np.ndarray:
        """Exact ∂residuals/∂x, (n_residuals, k_active)."""
        J, R, _ = self.space.jacobian(self.full(x), self.meas.q, self.target_idx)
        J = J[:, :, self.active]
        Jp = -J[:, :3, :].reshape(-1, self.n_params)
        if self._Rm is None:
            return Jp
        dr = log_so3(self._Rm @ np.swapaxes(R, -1, -2))
        Jr = -(right_jacobian_inv(dr) @ J[:, 3:, :])
        return np.concatenate([Jp, self._sqrt_k * Jr.reshape(-1, self.n_params)])
