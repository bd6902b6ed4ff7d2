"""Choosing the model: geometry alone, or with joint terms and a residual correction.

``--model auto`` selects forward and judges every candidate by K-fold cross-validation on the
calibration data (K = 5, folds by ``pose_id``, so the reflectors of one pose stay together):

1. geometric;
2. each joint term of :data:`robocal.model.terms.TERMS` added alone (harmonics, compliance,
   backlash: the cheaper first); the best is kept if it beats geometry;
3. each remaining term added to the one kept, and so on until no addition wins;
4. + residual (a Gaussian process) and + trees (gradient-boosted trees,
   :mod:`robocal.calibration.select.trees`) on the parametric model chosen, and on geometry alone;
   and, where the trees predict better than the process and both better than their parametric
   model, the trees with a process on what they leave (``trees+residual``).  The trees come
   first; each process is screened (a kernel tuned on a few hundred poses, each fold
   conditioned, not re-tuned: a tenth of the work) and tuned in full only where its screen does
   not lose clearly to them (:data:`~robocal.calibration.select.learned.SCREEN_RATIO` and the paired
   test) and takes something from its model: a process that cannot change the choice costs no
   more than its screen.

Forward selection keeps the number of fits linear-ish in the number of terms (at most
1 + k(k+1)/2 parametric fits for k terms) where every combination would be 2^k.

Each candidate is fitted on all the data; each fold then refits it on the other folds, from that
fit (same parameters, same noise weights), and predicts the held-out poses.  The lowest
cross-validated position RMS wins, unless a simpler model ties with it: within :data:`TIE`,
or not worse on the held-out poses by a paired test at :data:`SIGNIFICANCE` (on noise alone
the best of several candidates is better than geometry by luck, and a 1 % margin is within it).
Simpler means fewer terms (the model kept so far, against each addition); a learned correction
is less simple than any parametric model, the trees than the process (they take more from the
data), and the two stacked the least.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...backend import worker_pool
from ...exceptions import InputError, Note
from ...model.corrections import Correction
from ...model.measurements import Measurements
from ...model.metrics import Metrics, pose_errors
from ...model.robot import Robot
from ...model.terms import TERMS
from ..config import LEARNED, CalibrationConfig
from ..fit.parametric import Fit, fit_parametric, term_spec, unsupported_terms
from ..inputs import Inputs
from ..result import BudgetRow, LadderRow
from ..timing import stage
from .boosting import load_beside, worker_preparation
from .choice import SIGNIFICANCE, TRIAL_ORDER, Candidate, choose, learned_of, model_name, with_term
from .crossval import (
    K_FOLDS,
    CrossValidation,
    FoldData,
    Scheme,
    cross_validate,
    held_groups,
    pose_groups,
    predict,
    rms,
)
from .learned import (
    MIN_RESIDUAL_POSES,
    SCREEN_POINTS,
    SCREEN_RATIO,
    begin_screen,
    chained_kernels,
    cross_validate_residuals,
    cross_validate_stacked,
    cross_validate_trees,
    instrument_noise,
    learned_on_all,
    process_candidates,
    scratch_kernel,
    screen_loses,
    screened_processes,
    stacked_candidate,
    tree_candidates,
    warm_kernels,
)
from .residual import HYPER_POINTS, MAX_POINTS, tune_kernels
from .sets import choose_set, offered
from .trees import choose_settings

#: share of the data's values a model may spend on its unknowns (parameters, the residual
#: process's effective degrees of freedom) before its calibration figures are called fitted
MAX_DOF_SHARE = 0.5



@dataclass
class Chosen:
    """The model a calibration ends with: its parametric fit, its residual correction, the ladder
    (auto only: rows {model, cv_rms_mm, n_params}) and what was said."""

    name: str
    fit: Fit
    residual: Correction | None = None
    table: list[LadderRow] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    geometric: Fit | None = None
    #: held-out errors of the model (K-fold cross-validation on the calibration poses), and of
    #: the geometric fit for the guard to fall back on; None for a model returned unchanged
    prediction: Metrics | None = None
    geometric_prediction: Metrics | None = None
    #: how the held-out errors were made (:class:`~robocal.calibration.select.crossval.Scheme`), and the
    #: chosen model's held-out errors of each row (m, 3)
    scheme: Scheme | None = None
    held_errors: np.ndarray | None = None

    def budget(self, calibrated: Robot, validation: Measurements | None) -> list[BudgetRow]:
        """What each part of the model removes on the validation poses: position RMS (mm) of the
        nominal joints with fitted frames, the geometric fit, the fit with joint terms (each term
        refitted with the geometry: a term alone would take geometry's share too), and the
        residual correction on top."""
        if validation is None or calibrated.geometric or self.geometric is None:
            return []
        steps = [("nominal geometry, frames fitted", self.fit.setup.space.robot),
                 ("geometric calibration", self.geometric.robot)]
        parametric = calibrated.replace(residual=None)
        if self.fit is not self.geometric:
            steps.append((f"+ {'+'.join(t for t in self.name.split('+') if t in TERMS) or 'terms'}", parametric))
        if calibrated.residual is not None:
            steps.append((f"+ {learned_of(self.name) or 'residual'}", calibrated))
        rows, last = [], None
        for label, robot in steps:
            dp = pose_errors(robot, validation)[0]
            rms = float(np.sqrt(np.mean(np.sum(dp ** 2, axis=1))))
            rows.append(BudgetRow(label, rms, None if last is None else last - rms,
                                  tuple(float(v) for v in np.sqrt(np.mean(dp ** 2, axis=0)))))
            last = rms
        sigma = validation.sigma_position if validation.sigma_position is not None else \
            self.fit.setup.meas.sigma_position
        if sigma is not None:  # the floor: what the instrument's own noise alone would show
            rows.append(BudgetRow("the instrument's own noise (floor)", float(np.sqrt(instrument_noise(sigma))), None))
        return rows



def _rung(piece) -> tuple[Fit, CrossValidation]:
    """A worker's piece of the ladder: one parametric model fitted (from its parent's fit) and
    cross-validated."""
    inputs, config, spec, parent = piece
    fit = fit_parametric(inputs, config, spec, None, parent)
    return fit, cross_validate(fit, config)



def spent_dof(fit: Fit, residual: Correction | None) -> list[str]:
    """A loud note when the model spends most of the data on its unknowns: its figures on the
    calibration poses are then fitted, not measured accuracy."""
    n_data = fit.estimate.problem.n_values
    dof = 0.0 if residual is None else float(np.nan_to_num(residual.dof))
    # the parameters' effective number: one the prior holds spends none of the data
    used = fit.n_params - (0.0 if fit.prior_share is None else float(np.sum(fit.prior_share))) + dof
    if not used > MAX_DOF_SHARE * n_data:
        return []
    process = "" if residual is None else f" ({dof:.0f} of them the learned correction's)"
    return [f"the model spends {used:.0f} degrees of freedom{process} on {n_data} measured values: its figures on "
            "the calibration poses are fitted, not its accuracy; judge it on other poses (validation data) and "
            "measure more poses"]



def fit_model(inputs: Inputs, config: CalibrationConfig, progress=None, stages=None) -> Chosen:
    """The model the config asks for, or, for ``auto``, the one cross-validation chooses;
    ``stages`` (a callable, or None) hears what the ladder is at: (step, steps, what)."""
    meas = inputs.meas
    say = stages or (lambda step, steps, text: None)
    mixed = meas.camera is not None and not all(meas.camera)
    tree = inputs.nominal.tree is not None
    if tree and config.model_terms & set(LEARNED):  # a correction learned of one chain's poses
        raise InputError(f"{inputs.nominal.source or inputs.nominal.name} is a tree: learned corrections run along "
                         "one chain and are not supported on a tree; its joint terms are (--model compliance, …)",
                         option="model")
    if config.model != "auto" or mixed:
        # camera rows beside tracker rows: models are compared on held-out errors of one unit, and
        # these have two (px, mm); the geometric model is fitted and said
        terms = config.model_terms if config.model != "auto" else frozenset()
        lacking = unsupported_terms(terms, meas, config)
        if lacking:
            name, needs = next(iter(lacking.items()))
            raise InputError(f"the {name} term needs {needs}; {meas.source} gives none", option="model")
        learned = "+".join(t for t in LEARNED if t in terms)
        if learned and (meas.constraints is not None or meas.camera is not None):
            what = "rows that touched points or planes" if meas.constraints is not None else "camera rows (pixels)"
            raise InputError(f"a learned correction ({learned}) learns corrections of measured positions: {what} "
                             "measure none; calibrate the parametric model alone", option="model")
        if learned and len(set(pose_groups(meas))) < MIN_RESIDUAL_POSES:
            raise InputError(f"a learned correction ({learned}) learns from the poses what the parametric model "
                             f"leaves: {len(set(pose_groups(meas)))} poses are too few (at least "
                             f"{MIN_RESIDUAL_POSES}); measure more, or calibrate the parametric model alone",
                             option="model")
        choice = choose_set(inputs, config, progress, say) if offered(inputs, config) else None
        if choice is not None:  # the parameters the held-out data chose: the terms go on them
            config = choice.config
        if choice is not None and not terms:
            fit, cv = choice.fit, choice.cv
            prediction = cv.metrics()
        else:
            fit = fit_parametric(inputs, config, term_spec(terms, meas, config), progress)
            cv, prediction = predict(fit, config)  # how it predicts poses it has not seen, with or without validation
        residual = None
        parametric_prediction = prediction
        if learned:
            with worker_pool() as pool:
                data = FoldData.of(fit, cv)
                candidate = Candidate(tuple(sorted(terms - set(LEARNED))), learned, fit, cv.errors, data=data)
                if "residual" in learned:
                    with stage("model"):
                        candidate.kernels = tune_kernels(data.q, data.e[:, :3], config.seed, pool=pool)
                    candidate.errors = cross_validate_residuals([(data, cv, candidate.kernels)], config.seed, pool)[0]
                if "trees" in learned:
                    candidate.trees = cross_validate_trees(data, cv, meas, config.seed, pool)
                    candidate.errors = candidate.trees.errors if learned == "trees" else \
                        cross_validate_stacked(data, candidate.trees, candidate.kernels, config.seed, pool)
                residual = learned_on_all(candidate, config.seed, pool)
                prediction = cv.metrics(candidate.errors)
        geometric = fit
        if terms - set(LEARNED):  # the guard's comparison, and the error budget
            geometric = fit_parametric(inputs, config, term_spec((), meas, config))
        geometric_prediction = parametric_prediction if geometric is fit else predict(geometric, config)[1]
        said = [] if config.model != "auto" else [Note(
            "model auto: camera rows beside tracker rows are compared in no one unit, so the geometric model is "
            "fitted alone")]
        return Chosen(model_name(terms), fit, residual, [] if choice is None else choice.rows,
                      notes=([] if choice is None else choice.notes) + said + spent_dof(fit, residual),
                      geometric=geometric, prediction=prediction, geometric_prediction=geometric_prediction,
                      scheme=cv.scheme, held_errors=cv.errors if not learned else candidate.errors)
    groups, poses = held_groups(meas), pose_groups(meas)
    # a learned correction corrects measured positions: rows that touched points or planes, and
    # camera rows (pixels), have none; nor is one learned of a tree's several chains
    residuals = poses.max() + 1 >= MIN_RESIDUAL_POSES and meas.constraints is None and meas.camera is None and \
        not tree
    ladder: list[tuple[Candidate, CrossValidation]] = []
    # at most: geometry, each term alone, then each further term on the one kept so far
    lacking = unsupported_terms(TRIAL_ORDER, meas, config)
    trial_order = tuple(term for term in TRIAL_ORDER if term not in lacking)
    k = len(trial_order)
    steps = 1 + k * (k + 1) // 2 + (2 if residuals else 0)
    # what a stage tells the terminal is work done, in parametric fits: the learned candidates
    # (their tunings on up to 1000 poses and their folds) are about 12 of them on a thousand poses
    process = max(1.0, 12.0 * (min(len(set(poses)), HYPER_POINTS) / 1000) ** 2)
    work = steps - 2 + 2 * process if residuals else steps

    def rungs(wanted: list[tuple[str, ...]], parent: Candidate, pool: worker_pool) -> list[Candidate]:
        """The candidates of ``wanted`` (each set of terms fitted once, from the parent's fit):
        those not fitted yet on the pool's workers, each with its folds."""
        done = {c.terms: c for c, _ in ladder}
        new = [t for t in dict.fromkeys(wanted) if t not in done]
        if new:
            say(len(ladder), work, f"models {len(ladder) + 1}–{len(ladder) + len(new)}/{steps}: "
                f"{', '.join(model_name(t) for t in new)}, fits and {K_FOLDS} folds each")
            with stage("model"):  # a fit on a worker counts here, its own stages there
                fitted = pool.map(_rung, [(inputs, rung_config, term_spec(t, meas, config), parent.fit) for t in new])
            for t, (fit, cv) in zip(new, fitted):
                ladder.append((Candidate(t, "", fit, cv.errors), cv))
                done[t] = ladder[-1][0]
        return [done[t] for t in wanted]

    # forward selection: each round offers every term not yet in the model, and keeps the one
    # that predicts held-out poses better (as :func:`choose` judges), until none does.  A round's
    # fits run on numpy's kernels, here or on forked workers, whatever the load: numba's OpenMP
    # kernels abort in a forked child, and the numbers must not depend on the machine's load
    choice = choose_set(inputs, config, progress, say) if offered(inputs, config) else None
    if choice is not None:  # the parameters the held-out data chose: the terms go on them
        config = choice.config
        geometric, geometric_cv = choice.fit, choice.cv
    rung_config = CalibrationConfig.build(config, backend="numpy")
    # the workers start while geometry is fitted here (importing scikit-learn where it grows the
    # trees); where the compiled loop grows them, it is loaded here meanwhile, and the workers are
    # forked after, at the first round
    loading = load_beside() if residuals else None
    with worker_pool(prepare=worker_preparation() if residuals else ()) as pool:
        if choice is None:
            say(0, work, f"model 1/{steps}: geometric, fit and {K_FOLDS} folds")
            geometric = fit_parametric(inputs, config, term_spec((), meas, config), progress)
            geometric_cv = cross_validate(geometric, config)
        if loading is not None:
            loading.join()
        ladder.append((Candidate((), "", geometric, geometric_cv.errors), geometric_cv))
        parametric = ladder[0][0]
        while True:
            trials = rungs([with_term(parametric.terms, t) for t in trial_order if t not in parametric.terms],
                           parametric, pool)
            kept = choose([parametric, *trials], groups) if trials else parametric
            if kept is parametric:
                break
            parametric = kept
        # the learned corrections on the chosen parametric model, and on geometry alone: they can
        # take structure that joint terms would have taken more coarsely
        candidates = [c for c, _ in ladder]
        on = [(c, cv) for c, cv in ladder if residuals and c.terms in dict.fromkeys((parametric.terms, ()))]
        skipped = screened = None
        if on:
            done = len(candidates)

            def tell(text):
                say(done, done + process * len(on), f"learned: {text}")

            data = [FoldData.of(c.fit, cv) for c, cv in on]
            kept, geometry = on[-1], on[:-1]  # the parametric model kept, and geometry alone where it is not

            def pays(learned: list[Candidate]) -> bool:
                return choose([kept[0], *learned], groups) is not kept[0]

            # first on the model kept: a learned correction that cannot improve it cannot, on geometry
            # alone (less), beat it; the trees (the cheaper) first
            tell(f"{model_name(kept[0].terms + ('trees',))}: inner cross-validation")
            # the model kept's screen is needed whatever the trees do: its tuning goes to the workers
            # first, and the trees' pieces fill the cores beside it
            kept_screen = begin_screen(data[-1], config.seed, pool)
            settings = choose_settings(data[-1].q, data[-1].e, data[-1].groups, config.seed, pool)
            trees = tree_candidates([kept], data[-1:], settings, meas, config.seed, pool, tell)
            # a quick process first on each base a process would be tried on: where it takes nothing
            # from its model or loses clearly to the trees, no process (nor one stacked on the trees)
            # can change the choice
            both = bool(geometry) and pays(trees)
            tried = on if both else [kept]
            tell(f"{', '.join(model_name(c.terms + ('residual',)) for c, _ in tried)}: screen")
            tunings = [begin_screen(data[0], config.seed, pool), kept_screen] if both else [kept_screen]
            # with both bases, geometry's trees are needed whatever the screens say: their pieces run
            # beside geometry's screen tuning
            geometry_trees = tree_candidates(geometry, data[:1], settings, meas, config.seed, pool, tell) \
                if both else []
            screens = screened_processes(list(zip(data if both else data[-1:], [cv for _, cv in tried], tunings)),
                                         config.seed, pool)
            against = trees[0]
            if all(screen_loses(e, cv.errors, against, groups) for e, (_, cv) in zip(screens, tried)):
                processes = []
                if both:
                    trees = geometry_trees + trees
                elif geometry:
                    skipped = kept[0]
                screened = [LadderRow(model_name(c.terms + ("residual",)), rms(e), c.fit.n_params, screened=True)
                            for (c, _), e in zip(tried, screens)]
            elif both:  # both bases: the kernel of geometry's richer residuals leads
                tell(f"{', '.join(model_name(c.terms + ('residual',)) for c, _ in on)}: kernels")
                kernels = chained_kernels(data, config.seed, pool)
                processes = process_candidates(list(zip(on, data, kernels)), config.seed, pool, tell)
                trees = geometry_trees + trees
            else:
                tell(f"{model_name(kept[0].terms + ('residual',))}: kernels")
                kernel, nll = scratch_kernel(data[-1], config.seed, pool)
                processes = process_candidates([(kept, data[-1], kernel)], config.seed, pool, tell)
                if geometry and pays(processes):
                    base, again = warm_kernels(data[0], data[-1], nll, config.seed, pool)
                    # the model kept's process again where geometry's kernel led to a deeper basin
                    processes = process_candidates([(on[0], data[0], base)] + (
                        [] if again is None else [(kept, data[-1], again)]), config.seed, pool, tell) + \
                        ([] if again is not None else processes)
                    trees = tree_candidates(geometry, data[:1], settings, meas, config.seed, pool, tell) + trees
                elif geometry:
                    skipped = kept[0]
            learned = processes + trees
            stacked = stacked_candidate([c for c, _ in on], learned, config.seed, pool, tell)
            candidates += learned + ([stacked] if stacked is not None else [])
        chosen = choose(candidates, groups)
        residual = learned_on_all(chosen, config.seed, pool)

    def on_validation(c: Candidate) -> float | None:
        """What each candidate does on the validation poses, beside what cross-validation said."""
        if inputs.validation is None or (c.residual and c is not chosen):
            return None
        robot = c.fit.robot.replace(residual=residual if c.residual else None)
        return float(Metrics.of(robot, inputs.validation).position["rms"])

    rows = [LadderRow(c.name, c.cv_rms, c.fit.n_params,
                      int(min(len(c.errors), MAX_POINTS)) if "residual" in c.learned else None,
                      on_validation(c)) for c in candidates]
    unit = meas.unit
    what = "reprojection" if unit == "px" else "position"
    notes = [Note(f"model auto: {chosen.name} (cross-validated {what} RMS {chosen.cv_rms:.4g} {unit}; geometric "
             f"{candidates[0].cv_rms:.4g} {unit}; a richer model is kept only if it predicts held-out poses "
                  f"better, paired test p < {SIGNIFICANCE:g})")]
    if not residuals and (meas.constraints is not None or meas.camera is not None):
        notes.append(Note("model auto: learned corrections not tried: they learn corrections of measured positions, "
                          "which " + ("rows that touched points or planes" if meas.constraints is not None else
                                      "camera rows") + " have none"))
    if screened:
        rows += screened
        notes.append(Note(f"model auto: residual processes not tuned in full: screened with a kernel tuned on "
                     f"{SCREEN_POINTS} poses, each takes nothing from its model or predicts held-out poses more "
                     f"than {SCREEN_RATIO:g}× worse than {against.name} ({against.cv_rms:.4g} mm; the best screen "
                          f"{min(r.cv_rms_mm for r in screened):.4g} mm)"))
    if skipped is not None:
        notes.append(Note(f"model auto: learned corrections not tried on geometry alone: neither improves on "
                          f"{skipped.name}, which holds more"))
    if lacking:
        notes.append(Note(f"model auto: {' and '.join(lacking)} not tried: "
                          + "; ".join(f"the {name} term needs {needs}" for name, needs in lacking.items())))
    chosen_cv = next(cv for c, cv in ladder if c.fit is chosen.fit)
    if choice is not None:  # the sets compared, then the terms on the one kept
        rows, notes = choice.rows + rows[1:], choice.notes + notes
    return Chosen(chosen.name, chosen.fit, residual, rows, notes + spent_dof(chosen.fit, residual),
                  geometric=candidates[0].fit, prediction=chosen_cv.metrics(chosen.errors),
                  geometric_prediction=geometric_cv.metrics(), scheme=chosen_cv.scheme, held_errors=chosen.errors)


