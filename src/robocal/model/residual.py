"""A learned correction of what the parametric model leaves: Gaussian processes in joint space.

The correction δ(q) = [δp (3) mm, δr (3) rad] is added to the model's pose in the measuring
frame: p ← p + δp, R ← Exp(δr) R.  It is fitted by :mod:`robocal.calibration.residual`
(scikit-learn's GaussianProcessRegressor); predicting needs only what is stored here,
without pickle: the training inputs, the dual coefficients, and the kernels' parameters.

Each block of outputs (positions; orientations for full-pose data) has its own kernel
c² · exp(−½ Σ_i ((q_i − q'_i)/ℓ_i)²) on the commanded joint angles (rad), one length scale per
joint, and its targets standardised (mean, scale) before the fit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..math.so3 import exp_so3


@dataclass(frozen=True, eq=False)
class Block:
    """One kernel and the outputs it predicts: alpha (N, t) dual coefficients; length_scales (n,)
    rad; amplitude c² of the standardised targets; y_mean, y_scale (t,) in the outputs' units."""

    alpha: np.ndarray
    length_scales: np.ndarray
    amplitude: float
    y_mean: np.ndarray
    y_scale: np.ndarray

    def predict(self, X: np.ndarray, q: np.ndarray) -> np.ndarray:
        Xs, d = X / self.length_scales, q / self.length_scales
        sq = np.sum(d * d, 1)[:, None] + np.sum(Xs * Xs, 1)[None, :] - 2 * d @ Xs.T
        return (self.amplitude * np.exp(-0.5 * np.maximum(sq, 0.0))) @ self.alpha * self.y_scale + self.y_mean

    def to_dict(self) -> dict:
        return {"length_scales_rad": self.length_scales.tolist(), "amplitude": self.amplitude,
                "y_mean": self.y_mean.tolist(), "y_scale": self.y_scale.tolist(), "alpha": self.alpha.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Block:
        return cls(np.array(d["alpha"], float), np.array(d["length_scales_rad"], float), float(d["amplitude"]),
                   np.array(d["y_mean"], float), np.array(d["y_scale"], float))


@dataclass(frozen=True, eq=False)
class ResidualModel:
    """X (N, n) training joints rad; blocks: the position block (3 outputs, mm) and, for
    full-pose data, the orientation block (3 outputs, rad)."""

    X: np.ndarray
    blocks: tuple[Block, ...]

    @property
    def outputs(self) -> int:
        return sum(b.alpha.shape[1] for b in self.blocks)

    def predict(self, q: np.ndarray) -> np.ndarray:
        """δ (m, 3 or 6) at commanded joints q (m, n) rad; computed in chunks to bound memory."""
        q = np.atleast_2d(np.asarray(q, float))
        out = np.empty((len(q), self.outputs))
        for start in range(0, len(q), 4096):
            chunk = q[start:start + 4096]
            out[start:start + 4096] = np.concatenate([b.predict(self.X, chunk) for b in self.blocks], axis=1)
        return out

    def correct(self, q: np.ndarray, R: np.ndarray, p: np.ndarray):
        """The pose (R (m, 3, 3), p (m, 3) mm) with the correction at q added."""
        d = self.predict(q)
        p = p + d[:, :3]
        if d.shape[1] == 6:
            R = exp_so3(d[:, 3:]) @ R
        return R, p

    def to_dict(self) -> dict:
        return {"kind": "gaussian processes, RBF on the joint angles (rad)", "X": self.X.tolist(),
                "blocks": [b.to_dict() for b in self.blocks]}

    @classmethod
    def from_dict(cls, d: dict) -> ResidualModel:
        return cls(np.array(d["X"], float), tuple(Block.from_dict(b) for b in d["blocks"]))

    def save(self, path: str | Path) -> None:
        from ..io.atomic import atomic_write

        atomic_write(path, json.dumps(self.to_dict()) + "\n")
