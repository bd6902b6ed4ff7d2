"""robocal's compiled boosting grows scikit-learn's trees: on many data sets (many and few
distinct values, one joint and six, a fixed number of trees and early stopping, several seeds and
leaf sizes) every node, threshold, leaf value, gain, prediction after each tree and the final
prediction equal scikit-learn's ``HistGradientBoostingRegressor`` to the last bit; its binning, its
validation split and numpy's pairwise sum are each checked against the original; and the ladder's
pieces give the same numbers on either path."""

import numpy as np
import pytest
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.ensemble._hist_gradient_boosting.binning import _BinMapper
from sklearn.model_selection import train_test_split

from robocal.calibration.select import boosting, trees
from robocal.model.trees import Ensemble

pytest.importorskip("numba")

#: the compiled loop copies the releases it was checked against; with another, robocal fits by scikit-learn
copied = pytest.mark.skipif(boosting._sklearn_release() not in boosting.SKLEARN_GROWN,
                            reason="a scikit-learn release the compiled loop does not copy")

KW = dict(learning_rate=trees.LEARNING_RATE, max_leaf_nodes=trees.MAX_LEAF_NODES, max_trees=trees.MAX_TREES,
          patience=trees.PATIENCE)


def _sklearn(X, y, leaf, n_trees, seed):
    stop = n_trees is None
    return HistGradientBoostingRegressor(
        learning_rate=KW["learning_rate"], max_iter=KW["max_trees"] if stop else n_trees,
        max_leaf_nodes=KW["max_leaf_nodes"], min_samples_leaf=leaf, early_stopping=stop, validation_fraction=0.2,
        n_iter_no_change=KW["patience"], scoring="loss", tol=0.0, random_state=seed).fit(X, y)


def _case(rng, k):
    n, F = int(rng.integers(40, 900)), int(rng.integers(1, 7))
    X = rng.uniform(-3, 3, (n, F))
    if k % 4 == 0:
        X = np.round(X, 1)  # few distinct values: midpoints, and ties in the histograms
    y = np.sin(X[:, 0] * rng.uniform(0.5, 3)) + 0.3 * X[:, -1] * X[:, 0] + rng.normal(0, rng.uniform(0.01, 1), n)
    if k % 5 == 0:
        y = y * 1e-4  # an orientation's size (rad)
    return X, y, int(rng.choice([1, 5, 10, 30])), None if k % 3 == 0 else int(rng.integers(1, 120)), k % 4


@copied
def test_the_compiled_loop_grows_scikit_learn_s_trees_to_the_last_bit(rng):
    for k in range(14):
        X, y, leaf, n_trees, seed = _case(rng, k)
        test = rng.uniform(-3.5, 3.5, (40, X.shape[1]))
        model = _sklearn(X, y, leaf, n_trees, seed)
        ours = boosting.boost(X, y, min_samples_leaf=leaf, trees=n_trees, seed=seed, test=test, **KW)
        theirs = Ensemble.of_sklearn(model)
        for field in ("feature", "threshold", "left", "right", "value", "roots"):
            np.testing.assert_array_equal(getattr(ours.ensemble, field), getattr(theirs, field), err_msg=field)
        assert ours.ensemble.baseline == theirs.baseline and ours.n_iter == model.n_iter_
        gain = np.concatenate([p.nodes["gain"] for (p,) in model._predictors])
        inner = theirs.feature >= 0
        np.testing.assert_array_equal(ours.gain[inner], gain[inner])
        np.testing.assert_array_equal(ours.staged, np.array(list(model.staged_predict(test))))
        np.testing.assert_array_equal(ours.predict(X), model.predict(X))


@copied
def test_its_bins_and_its_validation_split_are_scikit_learn_s(rng):
    for n, digits in ((50, None), (254, None), (255, None), (256, None), (1000, None), (1000, 2), (3000, 1)):
        X = rng.normal(size=(n, 3)) * np.array([1.0, 1e-3, 100.0])
        if digits is not None:
            X = np.round(X, digits)
        X[:, 1] = X[0, 1] if n == 50 else X[:, 1]  # one joint held still
        seed = np.random.RandomState(n).randint(np.iinfo(np.uint32).max, dtype="u8")
        mapper = _BinMapper(n_bins=256, random_state=seed, n_threads=1).fit(X)
        ours = boosting._thresholds(X, seed)
        for a, b in zip(ours, mapper.bin_thresholds_):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(boosting._binned(X, ours), mapper.transform(X))
        _, train, val = boosting._split(n, 3, True)
        s_train, s_val = train_test_split(np.arange(n), test_size=0.2, random_state=boosting._split(n, 3, False)[0])
        np.testing.assert_array_equal(train, s_train)
        np.testing.assert_array_equal(val, s_val)


@copied
def test_a_joint_held_still_matches_and_a_nan_is_refused(rng):
    """A joint that never moved (one distinct value: no bin to split) grows scikit-learn's trees too;
    a NaN joint, where scikit-learn sends it the way most samples went and the bins would send it
    right, is refused, in the poses fitted and in those predicted."""
    X = rng.uniform(-2, 2, (300, 3))
    X[:, 1] = 0.7
    y = np.sin(2 * X[:, 0]) + rng.normal(0, 0.05, 300)
    model = _sklearn(X, y, 10, 40, 0)
    ours = boosting.boost(X, y, min_samples_leaf=10, trees=40, seed=0, test=X[:20], **KW)
    np.testing.assert_array_equal(ours.staged[-1], model.predict(X[:20]))
    assert not np.any(ours.ensemble.feature == 1)
    bad = X[:20].copy()
    bad[3, 2] = np.nan
    for kwargs in (dict(X=np.vstack([X, bad]), y=np.r_[y, y[:20]]), dict(X=X, y=y, test=bad)):
        with pytest.raises(ValueError, match="finite"):
            boosting.boost(min_samples_leaf=10, trees=40, seed=0, **kwargs, **KW)


def test_numpy_s_pairwise_sum_as_the_loop_adds(rng):
    from robocal.calibration.select.boost_kernels import _pairwise

    for n in [*range(1, 40), 127, 128, 129, 255, 256, 257, 1000, 1387, 4099]:
        a = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 8, n)  # wide range: every order of the sums shows
        assert _pairwise(a, 0, n) == np.sum(a)
        assert _pairwise(a, 3, n - 3) == np.sum(a[3:]) if n > 3 else True


@pytest.mark.parametrize("check", [False, True])
def test_the_ladder_s_pieces_are_the_same_on_either_path(rng, monkeypatch, check):
    """The inner cross-validation's curve (its first stretch of trees and the rest where the
    held-out error asks for them) and an outer fold's prediction and importance, compiled and by
    scikit-learn (the path without numba's kernels)."""
    q = rng.uniform(-2, 2, (240, 6))
    y = np.sin(2 * q[:, 0]) * np.cos(q[:, 2]) + rng.normal(0, 0.3 if check else 0.02, 240)
    piece = (q[:180], y[:180], q[180:], y[180:], 10, 0)
    fold = (q[:180], y[:180], q, trees.Settings(10, 37), 0)
    monkeypatch.delenv("ROBOCAL_NO_NUMBA", raising=False)
    monkeypatch.setattr("robocal.model.compiled.kernels_compiled", lambda: True)
    compiled = trees.curve(piece), trees._fold_piece(fold), trees._ensembles(q, y[:, None], 10, None, 0)
    monkeypatch.setenv("ROBOCAL_NO_NUMBA", "1")
    plain = trees.curve(piece), trees._fold_piece(fold), trees._ensembles(q, y[:, None], 10, None, 0)
    np.testing.assert_array_equal(compiled[0], plain[0])
    for a, b in zip(compiled[1], plain[1]):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(compiled[2][1], plain[2][1])
    for field in ("feature", "threshold", "left", "right", "value", "roots"):
        np.testing.assert_array_equal(getattr(compiled[2][0][0], field), getattr(plain[2][0][0], field))
    # noise: the first stretch passes its minimum and the curve stops there; structure: all the trees
    assert (compiled[0][trees.CURVE_FIRST:] == compiled[0][trees.CURVE_FIRST - 1]).all() == check


def test_another_scikit_learn_release_fits_its_own_trees(monkeypatch):
    """The compiled loop copies scikit-learn 1.9's algorithm (1.4 binned by other percentiles): with a
    release it was not checked against, scikit-learn fits the trees and the workers import it."""
    monkeypatch.delenv("ROBOCAL_NO_NUMBA", raising=False)
    monkeypatch.setattr("robocal.model.compiled.kernels_compiled", lambda: True)
    monkeypatch.setattr(boosting, "_sklearn_release", lambda: (1, 9))
    assert boosting.compiled()
    assert boosting.worker_preparation() == ()
    monkeypatch.setattr(boosting, "_sklearn_release", lambda: (1, 4))
    assert not boosting.compiled()
    assert boosting.worker_preparation() == ("sklearn.ensemble",)
    monkeypatch.setattr(boosting, "_sklearn_release", lambda: (1, 9))
    monkeypatch.setenv("ROBOCAL_NO_NUMBA", "1")
    assert not boosting.compiled()


def test_the_loop_is_loaded_beside_the_parent_s_work_or_not_at_all(monkeypatch, capsys):
    """Where the compiled loop grows the trees, a thread loads it into this process (so that the
    workers forked after inherit it); where scikit-learn grows them, nothing starts; a loop that
    fails to load there ends the thread quietly (it is said where the loop is used)."""
    from robocal.calibration.select import boost_kernels

    monkeypatch.setattr(boosting, "compiled", lambda: False)
    assert boosting.load_beside() is None
    monkeypatch.setattr(boosting, "compiled", lambda: True)
    thread = boosting.load_beside()
    thread.join(60)
    assert not thread.is_alive() and boost_kernels.grow_trees.signatures
    monkeypatch.setattr(boosting, "compile_boosting", lambda: 1 / 0)
    failing = boosting.load_beside()
    failing.join(60)
    assert not failing.is_alive() and "ZeroDivisionError" not in capsys.readouterr().err
