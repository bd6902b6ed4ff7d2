"""Step 9: what the fit says of itself: goodness of fit, covariance and standard uncertainties,
what the prior holds, whether the model is physical, and the warnings they call for.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...exceptions import Note
from ...model.parameters import is_term
from ...model.prior import prior_shares
from ..config import CalibrationConfig
from ..fit.camera_scale import scale_note
from ..fit.methods import Estimate
from ..fit.noise import NoiseEstimate
from ..fit.problem import Problem
from .diagnostics import GoodnessOfFit, Physicality, goodness_of_fit, joint_patterns, misfit_message, physicality
from .identifiability import analyse
from .statistics import covariance


@dataclass(frozen=True)
class Judgement:
    """Step 9's findings: goodness of fit, standard uncertainties and covariance (None for a
    swarm), each parameter's prior share (the leverage of its prior, 0 without one), the verdict
    on physicality, and what they call for saying."""

    goodness: GoodnessOfFit
    uncertainty: np.ndarray | None
    covariance: np.ndarray | None
    notes: list[str]
    prior_share: np.ndarray | None = None
    physical: Physicality = field(default_factory=Physicality)
    at_estimate: AtEstimate | None = None


@dataclass(frozen=True)
class AtEstimate:
    """The kept set's identifiability where the fit ended: its condition number, and the kept
    parameters the poses do not separate there (name → the kept ones it depends on).  A fit that
    walked along a valley the nominal model did not show ends where some column has fallen into
    the span of the others."""

    condition: float
    dependent: dict[str, tuple[str, ...]] = field(default_factory=dict)

    def notes(self, prior: bool) -> list[str]:
        if not self.dependent:
            return []
        pairs = "; ".join(f"{n} on {', '.join(r) or 'the others'}" for n, r in self.dependent.items())
        if prior:  # what the prior holds is said by name in the parameters table: a note, not a fault
            return [Note(f"at the estimate the poses do not separate {pairs}: held by their prior")]
        return [f"at the estimate the poses do not separate {pairs}: the fit ended in a valley the data cannot "
                "see, and those values are not measured (a prior would hold them: see --prior)"]

    def to_dict(self) -> dict:
        return {"condition_number": self.condition, "dependent": {n: list(r) for n, r in self.dependent.items()}}


def recheck(problem: Problem, x: np.ndarray) -> AtEstimate:
    """The identifiability analysis of the kept set on the data's Jacobian at the estimate."""
    again = analyse(problem.residual_jacobian(x), problem.names, problem.angle_mask, problem.meas.n_poses,
                    problem.space.robot.reach(), prefer=problem.names)
    return AtEstimate(again.condition, {n: again.reasons[n].related for n in again.dropped})


def turns(problem: Problem, x: np.ndarray) -> dict[str, float]:
    """Each joint-term parameter's largest turn of its joint over the poses (rad): max |B_t x_t|."""
    return {n: reach * abs(float(x[i])) for n, (i, reach) in _term_reach(problem).items()}


def _term_reach(problem: Problem) -> dict[str, tuple[int, float]]:
    """Each joint-term parameter's index and its largest turn of its joint per unit (max |B_t|)."""
    joints = problem.joints
    names = problem.names
    if joints is None or not any(is_term(n) for n in names):
        return {}
    order = list(problem.space.terms.names(problem.space.robot.n_joints))
    out = {}
    for i, n in enumerate(names):
        if is_term(n):
            column = joints.basis[:, :, order.index(n)]
            out[n] = (i, float(np.max(np.abs(column))) if column.size else 0.0)
    return out


#: a deviation this many prior widths off is implausible, where that is beyond the fixed bounds
PLAUSIBLE_WIDTHS = 4.0


def plausible_limits(problem: Problem, x: np.ndarray, inverse: np.ndarray | None) -> np.ndarray:
    """Each parameter's bound of plausibility, in its own units (a term's in rad of turn): the fixed
    bounds of :mod:`robocal.calibration.judge.diagnostics`, or :data:`PLAUSIBLE_WIDTHS` of the prior width the
    fit took where that is wider (a width stated, or one the data sized: then as the kind's other
    parameters show it, :func:`~robocal.calibration.fit.widths.others_width`)."""
    from ...model.parameters import is_angle
    from ..fit.widths import others_width
    from .diagnostics import PLAUSIBLE_ANGLE_RAD, PLAUSIBLE_LENGTH_MM, PLAUSIBLE_TERM_RAD

    sized = inverse is not None and bool(problem.setup.sized)
    sigma = others_width(problem, x, inverse) if sized else problem.prior_sigma
    reach = _term_reach(problem)
    out = np.empty(problem.n_params)
    for i, n in enumerate(problem.names):
        if n in reach:
            fixed, width = PLAUSIBLE_TERM_RAD, sigma[i] * reach[n][1]
        else:
            fixed, width = (PLAUSIBLE_ANGLE_RAD if is_angle(n) else PLAUSIBLE_LENGTH_MM), sigma[i]
        out[i] = max(fixed, PLAUSIBLE_WIDTHS * width) if np.isfinite(width) else fixed
    return out


def judge(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate) -> Judgement:
    """Step 9: goodness of fit, covariance and standard uncertainties, and the warnings they call for.

    The covariance is the posterior's, (JᵀJ + P)⁻¹ from the whitened Jacobian at the solution and
    the prior's information P (zero where free); the parameters' effective number tr H =
    k − Σ h_i (h_i the prior's share of parameter i) is what the data's degrees of freedom lose.
    With stated noise and a fit worse than it (reduced χ² = s > 1) the data's σ is taken as √s
    times the stated one: their information is JᵀJ/s, the prior's stays P, and the posterior is
    (JᵀJ/s + P)⁻¹ (never wider than the prior), which is then said; with estimated noise s is 1
    by construction.
    """
    problem, x = est.problem, est.x
    inverse = shares = None
    effective = None
    if config.least_squares:
        inverse = covariance(problem.map_jacobian(x))
        if problem.has_prior and np.all(np.isfinite(inverse)):
            shares = prior_shares(inverse, problem.prior_sigma)
            effective = float(problem.n_params - shares.sum())
    gof = goodness_of_fit(problem, x, noise.source, effective)
    notes: list[str] = []
    cov = None
    if config.least_squares and gof.dof > 0:
        scale = gof.reduced_chi2 if noise.source == "estimated" else max(1.0, gof.reduced_chi2)
        if problem.has_prior and scale > 1e-12:  # the data's information scaled, the prior's counted once
            # (noise-free data: s → 0, the data's information swamps the prior's, and s·(JᵀJ + P)⁻¹ is the limit)
            J = problem.map_jacobian(x)  # the data's rows, then the prior's: only the data's are scaled
            # (the prior's share stays the leverage its pseudo-observations had in the fit, as weighed there:
            # the degrees of freedom χ² is judged on are those of that fit)
            data = J.shape[0] - problem.n_prior
            cov = covariance(np.vstack([J[:data] / np.sqrt(scale), J[data:]]))
        else:
            cov = scale * inverse
    if gof.misfit():
        notes.append(misfit_message(gof, joint_patterns(problem, x))
                     + (f"; uncertainties scaled by √χ²ᵣ = {np.sqrt(gof.reduced_chi2):.3g}" if cov is not None else ""))
    unc = None if cov is None else np.sqrt(np.diag(cov))
    corr = None
    if cov is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(unc, unc)
    at_estimate = recheck(problem, x)
    notes += at_estimate.notes(problem.has_prior)
    said = scale_note(problem, x, cov)
    if said is not None:
        notes.append(said)
    verdict = physicality(problem.names, x, unc, corr, turns(problem, x), plausible_limits(problem, x, inverse))
    if not verdict.physical:
        notes.append(verdict.sentence())
    if config.least_squares and gof.dof <= 0:
        unc = np.full(problem.n_params, np.nan)
    return Judgement(gof, unc, cov, notes, shares, verdict, at_estimate)
