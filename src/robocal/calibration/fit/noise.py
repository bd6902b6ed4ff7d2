"""The noise model: how residuals are weighed, and σ estimated where it is not stated.

The measuring device's noise is a standard deviation per axis: σp (mm) for positions, σr
(rad, a rotation vector) for orientations.  Residuals are whitened by them, so the least
squares sum is χ² and the orientation weight of the papers' objective is k = (σp/σr)².

A σ that is not stated is estimated from the fit itself, block by block (variance
components): with the whitened Jacobian J and its hat matrix H = J (JᵀJ)⁻¹ Jᵀ, the
parameters use up tr(H) = k degrees of freedom, split between the blocks by the trace of
H over each block's rows, so σ̂_b² = |r_b|² / (N_b − tr_b(H)).  The fit is repeated with
the new weights until their ratio settles (a few refits; position-only data need none, since
a common scale of the residuals does not move the solution).  After that χ² equals its degrees of
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
#: with a prior, the data's σ itself sets their weight against it: a relative change of σ below
#: this moves the prior-held directions by a percent of their already small deviation
PRIOR_SETTLED = 5e-3
#: refits allowed to the reweighting
MAX_REWEIGHTS = 6
#: the Gauss–Newton step is taken as the refit when the χ² it reaches misses the χ² it
#: predicts by less than this (whitened, so in squared standard uncertainties): the problem is
#: linear there to within a tenth of σ, and LM would only confirm the step
LINEAR_CHI2 = 1e-2


@dataclass(frozen=True)
class NoiseModel:
    """What the user stated: σp (mm), σr (rad), or a fixed weight k = (σp/σr)² (mm²/rad²)."""

    position: float | None = None
    orientation: float | None = None
    k: float | None = None

    @classmethod
    def checked(cls, noise, angle_noise, k) -> NoiseModel:
        """From option values (``noise`` mm, ``angle_noise`` rad, ``k``), each checked: > 0 and
        finite, and not both angle_noise and k."""
        from ... import options as opt
        from ...exceptions import InputError

        values = {name: None if v is None else opt.number(v, name, minimum=0.0, strict=True)
                  for name, v in (("noise", noise), ("angle_noise", angle_noise), ("k", k))}
        if values["k"] is not None and values["angle_noise"] is not None:
            raise InputError("give the orientation noise or the weight k, not both", option="k")
        return cls(values["noise"], values["angle_noise"], values["k"])

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

    @property
    def meaning(self) -> str:
        """What the σ is: a stated σ is the instrument's noise; one estimated from the fit is the
        residual scatter, the instrument's noise plus everything the model leaves out."""
        if self.source == "stated":
            return "the measuring noise, as stated"
        return "residual scatter: the instrument's noise plus what the model leaves out"

    @property
    def label(self) -> str:
        return "noise σ" if self.source == "stated" else "residual scatter σ"

    def to_dict(self) -> dict:
        return {"position_mm": self.position,
                "orientation_deg": None if self.orientation is None else math.degrees(self.orientation),
                "source": self.source, "refits": self.refits, "meaning": self.meaning}


def leverage_split(problem: Problem, x: np.ndarray) -> tuple[float, float]:
    """Degrees of freedom the parameters use in the position and orientation blocks: the
    traces of the hat matrix over each block's rows (with stated distances and the prior's
    pseudo-observations, they add up to the parameter count: a parameter held by its prior uses
    none of the data's).

    tr_b(H) = tr(J_bᵀJ_b (JᵀJ + P)⁻¹): k×k products only, whatever the number of poses.
    """
    J = problem.residual_jacobian(x)
    n_pos, n_rot = problem.n_position_rows(), problem.n_orientation_rows()
    M_p = J[:n_pos].T @ J[:n_pos]
    M_r = J[n_pos:n_pos + n_rot].T @ J[n_pos:n_pos + n_rot]
    M_d = J[n_pos + n_rot:].T @ J[n_pos + n_rot:]  # stated distances: they use some too, but have their σ
    inv = np.linalg.pinv(M_p + M_r + M_d + problem.prior_information())
    return float(np.sum(M_p * inv.T)), float(np.sum(M_r * inv.T))


def position_values(problem: Problem) -> float:
    """The position block's values less what the eliminated points and planes use: three per
    measured point or point row, one per plane row (its offset along the normal), two per camera
    row (its pixel)."""
    planes = 0 if problem.constraints is None else int(problem.constraints.rows_of("plane").sum())
    pixels = 0 if problem.views is None else int(problem.views.rows.sum())
    return 3 * problem.meas.n_poses - 2 * planes - pixels - problem.n_nuisance


def block_sigmas(problem: Problem, x: np.ndarray, model: NoiseModel) -> tuple[float, float]:
    """σp, σr that these residuals show, keeping whatever the model states."""
    dp, dr = problem.scaled_errors(x)
    rss_p = float(np.sum(dp * dp))
    n_p = position_values(problem)
    used_p, used_r = leverage_split(problem, x)
    sr = problem.setup.sigma_orientation
    if dr is None:
        return (model.position if model.position is not None else _sigma(rss_p, n_p - used_p)), sr
    return _block_values(rss_p, n_p, used_p, float(np.sum(dr * dr)), dr.size, used_r, model)


@dataclass(frozen=True)
class Settled:
    """Weights that re-estimating would no longer change, and what the linearised problem says
    of the solution under them: the Gauss–Newton step (k,) from x, the whitened χ² it predicts,
    and the degrees of freedom the parameters use in each block."""

    sigmas: tuple[float, float]
    step: np.ndarray
    chi2: float
    used: tuple[float, float]


def settle(problem: Problem, x: np.ndarray, model: NoiseModel, iterations: int = 100) -> Settled:
    """σp, σr at which re-estimating would no longer change the weights, found on the
    linearised problem at x: each round takes the Gauss–Newton step of the current weights
    from one Jacobian, estimates the blocks' σ from the residuals it predicts (as
    :func:`block_sigmas`), and stops when the ratio settles.  The step then is the refit a
    chain of refits would end with, to first order (full-pose data, or any data with a prior;
    position-only data without one settle at once, see :func:`settled`)."""
    sp, sr = problem.setup.sigma_position, problem.setup.sigma_orientation
    n_pos, n_r = problem.n_position_rows(), problem.n_orientation_rows()
    r = problem.residuals(x)
    J = problem.residual_jacobian(x)
    # back to millimetres and radians, so any weights can be applied; stated distances keep theirs
    rot = slice(n_pos, n_pos + n_r)
    r_p, r_r, J_p, J_r = r[:n_pos] * sp, r[rot] * sr, J[:n_pos] * sp, J[rot] * sr
    r_d, J_d = r[n_pos + n_r:], J[n_pos + n_r:]
    # the prior's pseudo-observations: their weight does not change with the data's
    W = problem.prior_information()
    P_p, P_r, P_d = J_p.T @ J_p, J_r.T @ J_r, J_d.T @ J_d + W
    g_p, g_r, g_d = J_p.T @ r_p, J_r.T @ r_r, J_d.T @ r_d + W @ x
    c_p, c_r, c_d = float(r_p @ r_p), float(r_r @ r_r), float(r_d @ r_d) + float(x @ W @ x)
    n_free = position_values(problem)
    sigmas = (sp, sr)
    prior = problem.has_prior
    for _ in range(iterations if n_r or prior else 1):
        wp, wr = sigmas[0] ** -2, (sigmas[1] ** -2 if n_r else 0.0)
        inv = np.linalg.pinv(wp * P_p + wr * P_r + P_d)
        step = -inv @ (wp * g_p + wr * g_r + g_d)
        # |r + J δ|² per block from k×k products only, whatever the number of poses
        rss_p = c_p + 2 * g_p @ step + step @ P_p @ step
        rss_r = c_r + 2 * g_r @ step + step @ P_r @ step
        used = float(np.sum(wp * P_p * inv.T)), float(np.sum(wr * P_r * inv.T))
        if not n_r:
            new = (_block_values(rss_p, n_free, used[0], 0.0, 0, 0.0, model)[0], sr)
        else:
            new = _block_values(rss_p, n_free, used[0], rss_r, n_r, used[1], model)
        done = settled(sigmas, new, bool(n_r), prior)
        sigmas = new
        if done:
            break
    wp, wr = sigmas[0] ** -2, (sigmas[1] ** -2 if n_r else 0.0)
    inv = np.linalg.pinv(wp * P_p + wr * P_r + P_d)
    step = -inv @ (wp * g_p + wr * g_r + g_d)
    chi2 = wp * (c_p + 2 * g_p @ step + step @ P_p @ step) + wr * (c_r + 2 * g_r @ step + step @ P_r @ step) + \
        (c_d + 2 * g_d @ step + step @ P_d @ step)
    used = float(np.sum(wp * P_p * inv.T)), float(np.sum(wr * P_r * inv.T))
    return Settled(sigmas, step, float(chi2), used)


def confirmed(problem: Problem, x: np.ndarray, target: Settled, model: NoiseModel) -> bool:
    """Whether the residuals at x (the refit under ``target``'s weights) show those weights
    again, with the degrees of freedom of the linearised fit (no Jacobian needed)."""
    dp, dr = problem.scaled_errors(x)
    if dr is None:
        if not problem.has_prior:
            return True
        again = (_block_values(float(np.sum(dp * dp)), position_values(problem), target.used[0], 0.0, 0, 0.0,
                               model)[0], target.sigmas[1])
        return settled(target.sigmas, again, False, True)
    again = _block_values(float(np.sum(dp * dp)), position_values(problem), target.used[0], float(np.sum(dr * dr)),
                          dr.size, target.used[1], model)
    return settled(target.sigmas, again, True, problem.has_prior)


def _block_values(rss_p, n_p, used_p, rss_r, n_r, used_r, model: NoiseModel) -> tuple[float, float]:
    """σp, σr from the blocks' residual sums of squares and the degrees of freedom the fit used."""
    if model.k is not None:  # a fixed ratio: one pooled σ in position units
        pooled = model.position if model.position is not None else _sigma(rss_p + model.k * rss_r,
                                                                           n_p + n_r - used_p - used_r)
        return pooled, pooled / math.sqrt(model.k)
    sp = model.position if model.position is not None else _sigma(rss_p, n_p - used_p)
    sr = model.orientation if model.orientation is not None else _sigma(rss_r, n_r - used_r)
    return sp, sr


def _sigma(rss: float, dof: float) -> float:
    # a floor keeps the weights finite for noise-free data
    return max(math.sqrt(max(rss, 0.0) / dof) if dof > 0 else 0.0, 1e-12)


def settled(old: tuple[float, float], new: tuple[float, float], full_pose: bool, prior: bool = False) -> bool:
    """Whether new weights would change the fit.  Without a prior only the ratio σp/σr does (a
    common scale of all residuals leaves the least-squares solution where it is), so
    position-only data settle at once; with one, each σ weighs its block against the prior."""
    if prior and any(abs(n / o - 1.0) > PRIOR_SETTLED for n, o in zip(new[:1 + full_pose], old[:1 + full_pose])):
        return False
    if not full_pose:
        return True
    return abs(new[0] / new[1] - old[0] / old[1]) <= SETTLED * old[0] / old[1]
