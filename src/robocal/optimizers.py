"""Optimisers: the particle-swarm family of the papers and Levenberg–Marquardt.

Every optimiser returns an :class:`OptimizeResult` with the solution, the best
objective per iteration (``history``), and counts of iterations and objective
evaluations (one per particle per generation for swarms; one per residual-vector
evaluation for LM).  Swarms evaluate the whole population in one batched call.

Choices where the papers are silent (the same for all swarm methods):

- Search box: ``lower``/``upper`` per parameter (the caller centres it on the
  initial estimate).  A particle that leaves the box is put back on its wall and
  that velocity component is zeroed ("absorbing wall").
- Velocity limit: |v| ≤ the box half-width per dimension (Clerc & Kennedy's
  Vmax = Xmax).  Initial velocities are uniform in ±Vmax (Halton for IPSO).
- r1, r2 are drawn per particle and per dimension from U(0, 1).
- LDPSO-BT: when the population shrinks, the particles with the worst personal
  best leave (the swarm keeps its best memories); the population size follows
  ``N(t) = round(Nmax − (t−1)(Nmax−Nmin)/(T−1))`` rounded half up, as MATLAB does.
- IPSO: positions and velocities are 2·P consecutive points of a Halton sequence
  (one group each, as the paper describes), scrambled with the run's seed by
  default.  The plain sequence (``halton_scramble=False``) clusters in high
  dimensions: with 20 points, the coordinates built on primes up to 89 only cover
  the low part of [0, 1], so the initial swarm sits in one corner of the box for
  most error parameters; on Wen's ER10L-C10 scenario it ends at 1.6–2.7 mm RMS
  on three seeds of four, against 0.23–0.30 mm scrambled.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from . import _fast

Objective = Callable[[np.ndarray], np.ndarray]
Progress = Callable[[int, int, float], None]

SWARM_METHODS = ("pso", "ipso", "ldpso-bt")
METHODS = ("lm", "pso", "ipso", "ldpso-bt", "hybrid")

#: paper settings, the defaults of each method
PSO_DEFAULTS = {"particles": 240, "iterations": 500, "w": 0.8, "c1": 1.49, "c2": 1.49}  # Kou et al. 2022, Table 3
IPSO_DEFAULTS = {"particles": 20, "iterations": 2000, "c1": 2.05, "c2": 2.05}  # Wen et al. 2019, §3.1.2
LDPSO_DEFAULTS = {  # Kou et al. 2022, §3
    "particles": 240,
    "min_particles": 40,
    "iterations": 500,
    "w1": 0.8,
    "w2": 0.4,
    "switch": 0.8,
    "c1": 1.49,
    "c2": 1.49,
}


@dataclass
class OptimizeResult:
    """Outcome of one optimisation (modelled on scipy's OptimizeResult).

    x: best solution; fun: its objective; history: best objective after each
    iteration (index 0 = initial population / starting point); nit: iterations;
    nfev: objective evaluations; status: ``converged``, ``max_iterations``,
    ``diverged`` or ``failed``; time_s: wall time.
    """

    method: str
    x: np.ndarray
    fun: float
    history: np.ndarray
    nit: int
    nfev: int
    status: str
    message: str
    time_s: float
    extra: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.status in ("converged", "max_iterations") and math.isfinite(self.fun)


def constriction(phi: float) -> float:
    """Clerc's constriction factor K = 2 / |2 − φ − sqrt(φ² − 4φ)|, φ = c1 + c2 > 4."""
    if phi <= 4:
        raise ValueError(f"constriction needs c1 + c2 > 4, got {phi}")
    return 2.0 / abs(2.0 - phi - math.sqrt(phi * phi - 4.0 * phi))


def ldpso_population(t: int, n_max: int, n_min: int, iterations: int) -> int:
    """Population of generation t (1-based) under the linear decrease of Kou et al. eq. 7."""
    if iterations <= 1:
        return n_max
    return int(math.floor(n_max - (t - 1) * (n_max - n_min) / (iterations - 1) + 0.5))


class _Swarm:
    """Shared bookkeeping of the swarm methods: bests, box, velocity limit, history."""

    def __init__(self, objective: Objective, lower, upper, x0, v0, callback: Progress | None, iterations: int):
        self.f = objective
        self.lo = np.asarray(lower, float)
        self.hi = np.asarray(upper, float)
        self.vmax = 0.5 * (self.hi - self.lo)
        self.x = np.clip(x0, self.lo, self.hi)
        self.v = np.clip(v0, -self.vmax, self.vmax)
        fx = self.f(self.x)
        self.nfev = len(self.x)
        self.pbest = self.x.copy()
        self.pbest_f = np.where(np.isfinite(fx), fx, np.inf)
        g = int(np.argmin(self.pbest_f))
        self.gbest, self.gbest_f = self.pbest[g].copy(), float(self.pbest_f[g])
        self.history = [self.gbest_f]
        self.callback = callback
        self.iterations = iterations

    def step(self, mode: int, a: float, c1: float, c2: float, r1, r2, t: int) -> None:
        """One generation: velocity update (mode 0 inertia weight, 1 constriction, 2 social
        only), velocity limit, move, walls, evaluation and bests."""
        if _fast.AVAILABLE:
            x, v = _fast.swarm_step(
                mode, self.v, self.x, self.pbest, self.gbest, r1, r2, a, c1, c2, self.vmax, self.lo, self.hi
            )
        else:
            if mode == 0:
                v = a * self.v + c1 * r1 * (self.pbest - self.x) + c2 * r2 * (self.gbest - self.x)
            elif mode == 1:
                v = a * (self.v + c1 * r1 * (self.pbest - self.x) + c2 * r2 * (self.gbest - self.x))
            else:
                v = a * self.v + c2 * r2 * (self.gbest - self.x)
            v = np.minimum(np.maximum(v, -self.vmax), self.vmax)
            x = self.x + v
            out = (x < self.lo) | (x > self.hi)
            if out.any():
                x = np.minimum(np.maximum(x, self.lo), self.hi)
                v[out] = 0.0
        self.x, self.v = x, v
        fx = self.f(x)
        self.nfev += len(x)
        if _fast.AVAILABLE:
            g = _fast.update_bests(x, fx, self.pbest, self.pbest_f)
        else:
            fx[~np.isfinite(fx)] = np.inf
            better = fx < self.pbest_f
            self.pbest[better] = x[better]
            self.pbest_f[better] = fx[better]
            g = int(np.argmin(self.pbest_f))
        if self.pbest_f[g] < self.gbest_f:
            self.gbest, self.gbest_f = self.pbest[g].copy(), float(self.pbest_f[g])
        self.history.append(self.gbest_f)
        if self.callback is not None:
            self.callback(t, self.iterations, self.gbest_f)

    def keep(self, index: np.ndarray) -> None:
        self.x, self.v = self.x[index], self.v[index]
        self.pbest, self.pbest_f = self.pbest[index], self.pbest_f[index]

    def result(self, method: str, start: float, extra: dict | None = None) -> OptimizeResult:
        finite = math.isfinite(self.gbest_f)
        return OptimizeResult(
            method=method,
            x=self.gbest.copy(),
            fun=self.gbest_f,
            history=np.array(self.history),
            nit=len(self.history) - 1,
            nfev=self.nfev,
            status="max_iterations" if finite else "diverged",
            message=f"{len(self.history) - 1} generations" if finite else "no finite objective value found",
            time_s=time.perf_counter() - start,
            extra=extra or {},
        )


def _uniform_start(rng, n, lower, upper):
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    half = 0.5 * (upper - lower)
    return rng.uniform(lower, upper, (n, lower.size)), rng.uniform(-half, half, (n, lower.size))


def pso(
    objective: Objective,
    lower,
    upper,
    *,
    particles=240,
    iterations=500,
    w=0.8,
    c1=1.49,
    c2=1.49,
    seed=0,
    callback: Progress | None = None,
) -> OptimizeResult:
    """Standard global-best PSO: v ← w v + c1 r1 (pbest − x) + c2 r2 (gbest − x); x ← x + v."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    x0, v0 = _uniform_start(rng, particles, lower, upper)
    s = _Swarm(objective, lower, upper, x0, v0, callback, iterations)
    for t in range(1, iterations + 1):
        r1, r2 = rng.random((2,) + s.x.shape)
        s.step(0, w, c1, c2, r1, r2, t)
    return s.result("pso", start, {"particles": particles, "w": w, "c1": c1, "c2": c2})


def ipso(
    objective: Objective,
    lower,
    upper,
    *,
    particles=20,
    iterations=2000,
    c1=2.05,
    c2=2.05,
    seed=0,
    halton_scramble=True,
    callback: Progress | None = None,
) -> OptimizeResult:
    """IPSO of Wen et al. (2019): Halton initial positions and velocities, constriction factor
    v ← K (v + c1 r1 (pbest − x) + c2 r2 (gbest − x)), K from φ = c1 + c2 (paper: 0.7298)."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    dim = lower.size
    halton = qmc.Halton(d=dim, scramble=halton_scramble, seed=rng if halton_scramble else None)
    if not halton_scramble:
        halton.fast_forward(1)  # the unscrambled sequence starts at the origin
    h = halton.random(2 * particles)
    half = 0.5 * (upper - lower)
    x0 = lower + h[:particles] * (upper - lower)
    v0 = -half + h[particles:] * 2 * half
    K = constriction(c1 + c2)
    s = _Swarm(objective, lower, upper, x0, v0, callback, iterations)
    for t in range(1, iterations + 1):
        r1, r2 = rng.random((2,) + s.x.shape)
        s.step(1, K, c1, c2, r1, r2, t)
    return s.result(
        "ipso", start, {"particles": particles, "c1": c1, "c2": c2, "K": K, "halton_scramble": halton_scramble}
    )


def ldpso_bt(
    objective: Objective,
    lower,
    upper,
    *,
    particles=240,
    min_particles=40,
    iterations=500,
    w1=0.8,
    w2=0.4,
    switch=0.8,
    c1=1.49,
    c2=1.49,
    seed=0,
    callback: Progress | None = None,
) -> OptimizeResult:
    """LDPSO-BT of Kou et al. (2022): linearly decreasing population and a two-stage velocity
    update — standard with w1 for t ≤ switch·T, then v ← w2 v + c2 r2 (gbest − x)."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    x0, v0 = _uniform_start(rng, particles, lower, upper)
    s = _Swarm(objective, lower, upper, x0, v0, callback, iterations)
    sizes = []
    for t in range(1, iterations + 1):
        n = ldpso_population(t, particles, min_particles, iterations)
        if n < len(s.x):
            s.keep(np.sort(np.argsort(s.pbest_f, kind="stable")[:n]))
        sizes.append(len(s.x))
        r2 = rng.random(s.x.shape)
        if t <= switch * iterations:
            s.step(0, w1, c1, c2, rng.random(s.x.shape), r2, t)
        else:
            s.step(2, w2, 0.0, c2, r2, r2, t)
    return s.result(
        "ldpso-bt",
        start,
        {
            "particles": particles,
            "min_particles": min_particles,
            "w1": w1,
            "w2": w2,
            "switch": switch,
            "c1": c1,
            "c2": c2,
            "mean_population": float(np.mean(sizes)) if sizes else particles,
        },
    )


def pso_batch(
    objective: Callable[[np.ndarray], np.ndarray],
    lower,
    upper,
    batch: int,
    *,
    particles=100,
    iterations=200,
    w=0.8,
    c1=1.5,
    c2=1.5,
    seed=0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Independent global-best PSO swarms, one per problem of a batch, advanced together.

    objective maps X (batch, particles, k) to (batch, particles).  Same update, walls and
    velocity limit as :func:`pso`.  Returns the best x (batch, k), its objective (batch,)
    and the best objective per iteration (iterations + 1, batch).
    """
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    vmax = 0.5 * (hi - lo)
    k = lo.size
    x = rng.uniform(lo, hi, (batch, particles, k))
    v = rng.uniform(-vmax, vmax, (batch, particles, k))
    fx = objective(x)
    pbest, pbest_f = x.copy(), fx.copy()
    g = np.argmin(pbest_f, axis=1)
    rows = np.arange(batch)
    gbest, gbest_f = pbest[rows, g].copy(), pbest_f[rows, g].copy()
    history = [gbest_f.copy()]
    for _ in range(iterations):
        r1, r2 = rng.random((2, batch, particles, k))
        v = w * v + c1 * r1 * (pbest - x) + c2 * r2 * (gbest[:, None, :] - x)
        v = np.minimum(np.maximum(v, -vmax), vmax)
        x = x + v
        out = (x < lo) | (x > hi)
        x = np.minimum(np.maximum(x, lo), hi)
        v[out] = 0.0
        fx = objective(x)
        better = fx < pbest_f
        pbest[better] = x[better]
        pbest_f[better] = fx[better]
        g = np.argmin(pbest_f, axis=1)
        improved = pbest_f[rows, g] < gbest_f
        gbest[improved] = pbest[rows, g][improved]
        gbest_f[improved] = pbest_f[rows, g][improved]
        history.append(gbest_f.copy())
    return gbest, gbest_f, np.array(history)


#: above this many residuals, LM solves its steps from the normal equations (k×k) instead
#: of MINPACK's QR of the tall Jacobian: 10⁵ full poses are 6·10⁵ rows
NORMAL_EQUATIONS_ROWS = 30_000


def _lm_normal(
    residuals, jacobian, x0, tol: float, max_iter: int = 200, callback: Progress | None = None
) -> OptimizeResult:
    """Levenberg–Marquardt on the normal equations, with Marquardt's diagonal scaling and
    Nielsen's damping update.  Steps cost one JᵀJ product (BLAS) and a k×k solve; the
    residual itself is always evaluated exactly, so the fixed point is the same as MINPACK's."""
    start = time.perf_counter()
    x = np.asarray(x0, dtype=float).copy()
    r = residuals(x)
    cost = float(r @ r)
    history, nfev, njev = [cost], 1, 0

    def normal(x, r):
        J = jacobian(x)
        return J.T @ J, J.T @ r

    A, g = normal(x, r)
    njev += 1
    lam = 1e-6  # relative to diag(JᵀJ) (Marquardt scaling); a near start, so almost Gauss–Newton
    nu = 2.0
    status, message = "max_iterations", f"{max_iter} iterations"
    for _ in range(max_iter):
        D = np.maximum(np.diag(A), 1e-12 * max(float(np.max(np.diag(A))), 1e-300))
        try:
            h = np.linalg.solve(A + lam * np.diag(D), -g)
        except np.linalg.LinAlgError:
            h = np.linalg.lstsq(A + lam * np.diag(D), -g, rcond=None)[0]
        if np.linalg.norm(h) <= tol * (np.linalg.norm(x) + tol):
            status, message = "converged", "step below xtol"
            break
        x_new = x + h
        r_new = residuals(x_new)
        nfev += 1
        cost_new = float(r_new @ r_new)
        predicted = float(h @ (lam * D * h - g))  # 2·(L(0) − L(h)) of the linear model
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if callback is not None:
            callback(nfev, 0, min(cost, cost_new))
        if rho > 0 and np.isfinite(cost_new):
            decrease = cost - cost_new
            x, r, cost = x_new, r_new, cost_new
            history.append(cost)
            A, g = normal(x, r)
            njev += 1
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            if decrease <= tol * cost or cost == 0.0:
                status, message = "converged", "relative reduction of the sum of squares below ftol"
                break
        else:
            history.append(cost)
            lam *= nu
            nu *= 2.0
            if not np.isfinite(lam) or lam > 1e300:
                status, message = "failed", "damping grew without bound"
                break
    return OptimizeResult(
        "lm",
        x,
        cost,
        np.array(history),
        njev,
        nfev,
        status,
        message,
        time.perf_counter() - start,
        {"solver": "lm-normal"},
    )


def levenberg_marquardt(
    residuals: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    *,
    loss: str = "linear",
    f_scale: float = 1.0,
    max_nfev: int | None = None,
    tol: float = 1e-12,
    callback: Progress | None = None,
) -> OptimizeResult:
    """Levenberg–Marquardt (MINPACK through scipy ``least_squares``) with an analytic Jacobian.

    A robust loss (``huber``, ``soft_l1``, ``cauchy``) or fewer residuals than
    parameters switch to scipy's trust-region reflective solver, which supports them.
    history holds the best sum of squared residuals after each residual evaluation.
    """
    start = time.perf_counter()
    history: list[float] = []

    def fun(x):
        r = residuals(x)
        value = float(r @ r)
        history.append(min(value, history[-1]) if history else value)
        if callback is not None:
            callback(len(history), 0, history[-1])  # total 0: unknown in advance
        return r

    r0 = residuals(np.asarray(x0, float))
    if loss == "linear" and r0.size > NORMAL_EQUATIONS_ROWS:
        return _lm_normal(
            residuals, jacobian, x0, tol, max_iter=200 if max_nfev is None else max_nfev, callback=callback
        )
    method = "lm" if loss == "linear" and r0.size >= len(x0) else "trf"
    kwargs = {"loss": loss, "f_scale": f_scale} if method == "trf" else {}
    try:
        res = least_squares(
            fun,
            x0,
            jac=jacobian,
            method=method,
            x_scale="jac",
            xtol=tol,
            ftol=tol,
            gtol=tol,
            max_nfev=max_nfev,
            **kwargs,
        )
    except (ValueError, np.linalg.LinAlgError) as exc:
        return OptimizeResult(
            "lm",
            np.asarray(x0, float),
            float(r0 @ r0),
            np.array([float(r0 @ r0)]),
            0,
            1,
            "failed",
            str(exc),
            time.perf_counter() - start,
        )
    r = res.fun
    final = float(r @ r)
    status = "converged" if res.status > 0 else "max_iterations" if res.status == 0 else "failed"
    if not np.all(np.isfinite(res.x)) or not math.isfinite(final):
        status = "diverged"
    return OptimizeResult(
        method="lm",
        x=res.x,
        fun=final,
        history=np.array(history),
        nit=int(res.njev or 0),
        nfev=int(res.nfev),
        status=status,
        message=res.message,
        time_s=time.perf_counter() - start,
        extra={"solver": method, "loss": loss, "f_scale": f_scale},
    )
