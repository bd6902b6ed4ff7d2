"""Learned corrections on a parametric fit: the residual process, gradient-boosted trees and
the two stacked, each cross-validated with the parametric fit's folds, and fitted on all the poses.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...backend import SERIAL, worker_pool
from ...model.corrections import Correction, Stacked
from ...model.measurements import Measurements
from ...model.trees import TreeResidual
from ..fit.parametric import Fit
from ..timing import staged
from .choice import Candidate, model_name
from .crossval import K_FOLDS, CrossValidation, FoldData, residual_errors
from .residual import (
    begin_tuning,
    best_kernel,
    fit_residual,
    minimised,
    neg_log_likelihood,
    scratch_pieces,
    tune_kernels,
)
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
    """A worker's piece of the learned candidates: a process's fold prediction, a process's tuning
    on all poses, or an inner fold of the trees (:func:`robocal.calibration.select.trees.curve`)."""
    kind, args = piece
    return _fold_prediction(*args) if kind == "fold" else tune_kernels(*args)


@staged("model")
def chained_kernels(data: list[FoldData], seed: int | None, pool: worker_pool = SERIAL) -> list[tuple]:
    """The process's position kernel tuned on all the poses of each parametric fit (its
    :class:`FoldData`): the first from scratch, each next from the one before (the same poses,
    residuals of a nearby model: a warm start, not a shortcut, it runs to convergence; the
    likelihood has several basins, and residuals with more structure, geometry's, lead to the deeper)."""
    kernels = [tune_kernels(data[0].q, data[0].e[:, :3], seed, pool=pool)]
    for d in data[1:]:
        kernels.append(tune_kernels(d.q, d.e[:, :3], seed, kernels[-1], pool=pool))
    return kernels


@staged("model")
def scratch_kernel(data: FoldData, seed: int | None, pool: worker_pool = SERIAL) -> tuple[tuple, float]:
    """The process's position kernel tuned from scratch on all the poses of one fit, and its
    negative log likelihood there."""
    kernel, nll = best_kernel(pool.map(minimised, scratch_pieces(data.q, data.e, seed)))
    return (kernel,), nll


@staged("model")
def warm_kernels(geometric: FoldData, kept: FoldData, nll: float, seed: int | None,
                 pool: worker_pool = SERIAL) -> tuple[tuple, tuple | None]:
    """Geometry alone's position kernel tuned from scratch, and the model kept's re-tuned from it
    where that is more likely than its own from scratch (``nll``), else None."""
    base = tune_kernels(geometric.q, geometric.e[:, :3], seed, pool=pool)
    again = tune_kernels(kept.q, kept.e[:, :3], seed, base)
    return base, again if neg_log_likelihood(kept.q, kept.e, seed, again[0]) < nll else None


@staged("model")
def cross_validate_residuals(ladder: list[tuple[FoldData, CrossValidation, tuple]], seed: int | None,
                             pool: worker_pool = SERIAL) -> list[np.ndarray]:
    """For each parametric fit (its :class:`FoldData`, cross-validation and the kernel tuned on all
    its poses, :func:`chained_kernels`), the held-out position errors (m, 3) mm of the fit plus a
    residual process.

    Each fold tunes its own kernel on its training poses, so that the held-out poses judge a
    process that never saw them: a kernel tuned on all the poses and only conditioned per fold
    makes a process fitted to pure noise look better than none, and would be chosen.  The fold
    starts from the kernel of all the poses and runs :data:`FOLD_TUNING` iterations (from
    scratch, eight hyperparameters on a thousand poses take seconds per fold); on pure noise
    that is enough to leave the held-out poses unexplained, as they should be.  (A start from
    another fold's kernel would carry as much of the held-out poses: that fold trained on them.)
    Every fold of every fit is one piece of work for the pool's workers.
    """
    pieces = [piece for data, _, kernels in ladder for piece in data.process_folds(seed, kernels)]
    return _less_folds([(data, cv) for data, cv, _ in ladder], pool.map(_piece, pieces))


def _less_folds(bases: list[tuple[FoldData, CrossValidation]], predictions: list) -> list[np.ndarray]:
    """Each base's held-out errors less its folds' predictions, the folds of every base in turn."""
    done = iter(predictions)
    out = []
    for data, cv in bases:
        corrected = np.array(cv.errors, copy=True)
        for test, _ in data.folds:
            corrected[test] -= next(done)
        out.append(corrected)
    return out


#: poses a screening process is tuned on: its tuning costs the cube of their number, an eighth of
#: a full one on a thousand poses
SCREEN_POINTS = 500
#: a process whose screen predicts held-out poses worse than the best learned candidate by this
#: factor of RMS, and worse by the paired test at SCREEN_SIGNIFICANCE, is not tuned in full: a
#: process is simpler than trees, and wins where the paired test cannot tell it worse, so the
#: margin covers what a kernel tuned on fewer poses misses
SCREEN_RATIO = 1.5
SCREEN_SIGNIFICANCE = 1e-4


def _conditioned(piece) -> np.ndarray:
    """One fold of a screen: the process with the given kernels, not re-tuned, conditioned on the
    fold's training poses, predicting the held-out ones."""
    q_train, e_train, q_test, seed, kernels = piece
    return fit_residual(q_train, e_train, seed, kernels)[0].predict(q_test)


def begin_screen(data: FoldData, seed: int | None, pool: worker_pool = SERIAL):
    """The kernel tuning of a screen (:func:`screened_processes`) handed to the pool's workers now:
    its two starts are the longest pieces of the learned stage, and the pieces of whatever the
    caller runs next fill the cores the shorter one leaves."""
    return begin_tuning(data.q, data.e[:, :3], seed, points=SCREEN_POINTS, pool=pool)


@staged("model")
def screened_processes(screens: list[tuple[FoldData, CrossValidation, object]], seed: int | None,
                       pool: worker_pool = SERIAL) -> list[np.ndarray]:
    """Held-out position errors (m, 3) mm of a quick residual process on each parametric fit of
    ``screens`` ((its data, its cross-validation, its :func:`begin_screen`)): the kernel tuned on
    :data:`SCREEN_POINTS` poses of all the data, each fold conditioned on its training poses
    without re-tuning (every screen's folds one batch of pieces).  Near the full figure, on
    either side: its kernel has seen the held-out poses (optimistic) but fewer poses (it may
    miss structure)."""
    pieces = [args for data, _, tuning in screens for _, args in data.process_folds(seed, tuning())]
    return _less_folds([(data, cv) for data, cv, _ in screens], pool.map(_conditioned, pieces))


def screen_loses(screen: np.ndarray, base: np.ndarray, best: Candidate, groups: np.ndarray) -> bool:
    """Whether a screened process cannot change the choice: it takes nothing from its base's
    held-out errors ``base`` (its kernel found noise alone), or it loses clearly to the best
    learned candidate so far."""
    from .choice import worse_p_value
    from .crossval import rms

    if rms(screen) >= rms(base):
        return True
    return rms(screen) > SCREEN_RATIO * best.cv_rms and \
        worse_p_value(screen, best.errors, groups) < SCREEN_SIGNIFICANCE


def instrument_noise(sigma: np.ndarray | None) -> float:
    """The trace (mm²) of an instrument's stated position noise σ (m, 3) mm, averaged over the
    poses (0 unstated)."""
    return 0.0 if sigma is None else float(np.mean(np.sum(np.asarray(sigma, float) ** 2, axis=1)))


@staged("model")
def cross_validate_trees(data: FoldData, cv: CrossValidation, meas: Measurements, seed: int | None,
                         pool: worker_pool = SERIAL, settings: Settings | None = None) -> TreeCandidate:
    """The position trees of a parametric fit on all its poses and its held-out errors
    (:func:`robocal.calibration.select.trees.fit_trees`), with ``settings`` or those the inner
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




def process_candidates(bases: list[tuple[tuple[Candidate, CrossValidation], FoldData, tuple]], seed: int | None,
                       pool: worker_pool, say=None) -> list[Candidate]:
    """A residual process on each parametric base ((candidate, cross-validation), its
    :class:`FoldData` and its kernel), cross-validated: every fold of every base one piece of work."""
    (say or (lambda text: None))(f"{', '.join(model_name(c.terms + ('residual',)) for (c, _), _, _ in bases)}: "
                                 f"{K_FOLDS} folds")
    errors = cross_validate_residuals([(d, cv, k) for (_, cv), d, k in bases], seed, pool)
    return [Candidate(c.terms, "residual", c.fit, e, k, data=d) for ((c, _), d, k), e in zip(bases, errors)]


def tree_candidates(bases: list[tuple[Candidate, CrossValidation]], data: list[FoldData], settings: Settings,
                    meas: Measurements, seed: int | None, pool: worker_pool, say=None) -> list[Candidate]:
    """Gradient-boosted trees with ``settings`` on each parametric base, cross-validated."""
    (say or (lambda text: None))(f"{', '.join(model_name(c.terms + ('trees',)) for c, _ in bases)}: {K_FOLDS} folds")
    out = []
    for (c, cv), d in zip(bases, data):
        candidate = cross_validate_trees(d, cv, meas, seed, pool, settings)
        out.append(Candidate(c.terms, "trees", c.fit, candidate.errors, trees=candidate, data=d))
    return out


def stacked_candidate(bases: list[Candidate], learned: list[Candidate], seed: int | None, pool: worker_pool,
                      say=None) -> Candidate | None:
    """A process on what the trees leave, where the trees predict better than the process and both
    better than their parametric model, on the base of the better trees: on the trees' own poses
    what they leave is small (they fit them closely), so a process there can add to trees that
    lead, not lift trees that trail."""
    say = say or (lambda text: None)
    both = []
    for c in bases:
        p = next((x for x in learned if x.learned == "residual" and x.fit is c.fit), None)
        t = next((x for x in learned if x.learned == "trees" and x.fit is c.fit), None)
        if p is not None and t is not None and t.cv_rms <= p.cv_rms < c.cv_rms:
            both.append((p, t))
    if not both:
        return None
    p, t = min(both, key=lambda pair: pair[1].cv_rms)
    say(f"{model_name(t.terms + ('trees', 'residual'))}: {K_FOLDS} folds")
    errors = cross_validate_stacked(t.data, t.trees, p.kernels, seed, pool)
    return Candidate(t.terms, "trees+residual", t.fit, errors, p.kernels, t.trees, t.data)
