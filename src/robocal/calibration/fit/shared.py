"""Weighing camera rows by what a pose's rows share (:mod:`robocal.model.shared`): the ratio of the
shared error to each row's own estimated from the residuals, and the fit repeated until it settles.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...exceptions import Note
from ...model.shared import SharedErrors, estimate_ratio, groups_of
from ..config import CalibrationConfig
from .methods import Estimate, fit_lm
from .noise import NoiseEstimate

#: relative change of ρ below which the weights have settled
SETTLED = 2e-2
#: refits allowed to the settling
MAX_ROUNDS = 4
#: a shared part below this share of a row's variance (σ_b² < 1 % of σ_ε²) is not worth modelling
NEGLIGIBLE = 1e-2


def _refit(problem, x: np.ndarray, config: CalibrationConfig):
    """The fit under new weights from x: the Gauss–Newton step where the problem is linear there (the
    χ² it reaches is the χ² it predicts, within :data:`~robocal.calibration.fit.noise.LINEAR_CHI2`: LM would
    only confirm it), else LM."""
    from ...optimize.result import OptimizeResult
    from .noise import LINEAR_CHI2

    r, J = problem.map_residuals(x), problem.map_jacobian(x)
    step = np.linalg.lstsq(J, -r, rcond=None)[0]
    predicted = float(np.sum((r + J @ step) ** 2))
    reached = problem.map_residuals(x + step)
    chi2 = float(reached @ reached)
    if config.loss == "linear" and abs(chi2 - predicted) <= LINEAR_CHI2:
        return OptimizeResult("gauss-newton", x + step, chi2, np.array([chi2]), 1, 1, "converged",
                              "one Gauss–Newton step", 0.0)
    return fit_lm(problem, x, config)


def weigh_shared(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate
                 ) -> tuple[Estimate, NoiseEstimate, list[str]]:
    """Camera rows: the share of their error a pose's rows in one camera have in common (ρ),
    estimated from the residuals, and the fit repeated with the rows weighed by it until ρ settles."""
    from .weighting import reweigh

    problem = est.problem
    if problem.views is None or not (config.least_squares and est.optimization.status == "converged"):
        return est, noise, []
    found = estimate_ratio(problem.errors(est.x)[0], problem.meas)
    if found is None or found[0] < NEGLIGIBLE:
        return est, noise, []
    ratio, own = found[0], found[1]
    stated = config.noise_model.position is not None
    for _ in range(MAX_ROUNDS):
        # the rows' own σ with the ratio (the whitened rows' scale, unless stated): the prior weighs
        # against it; the σ is settled with the degrees of freedom the fit uses once ρ has settled
        setup = replace(problem.setup, shared=SharedErrors(ratio),
                        sigma_position=problem.setup.sigma_position if stated else own)
        problem = setup.problem(problem.names)
        lm = _refit(problem, est.x, config)
        est = est.refitted(problem, lm, f"a pose's camera rows weighed as sharing an error (ρ {ratio:.3g})")
        found = estimate_ratio(problem.errors(est.x)[0], problem.meas)
        if lm.status != "converged" or found is None or abs(found[0] / ratio - 1.0) <= SETTLED:
            break
        ratio, own = max(found[0], NEGLIGIBLE), found[1]
    est, noise = reweigh(est, config)
    _, own, common = found if found is not None else (ratio, float("nan"), float("nan"))
    n = np.bincount(groups_of(problem.meas)[groups_of(problem.meas) >= 0])
    return est, noise, [Note(f"a pose's camera rows share an error: σ {common:.3g} px common to the markers one camera "
                             f"saw at one pose, {own:.3g} px each row's own; what they share counts once for each of "
                             f"the {len(n)} groups (pose and camera), not once for each of its {np.mean(n):.3g} rows")]
