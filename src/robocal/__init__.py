"""robocal: calibration and error compensation of robots.

The command line (``robocal``) is a thin layer over this API::

    import robocal
    robot = robocal.load_robot("er10l-c10")
    sim = robocal.simulate(robot, 32, deviations="paper", noise=0.02, seed=1)
    result = robocal.calibrate(robot, sim.measurements, method="lm")
    print(result.metrics["before"].position, result.metrics["after"].position)

Importing robocal loads nothing heavy: the names below are imported on first use.
Architecture: see docs/ARCHITECTURE.md.
"""

from __future__ import annotations

import importlib

__version__ = "0.3.0"

_EXPORTS = {
    "CalibrationConfig": "robocal.calibration.config",
    "CalibrationResult": "robocal.calibration.result",
    "calibrate": "robocal.calibration.pipeline",
    "compensate": "robocal.compensation.commands",
    "evaluate": "robocal.evaluation",
    "InputError": "robocal.exceptions",
    "RobocalWarning": "robocal.exceptions",
    "Measurements": "robocal.model.measurements",
    "Metrics": "robocal.model.metrics",
    "ParameterSpace": "robocal.model.parameters",
    "Robot": "robocal.model.robot",
    "builtin_names": "robocal.io.builtins",
    "load_robot": "robocal.io.robotfile",
    "save_robot": "robocal.io.robotfile",
    "load_measurements": "robocal.io.measurements",
    "save_measurements": "robocal.io.measurements",
    "load_goals": "robocal.io.goals",
    "pose_errors": "robocal.model.metrics",
    "plan_poses": "robocal.plan.design",
    "reproduce": "robocal.papers.reproduce",
    "simulate": "robocal.simulation",
    "write_report": "robocal.report.html",
    "parse_urdf": "robocal.io.urdf",
    "urdf_text": "robocal.io.urdf",
    "load_study": "robocal.study.spec",
    "run_study": "robocal.study.driver",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'robocal' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
