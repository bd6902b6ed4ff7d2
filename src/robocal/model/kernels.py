"""Compiled kernels of the chain (the ``numba`` backend; imported only when it runs).

One compiled loop per particle runs the whole backward chain, the residuals and the
objective without temporaries, and particles run in parallel.  The results equal the
numpy path of :mod:`robocal.calibration.problem` (the tests check 1e-9 mm).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

CONVENTION_CODE = {"dh": 0, "hayati": 1, "craig": 2}


def chain_constants(geom: np.ndarray) -> np.ndarray:
    """Per-particle constants of the chain, (P, n, 8): a, cos α, sin α, cos θ, sin θ, d, cos β, sin β.

    With cos/sin of the joint values precomputed per pose (:func:`joint_trig`), the kernels
    form cos(q + θ) by the addition theorem and evaluate no trigonometric function at all.
    """
    c = np.empty(geom.shape[:-1] + (8,))
    c[..., 0] = geom[..., 0]
    np.cos(geom[..., 1], out=c[..., 1])
    np.sin(geom[..., 1], out=c[..., 2])
    np.cos(geom[..., 2], out=c[..., 3])
    np.sin(geom[..., 2], out=c[..., 4])
    c[..., 5] = geom[..., 3]
    np.cos(geom[..., 4], out=c[..., 6])
    np.sin(geom[..., 4], out=c[..., 7])
    return c


def joint_trig(q: np.ndarray) -> np.ndarray:
    """(m, n, 2) cos and sin of the joint values."""
    return np.ascontiguousarray(np.stack([np.cos(q), np.sin(q)], -1))


@njit(cache=True, inline="always")
def _chain(conv, g, q, base, tool, V, ncol):
    """Apply base · A_1 ⋯ A_n to the point column (ncol = 1) or all columns of V (3×4) in place."""
    n = g.shape[0]
    for c in range(4):
        for r in range(3):
            V[r, c] = tool[r, c]
    start = 3 if ncol == 1 else 0
    for i in range(n - 1, -1, -1):
        a = g[i, 0]
        ca = g[i, 1]
        sa = g[i, 2]
        ct = q[i, 0] * g[i, 3] - q[i, 1] * g[i, 4]  # cos(q + θ)
        st = q[i, 1] * g[i, 3] + q[i, 0] * g[i, 4]  # sin(q + θ)
        d = g[i, 5]
        cb = g[i, 6]
        sb = g[i, 7]
        for c in range(start, 4):
            x = V[0, c]
            y = V[1, c]
            z = V[2, c]
            if conv == 2:
                if c == 3:
                    z += d
                x, y = ct * x - st * y, st * x + ct * y
                if c == 3:
                    x += a
                y, z = ca * y - sa * z, sa * y + ca * z
            else:
                if conv == 1:
                    x, z = cb * x + sb * z, cb * z - sb * x
                y, z = ca * y - sa * z, sa * y + ca * z
                if c == 3:
                    x += a
                    z += d
                x, y = ct * x - st * y, st * x + ct * y
            V[0, c] = x
            V[1, c] = y
            V[2, c] = z
    for c in range(start, 4):
        x = V[0, c]
        y = V[1, c]
        z = V[2, c]
        for r in range(3):
            V[r, c] = base[r, 0] * x + base[r, 1] * y + base[r, 2] * z + (base[r, 3] if c == 3 else 0.0)


@njit(cache=True, inline="always")
def _constants_one(geom, g):
    """In-kernel :func:`chain_constants` of one particle: geom (n, ≥ 5) → g (n, 8)."""
    for i in range(geom.shape[0]):
        g[i, 0] = geom[i, 0]
        g[i, 1] = math.cos(geom[i, 1])
        g[i, 2] = math.sin(geom[i, 1])
        g[i, 3] = math.cos(geom[i, 2])
        g[i, 4] = math.sin(geom[i, 2])
        g[i, 5] = geom[i, 3]
        g[i, 6] = math.cos(geom[i, 4])
        g[i, 7] = math.sin(geom[i, 4])


@njit(cache=True, inline="always")
def _particle_objective(conv, g, base, tools, q, tidx, pm, Rm, use_rot, k, kind, V):
    """Objective of one particle whose chain constants are g (n, 8)."""
    ncol = 4 if use_rot else 1
    acc = 0.0
    for j in range(q.shape[0]):
        _chain(conv, g, q[j], base, tools[tidx[j]], V, ncol)
        dx = pm[j, 0] - V[0, 3]
        dy = pm[j, 1] - V[1, 3]
        dz = pm[j, 2] - V[2, 3]
        s = dx * dx + dy * dy + dz * dz
        if kind == 1:
            acc += math.sqrt(s)
        else:
            acc += s
            if use_rot:
                # M = R_m Rᵀ: trace and antisymmetric part give the angle at full precision
                tr = 0.0
                for r in range(3):
                    tr += Rm[j, r, 0] * V[r, 0] + Rm[j, r, 1] * V[r, 1] + Rm[j, r, 2] * V[r, 2]
                m21 = Rm[j, 2, 0] * V[1, 0] + Rm[j, 2, 1] * V[1, 1] + Rm[j, 2, 2] * V[1, 2]
                m12 = Rm[j, 1, 0] * V[2, 0] + Rm[j, 1, 1] * V[2, 1] + Rm[j, 1, 2] * V[2, 2]
                m02 = Rm[j, 0, 0] * V[2, 0] + Rm[j, 0, 1] * V[2, 1] + Rm[j, 0, 2] * V[2, 2]
                m20 = Rm[j, 2, 0] * V[0, 0] + Rm[j, 2, 1] * V[0, 1] + Rm[j, 2, 2] * V[0, 2]
                m10 = Rm[j, 1, 0] * V[0, 0] + Rm[j, 1, 1] * V[0, 1] + Rm[j, 1, 2] * V[0, 2]
                m01 = Rm[j, 0, 0] * V[1, 0] + Rm[j, 0, 1] * V[1, 1] + Rm[j, 0, 2] * V[1, 2]
                w0 = m21 - m12
                w1 = m02 - m20
                w2 = m10 - m01
                theta = math.atan2(0.5 * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2), 0.5 * (tr - 1.0))
                acc += k * theta * theta
    return acc


@njit(cache=True, parallel=True)
def objective(conv, geom, base, tools, q, tidx, pm, Rm, use_rot, k, kind):  # pragma: no cover
    """Objective per particle: kind 0 = Σ |δp|² + k θ², kind 1 = Σ |δp| (θ: angle of R_m Rᵀ).

    geom (P, n, 5), base (P, 4, 4), tools (P, T, 4, 4), q from :func:`joint_trig`.
    """
    P = geom.shape[0]
    out = np.empty(P)
    for p in prange(P):
        V = np.empty((3, 4))
        g = np.empty((geom.shape[1], 8))
        _constants_one(geom[p], g)
        out[p] = _particle_objective(conv, g, base[p], tools[p], q, tidx, pm, Rm, use_rot, k, kind, V)
    return out


@njit(cache=True, parallel=True)
def objective_joints(conv, geom0, cols, X, base, tools, q, tidx, pm, Rm, use_rot, k, kind):  # pragma: no cover
    """:func:`objective` when only joint parameters vary: particle p has geometry geom0 (n, 5)
    with X[p] added at the flat positions ``cols``; base (4, 4) and tools (T, 4, 4) are shared.
    No per-generation array of geometries is built."""
    P = X.shape[0]
    n = geom0.shape[0]
    out = np.empty(P)
    for p in prange(P):
        V = np.empty((3, 4))
        geom = geom0.copy()
        flat = geom.reshape(n * geom.shape[1])
        for c in range(cols.shape[0]):
            flat[cols[c]] += X[p, c]
        g = np.empty((n, 8))
        _constants_one(geom, g)
        out[p] = _particle_objective(conv, g, base, tools, q, tidx, pm, Rm, use_rot, k, kind, V)
    return out


@njit(cache=True, parallel=True)
def points(conv, g, base, tool, q):  # pragma: no cover
    """Positions (P, m, 3) mm of the tool point.

    g (P, n, 8) from :func:`chain_constants`, q (m, n, 2) from :func:`joint_trig`,
    base (P, 4, 4), tool (4, 4).
    """
    P = g.shape[0]
    m = q.shape[0]
    out = np.empty((P, m, 3))
    for p in prange(P):
        V = np.empty((3, 4))
        for j in range(m):
            _chain(conv, g[p], q[j], base[p], tool, V, 1)
            out[p, j, 0] = V[0, 3]
            out[p, j, 1] = V[1, 3]
            out[p, j, 2] = V[2, 3]
    return out


@njit(cache=True, parallel=True)
def apply_right_jacobian_inv(phi, w):  # pragma: no cover
    """:func:`robocal.math.so3.apply_right_jacobian_inv` for w (k, m, 3), fused."""
    k, m = w.shape[0], w.shape[1]
    out = np.empty_like(w)
    for j in prange(m):
        a0, a1, a2 = phi[j, 0], phi[j, 1], phi[j, 2]
        th = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if th < 1e-4:
            c = 1.0 / 12.0 + th * th / 720.0
        else:
            c = 1.0 / (th * th) - (1.0 + math.cos(th)) / (2.0 * th * math.sin(th))
        for i in range(k):
            b0, b1, b2 = w[i, j, 0], w[i, j, 1], w[i, j, 2]
            p0 = a1 * b2 - a2 * b1
            p1 = a2 * b0 - a0 * b2
            p2 = a0 * b1 - a1 * b0
            out[i, j, 0] = b0 + 0.5 * p0 + c * (a1 * p2 - a2 * p1)
            out[i, j, 1] = b1 + 0.5 * p1 + c * (a2 * p0 - a0 * p2)
            out[i, j, 2] = b2 + 0.5 * p2 + c * (a0 * p1 - a1 * p0)
    return out
