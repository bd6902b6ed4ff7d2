"""A learned correction of what the parametric model leaves: a Gaussian process in joint space.

The correction δ(q) = [δp (3) mm, δr (3) rad] is added to the model's pose in the measuring
frame: p ← p + δp, R ← Exp(δr) R.  It is fitted by :mod:`robocal.calibration.residual`
(scikit-learn's GaussianProcessRegressor); predicting needs only what is stored here,
without pickle: the training inputs, the dual coefficients, and the kernel's parameters.

Kernel: c² · exp(−½ Σ_i ((q_i − q'_i)/ℓ_i)²) on the commanded joint angles (rad), with one
length scale per joint; targets are standardised (mean, scale) before the fit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..math.so3 import exp_so3


@dataclass(frozen=True, eq=False)
class ResidualModel:
    """X (N, n) training joints rad; alpha (N, T) dual coefficients; length_scales (n,) rad;
    amplitude c² (dimensionless, of the standardised targets); y_mean, y_scale (T,) in mm and
    rad; T = 3 (position) or 6 (position and orientation)."""

    X: np.ndarray
    alpha: np.ndarray
    length_scales: np.ndarray
    amplitude: float
    y_mean: np.ndarray
    y_scale: np.ndarray

    def predict(self, q: np.ndarray) -> np.ndarray:
        """δ (m, T) at commanded joints q (m, n) rad; computed in blocks to bound memory."""
        q = np.atleast_2d(np.asarray(q, float))
        out = np.empty((len(q), self.alpha.shape[1]))
        Xs = self.X / self.length_scales
        for start in range(0, len(q), 4096):
            d = q[start:start + 4096] / self.length_scales
            sq = np.sum(d * d, 1)[:, None] + np.sum(Xs * Xs, 1)[None, :] - 2 * d @ Xs.T
            K = self.amplitude * np.exp(-0.5 * np.maximum(sq, 0.0))
            out[start:start + 4096] = K @ self.alpha
        return out * self.y_scale + self.y_mean

    def correct(self, q: np.ndarray, R: np.ndarray, p: np.ndarray):
        """The pose (R (m, 3, 3), p (m, 3) mm) with the correction at q added."""
        d = self.predict(q)
        p = p + d[:, :3]
        if d.shape[1] == 6:
            R = exp_so3(d[:, 3:]) @ R
        return R, p

    def to_dict(self) -> dict:
        return {"kind": "gaussian process, RBF on joint angles (rad)", "length_scales_rad": self.length_scales.tolist(),
                "amplitude": self.amplitude, "y_mean": self.y_mean.tolist(), "y_scale": self.y_scale.tolist(),
                "X": self.X.tolist(), "alpha": self.alpha.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> ResidualModel:
        return cls(np.array(d["X"], float), np.array(d["alpha"], float), np.array(d["length_scales_rad"], float),
                   float(d["amplitude"]), np.array(d["y_mean"], float), np.array(d["y_scale"], float))

    def save(self, path: str | Path) -> None:
        from ..io.atomic import atomic_write

        atomic_write(path, json.dumps(self.to_dict()) + "\n")
