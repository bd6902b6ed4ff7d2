"""Calibration: configuration, residuals, identifiability, statistics, methods, the pipeline.

- :mod:`.config` — :class:`CalibrationConfig`, every option validated once.
- :mod:`.problem` — residuals, Jacobians and swarm objectives.
- :mod:`.registration` — closed-form guesses of the measuring frame and tools.
- :mod:`.identifiability` — the identifiable subset and the reasons for the rest.
- :mod:`.methods` — LM, swarms and hybrid on those parameters.
- :mod:`.statistics` — covariance, F-test, outliers.
- :mod:`.inputs`, :mod:`.subset`, :mod:`.screening`, :mod:`.weighting`, :mod:`.judgement`,
  :mod:`.parametric` — the steps of one parametric fit, one module each.
- :mod:`.crossval`, :mod:`.learned`, :mod:`.choice`, :mod:`.selection`, :mod:`.guard` —
  held-out folds, learned corrections, the paired choice, the ladder, the final check.
- :mod:`.pipeline` — :func:`calibrate`, the named steps.
- :mod:`.result` — :class:`CalibrationResult` and its JSON.
"""

from .config import CalibrationConfig
from .pipeline import calibrate
from .result import CalibrationResult

__all__ = ["CalibrationConfig", "CalibrationResult", "calibrate"]
