"""The log marginal likelihood of the residual process and its gradient, computed lean.

The process of :mod:`robocal.calibration.residual` has the kernel
``c · exp(−½ Σ_d (Δq_d / ℓ_d)²) + σ² δ`` (scikit-learn's ``ConstantKernel * RBF + WhiteKernel``)
on standardised outputs.  Its hyperparameters are tuned by maximising the log marginal
likelihood summed over the outputs, exactly as ``GaussianProcessRegressor.fit`` does (same
parameters in log space, same bounds, same jitter, same L-BFGS-B): only the arithmetic is
arranged for speed.  scikit-learn builds the kernel's gradient as an (n, n, p) array and
contracts it with an (n, n, t) one at every evaluation; here the squared joint differences
are computed once per data set, the gradient is p dot products with W ∘ K
(W = ααᵀ − t K⁻¹), and K⁻¹ comes from the Cholesky factor (LAPACK ``potri``).  On a thousand
poses this is about three times faster per evaluation, and the tuning is the bulk of
``--model auto``.
"""

from __future__ import annotations

import numpy as np

#: what scikit-learn adds to the kernel's diagonal before the Cholesky factorisation
JITTER = 1e-10


class MarginalLikelihood:
    """The negative log marginal likelihood of standardised outputs Y (n, t) at joints q (n, d)
    rad, and its gradient, as functions of θ = log(c, ℓ_1..ℓ_d, σ²).

    Squared distances come from one product of the scaled joints, |z_i|² + |z_j|² − 2 z_i·z_j,
    and each length scale's gradient Σ_ij (W∘K)_ij (q_id − q_jd)² / ℓ_d² from a row sum and one
    product with q: a few passes over the n × n matrices, where scikit-learn makes (n, n, p).
    """

    def __init__(self, q: np.ndarray, y: np.ndarray):
        self.q = np.asarray(q, float)
        self.y = np.asarray(y, float)
        self.n, self.t = self.y.shape

    def __call__(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        from scipy.linalg import LinAlgError, cho_solve, cholesky
        from scipy.linalg.lapack import dpotri

        c, scales, noise = np.exp(theta[0]), np.exp(theta[1:-1]), np.exp(theta[-1])
        z = self.q / scales
        norms = np.einsum("ij,ij->i", z, z)
        Ks = z @ z.T
        Ks *= 2.0
        Ks -= norms[:, None]
        Ks -= norms[None, :]
        np.minimum(Ks, 0.0, out=Ks)  # −|z_i − z_j|², rounding kept on the right side of zero
        Ks *= 0.5
        np.exp(Ks, out=Ks)
        Ks *= c
        K = Ks.copy()
        K[np.diag_indices_from(K)] += noise + JITTER
        try:
            L = cholesky(K, lower=True, overwrite_a=True, check_finite=False)
        except LinAlgError:
            return np.inf, np.zeros_like(theta)
        alpha = cho_solve((L, True), self.y, check_finite=False)
        lml = (-0.5 * np.einsum("ik,ik->", self.y, alpha) - self.t * np.log(np.diag(L)).sum()
               - 0.5 * self.n * self.t * np.log(2 * np.pi))
        inverse, info = dpotri(L, lower=1, overwrite_c=1)
        if info != 0:
            return np.inf, np.zeros_like(theta)
        # W = ααᵀ − t K⁻¹ with K⁻¹ held as its lower triangle: K⁻¹ = Λ + Λᵀ − diag
        diag = np.diag(inverse).copy()
        lower = np.tril(inverse)
        lower *= Ks  # Λ ∘ Ks
        WK = alpha @ alpha.T
        WK *= Ks
        WK -= self.t * lower
        WK -= self.t * lower.T
        WK[np.diag_indices_from(WK)] += self.t * diag * c
        rows = WK.sum(axis=1)
        grad = np.empty_like(theta)
        grad[0] = 0.5 * rows.sum()
        # Σ_ij WK_ij (q_id − q_jd)² = 2 Σ_i q_id² rows_i − 2 q_dᵀ WK q_d (WK symmetric)
        spread = 2.0 * (self.q**2).T @ rows - 2.0 * np.einsum("id,id->d", self.q, WK @ self.q)
        grad[1:-1] = 0.5 * spread / scales**2
        grad[-1] = 0.5 * noise * (np.einsum("ik,ik->", alpha, alpha) - self.t * diag.sum())
        return -lml, -grad


def standardise(y: np.ndarray) -> np.ndarray:
    """The outputs as ``normalize_y=True`` sees them: each centred and divided by its std."""
    y = np.asarray(y, float)
    std = y.std(axis=0)
    return (y - y.mean(axis=0)) / np.where(std == 0, 1.0, std)
