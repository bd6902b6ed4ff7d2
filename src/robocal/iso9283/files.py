"""ISO 9283 files: the command sequence a test plan writes, and the measured campaigns it reads.

Plan file (written): ``pose, cycle, q1..qN`` (deg, mm for a sliding joint) and the commanded
pose ``cx, cy, cz`` (mm) ``crx, cry, crz`` (deg, R = Rz(crz) Ry(cry) Rx(crx)) in the robot's
base frame, one row per pose and cycle in the order the robot runs them.

Measured file (read): ``pose`` (a label such as P1), ``cycle``, the measured ``x, y, z`` (mm)
and optionally ``rx, ry, rz`` (deg); the commanded pose as ``cx, cy, cz`` [``crx, cry, crz``],
or as joints ``q1..qN`` with a robot whose nominal model gives the pose.  Measured and
commanded poses must be in one frame (the robot's base frame, as the standard states them;
with joints, the robot file's [base] puts the commanded poses in the measuring frame).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..io.atomic import read_text
from ..io.measurements import joints_from_file, joints_to_file
from ..io.table import numbers, read_csv, strings
from ..math.so3 import matrix_to_rpy, rpy_to_matrix
from .characteristics import Campaign
from .cube import TestPlan

#: commanded poses of one label that differ more than this between cycles are not one pose (mm, deg)
SAME_POSE_MM = 1e-3
#: the columns ``robocal compensate`` adds to an ISO plan's commands: read past, as the commands are
COMPENSATED = ("residual_mm", "residual_deg", "dq_max_deg", "status", "reason", "true_error_before_mm",
               "true_error_after_mm", "send_x", "send_y", "send_z", "send_rx", "send_ry", "send_rz")
#: magnitudes beyond which a value is a typo (mm, deg)
MAX_MM, MAX_DEG = 1e7, 36_000.0


def _short(value: float, decimals: int) -> str:
    """A command's number to ``decimals`` places (nm, nano-degrees: far below any robot's resolution), so
    that 2.4999999999999973 reads 2.5 and no zero has a sign."""
    return repr(round(float(value), decimals) + 0.0)


def plan_csv(plan: TestPlan, cycles: int, prismatic=None) -> str:
    """The command sequence: ``cycles`` cycles of P1..P5."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    n = plan.q.shape[1]
    w.writerow(["pose", "cycle", *(f"q{i + 1}" for i in range(n)), "cx", "cy", "cz", "crx", "cry", "crz"])
    qfile = joints_to_file(plan.q, prismatic)
    rpy = plan.rpy_deg()
    for c in range(1, cycles + 1):
        for k, label in enumerate(plan.labels):
            w.writerow([label, c, *(_short(v, 9) for v in qfile[k]), *(_short(v, 6) for v in plan.position[k]),
                        *(_short(v, 9) for v in rpy)])
    return out.getvalue()


def load_commands(path: str | Path, n_joints: int, prismatic=None):
    """An ISO 9283 command file (a plan, or its compensated commands): each row's pose label, cycle,
    joints (m, n) rad, and commanded pose (m, 6: mm, deg) — what a simulated campaign runs."""
    source = str(path)
    table = read_csv(read_text(path, "ISO 9283 command file"), source=source)
    columns = [f"q{i + 1}" for i in range(n_joints)]
    table.require(["pose", "cycle", *columns, "cx", "cy", "cz", "crx", "cry", "crz"])
    q = joints_from_file(numbers(table, columns, MAX_DEG, "deg"), prismatic)
    commanded = np.column_stack([numbers(table, ["cx", "cy", "cz"], MAX_MM, "mm"),
                                 numbers(table, ["crx", "cry", "crz"], MAX_DEG, "deg")])
    return strings(table, "pose", required=True), strings(table, "cycle", required=True), q, commanded


def campaign_csv(labels, cycles, measured: np.ndarray, rpy_deg: np.ndarray | None, commanded: np.ndarray) -> str:
    """A measured campaign as :func:`load_campaign` reads it: pose, cycle, x, y, z [rx, ry, rz] (mm, deg) and
    the commanded cx … crz."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    turned = rpy_deg is not None
    w.writerow(["pose", "cycle", "x", "y", "z", *(("rx", "ry", "rz") if turned else ()), "cx", "cy", "cz", "crx",
                "cry", "crz"])
    for k, (label, cycle) in enumerate(zip(labels, cycles)):
        w.writerow([label, cycle, *(repr(float(v)) for v in measured[k]),
                    *((repr(float(v)) for v in rpy_deg[k]) if turned else ()), *(repr(float(v)) for v in commanded[k])])
    return out.getvalue()


def _abc(rpy_deg: np.ndarray) -> np.ndarray:
    """a, b, c (deg) of rpy angles, on one branch (so that two spellings of a rotation agree)."""
    return np.degrees(matrix_to_rpy(rpy_to_matrix(np.radians(rpy_deg))))


def load_campaign(path: str | Path, robot=None) -> Campaign:
    """A measured campaign (see the module docstring); ``robot`` (a Robot) for joint commands."""
    source = str(path)
    table = read_csv(read_text(path, "measurement file"), source=source)
    table.require(["pose", "cycle", "x", "y", "z"])
    known = {"pose", "cycle", "x", "y", "z", "rx", "ry", "rz", "cx", "cy", "cz", "crx", "cry", "crz"}
    for h in table.header:
        if h in COMPENSATED:  # a compensated command file with the measured x, y, z added
            continue
        if h not in known and not (h.startswith("q") and h[1:].isdigit()):
            raise InputError(f"unknown column '{h}' (expected pose, cycle, x, y, z, optional rx, ry, rz, and the "
                             "commanded cx, cy, cz [crx, cry, crz] or q1..qN)", source=source)
    labels, cycles = strings(table, "pose", required=True), strings(table, "cycle", required=True)
    measured = numbers(table, ["x", "y", "z"], MAX_MM, "mm")
    orientation = table.together(("rx", "ry", "rz"), "orientation")
    m_abc = _abc(numbers(table, ["rx", "ry", "rz"], MAX_DEG, "deg")) if orientation else None
    joints = [h for h in table.header if h.startswith("q") and h[1:].isdigit()]
    if "cx" in table:
        table.require(["cx", "cy", "cz"])
        commanded = numbers(table, ["cx", "cy", "cz"], MAX_MM, "mm")
        turned = table.together(("crx", "cry", "crz"), "commanded orientation")
        c_abc = _abc(numbers(table, ["crx", "cry", "crz"], MAX_DEG, "deg")) if turned else None
    elif joints:
        if robot is None:
            raise InputError("the commanded poses are given as joints: name the robot whose nominal model turns them "
                             "into poses (--robot)", source=source)
        if len(joints) != robot.n_joints:
            raise InputError(f"{len(joints)} joint columns for a robot with {robot.n_joints} joints", source=source)
        q = joints_from_file(numbers(table, [f"q{i + 1}" for i in range(robot.n_joints)], MAX_DEG, "deg"),
                             tuple(bool(p) for p in robot.prismatic) if robot.prismatic.any() else None)
        T = robot.replace(residual=None).fk(q)
        commanded, c_abc = T[:, :3, 3], np.degrees(matrix_to_rpy(T[:, :3, :3]))
    else:
        raise InputError("no commanded poses: give cx, cy, cz [crx, cry, crz] or joints q1..qN with --robot",
                         source=source)
    if orientation and c_abc is None:
        orientation = False  # measured orientations without commanded ones: position characteristics only
    poses = tuple(dict.fromkeys(labels))
    cycle_ids = tuple(dict.fromkeys(cycles))
    index = {}
    for row, key in enumerate(zip(labels, cycles)):
        if key in index:
            raise InputError(f"pose {key[0]} cycle {key[1]} appears twice", source=source,
                             where=f"row {int(table.lines[row])}")
        index[key] = row
    missing = [(p, c) for p in poses for c in cycle_ids if (p, c) not in index]
    if missing:
        raise InputError(f"pose {missing[0][0]} has no row for cycle {missing[0][1]}: every pose is measured in "
                         "every cycle", source=source)
    if len(cycle_ids) < 2:
        raise InputError("repeatability needs at least 2 cycles of each pose (ISO 9283: 30)", source=source)
    rows = np.array([[index[(p, c)] for c in cycle_ids] for p in poses])  # (P, C)
    first = rows[:, 0]
    spread = np.max(np.linalg.norm(commanded[rows] - commanded[first][:, None], axis=2), axis=1)
    if np.any(spread > SAME_POSE_MM):
        k = int(np.argmax(spread))
        raise InputError(f"pose {poses[k]} is commanded at places {spread[k]:.3g} mm apart in different cycles",
                         source=source)
    return Campaign(Path(source).stem, poses, cycle_ids, measured[rows], commanded[first],
                    m_abc[rows] if orientation else None, c_abc[first] if orientation else None)
