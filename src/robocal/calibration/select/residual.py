"""Fitting the residual model: Gaussian processes on the joint angles.

What the parametric model leaves at each pose, e = measured − model (position mm and, for
full-pose data, orientation rad, in the measuring frame), is regressed on the commanded joint
angles with an anisotropic RBF kernel plus white noise, one kernel for the positions and one
for the orientations.  Length scales are bounded below by :data:`MIN_LENGTH_SCALE` and the
white noise by :data:`MIN_NOISE`, so that a process cannot memorise the measurement noise.

The process is scikit-learn's ``GaussianProcessRegressor(ConstantKernel * RBF + WhiteKernel,
normalize_y=True)``: the same kernel, parameters, bounds, start, jitter and L-BFGS-B tuning
(the tests compare the two), with the arithmetic done here: the likelihood without scikit-learn's
(n, n, p) gradient tensor (:mod:`robocal.calibration.select.likelihood`), and the conditioning one
Cholesky factor.  Importing scikit-learn alone took 0.8 s, a tenth of ``--model auto``.

Hyperparameters are tuned by maximum marginal likelihood on at most :data:`HYPER_POINTS`
poses (drawn with the seed; :data:`ORIENTATION_HYPER_POINTS` for the orientation block, which
the choice of model does not judge), and the process is conditioned on at most
:data:`MAX_POINTS`.  A kernel can be given per block: used as it is, or as the start of a
short tuning (``iterations``), which is how cross-validation re-tunes the kernel of all the
data on each fold's training poses at a fraction of the cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...backend import SERIAL, worker_pool
from ...model.residual import Block, ResidualModel, rbf

#: shortest length scale of the kernel (rad): about 11°, so one pose cannot bend the correction alone
MIN_LENGTH_SCALE = 0.2
MAX_LENGTH_SCALE = 100.0
#: smallest white-noise level of the standardised targets
MIN_NOISE = 1e-2
HYPER_POINTS = 1000
ORIENTATION_HYPER_POINTS = 500
MAX_POINTS = 2000


@dataclass(frozen=True, eq=False)
class Kernel:
    """c · exp(−½ Σ_d (Δq_d / ℓ_d)²) + σ² δ on standardised outputs, held as θ = log(c, ℓ_1..ℓ_n, σ²)
    (scikit-learn's θ of ``ConstantKernel * RBF + WhiteKernel``); ℓ in rad."""

    theta: np.ndarray

    @classmethod
    def start(cls, n_joints: int, length_scale: float = 1.0) -> Kernel:
        """Where a tuning from scratch starts: c = 1, every ℓ = ``length_scale`` rad, σ² = 0.5
        (scikit-learn's start with ℓ = 1)."""
        return cls(np.log(np.r_[1.0, np.full(n_joints, length_scale), 0.5]))

    @staticmethod
    def bounds(n_joints: int) -> list[tuple[float, float]]:
        """Bounds of θ: c in [1e-3, 100], ℓ in [MIN_LENGTH_SCALE, MAX_LENGTH_SCALE], σ² in [MIN_NOISE, 10]."""
        return ([(np.log(1e-3), np.log(1e2))] + [(np.log(MIN_LENGTH_SCALE), np.log(MAX_LENGTH_SCALE))] * n_joints
                + [(np.log(MIN_NOISE), np.log(10.0))])

    @property
    def amplitude(self) -> float:
        return float(np.exp(self.theta[0]))

    @property
    def length_scales(self) -> np.ndarray:
        return np.exp(self.theta[1:-1])

    @property
    def noise(self) -> float:
        return float(np.exp(self.theta[-1]))


#: length scales (rad) a tuning from scratch starts from, each to convergence, the most likely kept:
#: scikit-learn's 1 rad, and the shortest allowed, from which the likelihood sees every joint's
#: short-range structure (from 1 rad it is smoothed away and its gradient vanishes: on the UR10's
#: half splits that start ended in a basin with twice the white noise and 0.42 mm instead of 0.32 mm
#: on the validation poses, in two splits of three)
STARTS = (1.0, MIN_LENGTH_SCALE)


def _minimised(piece) -> tuple[np.ndarray, float]:
    """One L-BFGS-B tuning of θ on (q, y) from θ₀, at most ``iterations`` iterations (None: to
    convergence): the optimisation scikit-learn's ``GaussianProcessRegressor.fit`` runs (same
    objective, bounds and L-BFGS-B); θ and the negative log likelihood reached."""
    from scipy.optimize import minimize

    from .likelihood import MarginalLikelihood, standardise

    q, y, theta, iterations = piece
    result = minimize(MarginalLikelihood(q, standardise(y)), theta, jac=True, bounds=Kernel.bounds(q.shape[1]),
                      method="L-BFGS-B", options={} if iterations is None else {"maxiter": iterations})
    return result.x, float(result.fun)


def _tuned(q, y, start: Kernel | None, iterations: int | None, pool: worker_pool = SERIAL) -> Kernel:
    """The kernel of maximum marginal likelihood on (q, y): from scratch, from each of
    :data:`STARTS` to convergence (on the pool's workers) and the most likely kept, or from
    ``start`` for at most ``iterations`` L-BFGS-B iterations."""
    if start is not None:
        return Kernel(_minimised((q, y, start.theta, iterations))[0])
    return _scratch(q, y, pool).result()[0]


class _Tuning:
    """Tunings from scratch handed to a pool (:meth:`worker_pool.submit`); ``result()``: the most
    likely kernel and its negative log likelihood."""

    def __init__(self, pending):
        self.pending = pending

    def result(self) -> tuple[Kernel, float]:
        return best_kernel(self.pending.result())


def _start_pieces(q, y) -> list[tuple]:
    """A tuning from scratch as pieces of work for :func:`_minimised`: one per start of :data:`STARTS`,
    each to convergence (after ten iterations the eventual winner was not always ahead)."""
    return [(q, y, Kernel.start(q.shape[1], ls).theta, None) for ls in STARTS]


def _scratch(q, y, pool: worker_pool) -> _Tuning:
    return _Tuning(pool.submit(_minimised, _start_pieces(q, y)))


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


def _block(q, y, keep, kernel: Kernel, rng: np.random.Generator) -> Block:
    """The process with ``kernel`` conditioned on the poses ``keep``: y standardised, K = signal
    + (σ² + jitter) I factored once, α = K⁻¹ y."""
    from scipy.linalg import cho_solve, cholesky

    from .likelihood import JITTER, moments

    X, y = q[keep], y[keep]
    K = rbf(X, X, kernel.length_scales, kernel.amplitude)
    K[np.diag_indices_from(K)] += kernel.noise + JITTER
    L = cholesky(K, lower=True, overwrite_a=True, check_finite=False)
    mean, scale = moments(y)
    alpha = cho_solve((L, True), (y - mean) / scale, check_finite=False)
    block = Block(alpha=alpha.reshape(len(keep), -1), length_scales=kernel.length_scales, amplitude=kernel.amplitude,
                  y_mean=mean, y_scale=scale, dof=effective_dof(L, kernel.noise, rng) * y.shape[1],
                  noise=kernel.noise + JITTER)
    block.__dict__["_chol"] = L  # the factor its variance needs (Block.factor), already at hand
    return block


def _blocks(errors: np.ndarray):
    return (slice(0, 3), slice(3, 6))[: errors.shape[1] // 3]


def _picked(order: np.ndarray, k: int, points: int | None) -> np.ndarray:
    """The poses block k is tuned on: the first ``points`` of ``order`` (default its block's cap)."""
    return order[:points or (HYPER_POINTS if k == 0 else ORIENTATION_HYPER_POINTS)]


def _tune_block(q, y, order, k: int, start, iterations: int | None, points: int | None, pool: worker_pool):
    pick = _picked(order, k, points)
    return _tuned(q[pick], y[pick], start, iterations, pool)


def begin_tuning(q: np.ndarray, errors: np.ndarray, seed: int | None = 0, points: int | None = None,
                 pool: worker_pool = SERIAL):
    """:func:`tune_kernels` from scratch, its tunings handed to the pool's workers now while the
    caller goes on; the function returned gives the kernels ``tune_kernels(q, errors, seed,
    points=points, pool=pool)`` gives."""
    q, errors = np.asarray(q, float), np.asarray(errors, float)
    order = np.random.default_rng(seed).permutation(len(q))
    tunings = [_scratch(q[pick], errors[:, cols][pick], pool) for k, cols in enumerate(_blocks(errors))
               for pick in [_picked(order, k, points)]]
    return lambda: tuple(t.result()[0] for t in tunings)


def _tuning_poses(q: np.ndarray, y: np.ndarray, seed: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The poses a position kernel is tuned on: at most :data:`HYPER_POINTS`, drawn with the seed
    (those :func:`tune_kernels` takes)."""
    pick = np.random.default_rng(seed).permutation(len(q))[:HYPER_POINTS]
    return np.asarray(q, float)[pick], np.asarray(y, float)[pick]


def scratch_pieces(q: np.ndarray, errors: np.ndarray, seed: int | None) -> list[tuple]:
    """The position kernel's tunings from scratch (one per start of :data:`STARTS`), as pieces
    of work for :func:`minimised`; :func:`best_kernel` of their results is :func:`tune_kernels`'
    position kernel."""
    return _start_pieces(*_tuning_poses(q, np.asarray(errors, float)[:, :3], seed))


def best_kernel(runs: list[tuple[np.ndarray, float]]) -> tuple[Kernel, float]:
    """The most likely of the tunings' results, and its negative log likelihood."""
    theta, nll = min(runs, key=lambda run: run[1])
    return Kernel(theta), nll


def neg_log_likelihood(q: np.ndarray, errors: np.ndarray, seed: int | None, kernel: Kernel) -> float:
    """The position kernel's negative log marginal likelihood on the poses it is tuned on."""
    from .likelihood import MarginalLikelihood, standardise

    q, y = _tuning_poses(q, np.asarray(errors, float)[:, :3], seed)
    return float(MarginalLikelihood(q, standardise(y))(kernel.theta)[0])


def minimised(piece) -> tuple[np.ndarray, float]:
    """One tuning of θ (:func:`_minimised`), as a piece of work for a pool's workers."""
    return _minimised(piece)


def tune_kernels(q: np.ndarray, errors: np.ndarray, seed: int | None = 0, start: tuple | None = None,
                 iterations: int | None = None, points: int | None = None, pool: worker_pool = SERIAL) -> tuple:
    """The kernels (one per block: positions, orientations) of maximum marginal likelihood on at
    most ``points`` poses (default :data:`HYPER_POINTS`, :data:`ORIENTATION_HYPER_POINTS`) drawn
    with the seed: from ``start`` (a kernel per block, or None: from scratch), for at most
    ``iterations`` L-BFGS-B iterations (None: to convergence)."""
    q, errors = np.asarray(q, float), np.asarray(errors, float)
    order = np.random.default_rng(seed).permutation(len(q))
    return tuple(_tune_block(q, errors[:, cols], order, k, None if start is None or k >= len(start) else start[k],
                             iterations, points, pool) for k, cols in enumerate(_blocks(errors)))


def fit_residual(q: np.ndarray, errors: np.ndarray, seed: int | None = 0, kernels: tuple | None = None,
                 iterations: int | None = None, points: int | None = None,
                 pool: worker_pool = SERIAL) -> tuple[ResidualModel, tuple]:
    """A :class:`ResidualModel` of ``errors`` (m, 3 or 6) at commanded joints ``q`` (m, n) rad,
    and its kernels.  kernels: one per block (positions, orientations), None to tune it from
    scratch; a given kernel is used as it is, or, with ``iterations``, re-tuned from there (on at
    most ``points`` poses, see :func:`tune_kernels`); tunings from scratch use the pool's workers."""
    rng = np.random.default_rng(seed)
    q, errors = np.asarray(q, float), np.asarray(errors, float)
    order = rng.permutation(len(q))
    keep = np.sort(rng.permutation(len(q))[:MAX_POINTS])
    blocks, fitted = [], []
    for k, cols in enumerate(_blocks(errors)):
        given = None if kernels is None or k >= len(kernels) else kernels[k]
        kernel = given
        if given is None or iterations is not None:
            kernel = _tune_block(q, errors[:, cols], order, k, given, iterations, points, pool)
        blocks.append(_block(q, errors[:, cols], keep, kernel, rng))
        fitted.append(kernel)
    return ResidualModel(q[keep].copy(), tuple(blocks)), tuple(fitted)
