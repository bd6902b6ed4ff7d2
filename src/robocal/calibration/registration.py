"""Closed-form initial guesses of the measuring frame (base) and tool offsets.

Laser-tracker data live in the tracker's frame, metres away from and rotated against the
robot base, and the reflector sits somewhere on the flange.  Before any iterative
identification, the base frame is found by rigid registration (Kabsch) of nominal
forward-kinematics points to measured points; with unknown tool offsets the registration
alternates with a linear least-squares solve for each target's offset (the problem is
bilinear: fixing one makes the other linear).
"""

from __future__ import annotations

import numpy as np

from ..exceptions import InputError
from ..math.registration import rigid_registration
from ..math.se3 import homogeneous
from ..math.so3 import project_to_so3
from ..model.kinematics import chain_pose
from ..model.measurements import Measurements
from ..model.robot import Robot


def _check_spread(points: np.ndarray, source: str) -> None:
    centred = points - points.mean(0)
    s = np.linalg.svd(centred, compute_uv=False)
    if len(points) < 3 or s[1] < 1e-6 * max(s[0], 1e-300):
        raise InputError("measured points are (nearly) collinear or too few: the measuring frame cannot be "
                         "registered (need at least 3 poses spread in two directions)", source=source)


def register_frames(robot: Robot, meas: Measurements, mode: str, iterations: int = 50) -> Robot:
    """Robot with base (and, for ``base+tool``, tool offsets) fitted to the measurements.

    Joint geometry stays nominal.  For ``base+tool`` each target gets its own tool frame;
    with full-pose data its rotation is the chordal mean of the measured orientations
    relative to the flange.
    """
    if mode == "none":
        return robot
    _check_spread(meas.position, meas.source)
    targets = meas.target_names
    tools = {t: robot.tool_frames([t])[0] if (t == "" or t in robot.targets) else robot.tool.copy() for t in targets}
    R_f, p_f = chain_pose(robot.convention, robot.geometry, meas.q)  # flange in the robot base frame
    tidx = np.zeros(meas.n_poses, dtype=int) if meas.targets is None else np.array([targets.index(t)
                                                                                     for t in meas.targets])
    base = robot.base
    for _ in range(iterations if mode == "base+tool" else 1):
        stack = np.stack([tools[t] for t in targets])[tidx]
        base = rigid_registration(p_f + (R_f @ stack[:, :3, 3:])[..., 0], meas.position)
        if mode != "base+tool":
            break
        Rb, pb = base[:3, :3], base[:3, 3]
        for k, t in enumerate(targets):
            rows = tidx == k
            A = (Rb @ R_f[rows]).reshape(-1, 3)
            b = (meas.position[rows] - pb - p_f[rows] @ Rb.T).reshape(-1)
            offset, *_ = np.linalg.lstsq(A, b, rcond=None)
            R_t = tools[t][:3, :3]
            if meas.rotation is not None:
                R_t = project_to_so3((np.swapaxes(Rb @ R_f[rows], -1, -2) @ meas.rotation[rows]).sum(0))
            tools[t] = homogeneous(R_t, offset)
    if mode == "base+tool":
        named = {t: T for t, T in tools.items() if t != ""}
        return robot.replace(base=base, tool=tools.get("", robot.tool), targets={**robot.targets, **named})
    return robot.replace(base=base)
