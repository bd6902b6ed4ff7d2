"""One parametric model (geometry and joint terms) fitted to the data: steps 2–9.

:func:`fit_parametric` registers the frames, offers the candidates, keeps what the data
determine, runs the method, screens outliers, settles the weights, re-checks identifiability
at the estimate and judges the fit, each step in its own module.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...model.candidates import complete
from ...model.measurements import Measurements
from ...model.parameters import ParameterSpace
from ...model.prior import HELD, Prior
from ...model.robot import Robot
from ...model.terms import TERMS, TermSpec
from ...optimize.result import Progress
from ..config import CalibrationConfig, resolve_params
from ..inputs import Inputs
from ..judge.diagnostics import GoodnessOfFit, Physicality
from ..judge.identifiability import Identifiability
from ..judge.judgement import AtEstimate, judge
from ..select.subset import (
    Candidates,
    analyse_identifiability,
    choose_candidates,
    refine_at_estimate,
    searched_names,
)
from ..timing import stage
from . import cameras
from .instrument import InstrumentFit
from .methods import Estimate, optimize
from .noise import NoiseEstimate
from .problem import Setup
from .registration import fit_frames
from .screening import Screening, screen_outliers
from .shared import weigh_shared
from .weighting import reweigh, weigh_instrument, weigh_kinds
from .widths import size_widths


def complete_model(robot: Robot, config: CalibrationConfig) -> Robot:
    """The robot with β offered on DH parallel axes (:func:`robocal.model.candidates.complete`),
    unless the user's parameter list leaves β out (the papers' 24, for instance)."""
    requested = resolve_params(config.params, robot)
    if requested is not None and not any(n.startswith("beta") for n in requested):
        return robot
    return complete(robot)


def register(inputs: Inputs, config: CalibrationConfig, spec: TermSpec = TermSpec(),
             parent: Fit | None = None) -> Setup:
    """Step 2: the complete model, its frames fitted with the nominal joints (closed form, then
    LM on base and tools together: see :func:`~robocal.calibration.fit.registration.fit_frames`),
    the parameter space around the result, and the noise weighting to start with.  A swarm
    then searches a few millimetres around frames that are already right.  With a ``parent``
    fit of the same data (a simpler model), its registration (the same: it depends on the
    nominal joints only) and its settled weights are the start."""
    targets = inputs.meas.target_names if inputs.frames in ("base+tool", "tcp") else None
    prior = prior_of(inputs.nominal, config)
    if parent is not None:
        settled = parent.estimate.problem.setup
        return Setup(ParameterSpace.of(parent.setup.space.robot, targets, spec), inputs.meas, settled.sigma_position,
                     settled.sigma_orientation, config.use_orientation, config.backend,
                     settled.instrument, shared=settled.shared).with_prior(prior)
    sigma_p, sigma_r = config.noise_model.initial()
    with stage("optimize"):
        if inputs.meas.views is not None:
            initial = complete_model(inputs.nominal, config)
            if cameras.tracked(inputs.meas):  # the tracker's rows register the base, then the cameras start
                seen = np.array([bool(c) for c in inputs.meas.camera])
                initial = fit_frames(initial, inputs.meas.subset(~seen), inputs.frames, sigma_p, sigma_r)
            initial = cameras.register(initial, inputs.meas)
        elif inputs.session_frames:
            initial = register_sessions(complete_model(inputs.nominal, config), inputs.meas, inputs.frames, sigma_p,
                                        sigma_r)
        else:
            initial = fit_frames(complete_model(inputs.nominal, config), inputs.meas, inputs.frames, sigma_p, sigma_r)
    space = ParameterSpace.of(initial, targets, spec)
    return Setup(space, inputs.meas, sigma_p, sigma_r, config.use_orientation, config.backend).with_prior(prior)


def register_sessions(robot: Robot, meas: Measurements, frames: str, sigma_p: float, sigma_r: float) -> Robot:
    """Each session's frames fitted to its own rows with the nominal joints (as :func:`fit_frames`
    registers one campaign's): the first session's base is the robot's, each later one's a base of
    its own (:attr:`Robot.session_bases`), every session's tools its targets'."""
    labels = np.asarray(meas.session, dtype=object)
    first, bases, targets = None, {}, dict(robot.targets)
    for label in meas.sessions:
        own = fit_frames(robot, meas.subset(labels == label), frames, sigma_p, sigma_r)
        if first is None:
            first = own
        else:
            bases[label] = own.base
        named = {t: own.targets[t] for t in set(meas.subset(labels == label).target_names) if t in own.targets}
        targets.update(named)
        if "" in meas.subset(labels == label).target_names:
            targets[""] = own.tool
    tool = targets.pop("", first.tool)
    return first.replace(targets=targets, tool=tool, session_bases=bases)


def prior_of(nominal: Robot, config: CalibrationConfig) -> Prior | None:
    """The prior the least-squares fit takes: the defaults, the robot file's ``[prior]`` table over
    them, the config's (``--prior``) over that; None for a swarm alone, which minimises its
    paper's objective as the paper states it."""
    if not config.least_squares:
        return None
    base = nominal.prior if nominal.prior is not None else Prior()
    return base.merged(config.prior)




def _status_notes(est: Estimate, config: CalibrationConfig) -> list[str]:
    opt = est.optimization
    if opt.status in ("diverged", "failed"):
        return [f"optimizer {opt.method} {opt.status}: {opt.message}"]
    if config.least_squares and opt.status != "converged":
        return [f"Levenberg–Marquardt stopped before converging: {opt.message}"]
    return []


@dataclass
class Fit:
    """A parametric model (geometry and joint terms) fitted to the data: what steps 2–9 give."""

    setup: Setup
    candidates: Candidates
    identifiability: Identifiability
    estimate: Estimate
    screening: Screening
    noise: NoiseEstimate
    goodness: GoodnessOfFit
    uncertainty: np.ndarray | None
    covariance: np.ndarray | None
    notes: list[str]
    instrument: InstrumentFit | None = None
    #: each estimated parameter's prior share (0: the data alone; 1: the prior alone), None without a prior
    prior_share: np.ndarray | None = None
    physical: Physicality = field(default_factory=Physicality)
    #: the kept set's identifiability where the fit ended (None for a swarm alone)
    at_estimate: AtEstimate | None = None

    @property
    def held(self) -> list[str]:
        """The parameters the poses do not pin, held by their prior."""
        names = self.estimate.problem.names
        return [] if self.prior_share is None else [n for n, h in zip(names, self.prior_share) if h > HELD]

    @property
    def robot(self) -> Robot:
        return self.setup.space.apply(self.estimate.problem.full(self.estimate.x))

    @property
    def n_params(self) -> int:
        return self.estimate.problem.n_params


def term_spec(terms, meas: Measurements, config: CalibrationConfig) -> TermSpec:
    """The joint terms of a model for these data, each as its entry of
    :data:`robocal.model.terms.TERMS` chooses from the data and the config's settings."""
    settings = {"harmonics": config.harmonics, "row_order": config.row_order}
    return TermSpec({name: TERMS[name].option_for(meas, settings) for name in terms if name in TERMS})


def unsupported_terms(terms, meas: Measurements, config: CalibrationConfig) -> dict[str, str]:
    """The joint terms among ``terms`` these data cannot support, with what each needs (a drift
    needs time, a backlash directions of approach; the rows' order gives them only where
    ``row_order`` says it is the measuring order)."""
    settings = {"harmonics": config.harmonics, "row_order": config.row_order}
    return {name: TERMS[name].needs for name in terms if name in TERMS and not TERMS[name].option_for(meas, settings)}


def _start_from(parent: Fit | None, problem) -> np.ndarray | None:
    """The parent fit's values of the parameters ``problem`` shares with it (zero for the rest)."""
    if parent is None:
        return None
    values = dict(zip(parent.setup.space.names, parent.estimate.problem.full(parent.estimate.x)))
    return np.array([values.get(n, 0.0) for n in problem.names])


def fit_parametric(inputs: Inputs, config: CalibrationConfig, spec: TermSpec,
                   progress: Progress | None = None, parent: Fit | None = None) -> Fit:
    """Steps 2–9 for one parametric model; from a ``parent`` fit of the same data (a model with
    fewer terms) when given: its registration, weights and estimate are where this one starts,
    which changes the path, not the optimum (``auto`` tries each term on the model kept so far)."""
    setup = register(inputs, config, spec, parent)
    candidates = choose_candidates(setup, config, inputs.frames)
    with stage("statistics"):
        ident, notes = analyse_identifiability(setup, candidates)
    with stage("optimize"):
        problem = setup.problem(ident.kept)
        est = optimize(problem, setup.problem(searched_names(candidates, ident)), config, progress,
                       start=_start_from(parent, problem), scaled=parent is not None)
    with stage("statistics"):  # the refits inside count as optimizing
        est, screening, said = screen_outliers(est, config)
        notes += said + _status_notes(est, config)
        est, noise = reweigh(est, config)
        refined, ident = refine_at_estimate(est, ident, candidates, config)
        if refined is not est:  # parameters were added: their weights are settled again
            est, noise = reweigh(refined, config)
        est, noise, instrument = weigh_instrument(est, config, noise)
        est, noise, said = weigh_kinds(est, config, noise)
        notes += said
        est, noise, said = weigh_shared(est, config, noise)
        notes += said
        est, noise, said = size_widths(est, config, noise, prior_of(inputs.nominal, config))
        notes += said
        judged = judge(est, config, noise)
    return Fit(setup, candidates, ident, est, screening, noise, judged.goodness, judged.uncertainty,
               judged.covariance, notes + judged.notes, instrument, judged.prior_share, judged.physical,
               judged.at_estimate)
