"""The calibration pipeline: nominal robot + measurements → calibrated robot and honest figures.

:func:`calibrate` runs the steps of a calibration through the choice of model
(:mod:`robocal.calibration.select.selection`: steps 2–9 once per model, or a ladder of them for
``auto``), the final guard, and the evaluation:

1. :func:`~.inputs.load_inputs`: robot, data and validation data, checked against each other;
2. :func:`~.parametric.register`: a complete model (DH + β on parallel axes), the measuring
   frame (and tool offsets) in closed form, the noise weighting to start with;
3. :func:`~.subset.choose_candidates`: the parameters offered, from the config;
4. :func:`~.subset.analyse_identifiability`: the identifiable subset, the rest dropped with reasons;
5. :func:`robocal.calibration.fit.methods.optimize`: the configured method;
6. :func:`~.screening.screen_outliers`: with a robust loss, outliers left out and the inliers refitted;
7. :func:`~.weighting.reweigh`: σ estimated per residual block where not stated, and the fit repeated;
8. :func:`~.subset.refine_at_estimate`: identifiability re-checked at the estimate (F-test);
9. :func:`~.judgement.judge`: goodness of fit, standard uncertainties, misfit and plausibility warnings;
10. :func:`~.guard.guard`, then :func:`evaluate`: before/after metrics.

"Before" figures use the nominal joint geometry with the registered frames, i.e. the best
a rigid re-mounting of the nominal model can do, so that the improvement shown is the
calibration's own and not that of finding the tracker frame.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..backend import blas_threads
from ..exceptions import InputError, Note, RobocalWarning, split_notes
from ..model.covariance import ParameterCovariance
from ..model.measurements import Measurements
from ..model.metrics import Metrics, camera_figures
from ..model.region import Region
from ..model.robot import Robot
from ..model.uncertainty import known_targets, predicted_sigma
from ..optimize.result import Progress
from .config import CalibrationConfig
from .exports import ExportFigures
from .fit import cameras
from .fit.camera_scale import marker_sigma
from .fit.problem import warm_up
from .fit.screening import Screening
from .inputs import load_inputs
from .judge.guard import guard
from .result import CalibrationResult
from .select.crossval import sessions_disagree
from .select.residual import MAX_POINTS
from .select.selection import fit_model
from .timing import stage, timed


def calibrate(
    robot: str | Path | Robot,
    data: str | Path | Measurements | Sequence[str | Path | Measurements],
    method: str = "lm",
    *,
    config: CalibrationConfig | None = None,
    validate: str | Path | Measurements | None = None,
    columns: Mapping[str, str] | None = None,
    progress: Progress | None = None,
    stages: Callable[[str], None] | None = None,
    **options,
) -> CalibrationResult:
    """Calibrate ``robot`` (file, built-in name or Robot) on ``data`` (file or Measurements; several:
    each a session, or the sessions its ``session`` column names, held out in turn).

    Options are those of :class:`CalibrationConfig` (``frames``, ``params``, ``model``, …),
    given as keywords or as ``config``.  validate: poses not used to identify, for honest
    figures.  columns: map of file column names to robocal's.  progress: called with
    (iteration, total, best objective).  stages: called as ``--model auto`` starts each model
    with (models done, models in all, a line saying which), for a progress display.  The result's ``time_s`` is the
    optimizers' wall time; ``timings`` splits the whole call into stages
    (:mod:`robocal.calibration.timing`).  Warnings (something to act on, or a reason to doubt
    a figure) are issued as :class:`RobocalWarning` and listed in ``result.warnings``; notes
    (choices made, frames registered, sources read) are listed in ``result.notes`` only.
    """
    cfg = CalibrationConfig.build(config, **({"method": method} if config is None else {}), **options)
    with timed() as clock:
        result = _calibrate(robot, data, validate, cfg, columns, progress, stages)
    result.timings = clock.to_dict()
    result.time_s = clock.seconds["optimize"]
    for note in result.warnings:
        warnings.warn(note, RobocalWarning, stacklevel=2)
    return result


def order_notes(fit, meas: Measurements) -> list[str]:
    """What terms that depend on the measuring order took it from, and when a drift predicts."""
    terms = fit.setup.space.terms.options
    notes = []
    if "backlash" in terms:
        source = {"dir columns": "the dir1..dirN columns", "time order": "the time column's order",
                  "row order": "the rows' order (no dir1..dirN or time columns)"}.get(meas.order, "no order")
        notes.append(Note(f"backlash: each joint's direction of approach from {source} of {meas.source}"))
    if "drift" in terms:
        clock, reference = terms["drift"]
        if clock == "s":
            notes.append(Note(f"drift: time from the time column of {meas.source} (rates in deg/h); the model predicts "
                         f"the robot as it was at t = {reference:g} s (the last pose), and data with a time column "
                              "at their own time"))
        else:
            notes.append(Note(f"drift: {meas.source} has no time column, so its row numbers stand for time (rates in "
                         f"deg per 1000 rows); the model predicts the robot as it was at row {reference:g} (the "
                              "last pose), and other files there"))
    return notes


def evaluate(initial: Robot, calibrated: Robot, meas: Measurements, all_rows: Measurements,
             validation: Measurements | None, screening: Screening,
             frames: str = "none") -> tuple[dict[str, Metrics], list[str]]:
    """Step 10: before/after metrics on the calibration data and, when given, on validation data;
    with outliers left out, validation of the plain fit that kept them too.  Where the sessions'
    frames are their own, validation data are a session of their own: their frames (``frames``)
    are registered on them, for each model, as they would be on a new session."""
    notes: list[str] = []
    metrics = {"before": Metrics.of(initial, meas), "after": Metrics.of(calibrated, meas)}
    if all_rows is not meas:
        metrics["after_all_rows"] = Metrics.of(calibrated, all_rows)
    if validation is not None:
        def seen(robot: Robot) -> Robot:
            if not robot.session_bases:
                return robot
            from .fit.registration import fit_frames

            return fit_frames(robot.without_sessions(), validation, frames)

        if calibrated.session_bases:
            notes.append(Note("validation: a session of its own, its frames registered on its rows for each model"))
        initial, calibrated = seen(initial), seen(calibrated)
        metrics["validation_before"] = Metrics.of(initial, validation)
        metrics["validation_after"] = Metrics.of(calibrated, validation)
        if screening.with_outliers is not None:
            kept = metrics["validation_with_outliers_kept"] = Metrics.of(screening.with_outliers, validation)
            notes.append(f"leaving out {len(screening.outliers)} outlier poses changed the validation RMS from "
                         f"{kept.position['rms']:.4g} mm (plain fit of every pose) to "
                         f"{metrics['validation_after'].position['rms']:.4g} mm")
        from ..model.uncertainty import known_targets, region_note

        said = region_note(calibrated, validation.q, known_targets(calibrated, validation), validation.inputs,
                           validation.chain)
        if said:
            notes.append(f"validation: {said}")
    return metrics, notes


def geometry_for_receivers(calibrated: Robot, geometric: Robot | None) -> Robot:
    """What a URDF or a kinematics YAML carries: geometry and frames.  Where the model holds joint
    terms, the geometric calibration's (its own geometry was fitted beside the terms, which took
    their share: without them it is no geometric model); else the model's, without its learned
    correction."""
    if calibrated.terms is not None and not calibrated.terms.empty and geometric is not None:
        return geometric.replace(name=calibrated.name, terms=None, residual=None, region=calibrated.region,
                                 uncertainty=None)
    return calibrated.replace(residual=None)


def export_figures(calibrated: Robot, receiver: Robot, metrics: dict, meas: Measurements,
                   validation: Measurements | None, geometry: Metrics | None, held_out: str,
                   seen_sigma: float | None = None) -> ExportFigures:
    """The figures of the whole model and of what a URDF or a kinematics YAML carries of it
    (``receiver``, :func:`geometry_for_receivers`), on the validation poses when given, else
    predicted by cross-validation (``geometry``: the held-out figures of the receiver's part),
    else in-sample."""
    geometric = calibrated.geometric
    if validation is not None:
        key, part = "validation", Metrics.of(receiver, validation)
        whole = metrics["validation_after"]
    elif "predicted" in metrics and geometry is not None:
        key, part, whole = "predicted", geometry, metrics["predicted"]
    else:
        key, whole = "fit", metrics["after"]
        part = Metrics.of(receiver, meas)
    if geometric:
        part = whole
    tool_sigma = None
    if meas.unit == "px" and calibrated.region is not None and calibrated.region.sigma_mm is not None:
        tool_sigma = calibrated.region.sigma_mm
    return ExportFigures(key, whole.position["rms"], whole.position["max"], part.position["rms"],
                         part.position["max"], geometric, held_out,
                         "the model's own" if receiver.geometry is calibrated.geometry or geometric
                         else "the geometric calibration's", meas.unit,
                         None if whole.at_marker is None else whole.at_marker["rms"], tool_sigma, seen_sigma,
                         bool(calibrated.cameras), cameras.gauge(calibrated, meas) is not None)


def _validated(table, chosen: str, metrics) -> list:
    """The ladder, with the chosen model's validation RMS as the calibrated model gives it (with
    its region and how well it knows its TCP there), the figure the error budget and the metrics show."""
    if "validation_after" not in metrics:
        return table
    rms = metrics["validation_after"].position["rms"]
    return [replace(r, validation_rms_mm=rms) if r.model == chosen else r for r in table]


def _calibrate(robot, data, validate, cfg: CalibrationConfig, columns, progress, stages) -> CalibrationResult:
    with stage("load"):
        inputs = load_inputs(robot, data, validate, cfg, columns)
    if inputs.meas.unit == "px":  # the position block holds pixels: its σ is the pixels'
        if cfg.noise is not None:
            raise InputError("is a length (mm), and the camera rows are pixels: state their σ with --pixel-noise",
                             option="noise")
        cfg = replace(cfg, noise=cfg.pixel_noise)
    with stage("compile"):
        warm_up(cfg.backend, inputs.meas.full_pose and cfg.use_orientation)
    # the largest dense matrices: the residual process's (at most MAX_POINTS a side) and k × k
    with blas_threads(min(inputs.meas.n_poses, MAX_POINTS)):
        chosen = guard(fit_model(inputs, cfg, progress, stages))
    notes = list(inputs.notes) + order_notes(chosen.fit, inputs.meas)
    if chosen.held_errors is not None and chosen.scheme is not None and chosen.scheme.kind == "sessions":
        est = chosen.fit.estimate
        said = sessions_disagree(est.problem.meas, chosen.held_errors, est.problem.errors(est.x)[0])
        notes += [] if said is None else [said]
    fit = chosen.fit
    notes += fit.notes + chosen.notes
    est, setup = fit.estimate, fit.setup
    initial = setup.space.robot
    region = Region.of(inputs.meas.q, inputs.nominal.prismatic)
    calibrated = fit.robot.replace(name=f"{inputs.nominal.name} (calibrated)", residual=chosen.residual, region=region,
                                   uncertainty=None if fit.covariance is None else
                                   ParameterCovariance(tuple(est.problem.names), fit.covariance))
    if calibrated.uncertainty is not None:  # how well it knows its TCP where its data were
        sigma = predicted_sigma(calibrated, inputs.meas.q, known_targets(calibrated, inputs.meas), inputs.meas.inputs,
                                inputs.meas.chain)
        calibrated = calibrated.replace(region=region.with_sigma(float(np.median(sigma))))
    with stage("evaluate"):
        metrics, said = evaluate(initial, calibrated, est.problem.meas, inputs.meas, inputs.validation,
                                 fit.screening, inputs.frames)
        budget = chosen.budget(calibrated, inputs.validation)
    notes += said
    if chosen.prediction is not None:  # what the held-out poses said: the headline without validation poses
        metrics = {"before": metrics["before"], "predicted": chosen.prediction, **metrics}
    geometric = None if chosen.geometric is None or chosen.geometric is fit else chosen.geometric.robot
    receiver = geometry_for_receivers(calibrated, geometric)
    scheme = chosen.scheme
    held_out = "new poses" if scheme is None else scheme.held_out
    markers = None if est.problem.views is None else marker_sigma(est.problem, est.x, fit.covariance)
    exports = export_figures(calibrated, receiver, metrics, est.problem.meas, inputs.validation,
                             chosen.geometric_prediction, held_out,
                             None if markers is None else float(np.nanmedian(markers)))
    contact, seen = {}, {}
    for key, robot, data in (("before", initial, est.problem.meas), ("after", calibrated, est.problem.meas),
                             ("validation_before", initial, inputs.validation),
                             ("validation_after", calibrated, inputs.validation)):
        if data is not None and data.constraints is not None:
            contact[key] = data.constraints.figures(robot.positions(data.q, data.targets, data.inputs, data.chain))
        if data is not None and data.camera is not None and any(data.camera):
            seen[key] = camera_figures(robot, data)
    return CalibrationResult(
        config=cfg, robot=calibrated, initial=initial, nominal=inputs.nominal, names=est.problem.names, x=est.x,
        uncertainty=fit.uncertainty, identifiability=fit.identifiability, optimization=est.optimization,
        metrics=metrics, data=inputs.meas.source, n_poses=est.problem.meas.n_poses, full_pose=setup.full_pose,
        warnings=split_notes(notes)[0], notes=split_notes(notes)[1], measurements=est.problem.meas,
        validation=inputs.validation, outliers=fit.screening.outliers, reexpression_gap_mm=est.reexpression_gap_mm,
        noise=fit.noise, goodness_of_fit=fit.goodness, covariance=fit.covariance, frames=inputs.frames,
        model=chosen.name, model_selection=_validated(chosen.table, chosen.name, metrics), error_budget=budget,
        geometric=geometric, receiver=receiver,
        instrument=fit.instrument, all_rows=inputs.meas, excluded=cfg.exclude, contact=contact,
        prior_sigma=est.problem.prior_sigma if est.problem.has_prior else None, prior_share=fit.prior_share,
        physical=fit.physical, at_estimate=fit.at_estimate, exports=exports, cameras=seen,
        kind_sigma=getattr(est.problem.setup.instrument, "present", {}),  # KindWeights: σ by kind
        cross_validation=scheme,
    )
