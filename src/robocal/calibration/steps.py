"""The steps of a calibration: nominal robot + measurements → a fitted parametric model.

:func:`robocal.calibration.pipeline.calibrate` runs them, each a function below; each returns
what it found, and what it has to say as a list of notes (never a list it was handed):

1. :func:`load_inputs`: robot, data and validation data, checked against each other;
2. :func:`register`: a complete model (DH + β on parallel axes), the measuring frame (and
   tool offsets) in closed form, the noise weighting to start with;
3. :func:`choose_candidates`: the parameters offered, from the config;
4. :func:`analyse_identifiability`: the identifiable subset, the rest dropped with reasons;
5. :func:`robocal.calibration.methods.optimize`: the configured method;
6. :func:`screen_outliers`: with a robust loss, outliers left out and the inliers refitted;
7. :func:`reweigh`: σ estimated per residual block where not stated, and the fit repeated;
8. :func:`refine_at_estimate`: identifiability re-checked at the estimate (F-test);
9. :func:`judge`: goodness of fit, standard uncertainties, misfit and plausibility warnings;
10. :func:`evaluate`: before/after metrics.

"Before" figures use the nominal joint geometry with the registered frames, i.e. the best
a rigid re-mounting of the nominal model can do, so that the improvement shown is the
calibration's own and not that of finding the tracker frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..exceptions import InputError
from ..io.measurements import load_measurements
from ..io.robotfile import load_robot
from ..model.candidates import complete, frame_candidates, joint_candidates
from ..model.kinematics import joint_kinds
from ..model.measurements import Measurements
from ..model.metrics import Metrics
from ..model.parameters import ParameterSpace, is_angle, is_term
from ..model.robot import Robot
from ..model.terms import TERMS, TermSpec
from ..optimize.result import OptimizeResult, Progress
from . import checks
from .config import CalibrationConfig, resolve_params
from .diagnostics import GoodnessOfFit, goodness_of_fit, implausible_deviations, joint_patterns, misfit_message
from .identifiability import (
    NO_EFFECT,
    SECOND_ORDER,
    STILL,
    UNOBSERVABLE,
    UNVARIED,
    Identifiability,
    Reason,
    analyse,
)
from .instrument import (
    MAX_ROUNDS,
    Instrument,
    InstrumentFit,
    KindWeights,
    beyond_instrument,
    instrument_fit,
    kind_weights,
    with_instrument,
)
from .methods import Estimate, fit_lm, optimize
from .noise import (
    LINEAR_CHI2,
    MAX_REWEIGHTS,
    NoiseEstimate,
    block_sigmas,
    confirmed,
    leverage_split,
    settle,
    settled,
)
from .problem import Setup
from .registration import choose_frames, fit_frames
from .statistics import (
    MAX_OUTLIER_FRACTION,
    OUTLIER_GAP,
    OUTLIER_SIGMAS,
    covariance,
    f_test,
    leave_one_out,
    robust_outliers,
)
from .timing import stage

#: significance level of the F-test that decides whether parameters that become
#: identifiable at the estimate are worth adding
ADD_SIGNIFICANCE = 0.01
#: residual evaluations allowed to the refit with the added parameters
REFIT_EVALUATIONS = 100
#: F-test p of the Gauss–Newton step's predicted decrease above which the refit is not tried:
#: fifty times the significance level, where the refit would need to find several times the
#: decrease the linearisation predicts
CLEARLY_NOT_SIGNIFICANT = 0.5


@dataclass(frozen=True)
class Inputs:
    """The nominal robot, the measurements, validation data, the frames mode in effect, and what
    was noticed on the way (the frames chosen, degenerate data)."""

    nominal: Robot
    meas: Measurements
    validation: Measurements | None
    frames: str
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Candidates:
    """The parameters offered: joint names (``explicit`` when the user chose them) and frames."""

    joints: list[str]
    names: list[str]
    explicit: bool


def _measurements(data, nominal: Robot, config: CalibrationConfig, columns) -> Measurements:
    if isinstance(data, Measurements):
        if data.n_joints != nominal.n_joints:
            raise InputError(f"data have {data.n_joints} joints, the robot has {nominal.n_joints}", source=data.source)
        return data
    return load_measurements(data, **config.read_options(nominal, columns))


def load_inputs(robot, data, validate, config: CalibrationConfig, columns=None) -> Inputs:
    """Step 1: the nominal robot and the measurements, position-only when asked, checked; the
    frames mode (``auto`` decides here, and says what it decided, in the inputs' notes)."""
    notes: list[str] = []
    nominal = load_robot(robot)
    if nominal.residual is not None:  # a calibration learns its own correction from what its fit leaves
        notes.append(f"the residual model of {nominal.source or nominal.name} is not used as a starting point: a "
                     "calibration fits its own (with --model residual or auto)")
        nominal = nominal.replace(residual=None)
    if nominal.region is not None:  # a new calibration finds its own
        nominal = nominal.replace(region=None)
    meas = _measurements(data, nominal, config, columns)
    val = None if validate is None else _measurements(validate, nominal, config, columns)
    if not (meas.full_pose and config.use_orientation):
        meas = meas.position_only()
        val = None if val is None else val.position_only()
    if config.point_distance:  # stated here; measurements given as objects may carry their own
        meas = meas.with_distances(config.point_distance, config.distance_sigma)
        if val is not None and val.constraints is not None:
            val = val.with_distances(config.point_distance, config.distance_sigma)
    meas = _instrument_sigmas(meas, config, notes)
    meas = _excluded(meas, config.exclude, notes)
    if config.payload is not None:  # a stated payload where the files have no column
        meas = meas if meas.payload is not None else replace(meas, payload=np.full(meas.n_poses, config.payload))
        if val is not None and val.payload is None:
            val = replace(val, payload=np.full(val.n_poses, config.payload))
    frames = config.frames
    if meas.constraints is not None:
        frames, said = _contact_frames(frames, meas)
        notes += said
    elif frames in ("auto", "none"):
        choice = choose_frames(nominal, meas)
        if frames == "auto" and choice.mode != "none":  # it changed what is calibrated: say so
            notes.append(f"frames auto: {choice.sentence()}")
        elif frames == "none" and choice.mode != "none":
            notes.append(f"frames none, but {choice.sentence()}: calibrate with frames auto or {choice.mode}")
        frames = choice.mode if frames == "auto" else "none"
    tracker = meas if meas.constraints is None else meas.subset(~meas.constraints.rows)
    if tracker.n_poses:
        checks.check_targets(nominal, tracker, frames)
        checks.check_validation_targets(nominal, tracker, val)
        if config.length_unit is None:  # a stated unit overrides the spread check
            checks.check_units(nominal, tracker, frames)
    return Inputs(nominal, meas, val, frames, tuple(notes + checks.degeneracy_warnings(nominal, meas)))


def _contact_frames(frames: str, meas: Measurements) -> tuple[str, list[str]]:
    """The frames of data whose rows touched unknown points or planes: those can stand anywhere,
    so they cannot see the base frame; the tool point they see.  Tracker rows beside them see
    the base as ever."""
    c = meas.constraints
    if c.only and frames in ("base", "base+tool"):
        raise InputError(f"the base frame is not observable from {meas.source}: its rows touched points or planes "
                         "whose place is unknown (use frames tcp, or auto)", option="frames")
    if frames != "auto":
        return frames, []
    if c.only:
        return "tcp", ["frames auto: the rows touched points or planes whose place is unknown, so the base frame is "
                        "not observable from them; the tool point is identified (frames tcp)"]
    return "base+tool", ["frames auto: tracker rows beside rows that touched points or planes: base and tool are "
                         "identified (frames base+tool)"]


def _excluded(meas: Measurements, exclude: tuple[str, ...], notes: list[str]) -> Measurements:
    """The measurements without the poses ``exclude`` names (pose ids, or ``row N``); a name the
    data do not have is an error (a typo would otherwise leave a bad pose in)."""
    if not exclude:
        return meas
    ids = [meas.pose_ids[i] if meas.pose_ids is not None else f"row {int(meas.rows[i])}" for i in range(meas.n_poses)]
    unknown = [e for e in exclude if e not in set(ids)]
    if unknown:
        what = "pose_id" if meas.pose_ids is not None else "row (written 'row N')"
        raise InputError(f"excluded pose {unknown[0]!r} is not in the data (no such {what})", source=meas.source,
                         option="exclude")
    keep = [i for i, x in enumerate(ids) if x not in set(exclude)]
    if not keep:
        raise InputError(f"leaves none of the {meas.n_poses} poses to calibrate on", source=meas.source,
                         option="exclude")
    notes.append(f"{meas.n_poses - len(keep)} pose(s) left out as asked (--exclude): {', '.join(exclude[:10])}"
                 + (" …" if len(exclude) > 10 else ""))
    return meas.subset(keep)


def _instrument_sigmas(meas: Measurements, config: CalibrationConfig, notes: list[str]) -> Measurements:
    """The instrument's σ per point the fit weighs by: the file's columns, or the statement of
    ``instrument``; a stated noise σ of a block replaces its columns (and says so)."""
    if config.instrument is not None:
        statement = Instrument.parse(config.instrument)
        if meas.sigma_position is not None:
            notes.append(f"the sx, sy, sz columns of {meas.source} are replaced by {statement.sentence()}")
        return replace(with_instrument(meas, statement), sigma_source=statement.sentence(),
                       sigma_orientation=meas.sigma_orientation)
    for block, stated, columns in (("sigma_position", config.noise, "sx, sy, sz"),
                                   ("sigma_orientation", config.angle_noise if config.k is None else 0.0,
                                    "srx, sry, srz")):
        if stated is not None and getattr(meas, block) is not None:
            notes.append(f"the noise stated replaces the {columns} columns of {meas.source}")
            meas = replace(meas, **{block: None})
    return meas


def weigh_instrument(est: Estimate, config: CalibrationConfig,
                     noise: NoiseEstimate) -> tuple[Estimate, NoiseEstimate, InstrumentFit | None]:
    """Step 8b, where the data give the instrument's σ per point: weigh each point by
    σ_eff² = σ_i² + τ², τ the scatter beyond the instrument, and refit until τ settles (see
    :mod:`robocal.calibration.instrument`); then the misfit against the instrument alone."""
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
            est = Estimate(problem, est.optimization.then(lm, method=est.optimization.method, message=(
                f"{est.optimization.message}; weighed by the instrument's σ: {lm.message}"),
                history=est.optimization.history), lm.x, est.reexpression_gap_mm)
            est, noise = reweigh(est, config)
            if lm.status != "converged":
                break
    return est, noise, instrument_fit(est.problem, est.x, meas.sigma_source or "σ per point",
                                      leverage_split(est.problem, est.x))


def weigh_kinds(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate) -> tuple[Estimate, NoiseEstimate,
                                                                                         list[str]]:
    """Step 8c, tracker rows beside rows that touched points or planes: each kind weighed by its
    own σ, estimated from its residuals, and the fit repeated until they settle."""
    meas = est.problem.meas
    c = meas.constraints
    if c is None or c.only or meas.sigma_position is not None or noise.source == "stated" or \
            not (config.least_squares and est.optimization.status == "converged"):
        return est, noise, []
    for _ in range(MAX_ROUNDS):
        problem = est.problem
        weights = kind_weights(problem, est.x)
        if weights.settled(problem.setup.instrument, meas):
            break
        problem = replace(problem.setup, instrument=weights, sigma_position=weights.ref).problem(problem.names)
        lm = fit_lm(problem, est.x, config)
        est = Estimate(problem, est.optimization.then(lm, method=est.optimization.method, message=(
            f"{est.optimization.message}; each kind of rows weighed by its σ: {lm.message}"),
            history=est.optimization.history), lm.x, est.reexpression_gap_mm)
        if lm.status != "converged":
            break
    weights = est.problem.setup.instrument
    return est, noise, [] if not isinstance(weights, KindWeights) else [f"weighed by kind: {weights.sentence()}"]


def complete_model(robot: Robot, config: CalibrationConfig) -> Robot:
    """The robot with β offered on DH parallel axes (:func:`robocal.model.candidates.complete`),
    unless the user's parameter list leaves β out (the papers' 24, for instance)."""
    requested = resolve_params(config.params, robot.n_joints)
    if requested is not None and not any(n.startswith("beta") for n in requested):
        return robot
    return complete(robot)


def register(inputs: Inputs, config: CalibrationConfig, spec: TermSpec = TermSpec(),
             parent: Fit | None = None) -> Setup:
    """Step 2: the complete model, its frames fitted with the nominal joints (closed form, then
    LM on base and tools together: see :func:`~robocal.calibration.registration.fit_frames`),
    the parameter space around the result, and the noise weighting to start with.  A swarm
    then searches a few millimetres around frames that are already right.  With a ``parent``
    fit of the same data (a simpler model), its registration (the same: it depends on the
    nominal joints only) and its settled weights are the start."""
    targets = inputs.meas.target_names if inputs.frames in ("base+tool", "tcp") else None
    if parent is not None:
        settled = parent.estimate.problem.setup
        return Setup(ParameterSpace.of(parent.setup.space.robot, targets, spec), inputs.meas, settled.sigma_position,
                     settled.sigma_orientation, config.use_orientation, config.backend, settled.instrument)
    sigma_p, sigma_r = config.noise_model.initial()
    with stage("optimize"):
        initial = fit_frames(complete_model(inputs.nominal, config), inputs.meas, inputs.frames, sigma_p, sigma_r)
    space = ParameterSpace.of(initial, targets, spec)
    return Setup(space, inputs.meas, sigma_p, sigma_r, config.use_orientation, config.backend)


def choose_candidates(setup: Setup, config: CalibrationConfig, frames_mode: str) -> Candidates:
    """Step 3: joint candidates (the convention's or the config's) and the frames' parameters."""
    robot = setup.space.robot
    requested = resolve_params(config.params, robot.n_joints)
    joints = joint_candidates(robot) if requested is None else requested
    unknown = [n for n in joints if n not in setup.space.names]
    if unknown:
        raise InputError(f"unknown parameter '{unknown[0]}' for this {robot.convention} robot "
                         f"(known: {', '.join(setup.space.names[:8])}, …)", option="params")
    frames = frame_candidates(frames_mode, setup.meas.target_names, setup.full_pose)
    terms = setup.space.terms.names(robot.n_joints)
    return Candidates(joints, joints + [n for n in frames + terms if n not in joints], requested is not None)


def _still_reasons(setup: Setup, ident: Identifiability, names: list[str]) -> Identifiability:
    """With joints that never moved, identifiability is judged with each held at its mean: a
    joint's read-back jitter of a few thousandths of a degree must not make its geometry look
    separable from the frames that absorb it (it would be fitted to the jitter).  Parameters
    kept on the data as measured but not when held still are dropped for that reason."""
    still = checks.still_joints(setup.meas)
    if not still:
        return ident
    probe = setup.with_measurements(checks.held_still(setup.meas)).problem(names)
    held = analyse(probe.residual_jacobian(np.zeros(probe.n_params)), names, probe.angle_mask, setup.meas.n_poses,
                   setup.space.robot.reach())
    newly = [n for n in held.dropped if n in ident.kept]
    if not newly:
        return ident
    joints = tuple(i + 1 for i in still)
    reasons = {**held.reasons, **{n: Reason(STILL, held.reasons[n].related, coefficients=held.reasons[n].coefficients,
                                            joints=joints) for n in newly}}
    many = len(joints) > 1
    return held.with_changes(reasons=reasons, warnings=held.warnings + [
        f"joint{'s' if many else ''} {', '.join(map(str, joints))} never move{'' if many else 's'}: "
        f"{', '.join(newly)} dropped (absorbed by the frames and the other joints)"])


#: fewest poses at which a joint term's basis must differ from its most common value: with fewer,
#: the term is a constant offset (absorbed by the geometry) plus what one or two poses say
MIN_TERM_SUPPORT = 3


def term_support(basis: np.ndarray, groups: np.ndarray) -> tuple[int, int]:
    """(joint index, poses) of one term parameter's basis (m, n): the joint it acts on most, and
    how many poses (``groups``: pose index per row) hold a value other than its most common one."""
    joint = int(np.argmax(np.linalg.norm(basis, axis=0)))
    v = basis[:, joint]
    scale = float(np.max(np.abs(v))) or 1.0
    values, counts = np.unique(np.round(v / scale, 9), return_counts=True)
    mode = values[np.argmax(counts)]
    return joint, len(np.unique(groups[np.round(v / scale, 9) != mode]))


def unvaried_terms(setup: Setup, names: list[str]) -> dict[str, Reason]:
    """Joint terms among ``names`` whose input the poses did not vary, with the reason: a
    backlash from poses all approached one way (its column is the joint's offset, but for the
    pose whose direction is unknown), a drift over one time, any term whose column is constant
    but at a pose or two.  Numerically separable, such a term would be fitted to those few
    poses' noise and reported as if measured."""
    from ..model.terms import term_of

    space = setup.space
    terms = [n for n in names if is_term(n)]
    data = space.joint_data(setup.meas.q, setup.meas.inputs) if terms else None
    if data is None:
        return {}
    groups = np.unique(np.array(setup.meas.pose_ids if setup.meas.pose_ids is not None else
                                [str(r) for r in setup.meas.rows]), return_inverse=True)[1]
    order = list(space.terms.names(space.robot.n_joints))
    reasons = {}
    for name in terms:
        joint, support = term_support(data.basis[:, :, order.index(name)], groups)
        if support < MIN_TERM_SUPPORT:
            reasons[name] = Reason(UNVARIED, joints=(joint + 1,), detail=term_of(name).unvaried(joint + 1, support))
    return reasons


def gauge_names(setup: Setup) -> list[str]:
    """The base frame's parameters when every row touched an unknown point or plane: such data
    are the same in any frame (their points and planes move with it), so the parameters that
    only move the whole robot (θ1 and d1, a URDF's first origin) must be told from that motion
    and dropped; it is scanned first, then left out."""
    c = setup.meas.constraints
    return [] if c is None or not c.only else [n for n in setup.space.names if n.startswith("base_")]


def _without_gauge(setup: Setup, ident: Identifiability, gauge: list[str], names: list[str]) -> Identifiability:
    """The analysis with the base frame left out (said why), and, without a stated distance, the
    length scale fixed by the longest link (said why: points and planes see shapes, not sizes)."""
    if not gauge:
        return ident
    reasons = dict(ident.reasons)
    for n in gauge:
        reasons[n] = Reason(UNOBSERVABLE, detail="the frame the robot stands in: the rows touched points or planes "
                                                 "whose place is unknown, so any frame fits them alike")
    kept = [n for n in ident.kept if n not in gauge]
    said = []
    c = setup.meas.constraints
    if not c.distances:
        robot = setup.space.robot
        kinds = len(joint_kinds(robot.convention))
        lengths = [n for n in kept if setup.space.names.index(n) < setup.space.n_joint_params and not is_angle(n)]
        if lengths:
            value = {n: abs(float(robot.geometry.reshape(-1, robot.geometry.shape[1])[i // kinds, i % kinds]))
                     for n in lengths for i in [setup.space.names.index(n)]}
            longest = max(lengths, key=lambda n: value[n])
            reasons[longest] = Reason(UNOBSERVABLE, detail=(
                f"the length scale, held by {longest} at its nominal {value[longest]:.4g} mm: points and planes "
                "see the robot's shape, not its size; a known distance between two points (point_distance "
                "A,B=MM) or tracker rows make it visible"))
            kept.remove(longest)
            said.append(f"{longest} held at nominal: without a known distance the length scale is not observable "
                        "from points or planes")
    dropped = [n for n in names if n in reasons and n not in kept]
    return ident.with_changes(kept=kept, dropped=dropped, reasons=reasons, warnings=ident.warnings + said)


def analyse_identifiability(setup: Setup, candidates: Candidates) -> tuple[Identifiability, list[str]]:
    """Step 4: the identifiable subset at the initial robot; parameters that need the motion of a
    joint that never moved are dropped (see :func:`_still_reasons`)."""
    unvaried = unvaried_terms(setup, candidates.names)
    names = [n for n in candidates.names if n not in unvaried]
    gauge = gauge_names(setup)
    probe = setup.problem(gauge + names)
    J = probe.residual_jacobian(np.zeros(probe.n_params))
    ident = analyse(J, gauge + names, probe.angle_mask, setup.meas.n_poses, setup.space.robot.reach(), prefer=gauge)
    ident = _without_gauge(setup, _still_reasons(setup, ident, gauge + names), gauge, candidates.names)
    if unvaried:
        reasons = {**ident.reasons, **unvaried}
        ident = ident.with_changes(dropped=[n for n in candidates.names if n in reasons], reasons=reasons,
                                   warnings=ident.warnings + [f"{n} dropped: {r.detail}" for n, r in unvaried.items()])
    notes = list(ident.warnings)
    if candidates.explicit:
        bad = [n for n in candidates.joints if n in ident.reasons]
        if bad:
            notes.append(f"requested parameters not identifiable from these data, left at nominal: {', '.join(bad)}")
    if not ident.kept:
        raise InputError("no parameter is identifiable from these measurements", source=setup.meas.source)
    if probe.n_residuals < probe.n_params:
        notes.append(f"only {setup.meas.n_poses} poses ({probe.n_residuals} residuals) for {probe.n_params} "
                     f"candidate parameters: {len(ident.dropped)} dropped; measure more poses")
    return ident, notes


def searched_names(candidates: Candidates, ident: Identifiability) -> list[str]:
    """What a swarm searches: every geometric candidate that has any effect on the data (joint
    terms are left to LM, which hybrid runs after the swarm)."""
    return [n for n in candidates.names if not is_term(n)
            and (n not in ident.reasons or ident.reasons[n].kind not in (NO_EFFECT, STILL, UNVARIED))]


@dataclass(frozen=True)
class Screening:
    """Outliers left out by a robust fit, and the plain fit that keeps them (for comparison)."""

    outliers: list[dict]
    with_outliers: Robot | None = None


#: below this many poses per estimated parameter, outliers are judged on leave-one-out residuals
LEVERAGE_POSES_PER_PARAMETER = 20


def poses_per_parameter(problem) -> float:
    return problem.meas.n_poses / max(1, problem.n_params)


def screen_outliers(est: Estimate, config: CalibrationConfig) -> tuple[Estimate, Screening, list[str]]:
    """Step 6: poses that fail the outlier test (:func:`~robocal.calibration.statistics.robust_outliers`).

    With a robust loss they are left out and the inliers refitted by plain least squares (the
    answer as if the outliers were never measured); a plain fit on every pose is kept beside
    it, so that validation can say what leaving them out did.  With a plain fit they are only
    named, with the suggestion of a robust loss: only poses that stand apart are named, so the
    suggestion is not made for the continuous tail of an incomplete model.
    """
    problem = est.problem
    if not config.least_squares or est.optimization.status != "converged":
        return est, Screening([]), []
    dp, _ = problem.errors(est.x)
    # leverage matters where poses are few against the parameters; with many, each pose's share
    # of the fit is about k/m and the residuals are their own leave-one-out values
    few = poses_per_parameter(problem) < LEVERAGE_POSES_PER_PARAMETER
    flagged, sigma = robust_outliers(leave_one_out(dp, problem.residual_jacobian(est.x)) if few else dp)
    if not flagged.size:
        return est, Screening([]), []
    meas = problem.meas
    test = (f"leave-one-out residual beyond {OUTLIER_SIGMAS:g} σ̂ = {OUTLIER_SIGMAS * sigma:.3g} mm and standing "
            f"apart, {OUTLIER_GAP:g}× the next smaller one or more")
    if config.loss == "linear":
        return est, Screening([]), [f"{meas.labels(flagged)} look like outliers ({test}); a robust fit (loss huber, "
                                    "--loss huber) would leave them out"]
    plain = CalibrationConfig.build(config, loss="linear")
    keep_all = fit_lm(problem, est.x, plain)
    outliers = [{"row": int(meas.rows[i]), "pose_id": None if meas.pose_ids is None else meas.pose_ids[i],
                 "error_mm": float(np.linalg.norm(dp[i]))} for i in flagged]
    inliers = problem.setup.with_measurements(meas.subset(np.setdiff1d(np.arange(meas.n_poses), flagged)))
    refit_problem = inliers.problem(problem.names)
    lm = fit_lm(refit_problem, est.x, plain)
    merged = est.optimization.then(lm, method=est.optimization.method,
                                   message=f"{est.optimization.message}; {len(flagged)} outliers removed, inliers "
                                           f"refitted: {lm.message}", extra={"robust_scale_mm": sigma})
    notes = [f"{len(flagged)} outlier poses left out ({test}): {meas.labels(flagged)}"]
    if len(flagged) > MAX_OUTLIER_FRACTION * meas.n_poses:
        notes.append(f"{len(flagged)} of {meas.n_poses} poses ({100 * len(flagged) / meas.n_poses:.0f} %) left out "
                     f"as outliers, more than {100 * MAX_OUTLIER_FRACTION:g} %: the model may be incomplete rather "
                     "than the data bad; compare the validation figures with and without them")
    screening = Screening(outliers, problem.space.apply(problem.full(keep_all.x)))
    return est.replace(problem=refit_problem, optimization=merged, x=lm.x), screening, notes


def refine_at_estimate(est: Estimate, ident: Identifiability, candidates: Candidates,
                       config: CalibrationConfig) -> tuple[Estimate, Identifiability]:
    """Step 7: re-check identifiability at the estimate; add what the data determine there.

    Identifiability is judged from the Jacobian at a linearisation point.  At the nominal
    model some dependencies hold only to first order: with parallel axes 2 ∥ 3 in standard
    DH, d2 and d3 have identical columns, but a robot whose α2 is off by δ separates them by
    an angle ~δ; a tool point off axis 6 by the deviation of a6 makes θ6 act.  The analysis
    is repeated at the estimate with the kept set offered first; parameters that became
    independent are added and LM continues, and the addition is accepted only if a
    nested-model F-test says the fit improved significantly (p < ADD_SIGNIFICANCE).
    """
    if not config.least_squares or est.optimization.status != "converged":
        return est, ident
    setup = est.problem.setup
    # judged with still joints held still: their parameters stay out whatever the estimate
    gauge = gauge_names(setup)
    probe = setup.with_measurements(checks.held_still(setup.meas)).problem(gauge + candidates.names)
    deviation = est.problem.full(est.x)
    again = analyse(probe.residual_jacobian(deviation[probe.active]), gauge + candidates.names, probe.angle_mask,
                    setup.meas.n_poses, setup.space.robot.reach(), prefer=gauge + ident.kept)
    added = [n for n in again.kept if n not in ident.kept and n not in gauge
             and ident.reasons[n].kind not in (STILL, UNVARIED, UNOBSERVABLE)]
    if not added:
        return est, ident
    names = ident.kept + added
    wider = setup.problem(names)
    dof = wider.n_residuals - len(names) - wider.n_nuisance
    # First the Gauss–Newton step from the estimate: the decrease of χ² it predicts is what the
    # refit would reach where the problem is near linear.  Far from significant, the refit
    # (LM crawling along a weakly separated valley, most of a calibration's time) cannot change
    # the verdict, and is not run.
    x0 = deviation[wider.active]
    r, J = wider.residuals(x0), wider.residual_jacobian(x0)
    step = np.linalg.lstsq(J, -r, rcond=None)[0]
    p = f_test(float(r @ r), float(np.sum((r + J @ step) ** 2)), len(added), dof)
    lm = None
    if p < CLEARLY_NOT_SIGNIFICANT:
        # A parameter that separates only weakly makes LM crawl along a valley; the refit is a
        # test of whether the addition pays, so it gets a bounded budget.
        lm = fit_lm(wider, x0, config, max_nfev=REFIT_EVALUATIONS)
        p = f_test(est.optimization.fun, lm.fun, len(added), dof)
    if lm is None or lm.status != "converged" or p >= ADD_SIGNIFICANCE:
        second = {n: Reason(SECOND_ORDER, ident.reasons[n].related, p, ident.reasons[n].coefficients) for n in added}
        reasons = {**ident.reasons, **second}
        return est, ident.with_changes(reasons=reasons)
    final = analyse(wider.residual_jacobian(lm.x), names, wider.angle_mask, setup.meas.n_poses,
                    setup.space.robot.reach(), prefer=names)
    kept = [n for n in candidates.names if n in set(names)]
    refined = Identifiability(
        kept=kept, dropped=[n for n in candidates.names if n not in set(names)],
        reasons={n: r for n, r in ident.reasons.items() if n not in added},
        singular_values=final.singular_values, condition=final.condition, observability=final.observability,
        length_scale=final.length_scale, n_poses=final.n_poses,
        warnings=final.warnings + [f"{', '.join(added)} identifiable only away from the nominal model (added after "
                                   f"the first fit, F-test p={p:.2g}); expect large uncertainties"],
    )
    merged = est.optimization.then(lm, method=est.optimization.method, extra={"added_at_estimate": added},
                                   message=f"{est.optimization.message}; refit adding {', '.join(added)}: "
                                           f"{lm.message}")
    order = [names.index(n) for n in kept]
    return Estimate(setup.problem(kept), merged, lm.x[order], est.reexpression_gap_mm), refined


def reweigh(est: Estimate, config: CalibrationConfig) -> tuple[Estimate, NoiseEstimate]:
    """Step 7: estimate σ per residual block where it is not stated, and refit with it until
    the weights settle (see :mod:`robocal.calibration.noise`).  Swarms keep their answer; their
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
            moved = not settled(sigmas, target.sigmas, full)
            sigmas, problem = target.sigmas, problem.setup.with_noise(*target.sigmas).problem(problem.names)
            if not moved:  # the same solution, now weighed by the σ it shows
                est = est.replace(problem=problem)
                break
            x = est.x + target.step
            r = problem.residuals(x)
            chi2 = float(r @ r)
            if config.loss == "linear" and abs(chi2 - target.chi2) <= LINEAR_CHI2:
                # linear there: the Gauss–Newton step is the refit, and LM would only confirm it
                step = OptimizeResult("gauss-newton", x, chi2, np.array([chi2]), 1, 1, "converged",
                                      "one Gauss–Newton step", 0.0)
            else:
                step = fit_lm(problem, est.x, config)
            refits += 1
            # χ² under new weights is another scale: the history stays that of the first weights
            est = Estimate(problem, est.optimization.then(step, method=est.optimization.method, message=(
                f"{est.optimization.message}; reweighted (σp {sigmas[0]:.3g} mm): {step.message}"),
                history=est.optimization.history), step.x, est.reexpression_gap_mm)
            if step.status != "converged" or confirmed(problem, est.x, target, model):
                break
    return est, NoiseEstimate(sigmas[0], sigmas[1] if full else None, source, refits)


@dataclass(frozen=True)
class Judgement:
    """Step 9's findings: goodness of fit, standard uncertainties and covariance (None for a
    swarm), and what they call for saying."""

    goodness: GoodnessOfFit
    uncertainty: np.ndarray | None
    covariance: np.ndarray | None
    notes: list[str]


def judge(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate) -> Judgement:
    """Step 9: goodness of fit, covariance and standard uncertainties, and the warnings they call for.

    Uncertainties come from the whitened Jacobian at the solution, (JᵀJ)⁻¹.  With stated
    noise and a fit worse than it (reduced χ² > 1) they are scaled by the reduced χ², which
    is then said; with estimated noise the reduced χ² is 1 by construction.
    """
    gof = goodness_of_fit(est.problem, est.x, noise.source)
    notes: list[str] = []
    cov = None
    if config.least_squares and gof.dof > 0:
        scale = gof.reduced_chi2 if noise.source == "estimated" else max(1.0, gof.reduced_chi2)
        cov = covariance(est.problem.residual_jacobian(est.x), variance=scale)
    if gof.misfit():
        notes.append(misfit_message(gof, joint_patterns(est.problem, est.x))
                     + (f"; uncertainties scaled by √χ²ᵣ = {np.sqrt(gof.reduced_chi2):.3g}" if cov is not None else ""))
    unc = None if cov is None else np.sqrt(np.diag(cov))
    corr = None
    if cov is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(unc, unc)
    warning = implausible_deviations(est.problem.names, est.x, unc, corr)
    if warning:
        notes.append(warning)
    if config.least_squares and gof.dof <= 0:
        unc = np.full(est.problem.n_params, np.nan)
    return Judgement(gof, unc, cov, notes)


def evaluate(initial: Robot, calibrated: Robot, meas: Measurements, all_rows: Measurements,
             validation: Measurements | None, screening: Screening) -> tuple[dict[str, Metrics], list[str]]:
    """Step 10: before/after metrics on the calibration data and, when given, on validation data;
    with outliers left out, validation of the plain fit that kept them too."""
    notes: list[str] = []
    metrics = {"before": Metrics.of(initial, meas), "after": Metrics.of(calibrated, meas)}
    if all_rows is not meas:
        metrics["after_all_rows"] = Metrics.of(calibrated, all_rows)
    if validation is not None:
        metrics["validation_before"] = Metrics.of(initial, validation)
        metrics["validation_after"] = Metrics.of(calibrated, validation)
        if screening.with_outliers is not None:
            kept = metrics["validation_with_outliers_kept"] = Metrics.of(screening.with_outliers, validation)
            notes.append(f"leaving out {len(screening.outliers)} outlier poses changed the validation RMS from "
                         f"{kept.position['rms']:.4g} mm (plain fit of every pose) to "
                         f"{metrics['validation_after'].position['rms']:.4g} mm")
        from ..model.uncertainty import known_targets, region_note

        said = region_note(calibrated, validation.q, known_targets(calibrated, validation), validation.inputs)
        if said:
            notes.append(f"validation: {said}")
    return metrics, notes


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

    @property
    def robot(self) -> Robot:
        return self.setup.space.apply(self.estimate.problem.full(self.estimate.x))

    @property
    def n_params(self) -> int:
        return self.estimate.problem.n_params


def term_spec(terms, meas: Measurements, config: CalibrationConfig) -> TermSpec:
    """The joint terms of a model for these data, each as its entry of
    :data:`robocal.model.terms.TERMS` chooses from the data and the config's settings."""
    settings = {"harmonics": config.harmonics}
    return TermSpec({name: TERMS[name].option_for(meas, settings) for name in terms if name in TERMS})


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
                       start=_start_from(parent, problem))
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
        judged = judge(est, config, noise)
    return Fit(setup, candidates, ident, est, screening, noise, judged.goodness, judged.uncertainty,
               judged.covariance, notes + judged.notes, instrument)


