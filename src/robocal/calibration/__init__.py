"""Calibration: configuration, residuals, identifiability, statistics, methods, the pipeline.

- :mod:`.config` — :class:`CalibrationConfig`, every option validated once.
- :mod:`.problem` — residuals, Jacobians and swarm objectives.
- :mod:`.registration` — closed-form guesses of the measuring frame and tools.
- :mod:`.identifiability` — the identifiable subset and the reasons for the rest.
- :mod:`.methods` — LM, swarms and hybrid on those parameters.
- :mod:`.statistics` — covariance, F-test, outliers.
- :mod:`.pipeline` — :func:`calibrate`, the named steps.
- :mod:`.result` — :class:`CalibrationResult` and its JSON.
"""

from .config import CalibrationConfig
from .pipeline import calibrate
from .result import CalibrationResult

__all__ = ["CalibrationConfig", "CalibrationResult", "calibrate"]
