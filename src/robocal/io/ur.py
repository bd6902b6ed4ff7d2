"""Universal Robots calibrations: the kinematics YAML the UR ROS drivers extract from a
controller, and the controller's own DH delta form, read as robots; a calibrated model written
back as kinematics YAML for a ROS driver.

**Kinematics YAML** (``ur_calibration``'s output, ``ur_description``'s
``default_kinematics.yaml``)::

    kinematics:
      shoulder:  {x: 0, y: 0, z: 0.1273, roll: 0, pitch: 0, yaw: 0}   # m, rad
      upper_arm: …
      forearm: …
      wrist_1: …
      wrist_2: …
      wrist_3: …
      hash: calib_…

Each segment is a joint's origin in the frame before it, Trans(x, y, z) · Rz(yaw) Ry(pitch)
Rx(roll) (URDF's rpy), then the joint turns about its z axis; the chain runs from the base
frame of the controller's model to the flange.  robocal reads it as a robot of the ``urdf``
convention with exactly that chain (lengths in mm), and writes any six-joint model back by
folding what commutes with each joint's turn (a DH θ and d, a urdf joint's zero) into that
joint's origin; what follows the last joint's turn (a DH a6, α6) has no place in the YAML and
is said, for the controller's TCP.

**DH deltas** (the controller's ``calibration.conf``): per joint ``delta_a``, ``delta_d``
(m), ``delta_alpha``, ``delta_theta`` (rad), lists of six, added to a nominal standard-DH
model (a built-in ``ur10`` or a robot file).
"""

from __future__ import annotations

import math
import re

import numpy as np

from ..exceptions import InputError
from ..math.se3 import homogeneous, invert
from ..math.so3 import matrix_to_rpy, rpy_to_matrix
from ..model import urdf as U
from ..model.kinematics import chain_pose
from ..model.robot import Robot

SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
JOINT_NAMES = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
               "wrist_3_joint")
KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
DELTAS = ("delta_a", "delta_d", "delta_alpha", "delta_theta")
#: UR joints turn ±360°
LIMIT = math.radians(360.0)
#: what is left after the last joint below this counts as nothing (mm, rad)
LEFTOVER_MM, LEFTOVER_RAD = 1e-9, 1e-12


def _mapping(text: str, source: str) -> dict:
    """The nested mappings of scalars a kinematics YAML holds (block or flow style), by
    indentation; enough YAML for this file and nothing more."""
    root: dict = {}
    stack: list[tuple[int, dict]] = [(-1, root)]
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip() or line.strip() in ("---", "..."):
            continue
        indent = len(line) - len(line.lstrip())
        m = re.fullmatch(r"\s*([A-Za-z_][\w]*)\s*:\s*(.*)", line)
        if not m:
            raise InputError(f"cannot read {line.strip()!r} (expected key: value)", source=source,
                             where=f"line {number}")
        key, value = m.group(1), m.group(2).strip()
        while stack and indent <= stack[-1][0]:
            stack.pop()
        parent = stack[-1][1]
        if value.startswith("{") and value.endswith("}"):
            inner = {}
            for part in filter(None, (p.strip() for p in value[1:-1].split(","))):
                k, _, v = part.partition(":")
                inner[k.strip()] = v.strip()
            parent[key] = inner
        elif value == "":
            parent[key] = {}
            stack.append((indent, parent[key]))
        else:
            parent[key] = value.strip("'\"")
    return root


def _number(value, source: str, where: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{value!r} is not a number", source=source, where=where) from None
    if not math.isfinite(x):
        raise InputError(f"{value!r} is not finite", source=source, where=where)
    return x


def parse_ur_kinematics(text: str, *, source: str = "<kinematics>") -> Robot:
    """A robot (``urdf`` convention, mm) of a UR kinematics YAML: its chain exactly."""
    data = _mapping(text, source)
    kin = data.get("kinematics")
    if not isinstance(kin, dict):
        raise InputError("expected a 'kinematics:' mapping with shoulder, upper_arm, forearm, wrist_1, wrist_2, "
                         "wrist_3", source=source)
    unknown = set(kin) - set(SEGMENTS) - {"hash"}
    if unknown:
        raise InputError(f"unknown segment '{sorted(unknown)[0]}' (expected {', '.join(SEGMENTS)}, hash)",
                         source=source, where="kinematics")
    geom = np.zeros((6, U.WIDTH))
    for i, seg in enumerate(SEGMENTS):
        values = kin.get(seg)
        if not isinstance(values, dict):
            raise InputError(f"missing segment '{seg}'", source=source, where="kinematics")
        bad = set(values) - set(KEYS)
        if bad or set(KEYS) - set(values):
            key = sorted(bad or (set(KEYS) - set(values)))[0]
            raise InputError(f"{'unknown' if bad else 'missing'} key '{key}' (expected {', '.join(KEYS)})",
                             source=source, where=f"kinematics.{seg}")
        v = [_number(values[k], source, f"kinematics.{seg}.{k}") for k in KEYS]
        for k, x in zip(KEYS, v):  # the file's units are m and rad: say so when its numbers are not
            if k in KEYS[:3] and abs(x) > MAX_SEGMENT_M:
                raise InputError(f"{x:g} m is not a plausible segment of a UR arm (beyond {MAX_SEGMENT_M:g} m): the "
                                 "kinematics YAML holds metres, not millimetres", source=source,
                                 where=f"kinematics.{seg}.{k}")
            if k in KEYS[3:] and abs(x) > 2 * math.pi + 1e-9:
                raise InputError(f"{x:g} is not an angle in radians (beyond 2π): the kinematics YAML holds radians, "
                                 "not degrees", source=source, where=f"kinematics.{seg}.{k}")
        geom[i, U.X:U.Z + 1] = np.array(v[:3]) * 1000.0
        geom[i, U.ROLL:U.YAW + 1] = v[3:]
        geom[i, U.AZ] = 1.0
    label = kin.get("hash") if isinstance(kin.get("hash"), str) else ""
    return Robot("urdf", geom, np.tile([-LIMIT, LIMIT], (6, 1)), name=f"UR (kinematics {label or 'YAML'})",
                 source=source, joint_names=JOINT_NAMES)


def parse_ur_deltas(text: str, nominal: Robot, *, source: str = "<calibration.conf>") -> Robot:
    """``nominal`` (standard DH, six joints) with the DH deltas of a controller's calibration."""
    if nominal.convention != "dh" or nominal.n_joints != 6:
        raise InputError("DH deltas apply to a six-joint standard-DH nominal model (e.g. the built-in ur10)",
                         source=nominal.source or nominal.name)
    found = {}
    for number, raw in enumerate(text.splitlines(), 1):
        m = re.fullmatch(r"\s*(delta_\w+)\s*[=:]\s*\[(.*)\]\s*", raw.split("#", 1)[0])
        if m and m.group(1) in DELTAS:
            parts = [p for p in re.split(r"[,\s]+", m.group(2).strip()) if p]
            if len(parts) != 6:
                raise InputError(f"{m.group(1)} needs 6 values, got {len(parts)}", source=source,
                                 where=f"line {number}")
            found[m.group(1)] = np.array([_number(p, source, f"line {number}") for p in parts])
    missing = [k for k in DELTAS if k not in found]
    if missing:
        raise InputError(f"missing {missing[0]} = [six values]", source=source)
    from ..model.dh import ALPHA, THETA, A, D

    g = nominal.geometry.copy()
    g[:, A] += 1000.0 * found["delta_a"]
    g[:, D] += 1000.0 * found["delta_d"]
    g[:, ALPHA] += found["delta_alpha"]
    g[:, THETA] += found["delta_theta"]
    robot = nominal.replace(geometry=g, name=f"{nominal.name} (controller calibration)", source=source)
    _check_moves(nominal, robot, source)
    return robot


#: a UR segment longer than this (m) is not one: the file is in other units
MAX_SEGMENT_M = 5.0
#: the most a factory calibration moves the flange from the nominal model (mm, deg): UR speaks of
#: centimetres; deltas in millimetres or degrees move it by metres and radians
MAX_MOVE_MM, MAX_TURN_DEG = 100.0, 5.0


def _check_moves(nominal: Robot, robot: Robot, source: str) -> None:
    """Deltas cannot be judged one by one: a controller's calibration holds opposed offsets of
    hundreds of metres along parallel axes that cancel.  What they do to the flange can: over
    joint sets across the ranges, the calibrated model must stay within centimetres and a few
    degrees of the nominal one."""
    q = np.random.default_rng(0).uniform(-math.pi, math.pi, (64, nominal.n_joints))
    A, B = nominal.fk(q), robot.fk(q)
    moved = float(np.max(np.linalg.norm(A[:, :3, 3] - B[:, :3, 3], axis=1)))
    cos = np.clip((np.einsum("mij,mij->m", A[:, :3, :3], B[:, :3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    turned = float(np.degrees(np.max(np.arccos(cos))))
    if not (moved <= MAX_MOVE_MM and turned <= MAX_TURN_DEG):
        raise InputError(f"the deltas move the flange by up to {moved:.4g} mm and {turned:.3g}° from {nominal.name}: "
                         f"not a calibration of it in m and rad (a factory calibration moves it by centimetres; "
                         f"millimetres or degrees, or another robot's nominal model?)", source=source)


def holds(robot: Robot) -> bool:
    """Whether a UR kinematics YAML can hold this robot's joints: six turning joints, one chain, each
    turning about its own z (a URDF's)."""
    return robot.tree is None and robot.n_joints == 6 and not robot.prismatic.any() and \
        (robot.convention != "urdf" or bool(np.allclose(robot.geometry[:, U.AX:U.AZ + 1], [0.0, 0.0, 1.0])))


def joint_origins(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's origin O_i (6, 4, 4) in the frame before it, mm, with the joint turning
    about its z axis after it, and the fixed transform left after the last joint's turn
    (4, 4); the measuring frame ([base]) and the tool are left out."""
    if robot.n_joints != 6 or robot.prismatic.any():
        raise InputError("a UR kinematics YAML holds six turning joints", source=robot.source or robot.name)
    g = robot.geometry
    origins = np.zeros((6, 4, 4))
    previous = np.eye(4)
    if robot.convention == "urdf":
        if not np.allclose(g[:, U.AX:U.AZ + 1], [0.0, 0.0, 1.0]):
            raise InputError("a UR kinematics YAML turns every joint about its z axis; this model's axes differ",
                             source=robot.source or robot.name)
        for i in range(6):
            R = U.origin_rotation(g[i]) @ rpy_to_matrix(np.array([0.0, 0.0, g[i, U.OFFSET]]))
            origins[i] = homogeneous(R, g[i, U.X:U.Z + 1])
        return origins, np.eye(4)
    from ..model.dh import BETA, THETA, D

    for i in range(6):
        before, after = _split(robot.convention, g[i], THETA, D, BETA)
        origins[i] = previous @ before
        previous = after
    return origins, previous


def _split(convention: str, g: np.ndarray, THETA: int, D: int, BETA: int) -> tuple[np.ndarray, np.ndarray]:
    """A DH-family joint as (what commutes with its turn, put before it; what follows it)."""
    if convention == "craig":  # Rx(α) Tx(a) Rz(θ) Tz(d) · Rz(q): all of it before the turn
        R, p = chain_pose(convention, g[None], np.zeros((1, 1)))
        return homogeneous(R[0], p[0]), np.eye(4)
    turn = homogeneous(rpy_to_matrix(np.array([0.0, 0.0, g[THETA]])), np.array([0.0, 0.0, g[D]]))
    R, p = chain_pose(convention, g[None], np.zeros((1, 1)))
    return turn, invert(turn) @ homogeneous(R[0], p[0])  # Tx(a) Rx(α) Ry(β)


def ur_kinematics_yaml(robot: Robot, label: str = "") -> tuple[str, list[str]]:
    """The kinematics YAML of a six-joint model, and what it could not hold of its geometry (notes):
    a flange beyond the last joint's frame.  Joint terms and a learned correction it never holds;
    a calibration's export says so with the figures of each part."""
    origins, leftover = joint_origins(robot)
    notes = []
    if not (np.allclose(leftover[:3, 3], 0.0, atol=LEFTOVER_MM) and
            np.allclose(leftover[:3, :3], np.eye(3), atol=LEFTOVER_RAD)):
        xyz = ", ".join(f"{round(v, 4) + 0.0:g}" for v in leftover[:3, 3])  # + 0.0: no "-0"
        rpy = ", ".join(f"{round(math.degrees(v), 4) + 0.0:g}" for v in matrix_to_rpy(leftover[:3, :3]))
        notes.append(f"the flange sits at xyz ({xyz}) mm, rpy ({rpy}) deg after the last joint's frame: a kinematics "
                     "YAML ends at that frame, so add this offset to the controller's TCP")
    lines = ["kinematics:"]
    g = robot.geometry
    for i, (seg, O) in enumerate(zip(SEGMENTS, origins)):
        lines.append(f"  {seg}:")
        rpy = matrix_to_rpy(O[:3, :3])
        if robot.convention == "urdf" and not np.any(g[i, U.RX:U.OFFSET + 1]):
            rpy = g[i, U.ROLL:U.YAW + 1]  # as read: the same rotation, spelt as the file spelt it
        values = [*(O[:3, 3] / 1000.0), *rpy]
        # a round-off below a picometre or a nano-radian is a zero, and no zero has a sign
        lines += [f"    {k}: {(0.0 if abs(v) < 1e-12 else v)!r}" for k, v in zip(KEYS, map(float, values))]
    lines.append(f"  hash: {label or 'calib_robocal'}")
    return "\n".join(lines) + "\n", notes
