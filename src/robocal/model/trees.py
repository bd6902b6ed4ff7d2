"""A learned correction made of gradient-boosted regression trees on the joint angles.

Where the parametric model leaves a sharp, configuration-dependent pattern (a cable pulling
over one range of a joint, a bearing's run-out, a wrist's flex that changes with the elbow), a
Gaussian process with a smooth kernel smooths it away; boosted trees split the joint space where
the pattern changes.  One ensemble per output (δp: 3 mm; for full-pose data δr: 3 rad, in the
measuring frame's axes as :mod:`robocal.model.residual` describes), fitted by
:mod:`robocal.calibration.select.trees` with scikit-learn's ``HistGradientBoostingRegressor``.  A
calibrated model carries the trees as plain arrays (:class:`Ensemble`) and predicts with numpy:
using it needs no scikit-learn and no pickle.

Trees do not extrapolate: outside their data each leaf's value is the value of the nearest
region they saw, which on another campaign's configurations is a guess.  So the correction has a
support, measured in the metric the trees use: the distance from a pose to the nearest training
pose, each joint in units of its spread over the data and weighed by its share of the trees'
splits (a joint they never split on does not count; :meth:`TreeResidual.distance`).  Within
``reach`` (the distance within which the cross-validation's held-out poses lay, 95th
percentile) the correction is whole; it fades linearly to nothing at twice that distance
(:func:`fade`).  Its predicted variance (:meth:`TreeResidual.position_variance`) is the
ensemble's own error inside (what cross-validation measured of the correction), returning to
the prior (the mean square of what the parametric model left) outside.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .residual import apply_correction

#: poses the support's distance is computed on at once (bounds the (chunk, N) matrix)
CHUNK = 1024


def fade(distance: np.ndarray, reach: float) -> np.ndarray:
    """The share of the correction kept at ``distance`` from the data: 1 within ``reach``, 0 beyond
    twice it, linear between."""
    return np.clip(2.0 - np.asarray(distance, float) / max(reach, 1e-12), 0.0, 1.0)


def nearest(q: np.ndarray, X: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """The distance (m,) from each pose q (m, n) to its nearest pose of X (N, n), each joint
    weighed by ``scale`` (n,); in chunks of :data:`CHUNK` poses, to bound the (chunk, N) matrix."""
    q, X = q * scale, X * scale
    xx = np.sum(X * X, 1)
    out = np.empty(len(q))
    for start in range(0, len(q), CHUNK):
        c = q[start:start + CHUNK]
        sq = np.sum(c * c, 1)[:, None] + xx[None, :] - 2.0 * c @ X.T
        out[start:start + CHUNK] = np.sqrt(np.maximum(sq.min(axis=1), 0.0))
    return out


@dataclass(frozen=True, eq=False)
class Ensemble:
    """One output's trees as flat arrays over all their nodes: feature (joint index, −1 at a
    leaf), threshold (rad: a pose goes left when its joint ≤ threshold), left and right (absolute
    node indices), value (the leaf's contribution, learning rate included), roots (each tree's
    first node), baseline (the constant the trees add to), depth (the longest root-to-leaf path)."""

    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    value: np.ndarray
    roots: np.ndarray
    baseline: float
    depth: int

    def _walk(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The nodes as a walk needs them: a leaf splits on joint 0 at +inf and both its children
        are itself, so a pose stays on its leaf once there; children (2N,): node k's left child at
        2k, its right at 2k + 1; the trees in order of their depth, deepest first (order), and how
        many of them still have a level to descend after each step (busy)."""
        if self.__dict__.get("_walk_arrays") is None:
            leaf = self.feature < 0
            index = np.arange(len(self.feature))
            children = np.stack([np.where(leaf, index, self.left), np.where(leaf, index, self.right)], 1).ravel()
            depths = _tree_depths(self.feature, self.left, self.right, self.roots)
            order = np.argsort(-depths, kind="stable")
            depths = depths[order]
            busy = np.array([int(np.sum(depths > step)) for step in range(1, self.depth)], dtype=np.int64)
            # 32-bit indices: half the memory a step's gathers move
            self.__dict__["_walk_arrays"] = (np.where(leaf, 0, self.feature).astype(np.intp),
                                             np.where(leaf, np.inf, self.threshold), children.astype(np.int32),
                                             order, busy)
        return self.__dict__["_walk_arrays"]

    def per_tree(self, X: np.ndarray, backend: str = "auto") -> np.ndarray:
        """Each tree's contribution (m, trees) at X (m, n): the compiled walk (numba, where its
        kernels are compiled: :func:`robocal.model.compiled.resolve`), else every pose through
        every tree at once, one level a step, a step walking only the trees that still have a
        level below it (a tree's depth is about two thirds of the deepest one's); the same values."""
        X = np.ascontiguousarray(X, float)
        from .compiled import resolve

        if resolve(backend) == "numba":
            return _compiled_walk(self.feature, self.threshold, self.left, self.right, self.roots, self.value, X)
        feature, threshold, children, order, busy = self._walk()
        flat = X.ravel()
        offset = np.arange(len(X)) * X.shape[1]
        # (trees, m): the trees a step walks are rows
        node = np.repeat(self.roots[order][:, None].astype(np.int32), len(X), axis=1)
        for k in busy:
            at = node[:k]
            node[:k] = children[2 * at + (flat[offset + feature[at]] > threshold[at])]
        out = np.empty((len(X), len(order)))
        out[:, order] = self.value[node].T
        return out

    def predict(self, X: np.ndarray, backend: str = "auto") -> np.ndarray:
        """The sum of the trees at X (m, n) rad."""
        return self.per_tree(X, backend).sum(axis=1) + self.baseline

    def bound(self) -> float:
        """The largest |prediction| anywhere: |baseline| plus each tree's largest |leaf| (a pose
        ends in one leaf a tree); all the leaves' sum where the trees' nodes are not in order."""
        leaf = np.where(self.feature < 0, np.abs(self.value), 0.0)
        tree = _tree_of_nodes(self.roots, len(leaf))
        if tree is None:
            return abs(self.baseline) + float(np.sum(leaf))
        largest = np.zeros(len(self.roots))
        np.maximum.at(largest, tree, leaf)
        return abs(self.baseline) + float(np.sum(largest))

    @property
    def n_trees(self) -> int:
        return len(self.roots)

    def to_dict(self) -> dict:
        return {"baseline": self.baseline, "roots": self.roots.tolist(), "feature": self.feature.tolist(),
                "threshold": self.threshold.tolist(), "left": self.left.tolist(), "right": self.right.tolist(),
                "value": self.value.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Ensemble:
        feature = np.array(d["feature"], dtype=np.int64)
        left, right = np.array(d["left"], dtype=np.int64), np.array(d["right"], dtype=np.int64)
        threshold, value = np.array(d["threshold"], float), np.array(d["value"], float)
        roots = np.array(d["roots"], dtype=np.int64)
        n = len(feature)
        if not (len(left) == len(right) == len(threshold) == len(value) == n) or n == 0:
            raise ValueError("the arrays of an ensemble differ in length")
        inner = feature >= 0
        if np.any((left[inner] <= np.flatnonzero(inner)) | (right[inner] <= np.flatnonzero(inner))
                  | (left[inner] >= n) | (right[inner] >= n)) or np.any((roots < 0) | (roots >= n)):
            raise ValueError("an ensemble's node points outside its trees")
        return cls(feature, threshold, left, right, value, roots, float(d["baseline"]), _depth(feature, left, right,
                                                                                                roots))

    @classmethod
    def of_sklearn(cls, model, check: np.ndarray | None = None) -> Ensemble:
        """The trees of a fitted ``HistGradientBoostingRegressor`` (numerical features, no missing
        values: commanded joints are neither).  They are read from scikit-learn's private layout
        (``_predictors``, each tree's ``nodes`` record array, ``_baseline_prediction``): a release
        that changes it fails here, loudly (:func:`sklearn_layout`), and ``check`` (joints, (m, n))
        compares the ensemble's predictions with the model's own, so that a changed meaning of a
        field cannot pass as a wrong correction."""
        sklearn_layout(model)
        parts, offset = [], 0
        for (predictor,) in model._predictors:
            nodes = predictor.nodes
            leaf = nodes["is_leaf"].astype(bool)
            parts.append((np.where(leaf, -1, nodes["feature_idx"]).astype(np.int64),
                          nodes["num_threshold"].astype(float),
                          # int64 first: the records' uint32 children took a leaf's −1 as 2³² − 1
                          np.where(leaf, -1, nodes["left"].astype(np.int64) + offset),
                          np.where(leaf, -1, nodes["right"].astype(np.int64) + offset),
                          np.where(leaf, nodes["value"], 0.0).astype(float), offset))
            offset += len(nodes)
        feature, threshold, left, right, value = (np.concatenate([p[k] for p in parts]) for k in range(5))
        roots = np.array([p[5] for p in parts], dtype=np.int64)
        ensemble = cls(feature, threshold, left, right, value, roots, float(np.ravel(model._baseline_prediction)[0]),
                       _depth(feature, left, right, roots))
        if check is not None:
            # numpy's walk: this runs in the ladder's forked workers, which need not load numba for it
            ours = ensemble.predict(np.asarray(check, float), backend="numpy")
            theirs = model.predict(np.asarray(check, float))
            gap = float(np.max(np.abs(ours - theirs))) if len(ours) else 0.0
            if not gap <= 1e-9 * (1.0 + float(np.max(np.abs(theirs), initial=0.0))):
                raise RuntimeError(f"scikit-learn {_sklearn_version()}'s fitted trees read back differently "
                                   f"(predictions {gap:.3g} apart): robocal supports scikit-learn {SKLEARN_TESTED}")
        return ensemble


#: the scikit-learn releases whose tree layout robocal reads (pyproject.toml bounds the install)
SKLEARN_TESTED = ">=1.4.2, <1.10"
#: what robocal reads of each tree's node records
NODE_FIELDS = ("is_leaf", "feature_idx", "num_threshold", "left", "right", "value")


def _sklearn_version() -> str:
    import sklearn

    return sklearn.__version__


def sklearn_layout(model) -> None:
    """Fail loudly unless a fitted ``HistGradientBoostingRegressor`` has the private layout robocal
    reads: a list of one-predictor tuples, node records with :data:`NODE_FIELDS`, a baseline."""
    try:
        predictors = model._predictors
        baseline = np.ravel(model._baseline_prediction)
        ok = isinstance(predictors, list) and baseline.size == 1 and all(
            isinstance(p, (list, tuple)) and len(p) == 1 and set(NODE_FIELDS) <= set(p[0].nodes.dtype.names or ())
            for p in predictors)
    except AttributeError:
        ok = False
    if not ok:
        raise RuntimeError(f"scikit-learn {_sklearn_version()} lays out its fitted trees otherwise than robocal "
                           f"reads them: robocal supports scikit-learn {SKLEARN_TESTED}")


#: the walks a tree correction keeps (:meth:`TreeResidual.raw`), and the most poses one may have
RECALLED, RECALLED_POSES = 4, 20_000

#: pose-tree walks worth one chain evaluation of :data:`robocal.backend.PARALLEL_MIN_WORK` (a walk
#: down a 200-tree ensemble's tree takes about a third of a 6-joint chain's evaluation)
WALKS_PER_EVALUATION = 3


def _compiled_walk(feature, threshold, left, right, roots, value, X) -> np.ndarray:
    """Each tree's leaf value (m, trees) at X (m, n) by numba's walk, on the cores idle now where
    the call is long enough to pay for a second thread (a correction is applied after a pool's
    workers end, which the 1-minute load still counts as busy)."""
    from ..backend import run_kernel
    from .kernels import tree_walk, tree_walk_parallel

    return run_kernel(tree_walk, tree_walk_parallel, len(X) * len(roots) // WALKS_PER_EVALUATION,
                      feature, threshold, left, right, roots, value, X, now=True)


def _tree_of_nodes(roots: np.ndarray, n: int) -> np.ndarray | None:
    """Each of the n nodes' tree, where the nodes run tree by tree from the first root (as
    :meth:`Ensemble.of_sklearn` lays them out), else None."""
    if len(roots) == 0 or roots[0] != 0 or np.any(np.diff(roots) <= 0):
        return None
    return np.searchsorted(roots, np.arange(n), side="right") - 1


def _tree_depths(feature, left, right, roots) -> np.ndarray:
    """Each tree's number of levels (its longest root-to-leaf path); where the nodes are not laid
    out tree by tree, each tree as deep as the deepest."""
    level = np.zeros(len(feature), dtype=np.int64)
    for i in np.flatnonzero(feature >= 0):  # parents come first, so one pass settles every level
        level[left[i]] = level[right[i]] = level[i] + 1
    tree = _tree_of_nodes(roots, len(feature))
    if tree is None:
        return np.full(len(roots), int(level.max()) + 1 if len(level) else 1)
    out = np.zeros(len(roots), dtype=np.int64)
    np.maximum.at(out, tree, level + 1)
    return out


def _depth(feature, left, right, roots) -> int:
    """The longest root-to-leaf path of the trees (children always follow their parent)."""
    return int(_tree_depths(feature, left, right, roots).max()) if len(roots) else 1


@dataclass(frozen=True, eq=False)
class TreeResidual:
    """The tree correction: ensembles (3 outputs mm, or 6 with orientations rad); X (N, n)
    training joints rad, scale (n,) the weight of each joint in the support's metric (rad⁻¹:
    share of splits / spread); reach: the distance within which the correction is whole;
    inside and prior: the trace of the position correction's error covariance (mm²) within its
    data and where it has none; axes (3, 3) as :class:`~robocal.model.residual.ResidualModel`'s.
    dof: degrees of freedom taken from the data; importance (outputs, n): each joint's share of
    each output's split gain; taken (outputs,): the rms of each output's correction over the
    training poses (mm; rad); hyper: the settings chosen by the inner cross-validation."""

    ensembles: tuple[Ensemble, ...]
    X: np.ndarray
    scale: np.ndarray
    reach: float
    inside: float
    prior: float
    axes: np.ndarray = field(default_factory=lambda: np.eye(3))
    dof: float = float("nan")
    importance: np.ndarray | None = None
    taken: np.ndarray | None = None
    hyper: dict = field(default_factory=dict)

    kind = "trees"

    def __getstate__(self) -> dict:  # the walks kept (see _recalled) stay in this process
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_")}

    @property
    def outputs(self) -> int:
        return len(self.ensembles)

    @property
    def n_joints(self) -> int:
        return int(self.X.shape[1])

    def with_inside(self, inside: float) -> TreeResidual:
        return replace(self, inside=float(inside))

    def distance(self, q: np.ndarray) -> np.ndarray:
        """The distance (m,) from each pose to its nearest training pose in the trees' metric,
        √Σ_j (scale_j Δq_j)², and beyond each joint's range over the training poses (less the
        fringe :data:`~robocal.model.region.TRUST_RAD`) in units of the joint's spread there: a
        joint the trees never split on found nothing to split on within its range, which says
        nothing beyond it (a joint that never moved, moved, leaves the data at once)."""
        from .region import TRUST_RAD

        q = np.atleast_2d(np.asarray(q, float))
        beyond = np.maximum(np.maximum(self.X.min(axis=0) - q, q - self.X.max(axis=0)) - TRUST_RAD, 0.0)
        beyond = beyond / np.maximum(self.X.std(axis=0), 1e-6)
        return np.sqrt(nearest(q, self.X, self.scale) ** 2 + np.sum(beyond ** 2, axis=1))

    def weight(self, q: np.ndarray) -> np.ndarray:
        """The share (m,) of the correction kept at each pose (:func:`fade` of its distance)."""
        return fade(self.distance(q), self.reach)

    def raw(self, q: np.ndarray, positions: bool = False) -> np.ndarray:
        """The trees' own prediction (m, outputs), unfaded (``positions``: the orientations' columns 0)."""
        q = np.atleast_2d(np.asarray(q, float))
        k = 3 if positions and self.outputs > 3 else self.outputs
        out = np.zeros((len(q), self.outputs))
        out[:, :k] = self._recalled(q, k)
        return out

    def _recalled(self, q: np.ndarray, k: int) -> np.ndarray:
        """The first k ensembles' predictions (m, k) at q: walked, or the walk of the same joints
        (equal to the bit) kept from one of the last :data:`RECALLED` calls.  A calibration applies
        its correction to the same poses several times (its figures, its validation, its report)."""
        recent = self.__dict__.setdefault("_recent", [])
        for i, (joints, predictions) in enumerate(recent):
            if predictions.shape[1] >= k and joints.shape == q.shape and np.array_equal(joints, q):
                recent.insert(0, recent.pop(i))
                return predictions[:, :k]
        predictions = np.stack(self._predictions(self.ensembles[:k], q), axis=1)
        if len(q) <= RECALLED_POSES:
            recent.insert(0, (q.copy(), predictions))
            del recent[RECALLED:]
        return predictions

    def _predictions(self, ensembles: tuple[Ensemble, ...], q: np.ndarray) -> list[np.ndarray]:
        """Each ensemble's prediction (m,) at q: with numba's kernels, all their trees walked in one
        call (on the idle cores, where it is long enough to pay), each ensemble's columns then summed
        as :meth:`Ensemble.predict` sums its own."""
        from .compiled import resolve

        if len(ensembles) < 2 or resolve("auto") != "numba":
            return [e.predict(q) for e in ensembles]
        key = f"_stacked{len(ensembles)}"
        if self.__dict__.get(key) is None:  # the ensembles' nodes end to end, each tree's indices shifted
            offsets = np.cumsum([0] + [len(e.feature) for e in ensembles[:-1]])
            shifted = [(np.where(e.feature < 0, -1, e.left + o), np.where(e.feature < 0, -1, e.right + o))
                       for e, o in zip(ensembles, offsets)]
            self.__dict__[key] = (np.concatenate([e.feature for e in ensembles]),
                                  np.concatenate([e.threshold for e in ensembles]),
                                  np.concatenate([lr[0] for lr in shifted]), np.concatenate([lr[1] for lr in shifted]),
                                  np.concatenate([e.roots + o for e, o in zip(ensembles, offsets)]),
                                  np.concatenate([e.value for e in ensembles]),
                                  np.cumsum([0] + [e.n_trees for e in ensembles]))
        *arrays, bounds = self.__dict__[key]
        walked = _compiled_walk(*arrays, np.ascontiguousarray(q, float))
        # a copy per ensemble: its columns summed in the order and layout of its own walk's
        return [np.ascontiguousarray(walked[:, a:b]).sum(axis=1) + e.baseline
                for e, a, b in zip(ensembles, bounds[:-1], bounds[1:])]

    def predict(self, q: np.ndarray, positions: bool = False) -> np.ndarray:
        """δ (m, 3 or 6) at commanded joints q (m, n) rad, faded outside the data (``positions``:
        the orientations' trees not walked, their columns 0)."""
        q = np.atleast_2d(np.asarray(q, float))
        return self.weight(q)[:, None] * self.raw(q, positions)

    def position_bound(self) -> float:
        """The largest |δp| (mm) the correction adds anywhere (it fades, never grows)."""
        return float(np.sqrt(sum(e.bound() ** 2 for e in self.ensembles[:3])))

    def position_variance(self, q: np.ndarray) -> np.ndarray:
        """The trace (m,) mm² of the position correction's error covariance at q: ``inside``
        where the correction is whole, ``prior`` where it has faded, in proportion between."""
        w = self.weight(q)
        return w * self.inside + (1.0 - w) * self.prior

    def correct(self, q: np.ndarray, R: np.ndarray, p: np.ndarray, base_rotation: np.ndarray,
                rotations: bool = True):
        """The pose (R (m, 3, 3), p (m, 3) mm, measuring frame) with the correction at q added
        (``rotations`` False: p alone)."""
        return apply_correction(self, q, R, p, base_rotation, rotations)

    def summary(self) -> dict:
        names = ["x", "y", "z", "rx", "ry", "rz"][: self.outputs]
        out = {"kind": "gradient-boosted trees on the joint angles", "points": int(len(self.X)),
               "outputs": "position" if self.outputs == 3 else "position and orientation",
               "trees_per_output": [e.n_trees for e in self.ensembles], "reach": self.reach,
               "sigma_inside_mm": float(np.sqrt(self.inside)), "sigma_outside_mm": float(np.sqrt(self.prior)),
               **({"effective_dof": self.dof} if np.isfinite(self.dof) else {}), **({"settings": self.hyper}
                                                                                   if self.hyper else {})}
        if self.taken is not None:
            out["taken_rms"] = {n: float(v) for n, v in zip(names, self.taken)}
        if self.importance is not None:
            out["joint_importance"] = {n: [float(v) for v in row] for n, row in zip(names, self.importance)}
        return out

    def to_dict(self) -> dict:
        return {"kind": "gradient-boosted trees on the joint angles (rad)", "X": self.X.tolist(),
                "scale_per_rad": self.scale.tolist(), "reach": self.reach, "inside_mm2": self.inside,
                "prior_mm2": self.prior, "axes_in_base": self.axes.tolist(),
                **({"dof": self.dof} if np.isfinite(self.dof) else {}),
                **({"importance": self.importance.tolist()} if self.importance is not None else {}),
                **({"taken": self.taken.tolist()} if self.taken is not None else {}),
                "settings": self.hyper, "ensembles": [e.to_dict() for e in self.ensembles]}

    @classmethod
    def from_dict(cls, d: dict) -> TreeResidual:
        X = np.array(d["X"], float)
        scale = np.array(d["scale_per_rad"], float)
        axes = np.array(d.get("axes_in_base", np.eye(3)), float)
        ensembles = tuple(Ensemble.from_dict(e) for e in d["ensembles"])
        if X.ndim != 2 or scale.shape != (X.shape[1],) or axes.shape != (3, 3) or len(ensembles) not in (3, 6):
            raise ValueError("the shapes of X, scale_per_rad, axes_in_base or the number of ensembles do not agree")
        if any(int(e.feature.max()) >= X.shape[1] for e in ensembles):
            raise ValueError("a tree splits on a joint the model does not have")
        importance = np.array(d["importance"], float) if "importance" in d else None
        taken = np.array(d["taken"], float) if "taken" in d else None
        values = [float(d["reach"]), float(d["inside_mm2"]), float(d["prior_mm2"])]
        if not all(np.isfinite(values)) or min(values) < 0:
            raise ValueError("reach, inside_mm2 and prior_mm2 must be finite and not negative")
        return cls(ensembles, X, scale, *values, axes, float(d.get("dof", float("nan"))), importance, taken,
                   dict(d.get("settings", {})))
