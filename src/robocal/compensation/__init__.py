"""Compensation: joint commands and Cartesian goals that make the real robot land on its goals.

- :mod:`.ik` — batched damped-least-squares inverse kinematics with statuses.
- :mod:`.commands` — :func:`compensate`: nominal and calibrated model → commands.
"""

from .commands import CompensationResult, compensate

__all__ = ["CompensationResult", "compensate"]
