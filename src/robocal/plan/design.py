"""Calibration pose planning: choose the joint sets worth measuring.

Measuring is the expensive part of a calibration, and which poses are measured decides
how well the parameters are determined.  From M candidate joint sets inside the joint
limits (and any work-cell ranges), N are chosen to maximise an observability criterion of
the identification Jacobian: greedily, one pose at a time, then improved by exchanges
(DETMAX / Fedorov: swap a chosen pose for a candidate while that helps).

The Jacobian rows are whitened by the stated measurement noise (σ mm for positions, σ_r
rad for orientations), so that ``M = Σ JᵀJ`` is the Fisher information and ``M⁻¹`` the
covariance of the identified parameters.  Criteria:

- ``D`` / ``O1``: log det M (O1 = det(M)^(1/2k)/√N is a monotone function of it for a
  fixed N, so both pick the same poses; D-optimal design).
- ``O2`` σmin/σmax, ``O3`` σmin, ``O4`` σmin²/σmax of the Jacobian with angle columns
  scaled by the arm's reach (as in the identifiability report).

The report predicts the standard uncertainty of every parameter and the RMS position
error on fresh poses, for the plan and for random sets of the same size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import options as opt
from ..calibration.judge.identifiability import analyse
from ..calibration.judge.statistics import covariance, standard_uncertainties
from ..exceptions import InputError
from ..model.candidates import FRAME_MODES, complete, frame_candidates, joint_candidates
from ..model.parameters import ParameterSpace, is_angle
from ..model.robot import Robot
from ..simulation import MEASURES, random_joints

CRITERIA = ("O1", "O2", "O3", "O4", "D")


@dataclass
class Plan:
    """A planned pose set and what it predicts.

    q: (N, n) rad.  value: the criterion of the plan.  predicted_std: standard uncertainty
    of each parameter (mm, rad) for the stated noise.  predicted_rms: expected RMS position
    error (mm) of the calibrated model on fresh poses from the noise alone (the parameters' spread);
    expected_rms adds the model error the user states.  random_*: the same figures for
    random N-pose sets from the same candidates.
    """

    q: np.ndarray
    criterion: str
    value: float
    names: list[str]
    predicted_std: np.ndarray
    predicted_rms: float
    random_values: list[float] = field(default_factory=list)
    random_rms: list[float] = field(default_factory=list)
    exchanges: int = 0
    dropped: dict[str, str] = field(default_factory=dict)
    #: σ per axis (mm) of what the model cannot take, given by the user
    model_error: float = 0.0

    @property
    def expected_rms(self) -> float:
        """The validation RMS to expect (mm): what the poses leave of the parameters, and the
        model error no pose choice removes (3 axes of it)."""
        return math.sqrt(self.predicted_rms**2 + 3.0 * self.model_error**2)

    def to_dict(self) -> dict:
        return {
            "criterion": self.criterion,
            "value": self.value,
            "predicted_rms_mm": self.predicted_rms,
            "model_error_mm": self.model_error,
            "expected_rms_mm": self.expected_rms,
            "random_median_value": float(np.median(self.random_values)) if self.random_values else None,
            "random_median_rms_mm": float(np.median(self.random_rms)) if self.random_rms else None,
            "parameters": [{"name": n, "predicted_std": float(s)} for n, s in zip(self.names, self.predicted_std)],
            "dropped": [{"name": n, "reason": r} for n, r in self.dropped.items()],
            "exchanges": self.exchanges,
        }


def _blocks(robot: Robot, q: np.ndarray, names: list[str], measure: str, noise: float, angle_noise: float):
    """Whitened Jacobian blocks (m, r, k) and the unwhitened position rows (m, 3, k)."""
    space = ParameterSpace.of(robot)
    if robot.tree is None:
        J, _, _ = space.jacobian(np.zeros(space.size), q)
    else:  # a tree's pose is measured on every chain: its block stacks each chain's rows
        chains = robot.tree.names
        labels = [c for _ in range(len(q)) for c in chains]
        J, _, _ = space.jacobian(np.zeros(space.size), np.repeat(q, len(chains), axis=0), space.target_index(labels),
                                 chain=robot.tree.index(labels))
        J = J.reshape(len(q), len(chains), 6, -1)
        J = np.concatenate([J[:, :, :3].reshape(len(q), -1, J.shape[-1]),
                            J[:, :, 3:].reshape(len(q), -1, J.shape[-1])], axis=1)
    J = J[:, :, space.index(names)]
    if robot.tree is not None:
        half = J.shape[1] // 2
        pos = J[:, :half]
        if measure == "position":
            return pos / noise, pos
        return np.concatenate([pos / noise, J[:, half:] / angle_noise], axis=1), pos
    pos = J[:, :3]
    if measure == "position":
        return pos / noise, pos
    return np.concatenate([pos / noise, J[:, 3:] / angle_noise], axis=1), pos


def _o_from_singular(s, name):
    smin, smax = s[..., -1], s[..., 0]
    if name == "O2":
        return smin / smax
    if name == "O3":
        return smin
    return smin**2 / smax


def _scores(M: np.ndarray, blocks: np.ndarray, name: str, scale: np.ndarray) -> np.ndarray:
    """Criterion of M + J_cᵀJ_c for every candidate c (higher is better)."""
    if name in ("D", "O1"):
        # log det(M + JᵀJ) − log det M = log det(I + J M⁻¹ Jᵀ) (matrix determinant lemma)
        S = blocks @ np.linalg.inv(M) @ np.swapaxes(blocks, 1, 2)
        S[:, range(S.shape[1]), range(S.shape[1])] += 1.0
        return np.linalg.slogdet(S)[1]
    Ms = (M + np.swapaxes(blocks, 1, 2) @ blocks) * np.outer(scale, scale)
    ev = np.clip(np.linalg.eigvalsh(Ms), 0.0, None)
    return _o_from_singular(np.sqrt(ev[:, ::-1]), name)


def criterion_value(M: np.ndarray, name: str, scale: np.ndarray, n_poses: int) -> float:
    """Criterion of an information matrix M = JᵀJ (whitened rows): D = log det M,
    O1 = (σ1⋯σk)^(1/k)/√N of J, and O2–O4 of J with columns multiplied by ``scale``."""
    if name in ("D", "O1"):
        sign, logdet = np.linalg.slogdet(M)
        if sign <= 0:
            return -math.inf
        return float(logdet) if name == "D" else float(math.exp(logdet / (2 * len(M))) / math.sqrt(n_poses))
    ev = np.clip(np.linalg.eigvalsh(M * np.outer(scale, scale)), 0.0, None)
    return float(_o_from_singular(np.sqrt(ev[::-1]), name))


def _predicted_rms(M: np.ndarray, val_pos: np.ndarray) -> float:
    var = np.einsum("mak,kl,mal->m", val_pos, covariance(information=M), val_pos)
    return float(np.sqrt(np.mean(np.maximum(var, 0.0))))


def _greedy(A: np.ndarray, blocks: np.ndarray, n_poses: int, name: str, scale: np.ndarray, ridge: np.ndarray):
    """One pose at a time, the candidate that raises the criterion most (D until there are
    enough equations for the others to be defined)."""
    k, rows = A.shape[-1], blocks.shape[1]
    chosen: list[int] = []
    M = ridge.copy()
    free = np.ones(len(A), bool)
    for _ in range(n_poses):
        s = _scores(M, blocks, name if len(chosen) * rows >= k else "D", scale)
        s[~free] = -np.inf
        c = int(np.argmax(s))
        chosen.append(c)
        free[c] = False
        M = M + A[c]
    return chosen, M, free


def _exchange(chosen, M, free, A, blocks, name, scale, ridge, max_passes: int) -> tuple[np.ndarray, int]:
    """Swap a chosen pose for the candidate that helps most, while any helps (in place)."""
    n_poses, exchanges = len(chosen), 0
    best = criterion_value(M, name, scale, n_poses)
    for _ in range(max_passes):
        improved = False
        for pos in range(n_poses):
            out = chosen[pos]
            M_out = M - A[out]
            s = _scores(M_out + ridge, blocks, name, scale)
            s[~free] = -np.inf
            c = int(np.argmax(s))
            value = criterion_value(M_out + A[c], name, scale, n_poses)
            if value > best * (1 + 1e-9) + 1e-12:
                chosen[pos] = c
                free[out], free[c] = True, False
                M, best = M_out + A[c], value
                exchanges += 1
                improved = True
        if not improved:
            break
    return M, exchanges


def _check(name, measure, frames, noise, angle_noise, n_poses, candidates) -> None:
    opt.choice(name, CRITERIA, "criterion", "criterion")
    opt.choice(measure, MEASURES, "measure", "measure")
    opt.choice(frames, FRAME_MODES, "frames", "frames mode")
    opt.number(noise, "noise", minimum=0.0, strict=True)
    opt.number(angle_noise, "angle_noise", minimum=0.0, strict=True)
    if n_poses < 1 or candidates < n_poses:
        raise InputError(f"need 1 ≤ poses ≤ candidates, got {n_poses} and {candidates}", option="poses")


def reachable_candidates(robot: Robot, n: int, rng: np.random.Generator, joint_range=None, workspace=None,
                         tracker=None, fov: float | None = None, attempts: int = 50) -> tuple[np.ndarray, int]:
    """n random joint sets whose tool lies in ``workspace`` ((3, 2) mm box, base frame) and faces
    ``tracker`` ((3,) mm, base frame): the angle between the tool's z axis and the line to the
    tracker at most ``fov``/2 (deg, the reflector's acceptance cone); and how many were drawn."""
    if workspace is None and tracker is None:
        return random_joints(robot, n, rng, joint_range), n
    kept, drawn = [], 0
    for _ in range(attempts):
        q = random_joints(robot, 4 * n, rng, joint_range)
        drawn += len(q)
        ok = np.ones(len(q), bool)
        for chain in (None,) if robot.tree is None else robot.tree.names:  # a tree's every tip must be seen
            T = robot.replace(base=np.eye(4)).fk(q, chains=None if chain is None else [chain] * len(q))
            if workspace is not None:
                w = np.asarray(workspace, float)
                ok &= np.all((T[:, :3, 3] >= w[:, 0]) & (T[:, :3, 3] <= w[:, 1]), axis=1)
            if tracker is not None:
                to_tracker = np.asarray(tracker, float) - T[:, :3, 3]
                to_tracker /= np.linalg.norm(to_tracker, axis=1, keepdims=True)
                cos = np.einsum("mi,mi->m", T[:, :3, 2], to_tracker)
                ok &= cos >= math.cos(math.radians((fov if fov is not None else 90.0) / 2))
        kept.append(q[ok])
        if sum(len(k) for k in kept) >= n:
            break
    q = np.concatenate(kept)[:n]
    if len(q) < n:
        raise InputError(f"only {len(q)} of {drawn} random joint sets put the tool in the workspace and in view of the "
                         f"tracker; {n} candidates needed: widen --workspace, --fov or the joint limits",
                         option="workspace")
    return q, drawn


def short_moves(q: np.ndarray) -> np.ndarray:
    """An order of the poses q (N, n) that keeps joint moves short: nearest neighbour by the
    largest joint move, from the pose nearest the middle of them all."""
    n = len(q)
    if n < 3:
        return np.arange(n)
    left = list(range(n))
    current = int(np.argmin(np.max(np.abs(q - np.median(q, axis=0)), axis=1)))
    order = [current]
    left.remove(current)
    while left:
        d = np.max(np.abs(q[left] - q[current]), axis=1)
        current = left[int(np.argmin(d))]
        order.append(current)
        left.remove(current)
    return np.array(order)


def plan_poses(robot: Robot, n_poses: int, *, candidates: int = 2000, criterion: str = "O1", measure: str = "pose",
               frames: str = "none", joint_range=None, noise: float = 0.02, angle_noise: float = math.radians(0.001),
               seed: int = 0, random_sets: int = 20, validation: int = 500, max_passes: int = 10, workspace=None,
               tracker=None, fov: float | None = None, model_error: float = 0.0) -> Plan:
    """Choose ``n_poses`` of ``candidates`` random joint sets (see the module docstring), in an
    order that keeps joint moves short.

    joint_range: (lo, hi) rad for all joints or (n, 2) per joint, intersected with the
    limits.  noise / angle_noise: measurement σ (mm, rad) used to whiten the Jacobian.
    workspace, tracker, fov: see :func:`reachable_candidates`.  model_error: σ per axis (mm) of
    what the model cannot take (the residual scatter of an earlier calibration beyond the
    instrument): the expected validation RMS adds it, apart from what the poses determine.
    """
    name = criterion
    _check(name, measure, frames, noise, angle_noise, n_poses, candidates)
    rng = np.random.default_rng(seed)
    robot = complete(robot)  # plan for the parameters a calibration will estimate
    cand, _ = reachable_candidates(robot, candidates, rng, joint_range, workspace, tracker, fov)
    names = joint_candidates(robot) + frame_candidates(frames, ("",) if robot.tree is None else robot.tree.names,
                                                       measure == "pose")
    blocks, _ = _blocks(robot, cand, names, measure, noise, angle_noise)
    ident = analyse(blocks.reshape(-1, len(names)), names, np.array([is_angle(n) for n in names]), len(cand),
                    robot.reach())
    blocks = blocks[:, :, [names.index(n) for n in ident.kept]]
    k, rows = len(ident.kept), blocks.shape[1]
    if n_poses * rows < k:
        raise InputError(f"{n_poses} poses give {n_poses * rows} equations for {k} identifiable parameters",
                         option="poses")
    scale = np.where([is_angle(n) for n in ident.kept], robot.reach(), 1.0)
    A = np.swapaxes(blocks, 1, 2) @ blocks  # (M, k, k) information of each candidate
    ridge = 1e-9 * np.trace(A.sum(0)) / k * np.eye(k)  # lets the first picks be compared
    chosen, M, free = _greedy(A, blocks, n_poses, name, scale, ridge)
    M, exchanges = _exchange(chosen, M, free, A, blocks, name, scale, ridge, max_passes)
    _, val_pos = _blocks(robot, random_joints(robot, validation, rng, joint_range), ident.kept, measure, noise,
                         angle_noise)
    M_plan = M - ridge + 1e-15 * np.eye(k)
    chosen = np.asarray(chosen)[short_moves(cand[np.asarray(chosen)])]
    plan = Plan(q=cand[chosen], criterion=name, model_error=model_error,
                value=criterion_value(M_plan, name, scale, n_poses), names=ident.kept,
                predicted_std=standard_uncertainties(information=M_plan), predicted_rms=_predicted_rms(M_plan, val_pos),
                exchanges=exchanges, dropped={n: r.text() for n, r in ident.reasons.items()})
    for _ in range(random_sets):
        Mr = A[rng.choice(len(cand), n_poses, replace=False)].sum(0) + 1e-15 * np.eye(k)
        plan.random_values.append(criterion_value(Mr, name, scale, n_poses))
        plan.random_rms.append(_predicted_rms(Mr, val_pos))
    return plan

