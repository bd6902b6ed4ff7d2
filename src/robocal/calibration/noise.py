"""The noise model: how residuals are weighed, and σ estimated where it is not stated.

The measuring device's noise is a standard deviation per axis: σp (mm) for positions, σr
(rad, a rotation vector) for orientations.  Residuals are whitened by them, so the least
squares sum is χ² and the orientation weight of the papers' objective is k = (σp/σr)².

A σ that is not stated is estimated from the fit itself, block by block (variance
components): with the whitened Jacobian J and its hat matrix H = J (JᵀJ)⁻¹ Jᵀ, the
parameters use up tr(H) = k degrees of freedom, split between the blocks by the trace of
H over each block's rows, so σ̂_b² = |r_b|² / (N_b − tr_b(H)).  The fit is repeated with
the new weights until they settle (a few refits).  After that χ² equals its degrees of
freedom by construction, and the standard uncertainties from (JᵀJ)⁻¹ carry each block's
own noise, not one σ pooled over millimetres and radians.

With every σ stated, χ² tests the model: a fit far beyond the noise is a misfit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .problem import DEFAULT_K, Problem

#: relative change of σ below which the reweighting has settled
SETTLED = 1e-3
#: refits allowed to the reweighting
MAX_REWEIGHTS = 6


@dataclass(frozen=True)
class NoiseModel:
    """What the user stated: σp (mm), σr (rad), or a fixed weight k = (σp/σr)² (mm²/rad²)."""

    position: float | None = None
    orientation: float | None = None
    k: float | None = None

    def initial(self) -> tuple[float, float]:
        """Weights to start with: the stated values, else 1 mm and the default ratio k."""
        ratio = math.sqrt(self.k if self.k is not None else DEFAULT_K)
        if self.position is not None:
            return self.position, self.orientation if self.orientation is not None else self.position / ratio
        if self.orientation is not None:
            return self.orientation * ratio, self.orientation
        return 1.0, 1.0 / ratio

    def stated(self, full_pose: bool) -> bool:
        """Every block of these data has a stated σ (so χ² tests the model)."""
        if self.position is None:
            return False
        return not full_pose or self.orientation is not None or self.k is not None


@dataclass(frozen=True)
class NoiseEstimate:
    """The σ a fit used: position (mm), orientation (rad, None for position-only data),
    and whether they were stated or estimated (with the number of refits it took)."""

    position: float
    orientation: float | None
    source: str
    refits: int = 0

    def to_dict(self) -> dict:
        return {"position_mm": self.position,
                "orientation_deg": None if self.orientation is None else math.degrees(self.orientation),
                "source": self.source, "refits": self.refits}


def leverage_split(problem: Problem, x: np.ndarray) -> tuple[float, float]:
    """Degrees of freedom the parameters use in the position and orientation blocks: the
    traces of the hat matrix over each block's rows (they add up to the parameter count).

    tr_b(H) = tr(J_bᵀJ_b (JᵀJ)⁻¹): k×k products only, whatever the number of poses.
    """
    J = problem.residual_jacobian(x)
    n_pos = problem.n_position_rows()
    M_p = J[:n_pos].T @ J[:n_pos]
    M_r = J[n_pos:].T @ J[n_pos:]
    inv = np.linalg.pinv(M_p + M_r)
    return float(np.sum(M_p * inv.T)), float(np.sum(M_r * inv.T))


def block_sigmas(problem: Problem, x: np.ndarray, model: NoiseModel) -> tuple[float, float]:
    """σp, σr that these residuals show, keeping whatever the model states."""
    dp, dr = problem.errors(x)
    rss_p = float(np.sum(dp * dp))
    n_p = dp.size
    used_p, used_r = leverage_split(problem, x)
    sp, sr = problem.setup.sigma_position, problem.setup.sigma_orientation
    if dr is None:
        return (model.position if model.position is not None else _sigma(rss_p, n_p - used_p)), sr
    rss_r, n_r = float(np.sum(dr * dr)), dr.size
    if model.k is not None:  # a fixed ratio: one pooled σ in position units
        pooled = model.position if model.position is not None else _sigma(rss_p + model.k * rss_r,
                                                                           n_p + n_r - used_p - used_r)
        return pooled, pooled / math.sqrt(model.k)
    sp = model.position if model.position is not None else _sigma(rss_p, n_p - used_p)
    sr = model.orientation if model.orientation is not None else _sigma(rss_r, n_r - used_r)
    return sp, sr


def _sigma(rss: float, dof: float) -> float:
    # a floor keeps the weights finite for noise-free data
    return max(math.sqrt(rss / dof) if dof > 0 else 0.0, 1e-12)


def settled(old: tuple[float, float], new: tuple[float, float]) -> bool:
    return all(abs(n - o) <= SETTLED * max(abs(o), 1e-300) for o, n in zip(old, new))
