"""The tree correction: robocal's arrays predict what scikit-learn's trees predict, survive JSON,
fade where their data end, and a broken file is refused."""

import json

import numpy as np
import pytest
from sklearn.ensemble import HistGradientBoostingRegressor

from robocal.calibration.select.trees import choose_settings
from robocal.model.corrections import Stacked, correction_from_dict
from robocal.model.residual import Block, ResidualModel
from robocal.model.trees import Ensemble, TreeResidual, fade
from robocal.model.uncertainty import correction_note


def _step(q):
    """A pattern a smooth kernel cannot follow: steps in joints 1 and 3 (mm)."""
    return np.column_stack([0.3 * np.sign(q[:, 0] - 0.4) * (q[:, 2] > 0), 0.2 * (q[:, 0] > -1.0),
                            0.1 * np.sign(q[:, 2])])


def _ensembles(q, y, trees=60):
    models = [HistGradientBoostingRegressor(learning_rate=0.2, max_iter=trees, max_leaf_nodes=15, min_samples_leaf=10,
                                            early_stopping=False).fit(q, y[:, a]) for a in range(y.shape[1])]
    return models, tuple(Ensemble.of_sklearn(m) for m in models)


def test_the_arrays_predict_what_scikit_learn_predicts_and_survive_json(rng):
    q = rng.uniform(-2, 2, (300, 6))
    models, ensembles = _ensembles(q, _step(q) + rng.normal(0, 0.01, (300, 3)))
    fresh = np.vstack([rng.uniform(-2, 2, (50, 6)), rng.uniform(-9, 9, (20, 6))])  # far out too: a leaf's value
    for model, ensemble in zip(models, ensembles):
        back = Ensemble.from_dict(json.loads(json.dumps(ensemble.to_dict())))
        np.testing.assert_allclose(ensemble.predict(fresh), model.predict(fresh), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(back.predict(fresh), ensemble.predict(fresh))
        # exact on a threshold: a pose equal to it goes left, as scikit-learn sends it
        inner = np.flatnonzero(ensemble.feature >= 0)[:20]
        on = np.tile(fresh[:1], (len(inner), 1))
        on[np.arange(len(inner)), ensemble.feature[inner]] = ensemble.threshold[inner]
        np.testing.assert_allclose(ensemble.predict(on), model.predict(on), rtol=0, atol=1e-12)


def _model(q, rng, reach=0.5):
    _, ensembles = _ensembles(q, _step(q))
    return TreeResidual(ensembles, q, np.full(6, 1.0), reach, inside=0.01, prior=0.09,
                        importance=np.full((3, 6), 1 / 6), taken=np.ones(3))


def test_whole_within_its_reach_nothing_beyond_twice_it(rng):
    q = rng.uniform(-2, 2, (300, 6))
    model = _model(q, rng)
    np.testing.assert_allclose(model.predict(q[:30]), model.raw(q[:30]))  # at its poses: whole
    far = q[:30] + np.array([0, 0, 0, 0, 0, 5.0])  # joint 6 pushed 5 rad away: 5 > 2 × reach in this metric
    assert np.all(model.distance(far) > 1.0)
    np.testing.assert_array_equal(model.predict(far), 0.0)
    np.testing.assert_allclose(model.position_variance(far), 0.09)  # the prior: nothing known there
    np.testing.assert_allclose(model.position_variance(q[:30]), 0.01)
    # between: linear in the distance, and so is the variance
    d = np.array([0.0, 0.5, 0.75, 1.0, 1.5])
    np.testing.assert_allclose(fade(d, 0.5), [1.0, 1.0, 0.5, 0.0, 0.0])


def test_the_distance_is_the_nearest_pose_in_the_weighted_metric(rng):
    q = rng.uniform(-2, 2, (200, 6))
    model = TreeResidual(_model(q, rng).ensembles, q, np.array([2.0, 1.0, 0.0, 0.0, 0.5, 0.0]), 0.3, 0.0, 1.0)
    fresh = rng.uniform(-1.9, 1.9, (40, 6))  # within every joint's range: the nearest pose alone
    brute = np.sqrt(np.min(np.sum(((fresh[:, None] - q[None]) * model.scale) ** 2, axis=2), axis=1))
    np.testing.assert_allclose(model.distance(fresh), brute, rtol=1e-9, atol=1e-9)
    out = fresh.copy()
    out[:, 3] = q[:, 3].max() + np.radians(2.0) + 0.5  # joint 4 (no weight) 0.5 rad beyond its fringe
    nearest_only = np.sqrt(np.min(np.sum(((out[:, None] - q[None]) * model.scale) ** 2, axis=2), axis=1))
    np.testing.assert_allclose(model.distance(out) ** 2, nearest_only ** 2 + (0.5 / q[:, 3].std()) ** 2, rtol=1e-9)


def test_sidecar_kinds_round_trip_and_a_broken_tree_is_refused(rng):
    q = rng.uniform(-2, 2, (120, 6))
    trees = _model(q, rng)
    process = ResidualModel(q[:20], (Block(rng.normal(size=(20, 3)), np.ones(6), 1.0, np.zeros(3), np.ones(3),
                                           noise=0.1),))
    for model in (trees, Stacked(trees.with_inside(0.0), process)):
        back = correction_from_dict(json.loads(json.dumps(model.to_dict())))
        assert type(back) is type(model) and back.n_joints == 6
        np.testing.assert_allclose(back.predict(q[:10]), model.predict(q[:10]), atol=1e-12)
        np.testing.assert_allclose(back.position_variance(q[:10]), model.position_variance(q[:10]))
    stacked = Stacked(trees.with_inside(0.0), process)
    np.testing.assert_allclose(stacked.predict(q[:10]), trees.predict(q[:10]) + process.predict(q[:10]))
    broken = trees.to_dict()
    broken["ensembles"][0]["left"][broken["ensembles"][0]["roots"][1]] = 10 ** 7
    with pytest.raises(ValueError, match="outside its trees"):
        correction_from_dict(broken)
    with pytest.raises(ValueError, match="unknown kind"):
        correction_from_dict({"kind": "random forest"})


def test_the_inner_cross_validation_keeps_few_trees_on_noise_and_many_on_structure(rng):
    q = rng.uniform(-2, 2, (300, 6))
    noise = choose_settings(q, rng.normal(0, 0.02, (300, 3)), seed=0)
    wavy = np.column_stack([np.sin(3 * q[:, 0]) * np.cos(2 * q[:, 1]), np.cos(3 * q[:, 2]), q[:, 3] ** 2 / 4])
    structure = choose_settings(q, wavy + rng.normal(0, 0.02, (300, 3)), seed=0)
    assert noise.trees <= 10 < 50 <= structure.trees


def test_a_joint_that_never_moved_ends_the_support_when_it_moves(rng):
    """The trees cannot split on a joint held still, so its weight in their metric is nil; moved
    beyond where it was held, the pose is still outside the data, and the correction is gone."""
    q = rng.uniform(-2, 2, (300, 6))
    q[:, 5] = 0.3  # joint 6 held still over the whole campaign
    model = TreeResidual(_model(q, rng).ensembles, q, np.array([1.0, 1.0, 1.0, 1.0, 1.0, 0.0]), 0.5, 0.01, 0.09)
    inside = q[:20].copy()
    np.testing.assert_allclose(model.weight(inside), 1.0)
    inside[:, 5] += np.radians(1.0)  # within the 2° fringe of its value
    np.testing.assert_allclose(model.weight(inside), 1.0)
    moved = q[:20].copy()
    moved[:, 5] = 1.0
    np.testing.assert_array_equal(model.weight(moved), 0.0)
    assert "beyond the data of the learned correction (trees)" in correction_note(model, moved)


def test_a_scikit_learn_that_lays_its_trees_out_otherwise_fails_loudly_at_fit_time(rng):
    """robocal reads scikit-learn's private tree layout: a release that renames a field, or keeps
    the names but changes a meaning, must stop the fit, never give a silently wrong correction."""
    import copy

    q = rng.uniform(-2, 2, (200, 6))
    model, = _ensembles(q, _step(q)[:, :1], trees=10)[0]
    Ensemble.of_sklearn(model, q)  # the layout of the release installed, read back exactly
    renamed = copy.deepcopy(model)
    from numpy.lib import recfunctions

    for (predictor,) in renamed._predictors:  # a copy renamed: scikit-learn's record type is shared
        predictor.nodes = recfunctions.rename_fields(predictor.nodes, {"num_threshold": "threshold"})
    with pytest.raises(RuntimeError, match="lays out its fitted trees otherwise"):
        Ensemble.of_sklearn(renamed, q)
    # the same names with another meaning: a release whose leaves hold values before shrinkage
    # (applied when it predicts) would read back as trees that predict twice what the model does
    shifted = copy.deepcopy(model)
    for (predictor,) in shifted._predictors:
        predictor.nodes["value"] *= 2.0
    shifted.predict = model.predict
    with pytest.raises(RuntimeError, match="read back differently"):
        Ensemble.of_sklearn(shifted, q)
    del shifted._baseline_prediction
    with pytest.raises(RuntimeError, match="lays out its fitted trees otherwise"):
        Ensemble.of_sklearn(shifted, q)


def test_a_learned_correction_s_bound_holds_everywhere_and_the_map_that_uses_it_is_unchanged(rng, monkeypatch):
    """The bound on |δp| a correction can add (which lets the uncertainty map skip the correction
    where a candidate's TCP cannot be in the box): never exceeded, near or far from the data, for
    trees, a process and the two stacked; the map is the one the correction everywhere gives."""
    from robocal.io.robotfile import load_robot
    from robocal.model.uncertainty import uncertainty_map

    q = rng.uniform(-2, 2, (200, 6))
    trees = _model(q, rng)
    process = ResidualModel(q[:20], (Block(rng.normal(size=(20, 3)), np.full(6, 0.7), 1.0, np.full(3, 0.05),
                                           np.full(3, 0.2), noise=0.1),))
    every = np.vstack([rng.uniform(-2, 2, (3000, 6)), q + rng.normal(0, 0.01, q.shape)])
    for model in (trees, process, Stacked(trees.with_inside(0.0), process)):
        assert np.max(np.linalg.norm(model.predict(every)[:, :3], axis=1)) <= model.position_bound() * (1 + 1e-12)
    # the trees' bound is each tree's largest leaf: a pose can reach most of it
    raw = np.max(np.linalg.norm(trees.raw(every), axis=1))
    assert trees.position_bound() < 6 * raw
    robot = load_robot("ur10").replace(residual=trees)
    from robocal.model.uncertainty import in_base

    points = in_base(robot, robot.positions(q))
    box = np.stack([points.min(axis=0), points.min(axis=0) + 0.4 * np.ptp(points, axis=0)])
    low, high = np.full(6, -2.0), np.full(6, 2.0)
    kept = uncertainty_map(robot, low, high, n=300, seed=4, box=box)
    monkeypatch.setattr(TreeResidual, "position_bound", lambda self: np.inf)  # every candidate corrected
    every_one = uncertainty_map(robot, low, high, n=300, seed=4, box=box)
    assert kept.over == "workspace" and len(kept.position) == 300
    np.testing.assert_allclose(kept.position, every_one.position, rtol=0, atol=1e-9)
    np.testing.assert_allclose(kept.sigma, every_one.sigma, rtol=1e-12)
    # the map corrects the candidates a batch at a time until it has enough: its points are the first
    # 300 of its rounds' draws whose corrected TCP is in the box, as correcting every draw finds
    draws, found = np.random.default_rng(4), []
    while sum(len(f) for f in found) < 300:
        corrected = robot.positions(robot.couple(draws.uniform(low, high, (3000, 6))))
        local = in_base(robot, corrected)
        found.append(corrected[np.all((local >= box[0]) & (local <= box[1]), axis=1)])
    assert len(found) > 1  # rounds of candidates, each corrected in batches
    np.testing.assert_array_equal(kept.position, np.concatenate(found)[:300])
    np.testing.assert_array_equal(every_one.position, np.concatenate(found)[:300])  # every draw near: batches


def test_the_compiled_walk_and_numpy_s_give_every_tree_s_leaf_alike(rng, backend):
    """Each backend's walk (numba's compiled loop, numpy's level by level) lands every pose in the
    leaf scikit-learn's own prediction does: far out, on a threshold and at NaN too."""
    q = rng.uniform(-2, 2, (300, 6))
    models, ensembles = _ensembles(q, _step(q) + rng.normal(0, 0.01, (300, 3)))
    fresh = np.vstack([rng.uniform(-2, 2, (50, 6)), rng.uniform(-9, 9, (20, 6))])
    for model, ensemble in zip(models, ensembles):
        inner = np.flatnonzero(ensemble.feature >= 0)[:20]
        on = np.tile(fresh[:1], (len(inner), 1))
        on[np.arange(len(inner)), ensemble.feature[inner]] = ensemble.threshold[inner]
        nan = fresh[:5].copy()
        nan[:, 2] = np.nan
        X = np.vstack([fresh, on, nan])
        np.testing.assert_array_equal(ensemble.per_tree(X, backend), ensemble.per_tree(X, "numpy"))
        both = np.vstack([fresh, on])
        np.testing.assert_allclose(ensemble.predict(both, backend), model.predict(both), rtol=0, atol=1e-12)


def test_positions_skip_the_orientation_outputs_and_equal_the_whole_pose_s(rng, monkeypatch):
    """A position asks a correction for its position outputs alone: the same positions, to the bit,
    as the whole corrected pose gives (six-output trees, a process of two blocks, the two stacked),
    and the orientation trees are not walked for it."""
    from robocal.io.robotfile import load_robot

    q = rng.uniform(-2, 2, (300, 6))
    wavy = np.column_stack([_step(q), 1e-3 * np.sin(q[:, :3])])
    _, ensembles = _ensembles(q, wavy + rng.normal(0, 0.01, (300, 6)), trees=20)
    trees = TreeResidual(ensembles, q, np.full(6, 1.0), 0.5, inside=0.01, prior=0.09,
                         importance=np.full((6, 6), 1 / 6), taken=np.ones(6))
    block = lambda t: Block(rng.normal(size=(20, t)), np.full(6, 0.7), 1.0, np.full(t, 0.05),  # noqa: E731
                            np.full(t, 0.2), noise=0.1)
    process = ResidualModel(q[:20], (block(3), block(3)))
    fresh = np.vstack([rng.uniform(-2, 2, (40, 6)), q[:10] + 0.01])
    for correction in (trees, process, Stacked(trees.with_inside(0.0), process)):
        robot = load_robot("ur10").replace(residual=correction)
        whole = robot.fk(fresh)
        np.testing.assert_array_equal(robot.positions(fresh), whole[:, :3, 3])
        # the rotations it would give without the orientation outputs are NaN, never a plausible wrong one
        assert np.isnan(robot.fk(fresh, rotations=False)[:, :3, :3]).all() == (correction.outputs == 6)
    # a correction of positions alone leaves the rotations as they are: the whole pose, either way
    three = TreeResidual(ensembles[:3], q, np.full(6, 1.0), 0.5, inside=0.01, prior=0.09,
                         importance=np.full((3, 6), 1 / 6), taken=np.ones(6))
    robot = load_robot("ur10").replace(residual=three)
    np.testing.assert_array_equal(robot.fk(fresh, rotations=False), robot.fk(fresh))
    walked = []
    monkeypatch.setattr(TreeResidual, "_predictions",
                        lambda self, walk, X: walked.extend(walk) or [np.zeros(len(X))] * len(walk))
    # a copy: the correction above keeps its walks of these poses
    load_robot("ur10").replace(residual=trees.with_inside(0.01)).positions(fresh)
    assert walked == list(ensembles[:3])


def _six(rng, m=300):
    q = rng.uniform(-2, 2, (m, 6))
    wavy = np.column_stack([_step(q), 1e-3 * np.sin(q[:, :3])])
    _, ensembles = _ensembles(q, wavy + rng.normal(0, 0.01, (m, 6)), trees=40)
    return q, TreeResidual(ensembles, q, np.full(6, 1.0), 0.5, inside=0.01, prior=0.09,
                           importance=np.full((6, 6), 1 / 6), taken=np.ones(6))


@pytest.mark.parametrize("threads", [1, 2])
def test_all_outputs_walked_at_once_equal_each_ensemble_s_own_walk(rng, monkeypatch, threads):
    """The six outputs' trees walked in one call, serial or on two threads, give each output what
    its own ensemble predicts, to the bit (numpy's level-by-level walk as the reference)."""
    import robocal.backend as backend
    from robocal.backend import numba_installed

    if threads == 2 and not numba_installed():
        pytest.skip("the parallel walk is numba's")
    monkeypatch.setattr(backend, "kernel_threads", lambda work, now=False: threads)
    q, trees = _six(rng)
    fresh = np.vstack([rng.uniform(-2, 2, (400, 6)), rng.uniform(-9, 9, (20, 6)), q[:5]])
    fresh[-2:, 1] = np.nan
    expected = np.stack([e.predict(fresh, "numpy") for e in trees.ensembles], axis=1)
    np.testing.assert_array_equal(trees.raw(fresh), expected)
    np.testing.assert_array_equal(trees.with_inside(0.01).raw(fresh, positions=True)[:, :3], expected[:, :3])
    if numba_installed():  # the kernels themselves, on an ensemble's arrays
        from robocal.model.kernels import tree_walk, tree_walk_parallel

        e = trees.ensembles[0]
        arrays = (e.feature, e.threshold, e.left, e.right, e.roots, e.value, np.ascontiguousarray(fresh))
        np.testing.assert_array_equal(tree_walk_parallel(*arrays), tree_walk(*arrays))


def test_a_correction_recalls_its_walk_of_the_same_joints_and_only_of_those(rng, monkeypatch):
    """Applied to the same joints again, the trees are not walked again and give the same numbers;
    other joints, the same joints changed in place, or orientations after positions alone are
    walked afresh; the walks kept are not pickled with the correction."""
    import pickle

    q, trees = _six(rng)
    calls = []
    walk = TreeResidual._predictions
    monkeypatch.setattr(TreeResidual, "_predictions", lambda self, e, X: calls.append(len(e)) or walk(self, e, X))
    joints = rng.uniform(-2, 2, (50, 6))
    first = trees.raw(joints, positions=True)
    assert calls == [3]
    whole = trees.raw(joints)  # orientations too: walked
    assert calls == [3, 6]
    np.testing.assert_array_equal(trees.raw(joints.copy()), whole)
    np.testing.assert_array_equal(trees.raw(joints, positions=True), first)
    assert calls == [3, 6]
    joints[7, 2] += 1e-9  # the caller's array changed in place: not the joints walked
    changed = trees.raw(joints)
    assert calls == [3, 6, 6]
    np.testing.assert_array_equal(changed, np.stack([e.predict(joints, "numpy") for e in trees.ensembles], 1))
    for _ in range(5):  # more joints than it keeps: the oldest are walked again
        trees.raw(rng.uniform(-2, 2, (10, 6)))
    trees.raw(joints)
    assert calls[-1] == 6 and len(calls) == 3 + 5 + 1
    back = pickle.loads(pickle.dumps(trees))
    assert not [k for k in vars(back) if k.startswith("_")]
    np.testing.assert_array_equal(back.raw(joints), changed)
