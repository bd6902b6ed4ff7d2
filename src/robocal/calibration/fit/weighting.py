"""How the residuals are weighed: σ per block where not stated (step 7), the instrument's σ per
point, and each kind of rows by its own σ; each refits until the weights settle.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...exceptions import Note
from ...optimize.result import OptimizeResult
from ..config import CalibrationConfig
from .instrument import (
    MAX_ROUNDS,
    InstrumentFit,
    KindWeights,
    beyond_instrument,
    instrument_fit,
    kind_weights,
    several_kinds,
)
from .methods import Estimate, fit_lm
from .noise import LINEAR_CHI2, MAX_REWEIGHTS, NoiseEstimate, block_sigmas, confirmed, leverage_split, settle, settled


def weigh_instrument(est: Estimate, config: CalibrationConfig,
                     noise: NoiseEstimate) -> tuple[Estimate, NoiseEstimate, InstrumentFit | None]:
    """Step 8b, where the data give the instrument's σ per point: weigh each point by
    σ_eff² = σ_i² + τ², τ the scatter beyond the instrument, and refit until τ settles (see
    :mod:`robocal.calibration.fit.instrument`); then the misfit against the instrument alone."""
    meas = est.problem.meas
    if meas.sigma_position is None and meas.sigma_orientation is None:
        return est, noise, None
    if config.least_squares and est.optimization.status == "converged":
        for _ in range(MAX_ROUNDS):
            problem = est.problem
            weights = beyond_instrument(problem, est.x, leverage_split(problem, est.x))
            if weights.settled(problem.setup.instrument, meas):
                break
            problem = replace(problem.setup, instrument=weights).problem(problem.names)
            lm = fit_lm(problem, est.x, config)
            est = est.refitted(problem, lm, "weighed by the instrument's σ")
            est, noise = reweigh(est, config)
            if lm.status != "converged":
                break
    return est, noise, instrument_fit(est.problem, est.x, meas.sigma_source or "σ per point",
                                      leverage_split(est.problem, est.x))


def weigh_kinds(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate) -> tuple[Estimate, NoiseEstimate,
                                                                                         list[str]]:
    """Step 8c, rows of several kinds (tracker rows, rows that touched points or planes, rows a
    camera saw): each kind weighed by its own σ, estimated from its residuals, and the fit repeated
    until they settle."""
    meas = est.problem.meas
    if not several_kinds(meas) or meas.sigma_position is not None or noise.source == "stated" or \
            not (config.least_squares and est.optimization.status == "converged"):
        return est, noise, []
    for _ in range(MAX_ROUNDS):
        problem = est.problem
        weights = kind_weights(problem, est.x)
        if weights.settled(problem.setup.instrument, meas):
            break
        problem = replace(problem.setup, instrument=weights, sigma_position=weights.ref).problem(problem.names)
        lm = fit_lm(problem, est.x, config)
        est = est.refitted(problem, lm, "each kind of rows weighed by its σ")
        if lm.status != "converged":
            break
    weights = est.problem.setup.instrument
    return est, noise, [] if not isinstance(weights, KindWeights) else [Note(f"weighed by kind: {weights.sentence()}")]




def reweigh(est: Estimate, config: CalibrationConfig) -> tuple[Estimate, NoiseEstimate]:
    """Step 7: estimate σ per residual block where it is not stated, and refit with it until
    the weights settle (see :mod:`robocal.calibration.fit.noise`).  Swarms keep their answer; their
    σ is estimated once, for the report."""
    model, problem = config.noise_model, est.problem
    full = problem.uses_orientation
    source = "stated" if model.stated(full) else "estimated"
    sigmas = (problem.setup.sigma_position, problem.setup.sigma_orientation)
    refits = 0
    refit = config.least_squares and est.optimization.status == "converged"
    if source == "estimated" and problem.n_residuals > problem.n_params:
        if not refit:  # a swarm keeps its answer: σ is estimated once, for the report
            sigmas = block_sigmas(problem, est.x, model)
            return est.replace(problem=problem.setup.with_noise(*sigmas).problem(problem.names)), NoiseEstimate(
                sigmas[0], sigmas[1] if full else None, source, 0)
        for _ in range(MAX_REWEIGHTS):
            target = settle(problem, est.x, model)
            moved = not settled(sigmas, target.sigmas, full, problem.has_prior)
            sigmas, problem = target.sigmas, problem.setup.with_noise(*target.sigmas).problem(problem.names)
            if not moved:  # the same solution, now weighed by the σ it shows
                est = est.replace(problem=problem)
                break
            x = est.x + target.step
            r = problem.map_residuals(x)
            chi2 = float(r @ r)
            if config.loss == "linear" and abs(chi2 - target.chi2) <= LINEAR_CHI2:
                # linear there: the Gauss–Newton step is the refit, and LM would only confirm it
                step = OptimizeResult("gauss-newton", x, chi2, np.array([chi2]), 1, 1, "converged",
                                      "one Gauss–Newton step", 0.0)
            else:
                step = fit_lm(problem, est.x, config)
            refits += 1
            # χ² under new weights is another scale: the history stays that of the first weights
            est = est.refitted(problem, step, f"reweighted (σp {sigmas[0]:.3g} mm)")
            if step.status != "converged" or confirmed(problem, est.x, target, model):
                break
    return est, NoiseEstimate(sigmas[0], sigmas[1] if full else None, source, refits)
