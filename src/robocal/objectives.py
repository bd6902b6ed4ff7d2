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

from . import _fast
from .measurements import Measurements
from .parameters import ParameterSpace, joint_kinds
from .transforms import apply_right_jacobian_inv, log_so3

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
        _, base, tools = self.space.expand(np.zeros(self.space.size))
        self._nominal_frames = (base, tools)
        kinds = len(joint_kinds(self.space.robot.convention))
        # positions of the estimated joint parameters in the flat (n, 5) geometry
        self._geom_cols = ((self.active // kinds) * 5 + self.active % kinds).astype(np.int64)
        self._frames_active = bool(np.any(self.active >= self.space.n_joint_params))
        self._qtrig = _fast.joint_trig(self.meas.q)
        self._conv_code = _fast.CONVENTION_CODE[self.space.robot.convention]
        m = self.meas.n_poses
        self._tidx64 = np.zeros(m, dtype=np.int64) if self.target_idx is None else self.target_idx.astype(np.int64)
        self._Rm_kernel = self._Rm if self._Rm is not None else np.zeros((1, 3, 3))

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
        if self._Rm is None:
            return self.meas.position - self.space.points(self.full(X), self.meas.q, self.target_idx), None
        R, p = self.space.pose(self.full(X), self.meas.q, self.target_idx)
        return self.meas.position - p, log_so3(self._Rm @ np.swapaxes(R, -1, -2))

    def objective(self, X: np.ndarray, kind: str = "sum_squares", *, fast: bool | None = None) -> np.ndarray:
        """Objective of each candidate in X (P, k_active) → (P,).

        fast: use the compiled kernel (default: when numba is installed); the numpy
        path gives the same numbers.
        """
        if kind not in OBJECTIVES:
            raise ValueError(f"unknown objective {kind!r}")
        X = np.asarray(X, dtype=float)
        if (_fast.AVAILABLE if fast is None else fast) and X.ndim == 2:
            return self._fast_objective(X, kind)
        dp, dr = self.errors(X)
        if kind == "sum_norms":
            return np.sqrt(np.sum(dp * dp, axis=-1)).sum(-1)
        f = np.sum(dp * dp, axis=(-1, -2))
        if dr is not None:
            f = f + self.k * np.sum(dr * dr, axis=(-1, -2))
        return f

    def _fast_objective(self, X: np.ndarray, kind: str) -> np.ndarray:
        common = (self._qtrig, self._tidx64, self.meas.position, self._Rm_kernel, self._Rm is not None, self.k,
                  0 if kind == "sum_squares" else 1)  # fmt: skip
        if not self._frames_active:
            # each particle adds its joint errors to the nominal geometry inside the kernel
            base, tools = self._nominal_frames
            return _fast.objective_joints(self._conv_code, self.space.robot.geometry, self._geom_cols, X, base,
                                          tools, *common)  # fmt: skip
        geom, base, tools = self.space.expand(self.full(X))
        return _fast.objective(self._conv_code, geom, base, tools, *common)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Stacked residual vector [δp (3m), √k·δ (3m)] of one solution (k_active,)."""
        dp, dr = self.errors(x)
        if dr is None:
            return dp.ravel()
        return np.concatenate([dp.ravel(), self._sqrt_k * dr.ravel()])

    def residual_jacobian(self, x: np.ndarray) -> np.ndarray:
        """Exact ∂residuals/∂x, (n_residuals, k_active), Fortran-ordered as MINPACK wants."""
        Jc, R, _ = self.space.jacobian_columns(self.full(x), self.meas.q, self.target_idx, frames=self._frames_active)
        Jc = Jc[self.active]  # (k, m, 6)
        k, m = Jc.shape[0], Jc.shape[1]
        out = np.empty((k, self.n_residuals))
        out[:, : 3 * m] = -Jc[:, :, :3].reshape(k, 3 * m)
        if self._Rm is not None:
            dr = log_so3(self._Rm @ np.swapaxes(R, -1, -2))
            w = Jc[:, :, 3:]
            Jr = (
                _fast.apply_right_jacobian_inv(dr, np.ascontiguousarray(w))
                if _fast.AVAILABLE
                else (apply_right_jacobian_inv(dr, w))
            )
            out[:, 3 * m :] = -self._sqrt_k * Jr.reshape(k, 3 * m)
        return out.T
