"""Simulated measurement campaigns: plant errors in a robot, pick joint sets, measure with noise."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .kinematics import Robot
from .measurements import Measurements
from .parameters import ParameterSpace
from .transforms import exp_so3, xyz_rpy_to_transform

#: Wen et al. (2019) Table 2: true geometric errors of the ER10L-C10 (mm, rad).
WEN2019_ERRORS: dict[str, float] = {
    "a1": -0.4751, "alpha1": 0.0058, "theta1": 0.0091, "d1": -0.4221,
    "a2": 0.2565, "alpha2": 0.0092, "theta2": -0.0003, "d2": 0.0, "beta2": -0.0028,
    "a3": -0.3366, "alpha3": 0.0031, "theta3": 0.0060, "d3": 0.3409,
    "a4": -0.1827, "alpha4": -0.0093, "theta4": -0.0072, "d4": 0.1420,
    "a5": -0.1117, "alpha5": 0.0070, "theta5": -0.0016, "d5": 0.1753,
    "a6": -0.2536, "alpha6": 0.0087, "theta6": 0.0083, "d6": 0.1531,
}  # fmt: skip


def parallel_pairs(robot: Robot) -> list[int]:
    """0-based joints whose axis is nominally parallel to the next one (α ≡ 0 mod π, dh/hayati)."""
    al = robot.alpha[:-1]
    return [i for i, a in enumerate(al) if abs(math.remainder(a, math.pi)) < 1e-9]


def planted_errors(robot: Robot, spec: str, rng: np.random.Generator) -> dict[str, float]:
    """Joint-geometry errors from a spec: ``none``, ``paper`` (Wen 2019 Table 2, ER10L-C10),
    or ``uniform:LEN_MM,ANGLE_RAD`` (uniform in ±LEN on a, d and ±ANGLE on α, θ, and on β
    of hayati joints whose axis is parallel to the next)."""
    spec = spec.strip().lower()
    if spec == "none":
        return {}
    if spec == "paper":
        if robot.convention != "hayati" or robot.n_joints != 6:
            raise InputError(
                "errors 'paper' are Wen et al. Table 2, for the 6-joint hayati ER10L-C10", source="--errors"
            )
        return dict(WEN2019_ERRORS)
    if spec.startswith("uniform:"):
        try:
            length, angle = (float(v) for v in spec[len("uniform:") :].split(","))
        except ValueError:
            raise InputError("expected uniform:LEN_MM,ANGLE_RAD, e.g. uniform:0.25,0.05", source="--errors") from None
        if not (math.isfinite(length) and math.isfinite(angle)) or length < 0 or angle < 0:
            raise InputError("uniform bounds must be finite and ≥ 0", source="--errors")
        out: dict[str, float] = {}
        for i in range(robot.n_joints):
            out[f"a{i + 1}"] = rng.uniform(-length, length)
            out[f"alpha{i + 1}"] = rng.uniform(-angle, angle)
            out[f"theta{i + 1}"] = rng.uniform(-angle, angle)
            out[f"d{i + 1}"] = rng.uniform(-length, length)
        if robot.convention == "hayati":
            for i in parallel_pairs(robot):
                out[f"beta{i + 1}"] = rng.uniform(-angle, angle)
        return out
    raise InputError(f"unknown error spec {spec!r} (none | paper | uniform:LEN_MM,ANGLE_RAD)", source="--errors")


def joint_ranges(robot: Robot, joint_range: tuple[float, float] | None = None) -> np.ndarray:
    """(n, 2) rad sampling ranges: the given range clipped to the joint limits, else the
    limits, else ±π for joints without limits."""
    lim = robot.limits.copy()
    lim[~np.isfinite(lim[:, 0]), 0] = -math.pi
    lim[~np.isfinite(lim[:, 1]), 1] = math.pi
    if joint_range is not None:
        lo, hi = joint_range
        lim = np.column_stack([np.maximum(lim[:, 0], lo), np.minimum(lim[:, 1], hi)])
        if np.any(lim[:, 0] >= lim[:, 1]):
            raise InputError("joint range does not overlap the joint limits", source="--range")
    return lim


def random_joints(robot: Robot, n: int, rng: np.random.Generator, joint_range=None) -> np.ndarray:
    """n joint sets (n, joints) in rad, uniform inside :func:`joint_ranges`."""
    lim = joint_ranges(robot, joint_range)
    return rng.uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_joints))


@dataclass(frozen=True)
class Simulation:
    measurements: Measurements
    truth: Robot
    errors: dict[str, float]


def simulate(
    robot: Robot,
    n_poses: int,
    *,
    errors: str | dict[str, float] = "none",
    noise: float = 0.0,
    angle_noise: float = 0.0,
    joint_noise: float = 0.0,
    joint_noise_uniform: float = 0.0,
    measure: str = "pose",
    seed: int | None = 0,
    joint_range: tuple[float, float] | None = None,
    q: np.ndarray | None = None,
    base: tuple[float, ...] | None = None,
    tool: tuple[float, ...] | None = None,
) -> Simulation:
    """Simulate a measurement campaign on a robot with planted errors.

    errors: a spec for :func:`planted_errors` or a {parameter: value} dict (mm, rad;
    any name of :class:`ParameterSpace`).  noise: σ of the position noise per axis
    (mm).  angle_noise: σ of the orientation noise per axis (rad).  joint_noise: σ
    (rad) of Gaussian differences between commanded and actual joints;
    joint_noise_uniform: half-width (rad) of uniform ones (Wen 2019 adds U(−0.1, 0.1)
    rad).  The file records the commanded joints.  base/tool: the true measuring frame
    → base and flange → point as (x, y, z[, rx, ry, rz]) in mm and rad, replacing the
    robot's own.  q: joint sets to use instead of random ones (rad).
    """
    if measure not in ("pose", "position"):
        raise InputError("must be 'pose' or 'position'", source="--measure")
    if n_poses < 1 and q is None:
        raise InputError("need at least one pose", source="--poses")
    rng = np.random.default_rng(seed)
    space = ParameterSpace.of(robot)
    err = planted_errors(robot, errors, rng) if isinstance(errors, str) else dict(errors)
    try:
        truth = space.apply(space.vector(err))
    except KeyError as exc:
        raise InputError(f"unknown parameter {exc.args[0]}", source="errors") from None
    if base is not None:
        truth = truth.replace(base=_frame(base))
    if tool is not None:
        truth = truth.replace(tool=_frame(tool))
    q_cmd = random_joints(robot, n_poses, rng, joint_range) if q is None else np.asarray(q, float)
    q_act = q_cmd.copy()
    if joint_noise > 0:
        q_act = q_act + rng.normal(0.0, joint_noise, q_cmd.shape)
    if joint_noise_uniform > 0:
        q_act = q_act + rng.uniform(-joint_noise_uniform, joint_noise_uniform, q_cmd.shape)
    T = truth.fk(q_act)
    pos = T[:, :3, 3] + (rng.normal(0.0, noise, (len(q_cmd), 3)) if noise > 0 else 0.0)
    rot = None
    if measure == "pose":
        rot = T[:, :3, :3]
        if angle_noise > 0:
            rot = exp_so3(rng.normal(0.0, angle_noise, (len(q_cmd), 3))) @ rot
    meas = Measurements(q=q_cmd, position=pos, rotation=rot, source="<simulated>")
    return Simulation(meas, truth, err)


def _frame(values) -> np.ndarray:
    v = [float(x) for x in values]
    if len(v) not in (3, 6):
        raise InputError("a frame is x,y,z or x,y,z,rx,ry,rz", source="frame")
    return xyz_rpy_to_transform(v[:3], v[3:] if len(v) == 6 else [0.0, 0.0, 0.0])
