"""Gradient-boosted trees of one output, as :mod:`.trees` fits them, grown by robocal's compiled loop
or by scikit-learn: the same trees either way.

:func:`boost` is scikit-learn's ``HistGradientBoostingRegressor`` (squared loss, learning rate,
leaves, smallest leaf, early stopping on a held-out fifth as :mod:`.trees` sets them) with its own
binning and its own split of the validation poses (as its ``_BinMapper`` and ``train_test_split``
find them: :func:`_thresholds`, :func:`_split`), and its trees grown by
:func:`~.boost_kernels.grow_trees` where numba's kernels are compiled and scikit-learn is the
release the loop copies (:func:`compiled`), else by scikit-learn itself.  The compiled loop does what
scikit-learn's grower and splitter do, step by step (its module says how), so the trees, their
values, their gains and their predictions are the same to the last bit: a test grows both on many
data sets and compares every array.  It grows a tree in about a tenth of a millisecond where
scikit-learn's Python grower takes 0.6–0.7 ms (900 poses, six joints, 15 leaves).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ...model.trees import Ensemble, _depth

#: scikit-learn's histogram bins (255 for values, one for missing ones)
_BINS = 256


@dataclass(frozen=True, eq=False)
class Boosted:
    """One output's trees: the ensemble (thresholds in the joints' units), each node's split gain
    (−1 where none), and the predictions after each tree at the poses asked for (trees, m)."""

    ensemble: Ensemble
    gain: np.ndarray
    staged: np.ndarray | None

    @property
    def n_iter(self) -> int:
        return self.ensemble.n_trees

    def importance(self, n: int) -> np.ndarray:
        """Each of the n joints' share of the split gain."""
        e = self.ensemble
        inner = e.feature >= 0
        out = np.zeros(n)
        np.add.at(out, e.feature[inner], np.maximum(self.gain[inner], 0.0))
        total = out.sum()
        return out / total if total > 0 else out * 0.0

    def predict(self, X: np.ndarray) -> np.ndarray:
        """The baseline plus each tree's value, tree after tree (scikit-learn's order of the sums)."""
        X = np.asarray(X, float)
        per_tree = self.ensemble.per_tree(X, backend="numpy")
        return np.cumsum(np.column_stack([np.full(len(X), self.ensemble.baseline), per_tree]), axis=1)[:, -1]


def _split(n: int, seed: int | None, stop: bool):
    """scikit-learn's seed for its binning and validation split, and (early stopping) the training
    and validation rows it draws from it: ``train_test_split``'s shuffle, a fifth (rounded up) held out."""
    rng = np.random.RandomState(0 if seed is None else seed)
    random_seed = rng.randint(np.iinfo(np.uint32).max, dtype="u8")
    if not stop:
        return random_seed, np.arange(n), None
    held = math.ceil(0.2 * n)
    permutation = np.random.RandomState(random_seed).permutation(n)
    return random_seed, permutation[held:], permutation[:held]


#: scikit-learn's largest finite threshold
_ALMOST_INF = 1e300
#: poses above which scikit-learn bins a random subsample (:func:`_thresholds` hands those to it)
_SUBSAMPLE = 200_000


def _thresholds(X: np.ndarray, random_seed) -> list[np.ndarray]:
    """Each feature's bin thresholds as scikit-learn's ``_BinMapper`` finds them: the midpoints of its
    distinct values where there are at most 255, else its percentiles (``averaged_inverted_cdf``) at
    255 equal steps, duplicates out; above :data:`_SUBSAMPLE` poses, the binner itself."""
    if len(X) > _SUBSAMPLE:
        from sklearn.ensemble._hist_gradient_boosting.binning import _BinMapper

        return list(_BinMapper(n_bins=_BINS, random_state=random_seed, n_threads=1).fit(X).bin_thresholds_)
    out = []
    for column in X.T:
        distinct = np.unique(column)
        if len(distinct) == 1:
            t = np.asarray([], dtype=float)
        elif len(distinct) <= _BINS - 1:
            t = np.lib.stride_tricks.sliding_window_view(distinct, 2).mean(axis=1)
        else:
            t = np.percentile(column, np.linspace(0, 100, num=_BINS)[1:-1], method="averaged_inverted_cdf")
        unique = np.unique(t)
        if unique.shape[0] != t.shape[0]:
            t = unique
        out.append(np.clip(t, None, _ALMOST_INF))
    return out


def _binned(X: np.ndarray, thresholds: list[np.ndarray]) -> np.ndarray:
    """X's bins (m, n) uint8: a value's bin is the first threshold it does not exceed."""
    out = np.empty(X.shape, dtype=np.uint8)
    for f, t in enumerate(thresholds):
        out[:, f] = np.searchsorted(t, X[:, f], side="left")
    return out


def boost(X: np.ndarray, y: np.ndarray, *, learning_rate: float, max_leaf_nodes: int, min_samples_leaf: int,
          trees: int | None, max_trees: int, patience: int, seed: int | None, test: np.ndarray | None = None,
          test_y: np.ndarray | None = None, check_at: int = 0, check_patience: int = 0) -> Boosted:
    """Trees on y (m,) at X (m, n): ``trees`` of them, or (None) up to ``max_trees`` with early
    stopping on a held-out fifth (``patience`` trees without gain); ``test`` (k, n): poses whose
    prediction after each tree :attr:`Boosted.staged` holds; with their targets ``test_y``, growing
    stops after ``check_at`` trees (0: never) where the last lies more than ``check_patience`` trees
    past the least squared error there.  The compiled loop; callers take
    scikit-learn's own fit where numba's kernels are not compiled (:func:`compiled`)."""
    from .boost_kernels import grow_trees

    X, y = np.asarray(X, float), np.asarray(y, float)
    test = None if test is None else np.asarray(test, float)
    # a NaN joint would take the last bin here where scikit-learn sends it the way most samples went
    if not all(np.all(np.isfinite(a)) for a in (X, y, test, test_y) if a is not None):
        raise ValueError("boosting takes finite joints and targets")
    stop = trees is None
    random_seed, train, val = _split(len(X), seed, stop)
    thresholds = _thresholds(X[train], random_seed)
    Xb = _binned(X[train], thresholds)
    nbins = np.array([len(t) + 1 for t in thresholds], dtype=np.int64)
    empty = np.zeros((0, X.shape[1]), dtype=np.uint8)
    Xv = empty if val is None else _binned(X[val], thresholds)
    yv = np.zeros(0) if val is None else y[val]
    Xt = empty if test is None else _binned(test, thresholds)
    baseline = float(np.average(y[train]))
    max_iter = max_trees if stop else max(int(trees), 1)
    feature, bin_, left, right, value, gain, roots, staged = grow_trees(
        Xb, np.ascontiguousarray(y[train]), nbins, baseline, float(learning_rate),
        max_iter, int(max_leaf_nodes), int(min_samples_leaf), Xv, yv, int(patience), Xt,
        np.zeros(len(Xt)) if test_y is None else np.ascontiguousarray(test_y, float),
        int(check_at) if test_y is not None else 0, int(check_patience))
    threshold = np.zeros(len(feature))
    for f in range(X.shape[1]):
        at = feature == f
        threshold[at] = thresholds[f][bin_[at]]
    ensemble = Ensemble(feature, threshold, left, right, value, roots, baseline, _depth(feature, left, right, roots))
    return Boosted(ensemble, gain, None if test is None else staged)


#: the scikit-learn releases whose boosting the compiled loop was checked against, bit for bit (its binning
#: changed between 1.4 and 1.9: percentiles by "midpoint", then by "averaged_inverted_cdf")
SKLEARN_GROWN = ((1, 9),)


@functools.cache
def _sklearn_release() -> tuple[int, ...]:
    """The installed scikit-learn's (major, minor), read from its metadata without importing it."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return tuple(int(p) for p in version("scikit-learn").split(".")[:2])
    except (PackageNotFoundError, ValueError):
        return ()


def compiled() -> bool:
    """Whether this process grows trees by the compiled loop: numba's kernels run
    (:func:`robocal.model.compiled.resolve`) and the scikit-learn installed is one the loop was
    checked against (:data:`SKLEARN_GROWN`); else scikit-learn fits them itself, and the numbers
    are its own."""
    from ...model.compiled import resolve

    return _sklearn_release() in SKLEARN_GROWN and resolve("auto") == "numba"


def compile_boosting() -> None:
    """Compile the compiled loop into numba's cache (or load it) on a few poses, with the types
    :func:`boost` calls it with: the background compile's call (:mod:`robocal.calibration.precompile`)."""
    X = np.linspace(-1.0, 1.0, 80).reshape(40, 2)
    y = np.sin(3.0 * X[:, 0])
    boost(X, y, learning_rate=0.2, max_leaf_nodes=3, min_samples_leaf=5, trees=None, max_trees=3, patience=1, seed=0,
          test=X[:5], test_y=y[:5], check_at=1)


def load_beside():
    """Where the compiled loop grows the trees: a thread loading it into this process (starting
    numba's compiler, about 0.4 s on a process that has not yet, then the loop from the cache), so
    that workers forked once it is joined have it loaded, instead of each loading it at its first
    piece (W8: 0.2–0.45 s of each worker).  It runs beside this process's own work; None where
    scikit-learn grows the trees.  A loop that fails to load here fails again, and says so, where
    it is used."""
    import threading

    if not compiled():
        return None

    def load():
        try:
            compile_boosting()
        except Exception:  # noqa: BLE001  (said where the loop is used)
            pass

    thread = threading.Thread(target=load, name="robocal-load-boosting", daemon=True)
    thread.start()
    return thread


def worker_preparation() -> tuple[str, ...]:
    """What a worker of the ``auto`` ladder loads as it starts (:class:`robocal.backend.worker_pool`'s
    ``prepare``): nothing where the compiled loop grows the trees (the workers are forked from a
    process that has loaded it, :func:`load_beside`: loading it, or scikit-learn, in the workers as
    they start took a core from the geometric fit beside them; UR10 auto 6.7 → 6.2 s on the
    command line, W8 3.1 → 2.7 s), else scikit-learn's trees, which take a second to import."""
    return () if compiled() else ("sklearn.ensemble",)
