"""Statistics of a least-squares fit: covariance and standard uncertainties, residual
variance, the nested-model F-test and robust outlier screening.

One covariance routine serves the serial arms, the parallel mechanism and pose planning:
:func:`covariance` takes either the residual Jacobian J or an information matrix M = JᵀJ.
"""

from __future__ import annotations

import math

import numpy as np


def group_folds(groups: np.ndarray, k: int, seed: int | None) -> list[np.ndarray]:
    """K folds of row indices (k at least 2, at most the number of groups), drawn with the seed;
    rows of one group (the reflectors of one pose) stay together.  groups: 0..G−1 per row."""
    n = int(groups.max()) + 1
    k = max(2, min(k, n))
    fold_of = np.empty(n, dtype=int)
    fold_of[np.random.default_rng(seed).permutation(n)] = np.arange(n) % k
    assignment = fold_of[groups]
    return [np.flatnonzero(assignment == f) for f in range(k)]

#: a pose whose position residual exceeds this many robust σ is an outlier.  For isotropic
#: Gaussian noise |δp| follows a Maxwell law; P(|δp| > 6σ) ≈ 1e-7.
OUTLIER_SIGMAS = 6.0
#: median of the Maxwell distribution in units of the per-axis σ
MAXWELL_MEDIAN = 1.5382
#: fewer poses than this give no robust scale worth screening with
MIN_POSES_FOR_OUTLIERS = 8
#: an outlier also stands apart: its studentised residual is at least this many times the next
#: smaller one (gross errors are isolated; a tail of model misfit is continuous, neighbours in
#: it differ by a few percent)
OUTLIER_GAP = 1.5
#: leaving out more than this fraction of the poses gets a warning: the model, not the data, may be at fault
MAX_OUTLIER_FRACTION = 0.05


def covariance(J: np.ndarray | None = None, *, information: np.ndarray | None = None, variance: float = 1.0,
               rcond: float = 1e-14) -> np.ndarray:
    """variance · (JᵀJ)⁻¹ from J (rows, k) or from M = JᵀJ (k, k).

    Works on a k×k factor (QR of a tall J, or the symmetric square root of M), so 10⁵
    poses cost no more than a few.  Directions the data do not determine (singular values
    below rcond·σmax) give infinite variances on the parameters they touch.
    """
    if J is not None:
        J = np.asarray(J, dtype=float)
        R = np.linalg.qr(J, mode="r") if J.shape[0] > J.shape[1] else J
        _, s, Vt = np.linalg.svd(R, full_matrices=False)
        ev = s**2
    else:
        ev, V = np.linalg.eigh(np.asarray(information, dtype=float))
        ev, Vt = ev[::-1], V[:, ::-1].T
    k = Vt.shape[1]
    if ev.size < k:
        return np.full((k, k), np.inf)
    weak = ev <= (rcond**2) * max(float(ev[0]), 1e-300)
    inv = np.where(weak, np.inf, 1.0 / np.where(weak, 1.0, ev))
    if np.any(weak):
        cov = (Vt[~weak].T * inv[~weak]) @ Vt[~weak]
        touched = np.any(np.abs(Vt[weak]) > 1e-9, axis=0)
        cov[touched, :] = np.inf
        cov[:, touched] = np.inf
        return variance * cov
    return variance * ((Vt.T * inv) @ Vt)


def standard_uncertainties(J: np.ndarray | None = None, *, information: np.ndarray | None = None,
                           variance: float = 1.0) -> np.ndarray:
    """sqrt(diag(:func:`covariance`)); inf where the data do not determine a parameter."""
    return np.sqrt(np.diag(covariance(J, information=information, variance=variance)))


def residual_variance(residuals: np.ndarray, n_params: int) -> float:
    """σ̂² = |r|² / (N − k), or NaN without degrees of freedom."""
    dof = residuals.size - n_params
    return float(residuals @ residuals) / dof if dof > 0 else math.nan


def f_test(rss_restricted: float, rss_full: float, n_added: int, dof_full: int) -> float:
    """p-value that adding ``n_added`` parameters lowered the sum of squares only by chance."""
    from scipy.special import fdtrc  # the F distribution's survival function

    if dof_full <= 0 or rss_full >= rss_restricted:
        return 1.0
    stat = ((rss_restricted - rss_full) / n_added) / max(rss_full / dof_full, 1e-300)
    return float(fdtrc(n_added, dof_full, stat))


def leave_one_out(position_errors: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Position errors (m, 3) mm each pose would show had it not been fitted: (I − H_ii)⁻¹ δp_i,
    H_ii the pose's 3×3 block of the hat matrix J (JᵀJ)⁻¹ Jᵀ (J: the whitened Jacobian, its
    first 3m rows the positions).  A pose with leverage pulls the fit to itself and hides its
    own error; this undoes that, to first order."""
    m = len(position_errors)
    P = covariance(J)  # (JᵀJ)⁻¹, on a k×k factor
    if not np.all(np.isfinite(P)):
        return position_errors
    A = (J[:3 * m] @ np.linalg.cholesky(P)).reshape(m, 3, -1)  # P = L Lᵀ: H_ii = (J_i L)(J_i L)ᵀ
    H = np.einsum("mak,mbk->mab", A, A)
    I_H = np.eye(3) - H
    ok = np.linalg.det(I_H) > 1e-6
    out = position_errors.copy()
    out[ok] = np.linalg.solve(I_H[ok], position_errors[ok][..., None])[..., 0]
    return out


def robust_outliers(position_errors: np.ndarray, kinds: np.ndarray | None = None,
                    dofs: dict[int, int] | None = None) -> tuple[np.ndarray, float]:
    """Poses that fail the outlier test, and the robust σ (mm per axis).

    The test, on (ideally leave-one-out, see :func:`leave_one_out`) position errors: |δp|
    beyond OUTLIER_SIGMAS robust σ (σ from the median |δp| through the Maxwell law, so gross
    errors do not inflate it; Gaussian noise passes with probability 1 − 1e-7 per pose) *and*
    standing apart: sorted from the largest, the poses above the deepest gap where one |δp| is
    at least OUTLIER_GAP times the next.  A lost beam or a mislabelled row stands apart from the
    rest; the residuals of an incomplete model (real robots: compliance, gears) form a
    continuous tail, which no gap cuts, however far it reaches.

    kinds: an integer label per row (tracker rows, rows that touched points, rows that touched
    planes): each kind's σ is its own, and ``dofs`` gives the values a row of each kind carries (3
    for a point, 1 for a plane row: its offset along the normal, whose |e| follows χ with 1
    degree of freedom).  Each row's |e|/σ is carried to the Maxwell law (χ with 3) at the same tail
    probability, so one bound and one gap serve every kind.  The σ returned is the first kind's.
    """
    norm = np.linalg.norm(position_errors, axis=1)
    kinds = np.zeros(len(norm), dtype=int) if kinds is None else np.asarray(kinds, dtype=int)
    dofs = dofs or {}
    z = np.zeros(len(norm))
    sigma = None
    for kind in np.unique(kinds):
        rows = kinds == kind
        dof = dofs.get(int(kind), 3)
        s = float(np.median(norm[rows])) / MEDIANS[dof]
        sigma = s if sigma is None else sigma
        # a floor of 1e-9 mm: noise-free data have no outliers in their rounding
        z[rows] = norm[rows] / max(s, 1e-9) if dof == 3 else _as_maxwell(norm[rows] / max(s, 1e-9), dof)
    sigma = 0.0 if sigma is None else sigma
    if len(norm) < MIN_POSES_FOR_OUTLIERS:
        return np.zeros(0, dtype=int), sigma
    order = np.argsort(-z)
    ranked = z[order]
    gaps = np.flatnonzero((ranked[:-1] > OUTLIER_SIGMAS) & (ranked[:-1] >= OUTLIER_GAP * ranked[1:]))
    if not gaps.size:
        return np.zeros(0, dtype=int), sigma
    return np.sort(order[:gaps[-1] + 1]), sigma


#: medians of χ with 1, 2 and 3 degrees of freedom, in units of the per-axis σ: the half-normal's,
#: the Rayleigh law's (√(2 ln 2)) and the Maxwell law's
MEDIANS = {1: 0.6744898, 2: 1.1774100, 3: MAXWELL_MEDIAN}


def _as_maxwell(x: np.ndarray, dof: int) -> np.ndarray:
    """χ values with ``dof`` degrees of freedom carried to the Maxwell law's at the same tail probability."""
    from scipy.special import chdtrc, chdtri

    tail = np.clip(chdtrc(dof, x ** 2), 1e-300, 1.0)
    return np.sqrt(chdtri(3, tail))


def chi2_summary(chi2: float, dof: float) -> tuple[float | None, float | None]:
    """Reduced χ² and the probability of a χ² at least this large on ``dof`` degrees of freedom
    (None for both without degrees of freedom)."""
    if not dof > 0:
        return None, None
    from scipy.special import chdtrc  # the χ² survival function, without scipy.stats' import

    return chi2 / dof, float(chdtrc(dof, chi2))



class ChiSquared:
    """Reduced χ² and its probability, for a result that holds ``chi2`` and ``dof``."""

    chi2: float
    dof: float

    @property
    def reduced_chi2(self) -> float | None:
        return chi2_summary(self.chi2, self.dof)[0]

    @property
    def p_value(self) -> float | None:
        """Probability of a χ² at least this large if the model were complete and the noise as stated."""
        return chi2_summary(self.chi2, self.dof)[1]
