"""Goal files of a compensation: where the robot should go (CSV).

Columns ``q1..qn`` (deg: go where the nominal model says these joints go) and/or
``x, y, z[, rx, ry, rz]`` (mm, deg: a pose in the robot base frame, with the optional
joints as starting guess and configuration branch); optional ``pose_id`` names the rows and
``target`` places a reflector of the calibrated model (by its name) at the goal instead of the
tool centre point.

An ISO 9283 plan (``robocal iso9283 plan``: ``pose, cycle, q1..qn, cx, cy, cz, crx, cry, crz``) is a
goals file as it is: its commanded poses are the goals, its joints their start, and the compensated
commands keep each row's pose and cycle, so that the measured campaign is read by ``iso9283 evaluate``.
For a model with joint terms, ``tau1..tauN`` (N·m) give the joint torques at each goal and
``payload`` (kg) its payload, as in measurement files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .atomic import read_text
from .measurements import ReadOptions, euler_rotation, joints_from_file, read_pose_table


@dataclass
class Goals:
    """Goals of a compensation: q (m, n) rad and/or poses (position mm, rotation) in the base frame."""

    q: np.ndarray | None
    position: np.ndarray | None
    rotation: np.ndarray | None
    ids: list[str]
    source: str = "<goals>"
    torques: np.ndarray | None = None
    payload: np.ndarray | None = None
    targets: list[str] | None = None
    directions: np.ndarray | None = None
    time: np.ndarray | None = None
    #: an ISO 9283 plan's cycle of each goal (its ``ids`` the poses), None for other goals
    cycles: list[str] | None = None

    @property
    def n(self) -> int:
        return len(self.ids)


#: an ISO 9283 plan's columns and the goals' they are
ISO_PLAN = {"pose": "pose_id", "cx": "x", "cy": "y", "cz": "z", "crx": "rx", "cry": "ry", "crz": "rz"}


def _iso_plan(text: str, delimiter: str) -> tuple[str, list[str] | None]:
    """An ISO 9283 plan's text as a goals file's (its pose the goal's id, its commanded pose the goal,
    its cycle set aside), and each row's cycle; other text as it is, and None."""
    import csv
    import io

    sep = "\t" if delimiter == "tab" else " " if delimiter == "space" else delimiter
    rows = list(csv.reader(io.StringIO(text), delimiter=sep))
    if not rows or not {"pose", "cycle", "cx"} <= {h.strip() for h in rows[0]}:
        return text, None
    header = [h.strip() for h in rows[0]]
    at = header.index("cycle")
    out = io.StringIO()
    w = csv.writer(out, delimiter=sep, lineterminator="\n")
    w.writerow([ISO_PLAN.get(h, h) for i, h in enumerate(header) if i != at])
    for row in rows[1:]:
        if any(cell.strip() for cell in row):
            w.writerow([c for i, c in enumerate(row) if i != at])
    return out.getvalue(), [row[at].strip() for row in rows[1:] if any(cell.strip() for cell in row)]


def parse_goals(text: str, *, source: str = "<goals>", **options) -> Goals:
    """Goals from CSV text; options are those of :class:`~robocal.io.measurements.ReadOptions`."""
    read = ReadOptions(**options)
    text, cycles = _iso_plan(text, read.delimiter) if read.columns is None else (text, None)
    t = read_pose_table(text, source=source, options=read, require_joints=False, require_position=False)
    ids = t.pose_ids if t.pose_ids is not None else [str(r) for r in t.rows]
    return Goals(
        q=None if t.q is None else joints_from_file(t.q, read.prismatic),
        position=t.position,
        rotation=None if t.rpy is None else euler_rotation(t.rpy, read.euler),
        ids=list(ids),
        source=source,
        torques=t.torques,
        payload=t.payload,
        targets=t.targets,
        directions=t.directions,
        time=t.time,
        cycles=cycles,
    )


def load_goals(path: str | Path, **options) -> Goals:
    return parse_goals(read_text(path, "goals file"), source=str(path), **options)
