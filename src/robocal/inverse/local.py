"""Batched inverse kinematics by damped least squares on the joints, with a typed status per goal:
the polish every solution goes through, and the step from the controller's joints to the
calibrated robot's (small corrections, on the same configuration branch)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..math.so3 import orientation_error
from ..model.jointspace import condition_numbers, joint_jacobian
from ..model.robot import Robot
from ..model.terms import JointInputs

STATUSES = ("ok", "branch", "unreachable", "limit", "singular", "no_convergence")

#: weight of orientation against position in the joint-space solve, mm per rad
ROT_WEIGHT = 1000.0
#: convergence: position residual (mm) and orientation residual (rad)
TOL_MM, TOL_RAD = 1e-6, 1e-9
#: condition number of the weighted joint Jacobian above which a goal is called singular:
#: about 0.2 % of random poses of a 6R arm, those within a degree or so of a wrist or
#: elbow singularity, where a millimetre of correction can need tens of degrees of joints
SINGULAR_CONDITION = 1e4
#: largest joint step of one iteration (rad): corrections are small, so the solve walks
#: rather than jumps, and cannot leave the configuration branch it started on
MAX_STEP = 0.05
#: a reached solution further than this (rad) from its start changed configuration branch: it
#: is reported as ``branch`` (the pose is reached, but with other joints than the controller's)
BRANCH_TOLERANCE = math.radians(20.0)


@dataclass
class IKSolution:
    """Per goal: the joints, what is left of the goal, the status and why, and the numbers behind
    it (in the manner of an optimizer's result: a reached goal is ``ok``, every other status
    says why not, with the residual, the conditioning and the margin to the joint limits)."""

    q: np.ndarray  # (m, n) rad
    position_error: np.ndarray  # (m,) mm
    rotation_error: np.ndarray  # (m,) rad, zeros for position-only goals
    status: list[str]
    iterations: np.ndarray
    condition: np.ndarray | None = None  # (m,) of the weighted joint Jacobian, the worse of start and end
    limit_margin: np.ndarray | None = None  # (m,) rad (mm for a sliding joint) to the nearest joint limit
    moved: np.ndarray | None = None  # (m,) rad: the largest joint change from the start

    def reason(self, i: int) -> str:
        """What status i means, with its numbers."""
        s = self.status[i]
        if s == "ok":
            return "reached"
        if s == "singular":
            return f"the joint Jacobian's condition number is {self.condition[i]:.3g} (a singularity)"
        if s == "branch":
            return (f"reached, but {math.degrees(self.moved[i]):.3g}° of joint from the start: another configuration "
                    "branch")
        if s == "limit":
            return f"a joint held at its limit, {self.position_error[i]:.3g} mm from the goal"
        if s == "unreachable":
            return f"out of reach: the closest is {self.position_error[i]:.3g} mm and " \
                   f"{math.degrees(self.rotation_error[i]):.3g}° from the goal"
        return f"did not converge in {self.iterations[i]} steps ({self.position_error[i]:.3g} mm left)"


class _Residual:
    """Pose error of a robot against the goals, weighted: (position mm, rot_weight × rotation)."""

    def __init__(self, robot: Robot, position, rotation, rot_weight: float, inputs=None, targets=None):
        self.robot, self.position, self.rotation, self.w = robot, position, rotation, rot_weight
        self.inputs = inputs
        self.targets = None if targets is None else np.asarray(targets, dtype=object)

    def __call__(self, q, rows=slice(None)):
        T = self.robot.fk(q, None if self.targets is None else list(self.targets[rows]),
                          None if self.inputs is None else self.inputs.subset(rows))
        dp = self.position[rows] - T[:, :3, 3]
        dr = None if self.rotation is None else orientation_error(self.rotation[rows], T[:, :3, :3])
        e = dp if dr is None else np.concatenate([dp, self.w * dr], axis=1)
        return dp, dr, np.sum(e * e, axis=1), e


def _step(robot, q, e, start, full, rot_weight, lam):
    """Damped Gauss–Newton step of each active goal, at most MAX_STEP per joint."""
    n = q.shape[1]
    J = joint_jacobian(robot, q, full, rot_weight)
    A = np.swapaxes(J, 1, 2) @ J
    g = (np.swapaxes(J, 1, 2) @ e[..., None])[..., 0]
    # Levenberg's λ·I (not Marquardt's λ·diag): every joint pays alike for moving, so a joint
    # with a tiny lever (q6 with the point near its axis) does not take the step
    mu = lam * np.einsum("aii->ai", A).max(axis=1)
    step = np.linalg.solve(A + mu[:, None, None] * np.eye(n), g[..., None])[..., 0]
    if J.shape[1] < n:
        # Redundant (position only): the goal leaves joint directions free.  Pull the joints
        # back toward the start inside the null space of J, so the answer is the nearest
        # solution and does not drift from one linearisation to the next.
        back = start - q
        step += back - (np.linalg.pinv(J) @ (J @ back[..., None]))[..., 0]
    return step * np.minimum(1.0, MAX_STEP / np.maximum(np.abs(step).max(axis=1), 1e-300))[:, None]


def _met(dp: np.ndarray, dr: np.ndarray | None) -> np.ndarray:
    """Goals met: position within TOL_MM and rotation within TOL_RAD."""
    re = np.zeros(len(dp)) if dr is None else np.linalg.norm(dr, axis=1)
    return (np.linalg.norm(dp, axis=1) < TOL_MM) & (re < TOL_RAD)


def _statuses(reached, moved, cond, at_limit, stalled) -> list[str]:
    status = []
    for i in range(len(reached)):
        if cond[i] > SINGULAR_CONDITION:
            status.append("singular")
        elif reached[i] and moved[i] > BRANCH_TOLERANCE:
            status.append("branch")
        elif reached[i]:
            status.append("ok")
        elif at_limit[i]:
            status.append("limit")
        elif stalled[i]:
            status.append("unreachable")
        else:
            status.append("no_convergence")
    return status


def refuse_coupled(robot: Robot) -> None:
    """Inverse kinematics sets every joint freely: for a robot whose joint follows others it would
    answer a pose the robot cannot take (its coupled joint off its coupling), so it refuses."""
    if robot.coupled:
        from ..exceptions import InputError

        c = robot.coupled[0]
        raise InputError(f"joint {c.joint + 1} follows others ({c.describe(robot.joint_names)}): inverse kinematics "
                         "does not hold coupled joints, so robocal does not solve goals for this robot",
                         source=robot.source or robot.name)


def solve_ik(robot: Robot, position: np.ndarray, rotation: np.ndarray | None, q0: np.ndarray, *,
             rot_weight: float = ROT_WEIGHT, max_iter: int = 100, limits: bool = True,
             inputs: JointInputs | None = None, targets=None) -> IKSolution:
    """Joints reaching each goal pose (or position when rotation is None), batched.

    Positions in mm and rotations in the robot's measuring frame; q0 (m, n) rad starts each
    goal and keeps it on its configuration branch; joints stay inside the robot's limits.
    Statuses: ``ok``; ``singular`` (the joint Jacobian's condition number exceeds
    SINGULAR_CONDITION at the start or the solution); ``branch`` (reached, but on another
    configuration branch: the joints moved beyond BRANCH_TOLERANCE from the start); ``limit``
    (not reached, a joint held at its limit); ``unreachable`` (not reached, stalled away
    from the goal); ``no_convergence``.

    The pose is the robot's whole model (:meth:`Robot.fk`): joint terms, at the goals' joint
    :class:`~robocal.model.terms.JointInputs` (torques, payload, directions, time) where they
    need them, and the residual correction;
    targets: per goal, the robot's tool frame to place (a reflector's name), default its tool.
    The step uses the geometric joint Jacobian, which the terms change by a few hundredths of
    a percent: the solve converges on the full model's pose all the same.
    """
    refuse_coupled(robot)
    full = rotation is not None
    q = np.array(q0, dtype=float, copy=True)
    m = len(q)
    lo, hi = (robot.limits[:, 0], robot.limits[:, 1]) if limits else (-np.inf, np.inf)
    q = np.clip(q, lo, hi)
    start = q.copy()
    lam = np.full(m, 1e-6)
    iters = np.zeros(m, dtype=int)
    residual = _Residual(robot, position, rotation, rot_weight, inputs, targets)
    dp, dr, cost, e = residual(q)
    stalled = np.zeros(m, bool)
    cond_start = condition_numbers(robot, q, full, rot_weight)
    # a goal met stays met; a row's test changes only where the row moved (a few goals iterate long
    # after the rest are met: each pass tests and damps those alone)
    done = _met(dp, dr)
    for _ in range(max_iter):
        act = np.flatnonzero(~done & ~stalled)
        if act.size == 0:
            break
        iters[act] += 1
        q_try = np.clip(q[act] + _step(robot, q[act], e[act], start[act], full, rot_weight, lam[act]), lo, hi)
        dp_t, dr_t, c_try, e_t = residual(q_try, act)
        better = c_try < cost[act]
        ok = act[better]
        q[ok], dp[ok], cost[ok], e[ok] = q_try[better], dp_t[better], c_try[better], e_t[better]
        if dr is not None:
            dr[ok] = dr_t[better]
        done[ok] = _met(dp_t[better], None if dr is None else dr_t[better])
        lam[ok] = np.maximum(lam[ok] / 3.0, 1e-9)
        lam[act[~better]] *= 4.0
        stalled[act] |= lam[act] > 1e8
    pe = np.linalg.norm(dp, axis=1)
    re = np.zeros(m) if dr is None else np.linalg.norm(dr, axis=1)
    reached = (pe < TOL_MM * 10) & (re < TOL_RAD * 10)
    at_limit = np.any((q <= lo + 1e-9) | (q >= hi - 1e-9), axis=1) if limits else np.zeros(m, bool)
    cond = np.maximum(cond_start, condition_numbers(robot, q, full, rot_weight))
    moved = np.abs(q - start).max(axis=1)
    status = _statuses(reached, moved, cond, at_limit, stalled)
    margin = np.min(np.minimum(q - lo, hi - q), axis=1) if limits else np.full(m, np.inf)
    return IKSolution(q, pe, re, status, iters, cond, margin, moved)
