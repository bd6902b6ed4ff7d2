"""Which deviation parameters a calibration offers by default (before identifiability)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from .kinematics import joint_parameter_names
from .parameters import FRAME_AXES, tool_prefix
from .robot import Robot

#: what a calibration estimates besides the joints: nothing, the measuring frame, it and the tools,
#: or the tools alone, ``tcp`` (data that touched unknown points or planes cannot see the base)
FRAME_MODES = ("none", "base", "base+tool", "tcp")
#: ``auto``: registered when the data are not in the robot's frame (see calibration.registration)
FRAME_CHOICES = ("auto",) + FRAME_MODES


def parallel_pairs(robot: Robot) -> list[int]:
    """0-based joints whose axis is nominally parallel to the next one (α ≡ 0 mod π, dh/hayati;
    none for urdf, whose origins carry all six errors already)."""
    if robot.convention == "urdf":
        return []
    if robot.convention == "craig":
        # row i+1 holds α_i, the twist between axes i and i+1
        return [i for i in range(robot.n_joints - 1) if abs(math.remainder(robot.alpha[i + 1], math.pi)) < 1e-9]
    return [i for i, a in enumerate(robot.alpha[:-1]) if abs(math.remainder(a, math.pi)) < 1e-9]


def complete(robot: Robot) -> Robot:
    """A standard-DH robot with consecutive parallel axes as the same robot in the hayati
    convention (DH + β, identical at β = 0): β is the misalignment of parallel axes that d
    cannot express.  Other robots as they are."""
    if robot.convention != "dh" or not parallel_pairs(robot):
        return robot
    return robot.replace(convention="hayati")


def joint_candidates(robot: Robot) -> list[str]:
    """Default candidate joint parameters: a, α, θ, d of every joint, plus β of hayati joints
    whose axis is parallel to the next one (where β replaces the ill-defined d); for urdf the
    six errors of every joint origin and the joint's zero (identifiability drops what merges)."""
    names = [n for joint in joint_parameter_names(robot.convention, robot.geometry) for n in joint
             if not n.startswith("beta")]
    if robot.convention == "hayati":
        names += [f"beta{i + 1}" for i in parallel_pairs(robot)]
    return names


def zero_candidates(robot: Robot) -> list[str]:
    """Each joint's zero: the parameter its joint value adds to (θ, or d where it slides; a URDF
    joint's offset), the classic few a camera calibration of a hand-eye kind estimates."""
    from .kinematics import joint_value_columns

    columns = joint_value_columns(robot.convention, robot.geometry)
    return [names[c] for names, c in zip(joint_parameter_names(robot.convention, robot.geometry), columns)]


def frame_candidates(mode: str, targets: Sequence[str], full_pose: bool) -> list[str]:
    """Frame parameters of a frames mode: 6 for the base, 3 (position data) or 6 per tool."""
    names = []
    if mode in ("base", "base+tool"):
        names += [f"base_{a}" for a in FRAME_AXES]
    if mode in ("base+tool", "tcp"):
        axes = FRAME_AXES if full_pose else FRAME_AXES[:3]
        for t in targets:
            names += [f"{tool_prefix(t)}_{a}" for a in axes]
    return names
