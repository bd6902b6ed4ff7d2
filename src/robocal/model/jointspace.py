"""The joint-space Jacobian of a robot's measured point and its conditioning."""

from __future__ import annotations

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
