"""The joint-space Jacobian of a robot's measured point, its conditioning, and well-conditioned starts."""

from __future__ import annotations

import itertools

import numpy as np

from .kinematics import chain_twist_jacobian, joint_value_columns
from .robot import Robot


def joint_jacobian(robot: Robot, q: np.ndarray, full: bool, rot_weight: float) -> np.ndarray:
    """d(point mm, rot_weight × rotation rad)/dq, (m, 6, n), or (m, 3, n) when not ``full``.

    rot_weight (mm per rad) makes the rotation rows comparable to the position rows.
    """
    Jt, _, _, _ = chain_twist_jacobian(robot.convention, robot.geometry, q, robot.base, robot.tool[None])
    cols = joint_value_columns(robot.convention, robot.geometry)
    J = np.moveaxis(Jt[np.arange(robot.n_joints), cols], 0, -1)  # the joint value's own column
    return np.concatenate([J[:, :3], rot_weight * J[:, 3:]], axis=1) if full else J[:, :3]


def condition_numbers(robot: Robot, q: np.ndarray, full: bool, rot_weight: float) -> np.ndarray:
    """Condition number of :func:`joint_jacobian` per pose, (m,)."""
    s = np.linalg.svd(joint_jacobian(robot, q, full, rot_weight), compute_uv=False)
    return s[:, 0] / np.maximum(s[:, -1], 1e-300)


#: well-conditioned configurations offered as starts, best first
MAX_STARTS = 20


def ready_configurations(robot: Robot) -> list[np.ndarray]:
    """Configurations inside the limits to place the cube from, best conditioned first: the
    middle of each joint's range, with the shoulder, elbow and wrist bent by up to ±90° in steps
    of 30° (the middle of a ±360° range is a stretched, singular arm)."""
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    finite = np.isfinite(lo) & np.isfinite(hi)
    mid = np.where(finite, 0.5 * (np.where(finite, lo, 0.0) + np.where(finite, hi, 0.0)), 0.0)
    bend = [j for j in (1, 2, 4) if j < robot.n_joints and not robot.prismatic[j]]
    candidates = []
    for signs in itertools.product((0.0, 1.0, -1.0, 2.0, -2.0, 3.0, -3.0), repeat=len(bend)):
        q = mid.copy()
        q[bend] += np.radians(30.0) * np.array(signs)
        if np.all(q >= lo) and np.all(q <= hi):
            candidates.append(q)
    cond = condition_numbers(robot, np.array(candidates), True, robot.reach())
    return [candidates[i] for i in np.argsort(cond)[:MAX_STARTS]]
