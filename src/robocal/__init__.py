"""robocal: geometric calibration and error compensation of robots.

The command line (``robocal``) is a thin layer over this API::

    import robocal
    robot = robocal.load_robot("er10l-c10")
    sim = robocal.simulate(robot, 32, errors="paper", noise=0.02, seed=1)
    result = robocal.calibrate(robot, sim.measurements, method="lm")
    print(result.metrics["before"].position, result.metrics["after"].position)
"""

from .calibration import CalibrationResult, calibrate
from .errors import InputError, RobocalWarning
from .kinematics import Robot
from .measurements import Measurements, load_measurements, save_measurements
from .metrics import Metrics, pose_errors
from .parameters import ParameterSpace
from .robotfile import builtin_names, load_robot, save_robot
from .simulate import simulate

__all__ = [
    "CalibrationResult",
    "calibrate",
    "InputError",
    "Measurements",
    "Metrics",
    "ParameterSpace",
    "Robot",
    "RobocalWarning",
    "builtin_names",
    "load_measurements",
    "load_robot",
    "pose_errors",
    "save_measurements",
    "save_robot",
    "simulate",
]

__version__ = "0.1.0"
