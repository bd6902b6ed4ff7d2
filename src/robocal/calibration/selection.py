"""Choosing the model: geometry alone, or with joint terms and a residual correction.

``--model auto`` selects forward and judges every candidate by K-fold cross-validation on the
calibration data (K = 5, folds by ``pose_id``, so the reflectors of one pose stay together):

1. geometric;
2. each joint term of :data:`robocal.model.terms.TERMS` added alone (harmonics, compliance,
   backlash: the cheaper first); the best is kept if it beats geometry;
3. each remaining term added to the one kept, and so on until no addition wins;
4. + residual (a Gaussian process) and + trees (gradient-boosted trees,
   :mod:`robocal.calibration.trees`) on the parametric model chosen, and on geometry alone;
   and, where the trees predict better than the process and both better than their parametric
   model, the trees with a process on what they leave (``trees+residual``).

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

from dataclasses import dataclass, field, replace

import numpy as np

from ..backend import SERIAL, worker_pool
from ..exceptions import InputError
from ..model.corrections import Correction, Stacked
from ..model.measurements import Measurements
from ..model.metrics import Metrics, pose_errors
from ..model.robot import Robot
from ..model.terms import TERMS
from ..model.trees import TreeResidual
from .config import LEARNED, CalibrationConfig
from .methods import fit_lm
from .residual import HYPER_POINTS, MAX_POINTS, fit_residual, tune_kernels
from .result import BudgetRow, LadderRow
from .statistics import group_folds
from .steps import Fit, Inputs, fit_parametric, term_spec
from .timing import stage, staged
from .trees import Settings, TreeCandidate, choose_settings, fit_trees

#: the joint terms in the order ``auto`` tries them (each term's ``rung``: the cheaper first)
TRIAL_ORDER: tuple[str, ...] = tuple(sorted(TERMS, key=lambda t: TERMS[t].rung))


def with_term(terms: tuple[str, ...], term: str) -> tuple[str, ...]:
    """``terms`` and ``term``, in registry order (the order of their parameters)."""
    return tuple(t for t in TERMS if t in terms or t == term)
K_FOLDS = 5
#: relative difference of cross-validated RMS within which the simpler model is kept
TIE = 0.01
#: residual evaluations a fold's LM refit may take where its Gauss–Newton step is not enough.
#: Along a weakly determined valley LM crawls: UR10 series C, 400 position-only poses with base
#: and tool, the held-out RMS is 0.47911 mm after 10 evaluations, 0.47913 after 30, 0.48049
#: after 2000 (7.6 s of folds against 0.27 s)
FOLD_EVALUATIONS = 30
#: residual evaluations LM may take to polish a swarm's answer into the optimum its structure's
#: folds start from
POLISH_EVALUATIONS = 100
#: L-BFGS-B iterations with which each fold re-tunes the residual kernel on its own training poses
FOLD_TUNING = 5
#: a simpler model is kept unless the paired test says it predicts held-out poses worse at this level
SIGNIFICANCE = 0.01
#: fewest poses a residual process is learnt from: with fewer, it can only memorise them
MIN_RESIDUAL_POSES = 30
#: share of the data's values a model may spend on its unknowns (parameters, the residual
#: process's effective degrees of freedom) before its calibration figures are called fitted
MAX_DOF_SHARE = 0.5


def model_name(terms) -> str:
    terms = [t for t in (*TERMS, *LEARNED) if t in terms]
    return "+".join(terms) if terms else "geometric"


def learned_of(name: str) -> str:
    """The learned part of a model's name (``trees``, ``residual``, ``trees+residual``; '' for none)."""
    return "+".join(t for t in LEARNED if t in name.split("+"))


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


def pose_groups(meas: Measurements) -> np.ndarray:
    """Group index per row: the rows of one pose_id (its reflectors) form one group; rows that
    touched unknown points or planes, their setup (a held-out setup's points are new unknowns:
    the honest test), or without setups their point or plane."""
    labels = np.array(meas.pose_ids if meas.pose_ids is not None else [str(r) for r in meas.rows], dtype=object)
    c = meas.constraints
    if c is not None:
        g = np.maximum(c.group, 0)
        key = np.array([f"\x1f{c.setup[k]}" if c.setup[k] else f"\x1f{c.kind[k]} {c.label[k]}" for k in g],
                       dtype=object)
        labels = np.where(c.rows, key, labels)
    return np.unique(labels.astype(str), return_inverse=True)[1]


def folds(meas: Measurements, k: int, seed: int | None) -> list[np.ndarray]:
    """K folds of pose indices; poses sharing a pose_id (several reflectors) stay together."""
    return group_folds(pose_groups(meas), k, seed)


@dataclass
class CrossValidation:
    """Held-out position errors (m, 3) mm, the fold index sets, each fold's estimate, and the
    held-out orientation errors (m, 3) rad of full-pose data."""

    errors: np.ndarray
    folds: list[np.ndarray]
    estimates: list[np.ndarray]
    orientation: np.ndarray | None = None

    @property
    def rms(self) -> float:
        return rms(self.errors)

    def metrics(self, errors: np.ndarray | None = None) -> Metrics:
        """The held-out figures (``errors``: the position errors after a residual correction)."""
        return Metrics.from_errors(self.errors if errors is None else errors, self.orientation)


def _pose_rows(problem, index: np.ndarray) -> np.ndarray:
    """The residual rows of poses ``index``: their positions, orientations for full-pose data,
    and the stated distances between points they touched."""
    m = problem.meas.n_poses
    rows = (3 * index[:, None] + np.arange(3)).ravel()
    if problem.n_orientation_rows():
        rows = np.concatenate([rows, 3 * m + rows])
    if problem.n_distances:
        c = problem.constraints
        held = set(c.group[index][c.group[index] >= 0].tolist())
        first = problem.n_residuals - problem.n_distances
        rows = np.concatenate([rows, [first + d for d, (a, b, _) in enumerate(c.distances) if a in held or b in held]])
    return rows.astype(int)


@staged("model")
def cross_validate(fit: Fit, config: CalibrationConfig, start: np.ndarray | None = None) -> CrossValidation:
    """Refit the fitted model on K−1 folds and predict the K-th.

    Each fold's refit starts from the full-data estimate and takes the Gauss–Newton step of its
    training poses, from the full-data Jacobian less the held-out rows (a k×k solve); where the
    problem is linear there (the χ² the step reaches misses the χ² it predicts by less than
    :data:`~robocal.calibration.noise.LINEAR_CHI2`), that step is the refit LM would converge to,
    else LM continues from it, for at most :data:`FOLD_EVALUATIONS` evaluations.  Either way the
    estimate is the training poses' own optimum, or (from a swarm's answer along a weakly
    determined valley) as near it as changes the prediction.
    """
    from .noise import LINEAR_CHI2

    problem = fit.estimate.problem
    x0 = fit.estimate.x if start is None else start
    meas = problem.meas
    plain = CalibrationConfig.build(config, loss="linear")
    errors = np.zeros((meas.n_poses, 3))
    orientation = np.zeros((meas.n_poses, 3)) if problem.uses_orientation else None
    index_sets = folds(meas, K_FOLDS, config.seed)
    J, r = problem.residual_jacobian(x0), problem.residuals(x0)
    # the training poses' normal equations are the whole data's less the fold's: one pass over
    # the tall Jacobian instead of a copy and a factorisation per fold; its columns equilibrated
    # so that mm and rad compare and the k×k system keeps its digits
    scale = 1.0 / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
    Js = J * scale
    A, b, rr = Js.T @ Js, Js.T @ r, float(r @ r)
    estimates = []
    for test in index_sets:
        rows = _pose_rows(problem, test)
        Jf, rf = Js[rows], r[rows]
        At, bt, rrt = A - Jf.T @ Jf, b - Jf.T @ rf, rr - float(rf @ rf)
        y = np.linalg.lstsq(At, -bt, rcond=None)[0]
        x = x0 + y * scale
        predicted = rrt + 2.0 * float(y @ bt) + float(y @ At @ y)
        keep = np.ones(len(r), bool)
        keep[rows] = False
        reached = problem.residuals(x)[keep]
        if not abs(float(reached @ reached) - predicted) <= LINEAR_CHI2:
            train = np.setdiff1d(np.arange(meas.n_poses), test)
            x = fit_lm(problem.setup.with_measurements(meas.subset(train)).problem(problem.names), x, plain,
                       max_nfev=FOLD_EVALUATIONS, timed_as="model").x
        dp, dr = problem.setup.with_measurements(meas.subset(test)).problem(problem.names).errors(x)
        errors[test] = dp
        if orientation is not None and dr is not None:
            orientation[test] = dr
        estimates.append(x)
    return CrossValidation(errors, index_sets, estimates, orientation)


def predict(fit: Fit, config: CalibrationConfig) -> tuple[CrossValidation, Metrics]:
    """The held-out folds of a fitted model, and the figures they predict for new poses.

    LM's estimate is the data's optimum and its folds refit from it.  A swarm's answer is not:
    its folds would refit towards LM's optimum and predict LM's model, better than the one
    returned.  So its structure is cross-validated from LM's optimum (polished from the swarm's
    answer), whose folds give the structure's optimism (held-out minus in-sample mean square),
    and that optimism is added to the swarm's own in-sample misfit: the held-out errors scaled
    to √(own² + optimism)."""
    if config.least_squares:
        cv = cross_validate(fit, config)
        return cv, cv.metrics()
    problem = fit.estimate.problem
    plain = CalibrationConfig.build(config, loss="linear")
    polished = fit_lm(problem, fit.estimate.x, plain, max_nfev=POLISH_EVALUATIONS, timed_as="model").x
    cv = cross_validate(fit, config, start=polished)
    optimism = cv.rms ** 2 - rms(problem.errors(polished)[0]) ** 2
    own = rms(problem.errors(fit.estimate.x)[0])
    factor = np.sqrt(own ** 2 + max(optimism, 0.0)) / max(cv.rms, 1e-300)
    return cv, cv.metrics(cv.errors * factor)


def residual_errors(fit: Fit, x: np.ndarray, index: np.ndarray | None = None) -> tuple[Measurements, np.ndarray]:
    """The poses (all, or ``index``) and what the parametric model with estimate x leaves there,
    (m, 3) mm or (m, 6) with orientations (rad), in the measuring frame."""
    problem = fit.estimate.problem
    meas = problem.meas if index is None else problem.meas.subset(index)
    dp, dr = problem.setup.with_measurements(meas).problem(problem.names).errors(x)
    return meas, dp if dr is None else np.concatenate([dp, dr], axis=1)


def _rung(piece) -> tuple[Fit, CrossValidation]:
    """A worker's piece of the ladder: one parametric model fitted (from its parent's fit) and
    cross-validated."""
    inputs, config, spec, parent = piece
    fit = fit_parametric(inputs, config, spec, None, parent)
    return fit, cross_validate(fit, config)


@dataclass
class FoldData:
    """What a learned correction is fitted to: the poses' commanded joints q (m, n) rad, what the
    parametric fit leaves there e (m, 3 or 6), and per outer fold (held-out indices, what the
    fold's own parametric refit leaves on its training poses (m_train, 3 or 6))."""

    q: np.ndarray
    e: np.ndarray
    folds: list[tuple[np.ndarray, np.ndarray]]
    groups: np.ndarray | None = None

    @classmethod
    def of(cls, fit: Fit, cv: CrossValidation) -> FoldData:
        meas, e = residual_errors(fit, fit.estimate.x)
        folds = []
        for test, x in zip(cv.folds, cv.estimates):
            train = np.setdiff1d(np.arange(len(cv.errors)), test)
            folds.append((test, residual_errors(fit, x, train)[1]))
        return cls(meas.q, e, folds, pose_groups(meas))

    def train(self, test: np.ndarray) -> np.ndarray:
        return np.setdiff1d(np.arange(len(self.q)), test)

    def process_folds(self, seed: int | None, kernels: tuple) -> list:
        """The pieces of a process's outer folds (:func:`_piece`): each fold's training joints and
        position errors, its held-out joints, and the kernels its tuning starts from."""
        return [("fold", (self.q[self.train(test)], e_train[:, :3], self.q[test], seed, kernels))
                for test, e_train in self.folds]


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


def rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))


def worse_p_value(simple: np.ndarray, best: np.ndarray, groups: np.ndarray) -> float:
    """One-sided p-value of "the simpler model predicts held-out poses worse than the best":
    a paired t-test on the per-pose difference of squared held-out errors (reflectors of one
    pose summed, since they share the pose's joint errors)."""
    from scipy.special import stdtr  # Student's t distribution function

    d = np.bincount(groups, np.sum(simple**2, axis=1) - np.sum(best**2, axis=1))
    if len(d) < 3 or not np.any(d):
        return 1.0
    spread = d.std(ddof=1)
    if spread == 0:
        return 0.0 if d.mean() > 0 else 1.0
    return float(stdtr(len(d) - 1, -d.mean() / (spread / np.sqrt(len(d)))))


@dataclass
class Candidate:
    """One rung of the ladder: its terms, its learned correction ('', ``residual``, ``trees``,
    ``trees+residual``), its parametric fit, its held-out errors, and what its correction's
    fit on all the poses starts from (the process's kernels, the trees)."""

    terms: tuple[str, ...]
    learned: str
    fit: Fit
    errors: np.ndarray
    kernels: tuple | None = None
    trees: TreeCandidate | None = None
    data: FoldData | None = None

    @property
    def residual(self) -> bool:
        return bool(self.learned)

    @property
    def name(self) -> str:
        return model_name(self.terms + tuple(self.learned.split("+")))

    @property
    def cv_rms(self) -> float:
        return rms(self.errors)


def choose(candidates: list[Candidate], groups: np.ndarray) -> Candidate:
    """The simplest candidate (the first, in ladder order) that predicts held-out poses as well
    as the best one: within :data:`TIE` of its RMS, or not worse by the paired test at
    :data:`SIGNIFICANCE`.  A richer model must earn its place beyond the luck of the folds, and
    never predicts the held-out poses worse than the first (geometry)."""
    simplest = candidates[0]
    eligible = [simplest] + [c for c in candidates[1:] if c.cv_rms < simplest.cv_rms]
    best = min(eligible, key=lambda c: c.cv_rms)
    for c in eligible:
        if c is best or c.cv_rms <= best.cv_rms * (1 + TIE) or \
                worse_p_value(c.errors, best.errors, groups) >= SIGNIFICANCE:
            return c
    return best


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


def spent_dof(fit: Fit, residual: Correction | None) -> list[str]:
    """A loud note when the model spends most of the data on its unknowns: its figures on the
    calibration poses are then fitted, not measured accuracy."""
    n_data = fit.estimate.problem.n_residuals
    dof = 0.0 if residual is None else float(np.nan_to_num(residual.dof))
    used = fit.n_params + dof
    if not used > MAX_DOF_SHARE * n_data:
        return []
    process = "" if residual is None else f" ({dof:.0f} of them the learned correction's)"
    return [f"the model spends {used:.0f} degrees of freedom{process} on {n_data} measured values: its figures on "
            "the calibration poses are fitted, not its accuracy; judge it on other poses (validation data) and "
            "measure more poses"]


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


def fit_model(inputs: Inputs, config: CalibrationConfig, progress=None, stages=None) -> Chosen:
    """The model the config asks for, or, for ``auto``, the one cross-validation chooses;
    ``stages`` (a callable, or None) hears what the ladder is at: (step, steps, what)."""
    meas = inputs.meas
    say = stages or (lambda step, steps, text: None)
    if config.model != "auto":
        terms = config.model_terms
        learned = "+".join(t for t in LEARNED if t in terms)
        if learned and meas.constraints is not None:
            raise InputError(f"a learned correction ({learned}) learns corrections of measured positions: rows that "
                             "touched points or planes measure none; calibrate the parametric model alone",
                             option="model")
        if learned and len(set(pose_groups(meas))) < MIN_RESIDUAL_POSES:
            raise InputError(f"a learned correction ({learned}) learns from the poses what the parametric model "
                             f"leaves: {len(set(pose_groups(meas)))} poses are too few (at least "
                             f"{MIN_RESIDUAL_POSES}); measure more, or calibrate the parametric model alone",
                             option="model")
        fit = fit_parametric(inputs, config, term_spec(terms, meas, config), progress)
        residual = None
        cv, prediction = predict(fit, config)  # how it predicts poses it has not seen, with or without validation
        parametric_prediction = prediction
        if learned:
            with worker_pool() as pool:
                data = FoldData.of(fit, cv)
                candidate = Candidate(tuple(sorted(terms - set(LEARNED))), learned, fit, cv.errors, data=data)
                if "residual" in learned:
                    candidate.errors, candidate.kernels = cross_validate_residuals([(data, cv)], config.seed, pool)[0]
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
        return Chosen(model_name(terms), fit, residual, notes=spent_dof(fit, residual), geometric=geometric,
                      prediction=prediction, geometric_prediction=geometric_prediction)
    groups = pose_groups(meas)
    # a learned correction corrects measured positions: rows that touched points or planes have none
    residuals = groups.max() + 1 >= MIN_RESIDUAL_POSES and meas.constraints is None
    ladder: list[tuple[Candidate, CrossValidation]] = []
    # at most: geometry, each term alone, then each further term on the one kept so far
    k = len(TRIAL_ORDER)
    steps = 1 + k * (k + 1) // 2 + (2 if residuals else 0)
    # what a stage tells the terminal is work done, in parametric fits: the learned candidates
    # (their tunings on up to 1000 poses and their folds) are about 12 of them on a thousand poses
    process = max(1.0, 12.0 * (min(len(set(groups)), HYPER_POINTS) / 1000) ** 2)
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
    rung_config = CalibrationConfig.build(config, backend="numpy")
    say(0, work, f"model 1/{steps}: geometric, fit and {K_FOLDS} folds")
    geometric = fit_parametric(inputs, config, term_spec((), meas, config), progress)
    geometric_cv = cross_validate(geometric, config)
    ladder.append((Candidate((), "", geometric, geometric_cv.errors), geometric_cv))
    parametric = ladder[0][0]
    with worker_pool() as pool:
        while True:
            trials = rungs([with_term(parametric.terms, t) for t in TRIAL_ORDER if t not in parametric.terms],
                           parametric, pool)
            kept = choose([parametric, *trials], groups) if trials else parametric
            if kept is parametric:
                break
            parametric = kept
        # the learned corrections on the chosen parametric model, and on geometry alone: they can
        # take structure that joint terms would have taken more coarsely
        candidates = [c for c, _ in ladder]
        on = [(c, cv) for c, cv in ladder if residuals and c.terms in dict.fromkeys((parametric.terms, ()))]
        if on:
            done = len(candidates)
            candidates += learned_candidates(on, meas, config.seed, pool,
                                             lambda text: say(done, done + process * len(on), f"learned: {text}"))
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
    notes = [f"model auto: {chosen.name} (cross-validated position RMS {chosen.cv_rms:.4g} mm; geometric "
             f"{candidates[0].cv_rms:.4g} mm; a richer model is kept only if it predicts held-out poses "
             f"better, paired test p < {SIGNIFICANCE:g})"]
    chosen_cv = next(cv for c, cv in ladder if c.fit is chosen.fit)
    return Chosen(chosen.name, chosen.fit, residual, rows, notes + spent_dof(chosen.fit, residual),
                  geometric=candidates[0].fit, prediction=chosen_cv.metrics(chosen.errors),
                  geometric_prediction=geometric_cv.metrics())


@staged("evaluate")
def guard(chosen: Chosen) -> Chosen:
    """The last check before a model is returned: it must fit the calibration poses at least as
    well as the geometric fit (a richer model that does not has failed to converge or was
    misled), and the geometric fit at least as well as the nominal joints with their fitted
    frames (a calibration that made things worse has failed).  The better one is kept, and
    the note says why."""
    fit = chosen.fit
    meas = fit.estimate.problem.meas
    sigma_p, sigma_r = fit.noise.position, fit.noise.orientation

    def rms_of(robot: Robot) -> float:
        """Position RMS (mm) when it is all the data say; with orientations, the RMS of the
        errors weighed as the fit weighs them, in mm of position."""
        dp, dr = pose_errors(robot, meas)
        total = np.sum(dp * dp)
        if dr is not None and sigma_r:
            total += np.sum(dr * dr) * (sigma_p / sigma_r) ** 2
        return float(np.sqrt(total / len(dp)))

    model = fit.robot.replace(residual=chosen.residual)
    rms = rms_of(model)
    geometric = chosen.geometric
    if geometric is not None and geometric is not fit:
        rms_geometric = rms_of(geometric.robot)
        if rms > rms_geometric * (1 + 1e-6) + 1e-9:
            note = (f"model {chosen.name} fits the calibration poses worse than geometry alone ({rms:.4g} vs "
                    f"{rms_geometric:.4g} mm{'' if meas.rotation is None else ' weighed'} RMS): the geometric fit is "
                    "returned")
            chosen = replace(chosen, name="geometric", fit=geometric, residual=None,
                             notes=chosen.notes + [note], prediction=chosen.geometric_prediction)
            fit, rms = geometric, rms_geometric
    rms_nominal = rms_of(fit.setup.space.robot)
    if rms > rms_nominal * (1 + 1e-6) + 1e-9:
        est = fit.estimate
        held = replace(fit, estimate=est.replace(x=np.zeros_like(est.x)),
                       uncertainty=None if fit.uncertainty is None else np.full_like(fit.uncertainty, np.nan),
                       covariance=None)
        note = (f"the calibration fits the poses worse than the nominal model with its fitted frames ({rms:.4g} vs "
                f"{rms_nominal:.4g} mm RMS; optimizer {est.optimization.status}): the nominal joint geometry is "
                "returned unchanged; check the data and the robot file")
        chosen = replace(chosen, name="geometric", fit=held, residual=None, notes=chosen.notes + [note],
                         prediction=None)
    return chosen

