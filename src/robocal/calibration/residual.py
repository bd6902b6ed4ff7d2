"""Fitting the residual model: Gaussian processes on the joint angles (scikit-learn).

What the parametric model leaves at each pose, e = measured − model (position mm and, for
full-pose data, orientation rad, in the measuring frame), is regressed on the commanded joint
angles with an anisotropic RBF kernel plus white noise, one kernel for the positions and one
for the orientations.  Length scales are bounded below by :data:`MIN_LENGTH_SCALE` and the
white noise by :data:`MIN_NOISE`, so that a process cannot memorise the measurement noise.

Hyperparameters are tuned by maximum marginal likelihood on at most :data:`HYPER_POINTS`
poses (drawn with the seed; :data:`ORIENTATION_HYPER_POINTS` for the orientation block, which
the choice of model does not judge), and the process is conditioned on at most
:data:`MAX_POINTS`.  A kernel can be given per block: used as it is, or as the start of a
short tuning (``iterations``), which is how cross-validation re-tunes the kernel of all the
data on each fold's training poses at a fraction of the cost.
"""

from __future__ import annotations

import numpy as np

from ..model.residual import Block, ResidualModel

#: shortest length scale of the kernel (rad): about 11°, so one pose cannot bend the correction alone
MIN_LENGTH_SCALE = 0.2
MAX_LENGTH_SCALE = 100.0
#: smallest white-noise level of the standardised targets
MIN_NOISE = 1e-2
HYPER_POINTS = 1000
ORIENTATION_HYPER_POINTS = 500
MAX_POINTS = 2000


def _tuned(q, y, start, iterations: int | None):
    """The kernel of maximum marginal likelihood on (q, y): from scratch, or from ``start``
    for at most ``iterations`` L-BFGS-B iterations.  The optimisation scikit-learn's
    ``GaussianProcessRegressor.fit`` runs (same objective, start, bounds and L-BFGS-B), on the
    lean likelihood of :mod:`robocal.calibration.likelihood`."""
    from scipy.optimize import minimize
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    from .likelihood import MarginalLikelihood, standardise

    if start is None:
        start = (ConstantKernel(1.0, (1e-3, 1e2)) * RBF(np.ones(q.shape[1]), (MIN_LENGTH_SCALE, MAX_LENGTH_SCALE))
                 + WhiteKernel(0.5, (MIN_NOISE, 10.0)))
    objective = MarginalLikelihood(q, standardise(y))
    result = minimize(objective, start.theta, jac=True, bounds=start.bounds, method="L-BFGS-B",
                      options={} if iterations is None else {"maxiter": iterations})
    return start.clone_with_theta(result.x)


#: random probes of the stochastic trace estimate of a process's degrees of freedom
TRACE_PROBES = 32


def effective_dof(L: np.ndarray, noise: float, rng: np.random.Generator) -> float:
    """Effective degrees of freedom of a process per output, tr(K_s (K_s + σ²I)⁻¹) = N − σ² tr((K_s + σ²I)⁻¹),
    from the Cholesky factor L of K_s + σ²I; the trace of the inverse by Hutchinson's estimate
    (Rademacher probes), N² per probe instead of N³."""
    from scipy.linalg import cho_solve

    n = len(L)
    if n <= 4 * TRACE_PROBES:  # small: exact
        inverse_trace = float(np.trace(cho_solve((L, True), np.eye(n))))
    else:
        z = rng.choice([-1.0, 1.0], size=(n, TRACE_PROBES))
        inverse_trace = float(np.mean(np.sum(z * cho_solve((L, True), z), axis=0)))
    return float(np.clip(n - noise * inverse_trace, 0.0, n))


def _block(q, y, keep, kernel, rng: np.random.Generator) -> Block:
    from sklearn.gaussian_process import GaussianProcessRegressor

    final = GaussianProcessRegressor(kernel, normalize_y=True, optimizer=None).fit(q[keep], y[keep])
    signal = final.kernel_.k1  # ConstantKernel * RBF; the white noise acts on the training diagonal only
    dof = effective_dof(final.L_, float(final.kernel_.k2.noise_level), rng) * y.shape[1]
    return Block(alpha=np.asarray(final.alpha_, float).reshape(len(keep), -1),
                 length_scales=np.atleast_1d(signal.k2.length_scale).astype(float),
                 amplitude=float(signal.k1.constant_value),
                 y_mean=np.atleast_1d(final._y_train_mean).astype(float),
                 y_scale=np.atleast_1d(final._y_train_std).astype(float), dof=dof)


def _blocks(errors: np.ndarray):
    return (slice(0, 3), slice(3, 6))[: errors.shape[1] // 3]


def _tune_block(q, y, order, k: int, start, iterations: int | None, points: int | None):
    cap = points or (HYPER_POINTS if k == 0 else ORIENTATION_HYPER_POINTS)
    pick = order[:cap]
    return _tuned(q[pick], y[pick], start, iterations)


def tune_kernels(q: np.ndarray, errors: np.ndarray, seed: int | None = 0, start: tuple | None = None,
                 iterations: int | None = None, points: int | None = None) -> tuple:
    """The kernels (one per block: positions, orientations) of maximum marginal likelihood on at
    most ``points`` poses (default :data:`HYPER_POINTS`, :data:`ORIENTATION_HYPER_POINTS`) drawn
    with the seed: from ``start`` (a kernel per block, or None: from scratch), for at most
    ``iterations`` L-BFGS-B iterations (None: to convergence)."""
    q, errors = np.asarray(q, float), np.asarray(errors, float)
    order = np.random.default_rng(seed).permutation(len(q))
    return tuple(_tune_block(q, errors[:, cols], order, k, None if start is None or k >= len(start) else start[k],
                             iterations, points) for k, cols in enumerate(_blocks(errors)))


def fit_residual(q: np.ndarray, errors: np.ndarray, seed: int | None = 0, kernels: tuple | None = None,
                 iterations: int | None = None, points: int | None = None) -> tuple[ResidualModel, tuple]:
    """A :class:`ResidualModel` of ``errors`` (m, 3 or 6) at commanded joints ``q`` (m, n) rad,
    and its kernels.  kernels: one per block (positions, orientations), None to tune it from
    scratch; a given kernel is used as it is, or, with ``iterations``, re-tuned from there (on at
    most ``points`` poses, see :func:`tune_kernels`)."""
    rng = np.random.default_rng(seed)
    q, errors = np.asarray(q, float), np.asarray(errors, float)
    order = rng.permutation(len(q))
    keep = np.sort(rng.permutation(len(q))[:MAX_POINTS])
    blocks, fitted = [], []
    for k, cols in enumerate(_blocks(errors)):
        given = None if kernels is None or k >= len(kernels) else kernels[k]
        kernel = given
        if given is None or iterations is not None:
            kernel = _tune_block(q, errors[:, cols], order, k, given, iterations, points)
        blocks.append(_block(q, errors[:, cols], keep, kernel, rng))
        fitted.append(kernel)
    return ResidualModel(q[keep].copy(), tuple(blocks)), tuple(fitted)
