"""A learned correction of what the parametric model leaves: Gaussian processes in joint space.

The correction δ(q) = [δp (3) mm, δr (3) rad] is learnt in the axes of the measuring frame
it was fitted in (a tracker's own systematic errors live there, and on real data that fits
better than the base axes); it keeps the orientation of those axes in the robot's base
frame, R_o, so that it turns with the base when the robot is measured from elsewhere.  It is
added to the model's pose in the measuring frame as p ← p + R_b R_o δp, R ← Exp(R_b R_o δr) R,
with R_b the base frame's rotation (R_b R_o = I in the calibration's own frame).  It is fitted
by :mod:`robocal.calibration.residual`; predicting
needs only what is stored here, without pickle: the training inputs, the dual coefficients,
and the kernels' parameters.

Each block of outputs (positions; orientations for full-pose data) has its own kernel
c² · exp(−½ Σ_i ((q_i − q'_i)/ℓ_i)²) on the commanded joint angles (rad), one length scale per
joint, and its targets standardised (mean, scale) before the fit.

Its support is its data.  Away from them the process's posterior variance returns to its prior
c² (:meth:`Block.variance`) and its kernel part to zero; the standardisation's constant mean
fades the same way, by the kernel's correlation with the nearest training pose (1 there, 0 far
from all: the posterior variance's own shape, at the cost of the mean's evaluation, where the
variance would need a triangular solve per pose inside every inverse-kinematics step).  Outside
its data the correction contributes nothing, and its variance says how little is known there
(:func:`robocal.model.uncertainty.predicted_sigma`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..math.so3 import exp_so3


def rbf(a: np.ndarray, b: np.ndarray, length_scales: np.ndarray, amplitude: float) -> np.ndarray:
    """The kernel's signal part c · exp(−½ Σ_i ((a_i − b_i)/ℓ_i)²) between joints a (m, n) and
    b (k, n) rad: (m, k)."""
    a, b = a / length_scales, b / length_scales
    sq = np.sum(a * a, 1)[:, None] + np.sum(b * b, 1)[None, :] - 2 * a @ b.T
    return amplitude * np.exp(-0.5 * np.maximum(sq, 0.0))


@dataclass(frozen=True, eq=False)
class Block:
    """One kernel and the outputs it predicts: alpha (N, t) dual coefficients; length_scales (n,)
    rad; amplitude c² of the standardised targets; y_mean, y_scale (t,) in the outputs' units;
    dof: the effective degrees of freedom it took from its training data (all t outputs); noise:
    the white-noise variance (and jitter) of the standardised targets it was conditioned with."""

    alpha: np.ndarray
    length_scales: np.ndarray
    amplitude: float
    y_mean: np.ndarray
    y_scale: np.ndarray
    dof: float = float("nan")
    noise: float = float("nan")

    def _cross(self, X: np.ndarray, q: np.ndarray) -> np.ndarray:
        return rbf(q, X, self.length_scales, self.amplitude)

    def predict(self, X: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The correction at q (m, t): the kernel part, and the mean faded away from the data."""
        k = self._cross(X, q)
        near = k.max(axis=1) / self.amplitude if k.shape[1] else np.zeros(len(q))
        return k @ self.alpha * self.y_scale + np.outer(near, self.y_mean)

    def factor(self, X: np.ndarray):
        """The Cholesky factor of K + noise·I on the training joints X, worked out once."""
        if self.__dict__.get("_chol") is None:
            from scipy.linalg import cholesky

            K = rbf(X, X, self.length_scales, self.amplitude)
            K[np.diag_indices_from(K)] += self.noise
            self.__dict__["_chol"] = cholesky(K, lower=True, overwrite_a=True, check_finite=False)
        return self.__dict__["_chol"]

    def variance(self, X: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The posterior variance (m,) of the standardised signal at q: c² − k*ᵀ(K + noise·I)⁻¹k*,
        c² far from the data (NaN for a block saved without its noise level)."""
        if not np.isfinite(self.noise):
            return np.full(len(q), np.nan)
        from scipy.linalg import solve_triangular

        k = self._cross(X, q)
        v = solve_triangular(self.factor(X), k.T, lower=True, check_finite=False)
        return np.clip(self.amplitude - np.einsum("ij,ij->j", v, v), 0.0, self.amplitude)

    def to_dict(self) -> dict:
        return {"length_scales_rad": self.length_scales.tolist(), "amplitude": self.amplitude,
                "y_mean": self.y_mean.tolist(), "y_scale": self.y_scale.tolist(), "alpha": self.alpha.tolist(),
                **({"dof": self.dof} if np.isfinite(self.dof) else {}),
                **({"noise": self.noise} if np.isfinite(self.noise) else {})}

    @classmethod
    def from_dict(cls, d: dict) -> Block:
        return cls(np.array(d["alpha"], float), np.array(d["length_scales_rad"], float), float(d["amplitude"]),
                   np.array(d["y_mean"], float), np.array(d["y_scale"], float), float(d.get("dof", float("nan"))),
                   float(d.get("noise", float("nan"))))


@dataclass(frozen=True, eq=False)
class ResidualModel:
    """X (N, n) training joints rad; blocks: the position block (3 outputs, mm) and, for
    full-pose data, the orientation block (3 outputs, rad); axes (3, 3): the orientation of the
    outputs' axes in the robot's base frame."""

    X: np.ndarray
    blocks: tuple[Block, ...]
    axes: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def outputs(self) -> int:
        return sum(b.alpha.shape[1] for b in self.blocks)

    @property
    def dof(self) -> float:
        """Effective degrees of freedom taken from the data (every block, every output)."""
        return float(sum(b.dof for b in self.blocks))

    def predict(self, q: np.ndarray) -> np.ndarray:
        """δ (m, 3 or 6) at commanded joints q (m, n) rad; computed in chunks to bound memory."""
        q = np.atleast_2d(np.asarray(q, float))
        out = np.empty((len(q), self.outputs))
        for start in range(0, len(q), 4096):
            chunk = q[start:start + 4096]
            out[start:start + 4096] = np.concatenate([b.predict(self.X, chunk) for b in self.blocks], axis=1)
        return out

    def position_variance(self, q: np.ndarray) -> np.ndarray:
        """The posterior variance of the position correction at q (m,) mm², summed over its three
        axes (the trace of its covariance); its prior Σ c² y_scale² far from the data."""
        q = np.atleast_2d(np.asarray(q, float))
        block = self.blocks[0]
        out = np.empty(len(q))
        for start in range(0, len(q), 4096):
            out[start:start + 4096] = block.variance(self.X, q[start:start + 4096]) * float(np.sum(block.y_scale ** 2))
        return out

    def correct(self, q: np.ndarray, R: np.ndarray, p: np.ndarray, base_rotation: np.ndarray):
        """The pose (R (m, 3, 3), p (m, 3) mm, measuring frame) with the correction at q added;
        base_rotation (3, 3): the robot base's orientation in the measuring frame."""
        d = self.predict(q)
        turn = base_rotation @ self.axes
        p = p + d[:, :3] @ turn.T
        if d.shape[1] == 6:
            R = exp_so3(d[:, 3:] @ turn.T) @ R
        return R, p

    def summary(self) -> dict:
        """What the result JSON says of the model (the model itself goes to a file of its own)."""
        return {"kind": "gaussian process on the joint angles", "points": int(len(self.X)),
                "outputs": "position" if self.outputs == 3 else "position and orientation",
                "length_scales_rad": [b.length_scales.tolist() for b in self.blocks],
                **({"effective_dof": self.dof} if np.isfinite(self.dof) else {})}

    def to_dict(self) -> dict:
        return {"kind": "gaussian processes, RBF on the joint angles (rad)", "X": self.X.tolist(),
                "axes_in_base": self.axes.tolist(), "blocks": [b.to_dict() for b in self.blocks]}

    @classmethod
    def from_dict(cls, d: dict) -> ResidualModel:
        axes = np.array(d.get("axes_in_base", np.eye(3)), float)
        if axes.shape != (3, 3):
            raise ValueError(f"axes_in_base must be 3×3, got shape {axes.shape}")
        return cls(np.array(d["X"], float), tuple(Block.from_dict(b) for b in d["blocks"]), axes)
