"""Compensation: joint commands and Cartesian targets that make the real robot land on target.

The controller still runs its nominal model.  For each target robocal finds joints
q_c with ``FK_calibrated(q_c) = target`` by damped least squares (Levenberg–Marquardt
on the joints, batched over all targets), started from the nominal solution so the
arm stays on the same configuration branch, inside the joint limits.  It returns q_c
and, for controllers that take Cartesian goals, the pose the *nominal* model gives
for q_c: sending that pose makes the controller's own inverse kinematics produce q_c.

Targets are joint sets (``q1..qn``: go where the nominal model says these joints go)
or poses (``x, y, z[, rx, ry, rz]`` in the robot base frame, mm and deg, with optional
``q1..qn`` as the starting guess and branch selector).  A calibrated model with an
identified base is in the measuring frame; targets are moved there with
``base_calibrated · base_nominal⁻¹``.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError, atomic_write
from .kinematics import THETA, Robot, chain_twist_jacobian
from .measurements import read_table, read_text
from .metrics import Metrics
from .transforms import homogeneous, invert, log_so3, matrix_to_rpy, rpy_to_matrix

STATUSES = ("ok", "unreachable", "limit", "singular", "no_convergence")

#: weight of orientation against position in the joint-space solve, mm per rad
ROT_WEIGHT = 1000.0
#: convergence: position residual (mm) and orientation residual (rad)
TOL_MM, TOL_RAD = 1e-6, 1e-9
#: condition number of the weighted joint Jacobian above which a target is called singular:
#: about 0.2 % of random poses of a 6R arm, those within a degree or so of a wrist or
#: elbow singularity, where a millimetre of correction can need tens of degrees of joints
SINGULAR_CONDITION = 1e4
#: largest joint step of one iteration (rad): corrections are small, so the solve walks
#: rather than jumps, and cannot leave the configuration branch it started on
MAX_STEP = 0.05
#: a reached solution further than this (rad) from its start changed branch or sat on a
#: near-singular pose: it is reported as singular
BRANCH_TOLERANCE = math.radians(20.0)


@dataclass
class Targets:
    """Targets of a compensation: q (m, n) rad and/or poses (position mm, rotation) in the base frame."""

    q: np.ndarray | None
    position: np.ndarray | None
    rotation: np.ndarray | None
    ids: list[str]
    source: str = "<targets>"

    @property
    def n(self) -> int:
        return len(self.ids)


def parse_targets(
    text: str, *, source: str = "<targets>", n_joints: int | None = None, columns: Mapping[str, str] | None = None
) -> Targets:
    t = read_table(
        text, source=source, n_joints=n_joints, columns=columns, require_joints=False, require_position=False
    )
    ids = t.pose_ids if t.pose_ids is not None else [str(r) for r in t.rows]
    return Targets(
        q=None if t.q is None else np.radians(t.q),
        position=t.position,
        rotation=None if t.rpy is None else rpy_to_matrix(np.radians(t.rpy)),
        ids=list(ids),
        source=source,
    )


def load_targets(path: str | Path, *, n_joints: int | None = None, columns: Mapping[str, str] | None = None) -> Targets:
    return parse_targets(read_text(path, "targets file"), source=str(path), n_joints=n_joints, columns=columns)


@dataclass
class IKSolution:
    q: np.ndarray  # (m, n) rad
    position_error: np.ndarray  # (m,) mm
    rotation_error: np.ndarray  # (m,) rad, zeros for position-only targets
    status: list[str]
    iterations: np.ndarray


def _pose_error(robot: Robot, q, position, rotation):
    T = robot.fk(q)
    dp = position - T[:, :3, 3]
    dr = None if rotation is None else log_so3(rotation @ np.swapaxes(T[:, :3, :3], -1, -2))
    return dp, dr


def _residual(dp, dr, w):
    return dp if dr is None else np.concatenate([dp, w * dr], axis=1)


def solve_ik(
    robot: Robot,
    position: np.ndarray,
    rotation: np.ndarray | None,
    q0: np.ndarray,
    *,
    rot_weight: float = ROT_WEIGHT,
    max_iter: int = 100,
    limits: bool = True,
) -> IKSolution:
    """Joints reaching each target pose (or position when rotation is None), batched.

    Damped least squares on the joints from q0, each target with its own damping;
    joints are kept inside the robot's limits.  Statuses: ``ok``; ``singular`` (reached,
    but the joint Jacobian's condition number exceeds 1e3, so a tiny pose change needs
    a large joint change); ``limit`` (not reached, a joint held at its limit);
    ``unreachable`` (not reached, stalled away from the target); ``no_convergence``.
    """
    q = np.array(q0, dtype=float, copy=True)
    m, n = q.shape
    lo, hi = (robot.limits[:, 0], robot.limits[:, 1]) if limits else (-np.inf, np.inf)
    q = np.clip(q, lo, hi)
    start = q.copy()
    lam = np.full(m, 1e-6)
    iters = np.zeros(m, dtype=int)
    dp, dr = _pose_error(robot, q, position, rotation)
    cost = np.sum(_residual(dp, dr, rot_weight) ** 2, axis=1)
    done = np.zeros(m, bool)
    stalled = np.zeros(m, bool)
    cond_start = _condition(robot, q, rotation is not None, rot_weight)
    for _ in range(max_iter):
        pe = np.linalg.norm(dp, axis=1)
        re = np.zeros(m) if dr is None else np.linalg.norm(dr, axis=1)
        done |= (pe < TOL_MM) & (re < TOL_RAD)
        act = np.flatnonzero(~done & ~stalled)
        if act.size == 0:
            break
        iters[act] += 1
        J = _joint_jacobian(robot, q[act], rotation is not None, rot_weight)
        e = _residual(dp[act], None if dr is None else dr[act], rot_weight)
        A = np.swapaxes(J, 1, 2) @ J
        g = (np.swapaxes(J, 1, 2) @ e[..., None])[..., 0]
        # Levenberg's λ·I (not Marquardt's λ·diag): every joint pays alike for moving, so a
        # joint with a tiny lever (q6 with the point near its axis) does not take the step
        mu = lam[act] * np.einsum("aii->ai", A).max(axis=1)
        step = np.linalg.solve(A + mu[:, None, None] * np.eye(n), g[..., None])[..., 0]
        if J.shape[1] < n:
            # Redundant (position only): the target leaves joint directions free.  Pull the
            # joints back toward the start inside the null space of J, so the answer is the
            # nearest solution and does not drift from one linearisation to the next.
            Jp = np.linalg.pinv(J)
            back = start[act] - q[act]
            step += back - (Jp @ (J @ back[..., None]))[..., 0]
        step *= np.minimum(1.0, MAX_STEP / np.maximum(np.abs(step).max(axis=1), 1e-300))[:, None]
        q_try = np.clip(q[act] + step, lo, hi)
        dp_t, dr_t = _pose_error(robot, q_try, position[act], None if rotation is None else rotation[act])
        c_try = np.sum(_residual(dp_t, dr_t, rot_weight) ** 2, axis=1)
        better = c_try < cost[act]
        ok_rows = act[better]
        q[ok_rows] = q_try[better]
        dp[ok_rows] = dp_t[better]
        if dr is not None:
            dr[ok_rows] = dr_t[better]
        cost[ok_rows] = c_try[better]
        lam[ok_rows] = np.maximum(lam[ok_rows] / 3.0, 1e-9)
        bad = act[~better]
        lam[bad] *= 4.0
        stalled |= lam > 1e8
    pe = np.linalg.norm(dp, axis=1)
    re = np.zeros(m) if dr is None else np.linalg.norm(dr, axis=1)
    reached = (pe < TOL_MM * 10) & (re < TOL_RAD * 10)
    at_limit = np.any((q <= lo + 1e-9) | (q >= hi - 1e-9), axis=1) if limits else np.zeros(m, bool)
    moved = np.abs(q - start).max(axis=1)
    cond = np.maximum(cond_start, _condition(robot, q, rotation is not None, rot_weight))
    status = []
    for i in range(m):
        if cond[i] > SINGULAR_CONDITION or (reached[i] and moved[i] > BRANCH_TOLERANCE):
            status.append("singular")
        elif reached[i]:
            status.append("ok")
        elif at_limit[i]:
            status.append("limit")
        elif stalled[i]:
            status.append("unreachable")
        else:
            status.append("no_convergence")
    return IKSolution(q, pe, re, status, iters)


def _joint_jacobian(robot: Robot, q: np.ndarray, full: bool, rot_weight: float) -> np.ndarray:
    """d(point, weighted rotation)/dq, (m, 6 or 3, n)."""
    Jt, _, _, _ = chain_twist_jacobian(robot.convention, robot.geometry, q, robot.base, robot.tool[None])
    J = np.moveaxis(Jt[:, THETA], 0, -1)
    return np.concatenate([J[:, :3], rot_weight * J[:, 3:]], axis=1) if full else J[:, :3]


def _condition(robot: Robot, q: np.ndarray, full: bool, rot_weight: float) -> np.ndarray:
    s = np.linalg.svd(_joint_jacobian(robot, q, full, rot_weight), compute_uv=False)
    return s[:, 0] / np.maximum(s[:, -1], 1e-300)


@dataclass
class CompensationResult:
    """Per target: nominal commands, compensated joints and Cartesian goal, residual, status."""

    targets: Targets
    q_nominal: np.ndarray
    q: np.ndarray
    cartesian: np.ndarray  # (m, 4, 4): nominal FK of q, in the nominal base frame
    residual_mm: np.ndarray
    residual_deg: np.ndarray
    status: list[str]
    full_pose: bool
    true_before: np.ndarray | None = None  # (m, 3) position errors of the true robot at the nominal commands
    true_after: np.ndarray | None = None
    true_rot_before: np.ndarray | None = None
    true_rot_after: np.ndarray | None = None

    def counts(self) -> dict[str, int]:
        return {s: self.status.count(s) for s in STATUSES if s in self.status}

    def validation(self) -> dict[str, Metrics] | None:
        """True-robot errors at the nominal and at the compensated commands.

        ``nominal_commands`` and ``compensated_commands`` cover the rows with status ok;
        ``compensated_commands_all_rows`` covers every row, whatever its status.
        """
        if self.true_before is None:
            return None
        rows = np.array([s == "ok" for s in self.status])
        out = {}

        def rot(a, sel):
            return None if a is None else a[sel]

        if rows.any():
            out["nominal_commands"] = Metrics.from_errors(self.true_before[rows], rot(self.true_rot_before, rows))
            out["compensated_commands"] = Metrics.from_errors(self.true_after[rows], rot(self.true_rot_after, rows))
        out["compensated_commands_all_rows"] = Metrics.from_errors(self.true_after, self.true_rot_after)
        return out

    def to_csv(self) -> str:
        n = self.q.shape[1]
        header = ["pose_id"] + [f"q{i + 1}" for i in range(n)] + ["cx", "cy", "cz", "crx", "cry", "crz"]
        header += ["residual_mm", "residual_deg", "dq_max_deg", "status"]
        if self.true_before is not None:
            header += ["true_error_before_mm", "true_error_after_mm"]
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        qd = np.degrees(self.q)
        rpy = np.degrees(matrix_to_rpy(self.cartesian[:, :3, :3]))
        dq = np.degrees(np.abs(self.q - self.q_nominal).max(axis=1))
        for j in range(len(qd)):
            row = [self.targets.ids[j]] + [repr(float(v)) for v in qd[j]]
            row += [repr(float(v)) for v in self.cartesian[j, :3, 3]] + [repr(float(v)) for v in rpy[j]]
            row += [f"{self.residual_mm[j]:.3e}", f"{self.residual_deg[j]:.3e}", f"{dq[j]:.6f}", self.status[j]]
            if self.true_before is not None:
                row += [f"{np.linalg.norm(self.true_before[j]):.6f}", f"{np.linalg.norm(self.true_after[j]):.6f}"]
            w.writerow(row)
        return out.getvalue()

    def save(self, path: str | Path) -> None:
        atomic_write(path, self.to_csv())


def _mid_range(robot: Robot, m: int) -> np.ndarray:
    lim = robot.limits
    mid = np.where(np.isfinite(lim).all(axis=1), lim.mean(axis=1), 0.0)
    return np.tile(mid, (m, 1))


def compensate(
    nominal: Robot,
    calibrated: Robot,
    targets: Targets,
    *,
    truth: Robot | None = None,
    position_only: bool | None = None,
    rot_weight: float = ROT_WEIGHT,
) -> CompensationResult:
    """Compensated commands for every target (see the module docstring).

    position_only: solve for the position alone (default: for pose targets without
    orientation columns; joint targets use the full nominal pose).  truth: a simulated
    true robot; its errors at the nominal and the compensated commands are returned.
    """
    if nominal.n_joints != calibrated.n_joints:
        raise InputError(
            f"nominal robot has {nominal.n_joints} joints, calibrated has {calibrated.n_joints}", source="compensate"
        )
    m = targets.n
    if targets.position is not None:
        R = targets.rotation if targets.rotation is not None else np.broadcast_to(np.eye(3), (m, 3, 3))
        T_des = homogeneous(R, targets.position)
        full = targets.rotation is not None
        start = targets.q if targets.q is not None else _mid_range(nominal, m)
        nom = solve_ik(
            nominal,
            T_des[:, :3, 3],
            T_des[:, :3, :3] if full and not position_only else None,
            start,
            rot_weight=rot_weight,
        )
        q_nom = nom.q
    else:
        q_nom = targets.q
        T_des = nominal.fk(q_nom)
        full = True
    if position_only:
        full = False
    M = calibrated.base @ invert(nominal.base)
    T_cal = M @ T_des
    sol = solve_ik(calibrated, T_cal[:, :3, 3], T_cal[:, :3, :3] if full else None, q_nom, rot_weight=rot_weight)
    result = CompensationResult(
        targets=targets, q_nominal=q_nom, q=sol.q, cartesian=nominal.fk(sol.q), residual_mm=sol.position_error,
        residual_deg=np.degrees(sol.rotation_error), status=sol.status, full_pose=full,
    )  # fmt: skip
    if truth is not None:
        T_true = truth.base @ invert(nominal.base) @ T_des
        for attr, q in (("before", q_nom), ("after", sol.q)):
            Tq = truth.fk(q)
            setattr(result, f"true_{attr}", T_true[:, :3, 3] - Tq[:, :3, 3])
            if full:
                setattr(result, f"true_rot_{attr}", log_so3(T_true[:, :3, :3] @ np.swapaxes(Tq[:, :3, :3], -1, -2)))
    return result
