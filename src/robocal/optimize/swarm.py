"""One particle-swarm engine, and the swarm methods of the papers built on it.

The engine advances B independent global-best swarms of P particles each (B = 1 for a
calibration, B = number of targets for the batched PSO of Chen et al.) with one of three
velocity updates; the ``numba`` backend fuses the update, the ``numpy`` backend
broadcasts it, and both give the same particles.

Choices where the papers are silent (the same for every method):

- Search box: ``lower``/``upper`` per parameter (the caller centres it on the initial
  estimate).  A particle that leaves the box is put back on its wall and that velocity
  component is zeroed ("absorbing wall").
- Velocity limit: |v| ≤ the box half-width per dimension (Clerc & Kennedy's Vmax = Xmax).
  Initial velocities are uniform in ±Vmax (Halton for IPSO).
- r1, r2 are drawn per particle and per dimension from U(0, 1).
- LDPSO-BT: when the population shrinks, the particles with the worst personal best leave
  (the swarm keeps its best memories); the population follows
  ``N(t) = round(Nmax − (t−1)(Nmax−Nmin)/(T−1))`` rounded half up, as MATLAB does.
- IPSO: positions and velocities are 2·P consecutive points of a Halton sequence (one
  group each, as the paper describes), scrambled with the run's seed by default.  The
  plain sequence (``halton_scramble=False``) clusters in high dimensions: with 20 points,
  the coordinates built on primes up to 89 only cover the low part of [0, 1], so the
  initial swarm sits in one corner of the box for most parameters; on Wen's ER10L-C10
  scenario it ends at 1.6–2.7 mm RMS on three seeds of four, against 0.23–0.30 mm
  scrambled.

A swarm runs a fixed number of generations by design, so a finished run has status
``completed`` (``diverged`` when no particle ever had a finite objective).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable

import numpy as np

from ..model.compiled import resolve
from .result import OptimizeResult, Progress

Objective = Callable[[np.ndarray], np.ndarray]

#: velocity updates: inertia weight, constriction factor, social term only
INERTIA, CONSTRICTION, SOCIAL = 0, 1, 2


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


class SwarmEngine:
    """B independent swarms of P particles over k parameters, advanced together.

    objective maps positions (P, k) to (P,) for one swarm, or (B, P, k) to (B, P) for a
    batch (``batched=True``).  x0, v0: (B, P, k).  Non-finite objective values count as +∞.
    """

    def __init__(self, objective: Objective, lower, upper, x0, v0, *, batched: bool = False,
                 backend: str = "auto", callback: Progress | None = None, iterations: int = 0):
        self.f = objective
        self.batched = batched
        self.lo = np.asarray(lower, float)
        self.hi = np.asarray(upper, float)
        self.vmax = 0.5 * (self.hi - self.lo)
        self.B, self.P, self.k = np.shape(x0)
        # C order from the start, as the kernels return them: a Halton start comes in Fortran order,
        # and each layout is a kernel specialisation of its own (seconds of compiling on a first run)
        self.x = np.ascontiguousarray(np.clip(np.asarray(x0, float).reshape(-1, self.k), self.lo, self.hi))
        self.v = np.ascontiguousarray(np.clip(np.asarray(v0, float).reshape(-1, self.k), -self.vmax, self.vmax))
        self.kernels = None
        if resolve(backend) == "numba":
            from . import kernels

            self.kernels = kernels
        self.nfev = 0
        fx = self._evaluate(self.x)
        self.pbest = self.x.copy()
        self.pbest_f = np.where(np.isfinite(fx), fx, np.inf)
        self.gbest = np.empty((self.B, self.k))
        self.gbest_f = np.full(self.B, np.inf)
        self._update_global(self._group_argmin())
        self.history = [self.gbest_f.copy()]
        self.callback = callback
        self.iterations = iterations

    def _evaluate(self, x: np.ndarray) -> np.ndarray:
        X = x.reshape(self.B, -1, self.k) if self.batched else x
        fx = np.asarray(self.f(X), dtype=float).reshape(-1)
        self.nfev += len(x)
        return fx

    def _group_argmin(self) -> np.ndarray:
        P = len(self.x) // self.B
        return np.argmin(self.pbest_f.reshape(self.B, P), axis=1) + np.arange(self.B) * P

    def _update_global(self, rows: np.ndarray) -> None:
        if self.B == 1:  # the common case, without fancy indexing
            r = int(rows[0])
            if self.pbest_f[r] < self.gbest_f[0]:
                self.gbest[0] = self.pbest[r]
                self.gbest_f[0] = self.pbest_f[r]
            return
        better = self.pbest_f[rows] < self.gbest_f
        self.gbest[better] = self.pbest[rows[better]]
        self.gbest_f[better] = self.pbest_f[rows[better]]

    def draw(self, rng: np.random.Generator, n: int = 2) -> np.ndarray:
        """n arrays of U(0, 1) per particle and dimension, (n, rows, k)."""
        return rng.random((n, self.B, len(self.x) // self.B, self.k)).reshape(n, -1, self.k)

    def step(self, mode: int, a: float, c1: float, c2: float, r1: np.ndarray, r2: np.ndarray, t: int) -> None:
        """One generation: velocity update, velocity limit, move, walls, evaluation and bests."""
        P = len(self.x) // self.B
        if self.kernels is not None:
            x, v = self.kernels.step(mode, self.v, self.x, self.pbest, self.gbest, P, r1, r2, a, c1, c2,
                                     self.vmax, self.lo, self.hi)
        else:
            g = self.gbest[0] if self.B == 1 else np.repeat(self.gbest, P, axis=0)
            if mode == INERTIA:
                v = a * self.v + c1 * r1 * (self.pbest - self.x) + c2 * r2 * (g - self.x)
            elif mode == CONSTRICTION:
                v = a * (self.v + c1 * r1 * (self.pbest - self.x) + c2 * r2 * (g - self.x))
            else:
                v = a * self.v + c2 * r2 * (g - self.x)
            v = np.minimum(np.maximum(v, -self.vmax), self.vmax)
            x = self.x + v
            out = (x < self.lo) | (x > self.hi)
            if out.any():
                x = np.minimum(np.maximum(x, self.lo), self.hi)
                v[out] = 0.0
        self.x, self.v = x, v
        fx = self._evaluate(x)
        if self.kernels is not None:
            rows = self.kernels.update_bests(x, fx, self.pbest, self.pbest_f, P, self.B)
        else:
            fx[~np.isfinite(fx)] = np.inf
            better = fx < self.pbest_f
            self.pbest[better] = x[better]
            self.pbest_f[better] = fx[better]
            rows = self._group_argmin()
        self._update_global(rows)
        self.history.append(self.gbest_f.copy())
        if self.callback is not None:
            self.callback(t, self.iterations, float(self.gbest_f.min()))

    def keep(self, index: np.ndarray) -> None:
        """Keep only the particles ``index`` (one swarm only)."""
        if self.B != 1:
            raise ValueError("particles leave a single swarm only")
        self.x, self.v = self.x[index], self.v[index]
        self.pbest, self.pbest_f = self.pbest[index], self.pbest_f[index]

    @property
    def size(self) -> int:
        return len(self.x) // self.B

    def result(self, method: str, start: float, extra: dict) -> OptimizeResult:
        """The single swarm's outcome."""
        best = float(self.gbest_f[0])
        finite = math.isfinite(best)
        generations = len(self.history) - 1
        return OptimizeResult(
            method=method,
            x=self.gbest[0].copy(),
            fun=best,
            history=np.array([h[0] for h in self.history]),
            nit=generations,
            nfev=self.nfev,
            status="completed" if finite else "diverged",
            message=f"{generations} generations" if finite else "no finite objective value found",
            time_s=time.perf_counter() - start,
            extra=extra,
        )


def _floats_may_overflow(method):
    """Run a swarm method with overflow and invalid-value warnings off, for that call only:
    particles far outside any sensible model may overflow, and they simply lose."""

    @functools.wraps(method)
    def run(*args, **kwargs):
        with np.errstate(over="ignore", invalid="ignore"):
            return method(*args, **kwargs)

    return run


def _uniform_start(rng, n, lower, upper, batch: int = 1):
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    half = 0.5 * (upper - lower)
    shape = (batch, n, lower.size)
    return rng.uniform(lower, upper, shape), rng.uniform(-half, half, shape)


def _with_start(x0: np.ndarray, start) -> np.ndarray:
    """The initial positions with particle 0 of every swarm put at ``start`` (when given)."""
    if start is None:
        return x0
    x0 = np.array(x0, copy=True)
    x0[:, 0] = start
    return x0


@_floats_may_overflow
def pso(objective: Objective, lower, upper, *, particles: int, iterations: int, w: float, c1: float, c2: float,
        seed: int | None = 0, callback: Progress | None = None, backend: str = "auto",
        start: np.ndarray | None = None) -> OptimizeResult:
    """Standard global-best PSO: v ← w v + c1 r1 (pbest − x) + c2 r2 (gbest − x); x ← x + v.
    Kou et al. (2022), Table 3, give settings (:data:`robocal.presets.kou2022.PSO`).  start: a
    position for particle 0 (else random)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    x0, v0 = _uniform_start(rng, particles, lower, upper)
    x0 = _with_start(x0, start)
    s = SwarmEngine(objective, lower, upper, x0, v0, backend=backend, callback=callback, iterations=iterations)
    for t in range(1, iterations + 1):
        r1, r2 = s.draw(rng)
        s.step(INERTIA, w, c1, c2, r1, r2, t)
    return s.result("pso", t0, {"particles": particles, "w": w, "c1": c1, "c2": c2})


@_floats_may_overflow
def ipso(objective: Objective, lower, upper, *, particles: int, iterations: int, c1: float, c2: float,
         seed: int | None = 0, halton_scramble: bool = True, callback: Progress | None = None,
         backend: str = "auto", start: np.ndarray | None = None) -> OptimizeResult:
    """IPSO of Wen et al. (2019): Halton initial positions and velocities, constriction factor
    v ← K (v + c1 r1 (pbest − x) + c2 r2 (gbest − x)), K from φ = c1 + c2 (paper: 0.7298;
    settings :data:`robocal.presets.wen2019.IPSO`).  start: a position for particle 0 (else
    its Halton point)."""
    from .halton import halton

    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    # scipy.stats.qmc.Halton's numbers (the unscrambled sequence skips its origin)
    h = halton(2 * particles, lower.size, rng) if halton_scramble else halton(2 * particles, lower.size, start=1)
    half = 0.5 * (upper - lower)
    x0 = lower + h[:particles] * (upper - lower)
    v0 = -half + h[particles:] * 2 * half
    K = constriction(c1 + c2)
    s = SwarmEngine(objective, lower, upper, _with_start(x0[None], start), v0[None], backend=backend,
                    callback=callback, iterations=iterations)
    for t in range(1, iterations + 1):
        r1, r2 = s.draw(rng)
        s.step(CONSTRICTION, K, c1, c2, r1, r2, t)
    return s.result("ipso", t0, {"particles": particles, "c1": c1, "c2": c2, "K": K,
                                    "halton_scramble": halton_scramble})


@_floats_may_overflow
def ldpso_bt(objective: Objective, lower, upper, *, particles: int, min_particles: int, iterations: int,
             w1: float, w2: float, switch: float, c1: float, c2: float, seed: int | None = 0,
             callback: Progress | None = None, backend: str = "auto", start: np.ndarray | None = None
             ) -> OptimizeResult:
    """LDPSO-BT of Kou et al. (2022): linearly decreasing population and a two-stage velocity
    update, standard with w1 for t ≤ switch·T, then v ← w2 v + c2 r2 (gbest − x) (settings
    :data:`robocal.presets.kou2022.LDPSO_BT`).  start: a position for particle 0 (else random)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    x0, v0 = _uniform_start(rng, particles, lower, upper)
    x0 = _with_start(x0, start)
    s = SwarmEngine(objective, lower, upper, x0, v0, backend=backend, callback=callback, iterations=iterations)
    sizes = []
    for t in range(1, iterations + 1):
        n = ldpso_population(t, particles, min_particles, iterations)
        if n < s.size:
            s.keep(np.sort(np.argsort(s.pbest_f, kind="stable")[:n]))
        sizes.append(s.size)
        if t <= switch * iterations:
            r1, r2 = s.draw(rng)
            s.step(INERTIA, w1, c1, c2, r1, r2, t)
        else:
            (r2,) = s.draw(rng, 1)
            s.step(SOCIAL, w2, 0.0, c2, r2, r2, t)
    return s.result("ldpso-bt", t0, {
        "particles": particles, "min_particles": min_particles, "w1": w1, "w2": w2, "switch": switch,
        "c1": c1, "c2": c2, "mean_population": float(np.mean(sizes)) if sizes else particles,
    })


@_floats_may_overflow
def pso_batch(objective: Objective, lower, upper, batch: int, *, particles: int, iterations: int, w: float,
              c1: float, c2: float, seed: int | None = 0,
              backend: str = "auto") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Independent global-best PSO swarms, one per problem of a batch, advanced together.

    objective maps X (batch, particles, k) to (batch, particles).  Same update, walls and
    velocity limit as :func:`pso`; Chen et al. §4.2 give settings
    (:data:`robocal.presets.chen2023.PSO`).  Returns the best x
    (batch, k), its objective (batch,) and the best objective per iteration
    (iterations + 1, batch).
    """
    rng = np.random.default_rng(seed)
    x0, v0 = _uniform_start(rng, particles, lower, upper, batch)
    s = SwarmEngine(objective, lower, upper, x0, v0, batched=True, backend=backend)
    for t in range(1, iterations + 1):
        r1, r2 = s.draw(rng)
        s.step(INERTIA, w, c1, c2, r1, r2, t)
    return s.gbest.copy(), s.gbest_f.copy(), np.array(s.history)
