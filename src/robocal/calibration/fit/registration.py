"""Closed-form initial guesses of the measuring frame (base) and tool offsets.

Laser-tracker data live in the tracker's frame, metres away from and rotated against the
robot base, and the reflector sits somewhere on the flange.  Before any iterative
identification, the base frame is found by rigid registration (Kabsch) of nominal
forward-kinematics points to measured points; with unknown tool offsets the registration
alternates with a linear least-squares solve for each target's offset (the problem is
bilinear: fixing one makes the other linear).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...exceptions import InputError
from ...math.registration import rigid_registration
from ...math.se3 import homogeneous
from ...math.so3 import project_to_so3
from ...model.measurements import Measurements
from ...model.robot import Robot


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
    if mode in ("none", "tcp"):  # tools alone are fitted with the joints, from their nominal
        return robot
    _check_spread(meas.position, meas.source)
    targets = meas.target_names
    tools = {t: robot.tool_frames([t])[0] if (t == "" or t in robot.targets) else robot.tool.copy() for t in targets}
    R_f, p_f = robot.flange_frames(meas.q, meas.chain)  # flange in the robot base frame
    tidx = np.zeros(meas.n_poses, dtype=int) if meas.targets is None else np.array([targets.index(t)
                                                                                     for t in meas.targets])
    base = robot.base
    for _ in range(iterations if mode == "base+tool" else 1):
        stack = np.stack([tools[t] for t in targets])[tidx]
        previous, base = base, rigid_registration(p_f + (R_f @ stack[:, :3, 3:])[..., 0], meas.position)
        if mode != "base+tool" or np.abs(base - previous).max() < 1e-9:  # settled (LM refines it anyway)
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


def _rms(robot: Robot, meas: Measurements, targets) -> float:
    dp = meas.position - robot.positions(meas.q, targets, meas.inputs, meas.chain)
    return float(np.sqrt(np.mean(np.sum(dp * dp, axis=1))))


#: frames auto: registering must shrink the nominal model's RMS error by this factor, and by
#: at least AUTO_MIN_GAIN_MM, before the data count as living in another frame
AUTO_FACTOR, AUTO_MIN_GAIN_MM = 3.0, 1.0


@dataclass(frozen=True)
class FrameChoice:
    """What ``frames auto`` decided: the mode, and the nominal model's RMS position error (mm)
    as given and after fitting that mode's frames (None when nothing was fitted); ``robot``:
    the model with those frames, the very fit the sentence speaks of (None: as given)."""

    mode: str
    given_rms: float | None = None
    registered_rms: float | None = None
    reason: str = ""
    robot: Robot | None = None

    def sentence(self) -> str:
        if self.reason:
            return self.reason
        if self.mode == "none":
            return f"the data sit in the robot's frame ({self.given_rms:.4g} mm RMS as given)"
        what = "the base" if self.mode == "base" else "base and tool"
        return (f"the data are not in the robot's frame: the nominal model is {self.given_rms:.4g} mm RMS off as "
                f"given and {self.registered_rms:.4g} mm after registering {what} (frames {self.mode})")


def choose_frames(robot: Robot, meas: Measurements) -> FrameChoice:
    """For ``frames auto``: the frames mode the data need.

    The nominal model's RMS position error is compared as given, with a registered base,
    and with base and tools: a tracker's data, metres away and turned, shrink by orders of
    magnitude; data in the robot's own frame shrink only by what a rigid move can take of
    the geometric errors.  Reflectors the robot file does not know always need base+tool.
    """
    unknown = [t for t in meas.target_names if t and t not in robot.targets]
    targets = meas.targets if meas.targets and not unknown else None
    try:
        _check_spread(meas.position, meas.source)
    except InputError:
        return FrameChoice("none", reason="too few or collinear poses to register a frame; frames as given")
    if not unknown:
        given = _rms(robot, meas, targets)
        if given < AUTO_MIN_GAIN_MM:  # no registration can gain a millimetre
            return FrameChoice("none", given, None)
    # decided on the closed forms (cheap at any size), then the chosen frames fitted as they will
    # be used (closed form, then LM on position and, for full-pose data, orientation), whose
    # figure is the one said: what is said is what is then shown
    closed = register_frames(robot, meas, "base+tool")
    both = _rms(closed, meas, meas.targets)
    if unknown:
        fitted = fit_frames(robot, meas, "base+tool")
        rms = _rms(fitted, meas, meas.targets)
        return FrameChoice("base+tool", None, rms, f"reflector '{unknown[0]}' has no tool frame in the robot file, "
                           f"so base and tools are identified (frames base+tool; {rms:.4g} mm RMS registered)",
                           fitted)
    given = _rms(robot, meas, targets)
    if given <= AUTO_FACTOR * both or given - both < AUTO_MIN_GAIN_MM:
        return FrameChoice("none", given, None)
    base_only = register_frames(robot, meas, "base")
    if _rms(base_only, meas, targets) <= 1.5 * both + 0.5 and not _turned_tool(base_only, closed, meas, targets):
        fitted = fit_frames(robot, meas, "base")
        return FrameChoice("base", given, _rms(fitted, meas, targets), robot=fitted)
    fitted = fit_frames(robot, meas, "base+tool")
    return FrameChoice("base+tool", given, _rms(fitted, meas, meas.targets), robot=fitted)


#: a base-only registration whose orientations miss by this much more (deg, mean) than base and
#: tool together leaves a turned tool unexplained: the data need the tool too
TURNED_TOOL_DEG = 1.0


def _turned_tool(base_only: Robot, both: Robot, meas: Measurements, targets) -> bool:
    """Full-pose data whose measured target is turned against the flange: the positions may
    register with the base alone, the orientations cannot."""
    if meas.rotation is None:
        return False
    from ...math.so3 import orientation_error

    def mean_deg(robot, tg):
        R = robot.fk(meas.q, tg, meas.inputs, meas.chain)[:, :3, :3]
        return float(np.degrees(np.linalg.norm(orientation_error(meas.rotation, R), axis=1).mean()))

    return mean_deg(base_only, targets) > mean_deg(both, meas.targets) + TURNED_TOOL_DEG


def _fit_frames_whole(robot: Robot, meas: Measurements, mode: str, sigma_position: float,
                      sigma_orientation: float | None) -> Robot:
    """Frames of a model beyond geometry fitted through its whole forward model (joint terms,
    residual correction),
    by least squares with finite-difference derivatives: a handful of frame parameters."""
    from scipy.optimize import least_squares

    from ...math.so3 import exp_so3, orientation_error
    from .problem import DEFAULT_K

    sigma_r = sigma_orientation if sigma_orientation is not None else sigma_position / np.sqrt(DEFAULT_K)
    targets = [t for t in meas.target_names] if mode == "base+tool" else []
    width = 6 if meas.rotation is not None else 3

    def frames(x):
        base = homogeneous(exp_so3(x[3:6]), x[:3]) @ robot.base
        tools, k = {}, 6
        for t in targets:
            own = robot.tool if t == "" else robot.targets.get(t, robot.tool)
            turn = exp_so3(x[k + 3:k + 6]) if width == 6 else np.eye(3)
            tools[t] = own @ homogeneous(turn, x[k:k + 3])
            k += width
        named = {t: T for t, T in tools.items() if t}
        return robot.replace(base=base, tool=tools.get("", robot.tool), targets={**robot.targets, **named})

    def residuals(x):
        r = frames(x)
        T = r.fk(meas.q, meas.targets, meas.inputs, meas.chain)
        out = [((meas.position - T[:, :3, 3]) / sigma_position).ravel()]
        if meas.rotation is not None:
            out.append((orientation_error(meas.rotation, T[:, :3, :3]) / sigma_r).ravel())
        return np.concatenate(out)

    x0 = np.zeros(6 + width * len(targets))
    fit = least_squares(residuals, x0, method="lm", x_scale="jac")
    return frames(fit.x) if np.all(np.isfinite(fit.x)) and fit.cost <= 0.5 * np.sum(residuals(x0) ** 2) \
        else robot


def fit_frames(robot: Robot, meas: Measurements, mode: str, sigma_position: float = 1.0,
               sigma_orientation: float | None = None) -> Robot:
    """Frames of ``mode`` fitted to the measurements with the nominal joint geometry: the closed
    form of :func:`register_frames`, then Levenberg–Marquardt on the frame parameters alone
    (base and tools together, full pose when the data have it).

    The LM step matters when tools are unknown: the closed form registers the base while the
    reflector offset is still a guess, which can leave the base tens of millimetres off.
    """
    from ...model.candidates import frame_candidates
    from ...model.parameters import ParameterSpace
    from ...optimize.lm import levenberg_marquardt
    from .problem import DEFAULT_K, Setup

    c = meas.constraints
    if c is not None:  # rows that touched unknown points or planes: the tracker rows register the frames
        if c.only or mode in ("none", "tcp"):
            return robot
        meas = meas.subset(~c.rows)
    initial = register_frames(robot, meas, mode)
    if mode in ("none", "tcp"):
        return initial
    if not robot.geometric:  # what is fitted is the whole model's pose: terms and residual
        return _fit_frames_whole(initial, meas, mode, sigma_position, sigma_orientation)
    space = ParameterSpace.of(initial, meas.target_names if mode == "base+tool" else None)
    sigma_r = sigma_orientation if sigma_orientation is not None else sigma_position / np.sqrt(DEFAULT_K)
    rigid = Setup(space, meas, sigma_position, sigma_r).problem(frame_candidates(mode, meas.target_names,
                                                                                   meas.full_pose))
    x0 = np.zeros(rigid.n_params)
    lm = levenberg_marquardt(rigid.residuals, rigid.residual_jacobian, x0)
    start = rigid.residuals(x0)
    if not np.all(np.isfinite(lm.x)) or lm.fun > float(start @ start):
        return initial
    return space.apply(rigid.full(lm.x))
