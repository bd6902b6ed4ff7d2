"""A learned correction of what the parametric model leaves: Gaussian processes in joint space.

The correction δ(q) = [δp (3) mm, δr (3) rad] is learnt in the axes of the measuring frame
it was fitted in (a tracker's own systematic errors live there, and on real data that fits
better than the base axes); it keeps the orientation of those axes in the robot's base
frame, R_o, so that it turns with the base when the robot is measured from elsewhere.  It is
added to the model's pose in the measuring frame as p ← p + R_b R_o δp, R ← Exp(R_b R_o δr) R,
with R_b the base frame's rotation (R_b R_o = I in the calibration's own frame).  It is fitted
by :mod:`robocal.calibration.select.residual`; predicting
needs only what is stored here, without pickle: the training inputs, the dual coefficients,
and the kernels' parameters.

Each block of outputs (positions; orientations for full-pose data) has its own kernel
c² · exp(−½ Σ_i ((q_i − q'_i)/ℓ_i)²) on the commanded joint angles (rad), one length scale per
joint, and its targets standardised (mean, scale) before the fit.

Its support is its data.  Away from them the process's posterior variance returns to its prior
c² (:meth:`Block.variance`), and the correction fades with it, pose by pose: with e = 1 − var/c²
the share of its prior the data explain there, the correction is weighed by
:func:`fade` (e) = clip(2e − 1, 0, 1): whole where the data explain all of it, nothing where they
explain half or less (there its mean is mostly the kernel's reach, not the data's: on the UR10,
weighing by e itself let corrections from half a range away cost 0.3 µm on another campaign's
poses, while its held-out poses came out 1 µm better with the stricter fade).  The variance is
taken given the :data:`LOCAL` training poses most correlated with the pose: the exact one needs a
triangular solve over all poses for each pose, inside every inverse-kinematics step, and the
local one is the same far from the data and within a few 10⁻⁴ of it where the poses are.
Outside its data the correction contributes nothing, and its variance says how little is known
there (:func:`robocal.model.uncertainty.predicted_sigma`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..math.so3 import exp_so3

#: training poses a correction's fade is worked out on (:meth:`Block.explained`)
LOCAL = 32


def fade(explained: np.ndarray) -> np.ndarray:
    """How much of a correction is kept where its data explain the share ``explained`` of its prior."""
    return np.clip(2.0 * explained - 1.0, 0.0, 1.0)


def rbf(a: np.ndarray, b: np.ndarray, length_scales: np.ndarray, amplitude: float) -> np.ndarray:
    """The kernel's signal part c · exp(−½ Σ_i ((a_i − b_i)/ℓ_i)²) between joints a (m, n) and
    b (k, n) rad: (m, k)."""
    a, b = a / length_scales, b / length_scales
    sq = np.sum(a * a, 1)[:, None] + np.sum(b * b, 1)[None, :] - 2 * a @ b.T
    return amplitude * np.exp(-0.5 * np.maximum(sq, 0.0))


def apply_correction(model, q: np.ndarray, R: np.ndarray, p: np.ndarray, base_rotation: np.ndarray,
                     rotations: bool = True):
    """The pose (R (m, 3, 3), p (m, 3) mm, measuring frame) with a correction's δ = ``model.predict(q)``
    added: p ← p + R_b R_o δp and, with orientations, R ← Exp(R_b R_o δr) R (see
    :mod:`robocal.model.residual`).  ``rotations`` False: the positions alone are worked out (the
    orientation outputs are not predicted), and a correction that has orientation outputs returns R
    as NaN: a rotation without them would be a plausible wrong one."""
    d = model.predict(q, positions=not rotations)
    turn = base_rotation @ model.axes
    p = p + d[:, :3] @ turn.T
    if d.shape[1] == 6:
        R = exp_so3(d[:, 3:] @ turn.T) @ R if rotations else np.full_like(R, np.nan)
    return R, p


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
        """The correction at q (m, t), faded by the share of its prior the data explain there."""
        k = self._cross(X, q)
        mean = k @ self.alpha * self.y_scale + self.y_mean
        return mean if not np.isfinite(self.noise) else fade(self.explained(X, k))[:, None] * mean

    def bound(self) -> np.ndarray:
        """The largest |correction| (t,) anywhere: the kernel is at most c², the fade at most 1."""
        return np.abs(self.y_mean) + self.amplitude * np.sum(np.abs(self.alpha), axis=0) * np.abs(self.y_scale)

    def explained(self, X: np.ndarray, k: np.ndarray) -> np.ndarray:
        """1 − var/c² (m,) at the poses whose kernel rows against X are k (m, N): the posterior
        variance given the LOCAL most correlated training poses."""
        m, N = k.shape
        if N == 0:
            return np.zeros(m)
        near = np.argpartition(-k, LOCAL - 1, axis=1)[:, :LOCAL] if N > LOCAL else np.tile(np.arange(N), (m, 1))
        Xs = X[near] / self.length_scales  # (m, L, n)
        sq = np.sum((Xs[:, :, None] - Xs[:, None]) ** 2, axis=-1)
        A = self.amplitude * np.exp(-0.5 * sq)
        A[:, np.arange(A.shape[1]), np.arange(A.shape[1])] += self.noise
        ks = np.take_along_axis(k, near, axis=1)
        v = np.linalg.solve(A, ks[..., None])[..., 0]
        return np.clip(np.einsum("ml,ml->m", ks, v) / self.amplitude, 0.0, 1.0)  # k*ᵀA⁻¹k*/c² = 1 − var/c²

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

    kind = "residual"

    @property
    def outputs(self) -> int:
        return sum(b.alpha.shape[1] for b in self.blocks)

    @property
    def n_joints(self) -> int:
        return int(self.X.shape[1])

    @property
    def dof(self) -> float:
        """Effective degrees of freedom taken from the data (every block, every output)."""
        return float(sum(b.dof for b in self.blocks))

    def predict(self, q: np.ndarray, positions: bool = False) -> np.ndarray:
        """δ (m, 3 or 6) at commanded joints q (m, n) rad; computed in chunks to bound memory.
        ``positions``: the blocks of the position outputs alone, the others' columns 0."""
        q = np.atleast_2d(np.asarray(q, float))
        blocks, width = [], 0
        for b in self.blocks:
            if positions and width >= 3:
                break
            blocks.append(b)
            width += b.alpha.shape[1]
        out = np.zeros((len(q), self.outputs))
        for start in range(0, len(q), 4096):
            chunk = q[start:start + 4096]
            out[start:start + 4096, :width] = np.concatenate([b.predict(self.X, chunk) for b in blocks], axis=1)
        return out

    def weight(self, q: np.ndarray) -> np.ndarray:
        """The share (m,) of the position correction kept at q (:func:`fade`; 1 for a model saved
        without its noise level, which does not fade)."""
        q = np.atleast_2d(np.asarray(q, float))
        block = self.blocks[0]
        if not np.isfinite(block.noise):
            return np.ones(len(q))
        out = np.empty(len(q))
        for start in range(0, len(q), 4096):
            chunk = q[start:start + 4096]
            out[start:start + 4096] = fade(block.explained(self.X, block._cross(self.X, chunk)))
        return out

    def position_bound(self) -> float:
        """The largest |δp| (mm) the correction adds anywhere."""
        return float(np.linalg.norm(self.blocks[0].bound()[:3]))

    def position_variance(self, q: np.ndarray) -> np.ndarray:
        """The posterior variance of the position correction at q (m,) mm², summed over its three
        axes (the trace of its covariance); its prior Σ c² y_scale² far from the data."""
        q = np.atleast_2d(np.asarray(q, float))
        block = self.blocks[0]
        out = np.empty(len(q))
        for start in range(0, len(q), 4096):
            out[start:start + 4096] = block.variance(self.X, q[start:start + 4096]) * float(np.sum(block.y_scale ** 2))
        return out

    def correct(self, q: np.ndarray, R: np.ndarray, p: np.ndarray, base_rotation: np.ndarray,
                rotations: bool = True):
        """The pose (R (m, 3, 3), p (m, 3) mm, measuring frame) with the correction at q added;
        base_rotation (3, 3): the robot base's orientation in the measuring frame; ``rotations``
        False: p alone is corrected (the orientation outputs are not worked out)."""
        return apply_correction(self, q, R, p, base_rotation, rotations)

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
