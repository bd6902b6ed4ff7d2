"""Learned corrections on a parametric fit: the residual process, gradient-boosted trees and
the two stacked, each cross-validated with the parametric fit's folds, and fitted on all the poses.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..backend import SERIAL, worker_pool
from ..model.corrections import Correction, Stacked
from ..model.measurements import Measurements
from ..model.trees import TreeResidual
from .choice import Candidate, model_name
from .crossval import K_FOLDS, CrossValidation, FoldData, residual_errors
from .parametric import Fit
from .residual import fit_residual, tune_kernels
from .timing import staged
from .trees import Settings, TreeCandidate, choose_settings, fit_trees

#: L-BFGS-B iterations with which each fold re-tunes the residual kernel on its own training poses
FOLD_TUNING = 5
#: a simpler model is kept unless the paired test says it predicts held-out poses worse at this level
SIGNIFICANCE = 0.01
#: fewest poses a residual process is learnt from: with fewer, it can only memorise them
MIN_RESIDUAL_POSES = 30


def _fold_prediction(q_train, e_train, q_test, seed, kernels) -> np.ndarray:
    """One fold: the process re-tuned on the fold's training poses from the given kernels, and
    its prediction at the held-out joints."""
    gp, _ = fit_residual(q_train, e_train, seed, kernels, iterations=FOLD_TUNING)
    return gp.predict(q_test)


def _piece(piece):
    """A worker's piece of the residual candidates: a fold's prediction, or a tuning on all poses."""
    kind, args = piece
    return _fold_prediction(*args) if kind == "fold" else tune_kernels(*args)


@staged("model")
def cross_validate_residuals(ladder: list[tuple[FoldData, CrossValidation]], seed: int | None,
                             pool: worker_pool = SERIAL) -> list[tuple[np.ndarray, tuple]]:
    """For each parametric fit (its :class:`FoldData` and cross-validation), the held-out position
    errors (m, 3) mm of the fit plus a residual process, and the position kernel tuned on all the poses.

    Each fold tunes its own kernel on its training poses, so that the held-out poses judge a
    process that never saw them: a kernel tuned on all the poses and only conditioned per fold
    makes a process fitted to pure noise look better than none, and would be chosen.  The fold
    starts from the kernel of all the poses and runs :data:`FOLD_TUNING` iterations (from
    scratch, eight hyperparameters on a thousand poses take seconds per fold); on pure noise
    that is enough to leave the held-out poses unexplained, as they should be.  (A start from
    another fold's kernel would carry as much of the held-out poses: that fold trained on them.)

    The first fit's kernel is tuned from scratch; each next fit's starts from the one before
    (the same poses, residuals of a nearby model: a warm start, not a shortcut, it runs to
    convergence) and is tuned on the workers beside the previous fit's folds.
    """
    kernels = tune_kernels(ladder[0][0].q, ladder[0][0].e[:, :3], seed, pool=pool)
    out = []
    for i, (data, cv) in enumerate(ladder):
        pieces = data.process_folds(seed, kernels)
        if i + 1 < len(ladder):  # the longest piece first, so that no worker waits for it at the end
            pieces.insert(0, ("tune", (ladder[i + 1][0].q, ladder[i + 1][0].e[:, :3], seed, kernels)))
        done = pool.map(_piece, pieces)
        corrected = np.array(cv.errors, copy=True)
        for (test, _), prediction in zip(data.folds, done[len(done) - len(data.folds):]):
            corrected[test] -= prediction
        out.append((corrected, kernels))
        if i + 1 < len(ladder):
            kernels = done[0]
    return out


def instrument_noise(sigma: np.ndarray | None) -> float:
    """The trace (mm²) of an instrument's stated position noise σ (m, 3) mm, averaged over the
    poses (0 unstated)."""
    return 0.0 if sigma is None else float(np.mean(np.sum(np.asarray(sigma, float) ** 2, axis=1)))


@staged("model")
def cross_validate_trees(data: FoldData, cv: CrossValidation, meas: Measurements, seed: int | None,
                         pool: worker_pool = SERIAL, settings: Settings | None = None) -> TreeCandidate:
    """The position trees of a parametric fit on all its poses and its held-out errors
    (:func:`robocal.calibration.trees.fit_trees`), with ``settings`` or those the inner
    cross-validation chooses on its poses."""
    settings = settings or choose_settings(data.q, data.e, data.groups, seed, pool)
    return fit_trees(data.q, data.e, data.folds, cv.errors, instrument_noise(meas.sigma_position), settings, seed, pool)


def _leftover(data: FoldData, trees: TreeCandidate, model: TreeResidual | None) -> FoldData:
    """What the trees leave of the parametric residuals: ``model``'s on all the poses (when
    given), and fold by fold each fold's trees on its own training poses."""
    e = data.e.copy()
    if model is not None:
        raw = model.raw(data.q)
        e[:, :raw.shape[1]] -= raw
    folds = []
    for (test, e_train), raw in zip(data.folds, trees.fold_predictions):
        left = e_train.copy()
        left[:, :3] -= raw[data.train(test)]
        folds.append((test, left))
    return FoldData(data.q, e, folds, data.groups)


@staged("model")
def cross_validate_stacked(data: FoldData, trees: TreeCandidate, kernels: tuple, seed: int | None,
                           pool: worker_pool = SERIAL) -> np.ndarray:
    """The held-out position errors (m, 3) mm of trees with a process on what they leave: each
    fold's process re-tuned (from ``kernels``, the process's of the same parametric fit) on what
    the fold's trees leave on its training poses, and added to the trees' held-out correction."""
    left = _leftover(data, trees, None)
    corrected = np.array(trees.errors, copy=True)
    for (test, _), prediction in zip(left.folds, pool.map(_piece, left.process_folds(seed, kernels))):
        corrected[test] -= prediction
    return corrected




def _in_base(correction, fit: Fit):
    """The correction with its axes: the measuring axes, seen from the fit's base."""
    return replace(correction, axes=fit.robot.base[:3, :3].T.copy())


@staged("model")
def residual_on_all(fit: Fit, seed: int | None, kernels: tuple | None = None,
                    pool: worker_pool = SERIAL, errors: np.ndarray | None = None, iterations: int | None = None):
    """The residual process of a fit on all its poses (the position kernel reused when given;
    re-tuned from it for ``iterations``), learnt from ``errors`` (m, 3 or 6) when given, else
    from what the fit leaves."""
    meas, e = residual_errors(fit, fit.estimate.x)
    model = fit_residual(meas.q, e if errors is None else errors, seed, kernels, iterations=iterations, pool=pool)[0]
    return _in_base(model, fit)


#: L-BFGS-B iterations with which a process stacked on trees re-tunes, on all the poses, the
#: kernel of the process on the parametric fit alone
STACK_TUNING = 50


def learned_on_all(c: Candidate, seed: int | None, pool: worker_pool = SERIAL) -> Correction | None:
    """The chosen candidate's correction, fitted on all its poses."""
    if c.learned == "residual":
        return residual_on_all(c.fit, seed, c.kernels, pool)
    if "trees" in c.learned:
        trees = _in_base(c.trees.model(c.data.q, c.data.e, c.data.groups, seed, pool), c.fit)
        if c.learned == "trees":
            return trees
        left = _leftover(c.data, c.trees, trees)
        process = residual_on_all(c.fit, seed, c.kernels, pool, errors=left.e, iterations=STACK_TUNING)
        return Stacked(trees.with_inside(0.0), process)
    return None




def learned_candidates(bases: list[tuple[Candidate, CrossValidation]], meas: Measurements, seed: int | None,
                       pool: worker_pool, say=None) -> list[Candidate]:
    """The learned corrections on each parametric base: a process, trees, and where both improve
    on their base, the trees with a process on what they leave, on the base of the better."""
    say = say or (lambda text: None)
    data = [FoldData.of(c.fit, cv) for c, cv in bases]
    say(f"{', '.join(model_name(c.terms + ('residual',)) for c, _ in bases)}: kernels and {K_FOLDS} folds")
    processes = [Candidate(c.terms, "residual", c.fit, errors, kernels, data=d) for (c, _), d, (errors, kernels) in
                 zip(bases, data, cross_validate_residuals([(d, cv) for d, (_, cv) in zip(data, bases)], seed, pool))]
    say(f"{', '.join(model_name(c.terms + ('trees',)) for c, _ in bases)}: inner cross-validation and {K_FOLDS} folds")
    trees = []
    # the settings chosen on the parametric model kept (the last base), and used on geometry alone too
    settings = choose_settings(data[-1].q, data[-1].e, data[-1].groups, seed, pool)
    for (c, cv), d in zip(bases, data):
        candidate = cross_validate_trees(d, cv, meas, seed, pool, settings)
        trees.append(Candidate(c.terms, "trees", c.fit, candidate.errors, trees=candidate, data=d))
    out = processes + trees
    # a process on what the trees leave, where the trees predict better than the process and both
    # better than their parametric model: on the trees' own poses what they leave is small (they
    # fit them closely), so a process there can add to trees that lead, not lift trees that trail
    both = [(p, t) for (c, _), p, t in zip(bases, processes, trees) if t.cv_rms <= p.cv_rms < c.cv_rms]
    if both:
        p, t = min(both, key=lambda pair: pair[1].cv_rms)
        say(f"{model_name(t.terms + ('trees', 'residual'))}: {K_FOLDS} folds")
        errors = cross_validate_stacked(t.data, t.trees, p.kernels, seed, pool)
        out.append(Candidate(t.terms, "trees+residual", t.fit, errors, p.kernels, t.trees, t.data))
    return out
