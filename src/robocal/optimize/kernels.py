"""Compiled swarm update (the ``numba`` backend of :mod:`robocal.optimize.swarm`).

Imported only when a swarm runs on numba.  The arithmetic follows the numpy path's
operation order, so both give the same particles bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def step(mode, v, x, pbest, gbest, P, r1, r2, a, c1, c2, vmax, lo, hi):  # pragma: no cover
    """Velocity and position update of particles (R, k), fused.

    gbest (G, k) holds each swarm's best; particle row r belongs to swarm r // P.
    mode 0: v ← a v + c1 r1 (pbest − x) + c2 r2 (gbest − x)   (inertia weight a)
    mode 1: v ← a (v + c1 r1 (pbest − x) + c2 r2 (gbest − x)) (constriction a)
    mode 2: v ← a v + c2 r2 (gbest − x)                       (social only)
    Then |v| ≤ vmax, x ← x + v, and a coordinate leaving [lo, hi] is put on the wall with
    its velocity zeroed.  Returns the new (x, v).
    """
    R, k = x.shape
    xn = np.empty_like(x)
    vn = np.empty_like(v)
    for p in range(R):
        g = p // P
        for j in range(k):
            if mode == 0:
                u = a * v[p, j] + c1 * r1[p, j] * (pbest[p, j] - x[p, j]) + c2 * r2[p, j] * (gbest[g, j] - x[p, j])
            elif mode == 1:
                u = a * (v[p, j] + c1 * r1[p, j] * (pbest[p, j] - x[p, j]) + c2 * r2[p, j] * (gbest[g, j] - x[p, j]))
            else:
                u = a * v[p, j] + c2 * r2[p, j] * (gbest[g, j] - x[p, j])
            u = min(max(u, -vmax[j]), vmax[j])
            y = x[p, j] + u
            if y < lo[j]:
                y = lo[j]
                u = 0.0
            elif y > hi[j]:
                y = hi[j]
                u = 0.0
            xn[p, j] = y
            vn[p, j] = u
    return xn, vn


@njit(cache=True)
def update_bests(x, fx, pbest, pbest_f, P, n_groups):  # pragma: no cover
    """Personal bests in place (a non-finite fx never improves one); returns the row of the
    best personal best of each swarm, (n_groups,)."""
    best = np.full(n_groups, -1)
    for p in range(x.shape[0]):
        f = fx[p]
        if f < pbest_f[p]:  # NaN compares false; +inf never below a finite best
            pbest_f[p] = f
            for j in range(x.shape[1]):
                pbest[p, j] = x[p, j]
        g = p // P
        if best[g] < 0 or pbest_f[p] < pbest_f[best[g]]:
            best[g] = p
    return best


def warm_up() -> None:
    """Compile (or load from numba's cache) both kernels with the types a swarm calls them
    with, so that no swarm's clock includes it."""
    z, row = np.zeros((2, 1)), np.zeros(1)
    step(0, z, z.copy(), z.copy(), np.zeros((1, 1)), 2, z, z, 0.5, 1.0, 1.0, row + 1.0, row - 1.0, row + 1.0)
    update_bests(z, np.zeros(2), z.copy(), np.full(2, np.inf), 2, 1)
