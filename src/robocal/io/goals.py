"""Goal files of a compensation: where the robot should go (CSV).

Columns ``q1..qn`` (deg: go where the nominal model says these joints go) and/or
``x, y, z[, rx, ry, rz]`` (mm, deg: a pose in the robot base frame, with the optional
joints as starting guess and configuration branch); optional ``pose_id`` names the rows and
``target`` places a reflector of the calibrated model (by its name) at the goal instead of the
tool centre point.
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

    @property
    def n(self) -> int:
        return len(self.ids)


def parse_goals(text: str, *, source: str = "<goals>", **options) -> Goals:
    """Goals from CSV text; options are those of :class:`~robocal.io.measurements.ReadOptions`."""
    read = ReadOptions(**options)
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
    )


def load_goals(path: str | Path, **options) -> Goals:
    return parse_goals(read_text(path, "goals file"), source=str(path), **options)
