"""Evaluating a robot model on measured data: the error metrics of SPEC §8."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from .exceptions import InputError
from .io.measurements import load_measurements
from .io.robotfile import load_robot
from .model.measurements import Measurements
from .model.metrics import Metrics
from .model.robot import Robot


def evaluate(robot: str | Path | Robot, data: str | Path | Measurements, *,
             columns: Mapping[str, str] | None = None) -> Metrics:
    """Error metrics of ``robot`` (file, built-in name or Robot) on ``data`` (file or Measurements)."""
    r = load_robot(robot)
    meas = data if isinstance(data, Measurements) else load_measurements(data, n_joints=r.n_joints, columns=columns,
                                                                          robot_label=r.source)
    missing = [t for t in meas.target_names if t and t not in r.targets]
    if missing:
        raise InputError(f"target '{missing[0]}' has no tool frame in the robot {r.source or r.name}",
                         source=meas.source)
    return Metrics.of(r, meas)
