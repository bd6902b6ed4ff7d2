"""Cross-validation of a parametric fit: folds by pose (or setup), each fold refitted from the
whole data's estimate, and the held-out errors that predict new poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.measurements import Measurements
from ...model.metrics import Metrics, pixel_scale
from ..config import CalibrationConfig
from ..fit.methods import fit_lm
from ..fit.parametric import Fit
from ..judge.statistics import group_folds
from ..timing import staged

K_FOLDS = 5
#: residual evaluations a fold's LM refit may take where its Gauss–Newton step is not enough.
#: Along a weakly determined valley LM crawls: UR10 series C, 400 position-only poses with base
#: and tool, the held-out RMS is 0.47911 mm after 10 evaluations, 0.47913 after 30, 0.48049
#: after 2000 (7.6 s of folds against 0.27 s)
FOLD_EVALUATIONS = 30
#: residual evaluations LM may take to polish a swarm's answer into the optimum its structure's
#: folds start from
POLISH_EVALUATIONS = 100


def pose_groups(meas: Measurements) -> np.ndarray:
    """Group index per row: the rows of one pose_id (its reflectors) form one group; rows that
    touched unknown points or planes, their setup (a held-out setup's points are new unknowns:
    the honest test), or without setups their point or plane; rows cameras saw at one pose (the
    same joints: every marker each camera saw there) without pose_ids, that pose."""
    labels = np.array(meas.pose_ids if meas.pose_ids is not None else [str(r) for r in meas.rows], dtype=object)
    if meas.views is not None and meas.pose_ids is None:
        same = np.unique(np.round(meas.q, 9), axis=0, return_inverse=True)[1].ravel()
        labels = np.where(meas.views.rows, np.array([f"\x1eq{k}" for k in same], dtype=object), labels)
    c = meas.constraints
    if c is not None:
        g = np.maximum(c.group, 0)
        key = np.array([f"\x1f{c.setup[k]}" if c.setup[k] else f"\x1f{c.kind[k]} {c.label[k]}" for k in g],
                       dtype=object)
        labels = np.where(c.rows, key, labels)
    return np.unique(labels.astype(str), return_inverse=True)[1]


@dataclass(frozen=True)
class Scheme:
    """Which rows a cross-validation holds out together, and how many folds: whole sessions
    (``sessions``, one fold each: a calibration is used in sessions after the one that measured
    it), whole setups of rows that touched points or planes (``setups``: their points are new
    unknowns), contiguous blocks of the measuring order (``blocks``: camera rows without
    sessions, whose neighbouring poses share a mounting and a drift that a random fold would
    count as new), or poses drawn at random (``poses``)."""

    kind: str
    k: int
    #: a held-out session's frames were registered on its own rows (sessions with frames of their own)
    registered: bool = False

    @property
    def new(self) -> str:
        """What a held-out figure predicts: "a new session", "new poses", "new setups"."""
        return {"sessions": "a new session", "setups": "new setups"}.get(self.kind, "new poses")

    @property
    def short(self) -> str:
        """The scheme in a column title: "leave-one-session-out", "5-fold CV"."""
        return {"sessions": "leave-one-session-out", "blocks": f"{self.k} blocks in order"}.get(
            self.kind, f"{self.k}-fold CV")

    @property
    def phrase(self) -> str:
        """The scheme in a sentence: "leave-one-session-out, 10 sessions"."""
        return {"sessions": f"leave-one-session-out, {self.k} sessions"
                            + (", each with its frames registered on its own rows" if self.registered else ""),
                "setups": f"{self.k}-fold cross-validation by setup: their points are new unknowns",
                "blocks": f"{self.k}-fold cross-validation by blocks of the rows' order",
                "poses": f"{self.k}-fold cross-validation of the calibration poses"}[self.kind]

    @property
    def held_out(self) -> str:
        """What a held-out figure predicts, and how: "a new session (leave-one-session-out, 10 sessions)"."""
        return f"{self.new} ({self.phrase})"

    def to_dict(self) -> dict:
        return {"kind": self.kind, "folds": self.k, "predicts": self.new, "description": self.phrase,
                **({"frames_registered": True} if self.registered else {})}


def scheme(meas: Measurements) -> Scheme:
    """How ``meas`` is cross-validated (:class:`Scheme`)."""
    if len(meas.sessions) >= 2:
        return Scheme("sessions", len(meas.sessions))
    groups = pose_groups(meas)
    k = max(2, min(K_FOLDS, int(groups.max()) + 1))
    c = meas.constraints
    if c is not None and any(c.setup):
        return Scheme("setups", k)
    if meas.unit == "px":
        return Scheme("blocks", k)
    return Scheme("poses", k)


#: a held-out session missed by more than this many times the fit's own RMS: the sessions disagree
SESSIONS_DISAGREE = 1.5


def sessions_disagree(meas: Measurements, held: np.ndarray, fitted: np.ndarray) -> str | None:
    """A warning where whole sessions held out are predicted far worse than the fit leaves its rows
    (:data:`SESSIONS_DISAGREE`): something the model shares between sessions moved between them (the
    instrument, a camera, the markers), naming the sessions missed most; None otherwise.  held,
    fitted: each row's held-out and in-sample errors (m, 3)."""
    if len(meas.sessions) < 2:
        return None
    index = np.unique(np.asarray(meas.session, dtype=str), return_inverse=True)[1].ravel()
    rows = meas.length_rows if meas.unit == "mm" and meas.camera is not None else np.ones(meas.n_poses, bool)
    out, inside = rms(held[rows]), rms(fitted[rows])
    if not out > SESSIONS_DISAGREE * inside:
        return None
    labels = np.unique(np.asarray(meas.session, dtype=str))
    per = sorted(((rms(held[rows & (index == g)]), labels[g]) for g in np.unique(index[rows])), reverse=True)
    worst = ", ".join(f"{label} {value:.4g}" for value, label in per[:3])
    unit = meas.unit
    return (f"the sessions disagree: a session held out is missed by {out:.4g} {unit} RMS where the fit leaves "
            f"{inside:.4g} {unit} (worst: {worst} {unit}): something the model takes as one for every session "
            "moved between them (the instrument, a camera, the markers); calibrate the sessions apart, or "
            "re-register the frames of each")


#: fewest sessions a paired test pairs by session (with two, a t-test has one degree of freedom)
MIN_PAIRED_SESSIONS = 3


def held_groups(meas: Measurements) -> np.ndarray:
    """The units a paired test of held-out errors pairs: sessions where the rows hold enough of them
    (:data:`MIN_PAIRED_SESSIONS`; the poses of one session share its mounting: they are not independent
    looks), else poses (each held out with its session)."""
    if len(meas.sessions) >= MIN_PAIRED_SESSIONS:
        return np.unique(np.asarray(meas.session, dtype=str), return_inverse=True)[1].ravel()
    return pose_groups(meas)


def folds(meas: Measurements, k: int, seed: int | None) -> list[np.ndarray]:
    """The folds of pose indices of :func:`scheme` (``k`` where poses are drawn): a session each,
    contiguous blocks of poses, or groups drawn with the seed; poses sharing a pose_id (several
    reflectors), or a camera's rows at one pose, stay together."""
    how = scheme(meas)
    if how.kind == "sessions":
        index = np.unique(np.asarray(meas.session, dtype=str), return_inverse=True)[1].ravel()
        first = np.unique(index, return_index=True)[1]
        return [np.flatnonzero(index == g) for g in index[np.sort(first)]]
    groups = pose_groups(meas)
    if how.kind == "blocks":
        first = np.unique(groups, return_index=True)[1]  # each pose's first row: the measuring order
        rank = np.empty(len(first), int)
        rank[np.argsort(first)] = np.arange(len(first))
        block = (rank * how.k) // len(first)
        return [np.flatnonzero(block[groups] == b) for b in range(how.k)]
    return group_folds(groups, k, seed)


@dataclass
class CrossValidation:
    """Held-out position errors (m, 3) mm, the fold index sets, each fold's estimate, and the
    held-out orientation errors (m, 3) rad of full-pose data."""

    errors: np.ndarray
    folds: list[np.ndarray]
    estimates: list[np.ndarray]
    orientation: np.ndarray | None = None
    unit: str = "mm"  # px where every row is a camera's
    #: the rows the figures are of: every row, or those in mm where camera rows stand beside them
    keep: np.ndarray | None = None
    scheme: Scheme | None = None
    #: camera rows: each row's mm per px at its marker with the whole data's model (None for others)
    mm_per_px: np.ndarray | None = None

    @property
    def rms(self) -> float:
        return rms(self.errors if self.keep is None else self.errors[self.keep])

    def metrics(self, errors: np.ndarray | None = None) -> Metrics:
        """The held-out figures (``errors``: the position errors after a residual correction)."""
        errors = self.errors if errors is None else errors
        orientation = self.orientation
        if self.keep is not None:
            errors, orientation = errors[self.keep], None if orientation is None else orientation[self.keep]
        return Metrics.from_errors(errors, orientation, self.unit, self.mm_per_px)


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
    :data:`~robocal.calibration.fit.noise.LINEAR_CHI2`), that step is the refit LM would converge to;
    else a second step from the training poses' own Jacobian, taken where it is linear, else LM
    continues from it, for at most :data:`FOLD_EVALUATIONS` evaluations.  Either way the
    estimate is the training poses' own optimum, or (from a swarm's answer along a weakly
    determined valley) as near it as changes the prediction.
    """
    from ..fit.noise import LINEAR_CHI2

    problem = fit.estimate.problem
    x0 = fit.estimate.x if start is None else start
    meas = problem.meas
    plain = CalibrationConfig.build(config, loss="linear")
    errors = np.zeros((meas.n_poses, 3))
    orientation = np.zeros((meas.n_poses, 3)) if problem.uses_orientation else None
    index_sets = folds(meas, K_FOLDS, config.seed)
    # sessions with frames of their own: a held-out session is predicted as a new one is used, its frames
    # registered on its own rows with the geometry the others gave
    registered = bool(problem.space.sessions) and scheme(meas).kind == "sessions"
    # the data with the prior: a fold's training poses keep every prior pseudo-observation
    J, r = problem.map_jacobian(x0), problem.map_residuals(x0)
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
        reached = problem.map_residuals(x)[keep]
        if not abs(float(reached @ reached) - predicted) <= LINEAR_CHI2:
            # a second Gauss–Newton step, from the training poses' own Jacobian there: where the
            # first step's curvature was all that was missing (a session held out moves the optimum
            # further than a few poses do), it lands where LM would, for one Jacobian instead of five
            train = np.setdiff1d(np.arange(meas.n_poses), test)
            part = problem.setup.with_measurements(meas.subset(train)).problem(problem.names)
            Jt, rt = part.map_jacobian(x), part.map_residuals(x)
            step = np.linalg.lstsq(Jt, -rt, rcond=None)[0]
            again = part.map_residuals(x + step)
            if abs(float(again @ again) - float(np.sum((rt + Jt @ step) ** 2))) <= LINEAR_CHI2:
                x = x + step
            else:
                x = fit_lm(part, x, plain, max_nfev=FOLD_EVALUATIONS, timed_as="model").x
        held = problem.setup.with_measurements(meas.subset(test)).problem(problem.names)
        dp, dr = held.errors(x) if not registered else _registered(problem, meas.subset(test), x, plain)
        errors[test] = dp
        if orientation is not None and dr is not None:
            orientation[test] = dr
        estimates.append(x)
    mixed = meas.unit == "mm" and meas.camera is not None
    scale = pixel_scale(fit.robot, meas) if meas.unit == "px" else None
    how = scheme(meas)
    return CrossValidation(errors, index_sets, estimates, orientation, meas.unit, meas.length_rows if mixed else None,
                           Scheme(how.kind, how.k, registered), scale)


def session_frames_of(names: list[str], label: str, first: str) -> list[str]:
    """The parameters of ``names`` that are session ``label``'s own frames: the first session's base
    and tools (``base_…``, the targets' own names), a later one's ``base[LABEL]_…`` and ``tool[…@LABEL]_…``."""
    if label == first:
        return [n for n in names if n.startswith("base_") or (n.startswith("tool") and "@" not in n)]
    return [n for n in names if n.startswith(f"base[{label}]_") or (n.startswith("tool[") and f"@{label}]_" in n)]


def _registered(problem, held: Measurements, x: np.ndarray, config: CalibrationConfig):
    """The errors of a held-out session's rows with the fold's estimate x, its own frames registered on
    them first (LM on those frames alone, the rest as x has it)."""
    label = held.session[0]
    own = session_frames_of(problem.names, label, problem.meas.sessions[0])
    setup = problem.setup.around(problem.space.apply(problem.full(x)))
    part = setup.with_measurements(held).problem(own) if own else None
    if part is None:
        return setup.with_measurements(held).problem(problem.names).errors(np.zeros(problem.n_params))
    step = fit_lm(part, np.zeros(part.n_params), config, max_nfev=FOLD_EVALUATIONS, timed_as="model").x
    return part.errors(step)


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



def rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))


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

