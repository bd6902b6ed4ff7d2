"""The log marginal likelihood of the residual process and its gradient, computed lean.

The process of :mod:`robocal.calibration.select.residual` has the kernel
``c · exp(−½ Σ_d (Δq_d / ℓ_d)²) + σ² δ`` (scikit-learn's ``ConstantKernel * RBF + WhiteKernel``)
on standardised outputs.  Its hyperparameters are tuned by maximising the log marginal
likelihood summed over the outputs, exactly as ``GaussianProcessRegressor.fit`` does (same
parameters in log space, same bounds, same jitter, same L-BFGS-B): only the arithmetic is
arranged for speed.  scikit-learn builds the kernel's gradient as an (n, n, p) array and
contracts it with an (n, n, t) one at every evaluation; here the gradient needs W ∘ K
(W = ααᵀ − t K⁻¹) only through a few products, and K⁻¹ comes from the Cholesky factor
(LAPACK ``potri``).  On a
thousand poses an evaluation costs about the Cholesky factor and the inverse (30 of 40 ms here),
and the tuning is the bulk of ``--model auto``.
"""

from __future__ import annotations

import numpy as np

#: what scikit-learn adds to the kernel's diagonal before the Cholesky factorisation
JITTER = 1e-10


class MarginalLikelihood:
    """The negative log marginal likelihood of standardised outputs Y (n, t) at joints q (n, d)
    rad, and its gradient, as functions of θ = log(c, ℓ_1..ℓ_d, σ²).

    With W = ααᵀ − t K⁻¹ the gradient needs W ∘ K_s only through its row sums and its product
    with q (Σ_ij (W∘K_s)_ij (q_id − q_jd)² = 2 Σ_i q_id² r_i − 2 q_dᵀ (W∘K_s) q_d).  The ααᵀ part
    never becomes a matrix: (ααᵀ ∘ K_s) v = Σ_k α_k ∘ K_s (α_k ∘ v), one product of K_s with
    t(d + 1) columns.  The K⁻¹ part is the lower triangle Λ LAPACK's ``potri`` leaves, used as
    Λ + Λᵀ − diag Λ without forming its transpose.
    """

    def __init__(self, q: np.ndarray, y: np.ndarray):
        self.q = np.asarray(q, float)
        self.y = np.asarray(y, float)
        self.n, self.t = self.y.shape
        self._q2 = self.q**2

    def __call__(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        from scipy.linalg import LinAlgError, cho_solve, cholesky
        from scipy.linalg.lapack import dpotri
        from scipy.spatial.distance import cdist

        c, scales, noise = np.exp(theta[0]), np.exp(theta[1:-1]), np.exp(theta[-1])
        q, t, n = self.q, self.t, self.n
        z = q / scales
        Ks = cdist(z, z, "sqeuclidean")
        Ks *= -0.5
        np.exp(Ks, out=Ks)
        Ks *= c
        K = Ks.copy()
        K[np.diag_indices_from(K)] += noise + JITTER
        try:
            L = cholesky(K, lower=True, overwrite_a=True, check_finite=False)
        except LinAlgError:
            return np.inf, np.zeros_like(theta)
        alpha = cho_solve((L, True), self.y, check_finite=False)
        lml = (-0.5 * np.einsum("ik,ik->", self.y, alpha) - t * np.log(np.diag(L)).sum()
               - 0.5 * n * t * np.log(2 * np.pi))
        inverse, info = dpotri(L, lower=1, overwrite_c=1)  # lower triangle of K⁻¹, zeros above
        if info != 0:
            return np.inf, np.zeros_like(theta)
        d = q.shape[1]
        # (ααᵀ ∘ Ks) [1, q]: one product of Ks with the columns α_k and α_k ∘ q_d
        G = Ks @ np.concatenate([alpha, (alpha[:, :, None] * q[:, None, :]).reshape(n, t * d)], axis=1)
        rows = np.einsum("ik,ik->i", alpha, G[:, :t])
        WKq = np.einsum("ik,ikd->id", alpha, G[:, t:].reshape(n, t, d))
        diag = np.diag(inverse).copy()
        inverse *= Ks  # B = Λ ∘ Ks, lower triangle
        bdiag = diag * c
        rows -= t * (inverse.sum(axis=1) + inverse.sum(axis=0) - bdiag)
        WKq -= t * (inverse @ q + inverse.T @ q - bdiag[:, None] * q)
        grad = np.empty_like(theta)
        grad[0] = 0.5 * rows.sum()
        spread = 2.0 * self._q2.T @ rows - 2.0 * np.einsum("id,id->d", q, WKq)
        grad[1:-1] = 0.5 * spread / scales**2
        grad[-1] = 0.5 * noise * (np.einsum("ik,ik->", alpha, alpha) - t * diag.sum())
        return -lml, -grad


def moments(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each output's mean and scale as ``normalize_y=True`` takes them: its std, 1 where it is 0."""
    y = np.asarray(y, float)
    std = y.std(axis=0)
    return y.mean(axis=0), np.where(std == 0, 1.0, std)


def standardise(y: np.ndarray) -> np.ndarray:
    """The outputs as ``normalize_y=True`` sees them: each centred and divided by its scale."""
    mean, scale = moments(y)
    return (np.asarray(y, float) - mean) / scale
