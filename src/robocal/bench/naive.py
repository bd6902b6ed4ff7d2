"""A straightforward numpy IPSO of Wen et al.'s workload: the reference robocal's own time is
measured against (W1), written as a newcomer to numpy would, sharing no code with robocal.

Forward kinematics multiplies one 4×4 matrix per joint (Hayati: Rz(q+θ)·Tz(d)·Tx(a)·Rx(α)·Ry(β),
the textbook matrix)
for every particle and pose at once; the objective is Σ |p_m − p|² + k·θ², θ the angle of
R_m·Rᵀ from its trace; the swarm is Clerc's constriction PSO from a scrambled Halton start.
"""

from __future__ import annotations

import time

import numpy as np


def _joint_matrices(a, alpha, theta, d, beta, q):
    """(P, m, 4, 4) transforms of one joint, the textbook matrix filled in: a … beta (P,), q (m,)."""
    t = q[None, :] + theta[:, None]
    ct, st = np.cos(t), np.sin(t)
    ca, sa = np.cos(alpha)[:, None], np.sin(alpha)[:, None]
    cb, sb = np.cos(beta)[:, None], np.sin(beta)[:, None]
    A = np.zeros(t.shape + (4, 4))
    # Rz(t)·Rx(α) has columns (ct, st, 0), (−st cα, ct cα, sα), (st sα, −ct sα, cα); ·Ry(β) mixes the first and last
    A[..., 0, 0], A[..., 1, 0], A[..., 2, 0] = ct * cb - st * sa * sb, st * cb + ct * sa * sb, -ca * sb
    A[..., 0, 1], A[..., 1, 1], A[..., 2, 1] = -st * ca, ct * ca, sa
    A[..., 0, 2], A[..., 1, 2], A[..., 2, 2] = ct * sb + st * sa * cb, st * sb - ct * sa * cb, ca * cb
    A[..., 0, 3], A[..., 1, 3], A[..., 2, 3] = a[:, None] * ct, a[:, None] * st, d[:, None]
    A[..., 3, 3] = 1.0
    return A


def objective(table: np.ndarray, X: np.ndarray, columns: list[tuple[int, int]], q: np.ndarray, p_m: np.ndarray,
              R_m: np.ndarray, k: float) -> np.ndarray:
    """Objective of each particle X (P, k): its values added to the DH table (n, 5: a, α, θ, d, β)
    at ``columns`` (joint, column)."""
    geometry = np.repeat(table[None], len(X), axis=0)
    for c, (joint, column) in enumerate(columns):
        geometry[:, joint, column] += X[:, c]
    T = np.broadcast_to(np.eye(4), (len(X), len(q), 4, 4))
    for i in range(table.shape[0]):
        g = geometry[:, i]
        T = T @ _joint_matrices(g[:, 0], g[:, 1], g[:, 2], g[:, 3], g[:, 4], q[:, i])
    dp = p_m[None] - T[..., :3, 3]
    M = R_m[None] @ np.swapaxes(T[..., :3, :3], -1, -2)
    angle = np.arccos(np.clip((np.trace(M, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
    return np.sum(dp * dp, axis=(1, 2)) + k * np.sum(angle * angle, axis=1)


def ipso(f, lower: np.ndarray, upper: np.ndarray, particles: int, iterations: int, c1: float, c2: float,
         seed: int = 0) -> tuple[np.ndarray, float, float]:
    """(best x, its objective, seconds) of constriction PSO from a scrambled Halton start."""
    from scipy.stats import qmc

    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    h = qmc.Halton(d=len(lower), scramble=True, seed=rng).random(2 * particles)
    x = lower + h[:particles] * (upper - lower)
    vmax = (upper - lower) / 2
    v = -vmax + h[particles:] * 2 * vmax
    phi = c1 + c2
    K = 2.0 / abs(2.0 - phi - np.sqrt(phi * phi - 4.0 * phi))
    fx = f(x)
    best_x, best_f = x.copy(), fx.copy()
    g = int(np.argmin(best_f))
    for _ in range(iterations):
        r1, r2 = rng.random(x.shape), rng.random(x.shape)
        v = K * (v + c1 * r1 * (best_x - x) + c2 * r2 * (best_x[g] - x))
        v = np.clip(v, -vmax, vmax)
        x = x + v
        outside = (x < lower) | (x > upper)
        x = np.clip(x, lower, upper)
        v[outside] = 0.0
        fx = f(x)
        better = fx < best_f
        best_x[better], best_f[better] = x[better], fx[better]
        g = int(np.argmin(best_f))
    return best_x[g], float(best_f[g]), time.perf_counter() - start


def wen2019(k: float):
    """Wen 2019's IPSO workload on robocal's simulated ER10L-C10 campaign, orientation weighed
    by k (mm²/rad², robocal's default): (objective, lower, upper) for :func:`ipso`."""
    from ..io.robotfile import load_robot
    from ..presets import wen2019 as paper
    from ..simulation import simulate

    robot = load_robot("er10l-c10")
    sim = simulate(robot, paper.POSES, deviations="paper", seed=1)
    meas = sim.measurements
    kinds = {"a": 0, "alpha": 1, "theta": 2, "d": 3, "beta": 4}
    columns = []
    for name in paper.PARAMETERS:
        kind = name.rstrip("0123456789")
        columns.append((int(name[len(kind):]) - 1, kinds[kind]))
    box = np.array([paper.BOX[1] if kind in ("alpha", "theta", "beta") else paper.BOX[0]
                    for kind in (n.rstrip("0123456789") for n in paper.PARAMETERS)])
    table = np.array(robot.geometry[:, :5], dtype=float)

    def f(X):
        return objective(table, X, columns, meas.q, meas.position, meas.rotation, k)

    return f, -box, box
