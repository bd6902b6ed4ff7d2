"""The covariance of a calibrated model's parameters, as the model carries it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class ParameterCovariance:
    """The covariance (k, k) of a calibrated model's parameters ``names`` (the deviations it
    identified: mm, rad, joint terms in their own units), from its calibration."""

    names: tuple[str, ...]
    matrix: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "matrix", np.asarray(self.matrix, float))
