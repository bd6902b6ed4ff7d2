"""Fitting the tree correction: gradient-boosted trees on the joint angles, judged by cross-validation.

What the parametric model leaves at each pose, e = measured − model (mm; rad for orientations,
in the measuring frame), is regressed on the commanded joint angles by scikit-learn's
``HistGradientBoostingRegressor``, one per output, with squared loss, learning rate
:data:`LEARNING_RATE` and at most :data:`MAX_LEAF_NODES` leaves a tree (small trees: a model that
travels in a JSON file and predicts inside every inverse-kinematics step).  The smallest leaf
(:data:`LEAF_SIZES`) and the number of trees (up to :data:`MAX_TREES`) are chosen by an inner
:data:`INNER_FOLDS`-fold cross-validation on the poses it is given, the folds drawn with the seed
and the whole curve over the number of trees read from one fit per fold (staged predictions).
The orientation outputs take the leaf size chosen on the positions and their own number of trees.

The candidate is judged like the Gaussian process (:mod:`robocal.calibration.select.selection`): each
outer fold fits trees, with the settings chosen on all the poses, to what its own parametric
refit leaves on its training poses and predicts the held-out ones.  Choosing two settings on all
the poses lends the held-out figure a little optimism; the settings' curve is flat near its
optimum (UR10 series C: 0.162–0.170 mm for 10–20 poses a leaf and 150–600 trees), and on pure
noise the inner cross-validation keeps a handful of trees, which the paired test does not prefer
to none.

The same folds give the correction's support and uncertainty (:mod:`robocal.model.trees`): the
held-out poses' distances to their fold's training poses (95th percentile: the reach), the
held-out error of the correction less the instrument's noise, and the spread of the fold
ensembles at every pose (delete-a-fold jackknife), the larger of the two kept as its error
within the data.  Its degrees of freedom are Efron's covariance penalty, n (cv − fit)/(2 cv) per
output (the optimism of the fit on its own poses).

Every fit runs OpenMP on one thread: the pieces run on :class:`~robocal.backend.worker_pool`'s
workers, and on a thousand poses one thread is faster than two (0.10 s against 0.12 s a fit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...backend import SERIAL, worker_pool
from ...model.trees import Ensemble, TreeResidual, fade, nearest
from ..judge.statistics import group_folds
from .boosting import Boosted, boost, compiled

LEARNING_RATE = 0.2
MAX_TREES = 200
MAX_LEAF_NODES = 15
#: smallest leaves the inner cross-validation tries (poses); those above a quarter of a fold's training poses are not
LEAF_SIZES = (10, 30)
INNER_FOLDS = 3
#: trees without gain on the held-out poses after which early stopping ends (orientations)
PATIENCE = 20
#: share of the held-out poses the reach of the correction covers
REACH_QUANTILE = 95.0
#: poses the support keeps (the nearest-pose distance is computed against them)
MAX_SUPPORT = 2000


@dataclass(frozen=True)
class Settings:
    """What the inner cross-validation chose: the smallest leaf (poses) and the number of trees
    (the positions')."""

    leaf: int
    trees: int

    def to_dict(self) -> dict:
        return {"learning_rate": LEARNING_RATE, "max_leaf_nodes": MAX_LEAF_NODES, "min_samples_leaf": self.leaf,
                "trees_position": self.trees}


def _regressor(leaf: int, trees: int | None, seed: int | None):
    """The regressor with ``trees`` trees, or (None) up to :data:`MAX_TREES` with early stopping
    on a held-out fifth of the poses (:data:`PATIENCE` trees without gain)."""
    from sklearn.ensemble import HistGradientBoostingRegressor

    stop, trees = trees is None, MAX_TREES if trees is None else max(int(trees), 1)
    # tol 0: the default 1e-7 is absolute, and an orientation's squared error in rad² is of that order
    return HistGradientBoostingRegressor(learning_rate=LEARNING_RATE, max_iter=trees,
                                         max_leaf_nodes=MAX_LEAF_NODES, min_samples_leaf=int(leaf), early_stopping=stop,
                                         validation_fraction=0.2, n_iter_no_change=PATIENCE, scoring="loss", tol=0.0,
                                         random_state=0 if seed is None else seed)


def _one_thread():
    """OpenMP on one thread for the block.  threadpoolctl limits the libraries loaded when it is
    called, so scikit-learn's OpenMP runtime is loaded first: in a fresh worker a limit set before
    it left every fit on every core, and two workers' busy-waiting threads made a 3 s inner
    cross-validation take 60 s."""
    import sklearn.ensemble  # noqa: F401  (its OpenMP runtime, so that the limit reaches it)
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1, user_api="openmp")


def _grown(q, y, leaf: int, trees: int | None, seed, test=None, test_y=None, check_at: int = 0) -> Boosted:
    """One output's trees on y (m,) at q (:mod:`.boosting`): robocal's compiled loop where numba's kernels
    are compiled, else scikit-learn's own fit (the same trees); ``test``, ``test_y`` and ``check_at`` as
    :func:`~.boosting.boost` takes them."""
    if compiled():
        return boost(q, y, learning_rate=LEARNING_RATE, max_leaf_nodes=MAX_LEAF_NODES, min_samples_leaf=leaf,
                     trees=trees, max_trees=MAX_TREES, patience=PATIENCE, seed=seed, test=test, test_y=test_y,
                     check_at=check_at, check_patience=CURVE_PATIENCE)
    with _one_thread():
        model = _regressor(leaf, trees, seed)
        staged = None
        if check_at:  # a first stretch of trees, then the rest where the held-out curve asks for them
            model.set_params(warm_start=True)
            for grown in (check_at, MAX_TREES):
                model.set_params(max_iter=grown)
                model.fit(q, y)
                staged = np.array(list(model.staged_predict(test)))  # (trees, m)
                sq = np.sum((staged - test_y[None, :]) ** 2, axis=1)
                if model.n_iter_ < grown or model.n_iter_ - int(np.argmin(sq)) > CURVE_PATIENCE:
                    break
        else:
            model.fit(q, y)
            if test is not None:
                staged = np.array(list(model.staged_predict(test)))
        check = q[:: max(1, len(q) // 200)]  # the ensemble read back predicts as the model does
        gain = np.concatenate([predictor.nodes["gain"] for (predictor,) in model._predictors])
        return Boosted(Ensemble.of_sklearn(model, check), gain.astype(float), staged)


#: trees an inner fold grows first, and how many past its held-out minimum tell it to stop there:
#: boosting at LEARNING_RATE that has not improved for that many trees does not come back below
#: its minimum (it overfits from there), and where the data hold nothing for trees to take (a
#: parametric model at the noise) the minimum comes within a few trees; else it grows to MAX_TREES
CURVE_FIRST = 60
CURVE_PATIENCE = 50


def curve(piece) -> np.ndarray:
    """An inner fold's output: the held-out squared error after each tree, up to
    :data:`MAX_TREES`; an output whose first :data:`CURVE_FIRST` trees pass their minimum by
    :data:`CURVE_PATIENCE` stops there, its curve staying at its last value.  One output a piece:
    the outputs are fitted independently, and eighteen pieces share two workers evenly where six
    (an inner fold's three outputs each) left one idle a third of the time."""
    q_train, y_train, q_test, y_test, leaf, seed = piece
    out = np.empty(MAX_TREES)
    staged = _grown(q_train, y_train, leaf, MAX_TREES, seed, q_test, y_test, CURVE_FIRST).staged
    sq = np.sum((staged - y_test[None, :]) ** 2, axis=1)
    out[:len(sq)] = sq
    out[len(sq):] = sq[-1]
    return out


def inner_pieces(q: np.ndarray, e: np.ndarray, groups: np.ndarray | None = None,
                 seed: int | None = 0) -> tuple[list[int], list[tuple]]:
    """The leaf sizes the inner cross-validation tries on the positions e (m, 3) mm at q, and its
    pieces of work (:func:`curve`, one per leaf size, inner fold and output; groups: the pose of
    each row, rows of one pose stay in one fold).  Leaves above a quarter of a fold's training
    poses are not tried."""
    q, e = np.asarray(q, float), np.asarray(e, float)[:, :3]
    smallest = len(q) - -(-len(q) // INNER_FOLDS)
    leaves = [leaf for leaf in LEAF_SIZES if leaf <= max(smallest // 4, LEAF_SIZES[0])]
    groups = np.arange(len(q)) if groups is None else np.unique(groups, return_inverse=True)[1]
    folds = group_folds(groups, INNER_FOLDS, seed)
    train = [np.setdiff1d(np.arange(len(q)), test) for test in folds]
    return leaves, [(q[tr], e[tr, a], q[te], e[te, a], leaf, seed) for leaf in leaves for tr, te in zip(train, folds)
                    for a in range(e.shape[1])]


def settings_of(leaves: list[int], curves: list[np.ndarray]) -> Settings:
    """The leaf size and number of trees of the lowest inner cross-validated error: the curves of
    :func:`inner_pieces`' pieces summed over the outputs, then over the inner folds (in that
    order: the sums are the same to the last bit whatever the pieces' grouping)."""
    outputs = len(curves) // (len(leaves) * INNER_FOLDS)
    folds = []
    for f in range(len(leaves) * INNER_FOLDS):
        summed = np.zeros(MAX_TREES)
        for c in curves[f * outputs:(f + 1) * outputs]:
            summed += c
        folds.append(summed)
    total = np.array([sum(folds[i * INNER_FOLDS:(i + 1) * INNER_FOLDS]) for i in range(len(leaves))])
    best_leaf, best_trees = np.unravel_index(np.argmin(total), total.shape)
    return Settings(leaves[best_leaf], int(best_trees) + 1)


def choose_settings(q: np.ndarray, e: np.ndarray, groups: np.ndarray | None = None, seed: int | None = 0,
                    pool: worker_pool = SERIAL) -> Settings:
    """The leaf size and number of trees of the lowest inner cross-validated error of the
    positions e (m, 3) mm at q (see :func:`inner_pieces`)."""
    leaves, pieces = inner_pieces(q, e, groups, seed)
    return settings_of(leaves, pool.map(curve, pieces))


def _ensembles(q, y, leaf: int, trees: int | None, seed) -> tuple[list[Ensemble], np.ndarray]:
    """The ensembles of y's columns, and each one's joint importance (outputs, n); trees None:
    as many as early stopping keeps."""
    grown = [_grown(q, y[:, a], leaf, trees, seed) for a in range(y.shape[1])]
    return [b.ensemble for b in grown], np.array([b.importance(q.shape[1]) for b in grown])


def _fold_piece(piece):
    """An outer fold's output: its trees fitted on the training poses, their raw prediction at
    every pose (m,) and their joint importance (1, n).  One output a piece (see :func:`curve`)."""
    q_train, y_train, q_all, settings, seed = piece
    grown = _grown(q_train, y_train, settings.leaf, settings.trees, seed, test=q_all)
    return grown.staged[-1], grown.importance(q_train.shape[1])[None, :]


@dataclass
class TreeCandidate:
    """The trees of one parametric fit, judged: the held-out position errors (m, 3) mm after
    their correction, each fold's raw prediction at every pose (for a Gaussian process stacked on
    them), the settings, and what the model fitted on all the poses will carry (its support's
    metric and reach, its error inside and outside the data, its degrees of freedom)."""

    errors: np.ndarray
    fold_predictions: list[np.ndarray]
    settings: Settings
    scale: np.ndarray
    reach: float
    inside: float
    prior: float
    dof: float

    def model(self, q: np.ndarray, e: np.ndarray, groups: np.ndarray | None, seed: int | None = 0,
              pool: worker_pool = SERIAL) -> TreeResidual:
        """The trees fitted on all the poses: e (m, 3) mm, or (m, 6) with orientations rad.  The
        orientations' trees take the positions' leaf size; the choice of model does not judge
        them, and their number is set by early stopping on a held-out fifth of the poses (drawn
        with the seed): one fit, where an inner cross-validation took nine."""
        q, e = np.asarray(q, float), np.asarray(e, float)
        # one output a piece; the orientations' (early stopping) first, as the longer
        outputs = ([3, 4, 5] if e.shape[1] == 6 else []) + [0, 1, 2]
        parts = dict(zip(outputs, pool.map(_ensembles_piece, [
            (q, e[:, a:a + 1], self.settings.leaf, self.settings.trees if a < 3 else None, seed) for a in outputs])))
        ensembles = [parts[a][0][0] for a in sorted(parts)]
        importance = np.vstack([parts[a][1] for a in sorted(parts)])
        hyper = self.settings.to_dict()
        if e.shape[1] == 6:
            hyper["trees_orientation"] = [ens.n_trees for ens in ensembles[3:]]
        taken = np.sqrt(np.mean(np.stack([parts[a][2] for a in sorted(parts)], 1) ** 2, axis=0))
        keep = np.sort(np.random.default_rng(seed).permutation(len(q))[:MAX_SUPPORT])
        return TreeResidual(tuple(ensembles), q[keep].copy(), self.scale, self.reach, self.inside, self.prior,
                            dof=self.dof, importance=importance, taken=taken, hyper=hyper)


def _ensembles_piece(piece):
    """An output's ensembles and importance (:func:`_ensembles`), and its prediction at the poses
    it was grown on (m,): walked where it was grown, beside the other outputs'."""
    ensembles, importance = _ensembles(*piece)
    return ensembles, importance, ensembles[0].predict(piece[0])


def metric_scale(q: np.ndarray, importance: np.ndarray) -> np.ndarray:
    """Each joint's weight in the support's metric (rad⁻¹): √(share of the position trees' split
    gain) / the joint's spread over the data."""
    share = importance[:3].mean(axis=0)
    spread = np.maximum(np.std(q, axis=0), 1e-6)
    return np.sqrt(share) / spread


def fit_trees(q: np.ndarray, e: np.ndarray, folds: list[tuple[np.ndarray, np.ndarray]], held_out: np.ndarray,
              noise: float, settings: Settings, seed: int | None = 0, pool: worker_pool = SERIAL) -> TreeCandidate:
    """The outer cross-validation of position trees with the settings on e (m, 3 or more;
    positions mm first) at commanded joints q (m, n) rad.  folds: per outer fold (held-out pose
    indices, what its parametric refit leaves on its training poses (m_train, 3 or more));
    held_out: the parametric model's held-out errors (m, 3) mm; noise: the trace (mm²) of the
    instrument's position noise (0 unknown).  The support's metric weighs the joints by the
    folds' mean importance."""
    q, e = np.asarray(q, float), np.asarray(e, float)[:, :3]
    every = np.arange(len(q))
    trains = [np.setdiff1d(every, test) for test, _ in folds]
    parts = iter(pool.map(_fold_piece, [(q[train], e_train[:, a], q, settings, seed)
                                        for train, (_, e_train) in zip(trains, folds) for a in range(3)]))
    done = [[next(parts) for _ in range(3)] for _ in folds]
    raw = [np.stack([p[0] for p in fold], 1) for fold in done]
    scale = metric_scale(q, np.mean([np.vstack([p[1] for p in fold]) for fold in done], axis=0))
    distances = [nearest(q[test], q[train], scale) for train, (test, _) in zip(trains, folds)]
    reach = float(np.percentile(np.concatenate(distances), REACH_QUANTILE))
    errors = np.array(held_out, float, copy=True)
    for (test, _), prediction, d in zip(folds, raw, distances):
        errors[test] -= fade(d, reach)[:, None] * prediction[test]
    cv = float(np.mean(np.sum(errors ** 2, 1)))
    spread = np.stack(raw)  # (K, m, 3): the fold ensembles at every pose
    k = len(raw)
    jackknife = float(np.mean((k - 1) / k * np.sum((spread - spread.mean(0)) ** 2, axis=(0, 2))))
    inside = max(cv - noise, jackknife, 0.0)
    prior = max(float(np.mean(np.sum(e ** 2, 1))) - noise, inside)
    # each fold's misfit on its own training poses against the held-out misfit: the optimism
    fit_mse = np.mean([np.mean((e_train[:, :3] - r[train]) ** 2, axis=0)
                       for (_, e_train), r, train in zip(folds, raw, trains)], axis=0)
    cv_mse = np.mean(errors ** 2, axis=0)
    dof = float(np.sum(np.clip(len(q) * (cv_mse - fit_mse) / (2.0 * np.maximum(cv_mse, 1e-300)), 0.0, len(q))))
    return TreeCandidate(errors, raw, settings, scale, reach, inside, prior, dof)
