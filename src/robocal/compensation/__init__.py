"""Compensation: joint commands and Cartesian goals that make the real robot land on its goals.

- :mod:`.commands` — :func:`compensate`: nominal and calibrated model → commands, through the
  one inverse kinematics (:mod:`robocal.inverse`) and the one frame algebra (:mod:`robocal.cell`).
"""

from .commands import CompensationResult, compensate

__all__ = ["CompensationResult", "compensate"]
