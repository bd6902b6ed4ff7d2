"""Prior widths the data can size (MODEL §3.1): where many parameters of one kind are estimated (a
robot's seven lengths of each sort, six compliances, seven joints' harmonics), how far they
deviate says how wide their kind's prior is.  One default width cannot serve a machined industrial
arm and a light elastic torso alike, nor a harmonic drive and a cable drive.

The width is the evidence's fixed point (MacKay's): with the posterior mean x̂_i and variance C_ii
under width w, each parameter's well-determinedness γ_i = 1 − C_ii/σ_i² (σ_i the width in its own
units), and w² = Σ (x̂_i w/σ_i)² / Σ γ_i, repeated with the refit until it settles.  The data widen a
kind only where its parameters are determined (Σγ ≥ :data:`MIN_DETERMINED`, of at least
:data:`MIN_MEMBERS`) and only beyond the default: a narrower width from a dozen deviations would
claim more than they show, and a default is what is known before measuring.  A width stated in the
robot file's ``[prior]`` or on the command line is never sized.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ...exceptions import Note
from ...model.prior import ALL, DEFAULTS, Prior, kind_of
from ..config import CalibrationConfig
from ..judge.statistics import covariance
from .methods import Estimate
from .noise import NoiseEstimate

#: the kinds the data may size
SIZED = ("length", "angle", "zero", "compliance", "harmonic", "backlash", "drift")
#: fewest estimated parameters of a kind for its width to be sized
MIN_MEMBERS = 4
#: the kind's parameters must be this determined in all (Σγ): a width from fewer says too little
MIN_DETERMINED = 2.5
#: relative change of a width below which it has settled
SETTLED = 0.05
#: rounds of sizing and refitting
MAX_ROUNDS = 5
#: units of each kind's width as the notes say it
UNITS = {"length": " mm", "drift": "°/h"}


def others_width(problem, x: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Each parameter's prior width (its own units) as the other parameters of its kind show it, for a
    kind the data sized (:attr:`Setup.sized`; the width used for the rest), never below the default:
    one parameter far off its kind (a link 30 mm off its drawing) is judged against what the others
    show, not against a width it widened itself.  C: the posterior covariance at x."""
    sigma = np.array(problem.prior_sigma, float)
    sized = problem.setup.sized
    if not sized:
        return sigma
    prismatic = problem.space.robot.prismatic
    kinds = np.array([kind_of(n, prismatic) for n in problem.names], dtype=object)
    out = sigma.copy()
    for kind, width in sized.items():
        index = np.flatnonzero((kinds == kind) & np.isfinite(sigma))
        u2 = (x[index] / sigma[index]) ** 2
        gamma = np.clip(1.0 - np.diag(C)[index] / sigma[index] ** 2, 0.0, 1.0)
        floor = DEFAULTS[kind][0] / width  # the default, in units of the width used
        for j, i in enumerate(index):
            rest = np.arange(len(index)) != j
            ratio = math.sqrt(float(u2[rest].sum()) / max(float(gamma[rest].sum()), 1e-12))
            out[i] = sigma[i] * max(ratio, floor)
    return out


def size_widths(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate, prior: Prior | None
                ) -> tuple[Estimate, NoiseEstimate, list[str]]:
    """The fit with each unstated kind's width sized by the data where they show it wider than the
    default (see the module), and the note that says which."""
    from .shared import _refit
    from .weighting import reweigh

    problem = est.problem
    if prior is None or not problem.has_prior or not config.least_squares or \
            est.optimization.status != "converged" or ALL in prior.widths or problem.views is not None:
        # (pixels: what a camera calibration leaves out shows as wide deviations; their prior is the
        # guard against it, and stays as stated)
        return est, noise, []
    prismatic = problem.space.robot.prismatic
    kinds: dict[str, list[int]] = {}
    for i, name in enumerate(problem.names):
        kind = kind_of(name, prismatic)
        if kind in SIZED and kind not in prior.widths and name not in prior.widths and \
                math.isfinite(problem.prior_sigma[i]):
            kinds.setdefault(kind, []).append(i)
    kinds = {k: v for k, v in kinds.items() if len(v) >= MIN_MEMBERS}
    if not kinds:
        return est, noise, []
    widths: dict[str, float] = {}
    for _ in range(MAX_ROUNDS):
        x, sigma = est.x, problem.prior_sigma
        C = covariance(problem.map_jacobian(x))
        changed = {}
        for kind, index in kinds.items():
            width = widths.get(kind, DEFAULTS[kind][0])
            gamma = 1.0 - np.diag(C)[index] / sigma[index] ** 2
            if not np.all(np.isfinite(gamma)) or gamma.sum() < MIN_DETERMINED:
                continue
            sized = max(width * math.sqrt(float(np.sum((x[index] / sigma[index]) ** 2)) / gamma.sum()),
                        DEFAULTS[kind][0])
            if abs(sized / width - 1.0) > SETTLED:
                changed[kind] = sized
        if not changed:
            break
        widths.update(changed)
        setup = replace(problem.setup.with_prior(prior.merged(Prior(widths))), sized=dict(widths))
        problem = setup.problem(problem.names)
        step = _refit(problem, x, config)
        est = est.refitted(problem, step, "prior widths sized by the data")
        est, noise = reweigh(est, config)
        if step.status != "converged":
            break
    if not widths:
        return est, noise, []
    said = ", ".join(f"{k} {w:.3g}{UNITS.get(k, '°')} (default {DEFAULTS[k][0]:g}{UNITS.get(k, '°')})"
                     for k, w in widths.items())
    return est, noise, [Note(f"prior widths from the data: {said}: these data show deviations of that kind wider "
                             "than the default; the verdict on physicality takes the width used; state --prior "
                             "KIND=WIDTH to hold them")]
