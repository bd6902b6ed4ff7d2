"""Compiled kernels of the chain (the ``numba`` backend; imported only when it runs).

One compiled loop per particle runs the whole backward chain, the residuals and the
objective; each joint runs over all poses in one contiguous loop, so that the compiler's vector
lanes take several poses at once, and the measurements are compared in the robot's base frame
(moved there once per call, not once per particle).  Each entry point comes twice: a serial
one, for the calls a swarm makes (a few hundred chain evaluations: a thread pool costs more
than it gains, and a serial kernel starts no OpenMP layer), and a parallel one for large
calls (``*_parallel``).  The results
equal the numpy path of :mod:`robocal.calibration.fit.problem` (the tests check 1e-9 mm).
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
    """(n, 2, m) cos and sin of the joint values q (m, n), joint first: the kernels run each
    joint over all poses in one contiguous loop."""
    return np.ascontiguousarray(np.stack([np.cos(q.T), np.sin(q.T)], 1))


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
def _tool_columns(tools, tidx, S):
    """S (12, m): per pose, the tool frame's axes x, y, z and its point, three rows each."""
    for j in range(tidx.shape[0]):
        T = tools[tidx[j]]
        for c in range(4):
            for r in range(3):
                S[3 * c + r, j] = T[r, c]


@njit(cache=True, inline="always")
def _turn_column(conv, X, Y, Z, j, ct, st, ca, sa, cb, sb, ta, td):
    """Pose j of a column (rows X, Y, Z of S) turned by one joint: DH and Hayati Rz(q+θ)·Tz(d)·Tx(a)·Rx(α)
    [·Ry(β)], Craig Rx(α)·Tx(a)·Rz(q+θ)·Tz(d) (ta, td: a and d for the point, 0.0 for an axis, added
    all the same)."""
    if conv == 2:
        x, y, z = X[j], Y[j], Z[j] + td
        x, y = ct * x - st * y + ta, st * x + ct * y
        X[j], Y[j], Z[j] = x, ca * y - sa * z, sa * y + ca * z
        return
    x, y, z = X[j], Y[j], Z[j]
    if conv == 1:
        x, z = cb * x + sb * z, cb * z - sb * x
    y, z = ca * y - sa * z, sa * y + ca * z
    x += ta
    X[j], Y[j], Z[j] = ct * x - st * y, st * x + ct * y, z + td


@njit(cache=True, inline="always")
def _chain_columns(conv, g, q, S, first):
    """Turn the columns of S (12, m) from column ``first`` on (0: the frame's axes and its point; 3: the
    point alone) by A_n, …, A_1 in turn (:func:`_turn_column`); q (n, 2, m) from :func:`joint_trig`,
    g (n, 8).

    Each joint takes cos and sin of q + θ at every pose, then turns the three axes' columns of a pose
    one after the other in one loop over the poses, then the point's in another, each loop with the
    convention a constant: the compiler keeps a pose's numbers in registers and its vector lanes take
    several poses at once.  A loop per column read and wrote every row four times a joint (W1's
    objective 54 → 33 µs a generation, 40 particles × 2000 full poses 6.3 → 3.5 ms; position-only
    calls as before; the same operations, the same bits)."""
    m = S.shape[1]
    X0, Y0, Z0, X1, Y1, Z1 = S[0], S[1], S[2], S[3], S[4], S[5]
    X2, Y2, Z2, X3, Y3, Z3 = S[6], S[7], S[8], S[9], S[10], S[11]
    CT = np.empty(m)  # cos and sin of q + θ at every pose: once a joint, for every column
    ST = np.empty(m)
    for i in range(g.shape[0] - 1, -1, -1):
        a, ca, sa, c0, s0, d, cb, sb = g[i, 0], g[i, 1], g[i, 2], g[i, 3], g[i, 4], g[i, 5], g[i, 6], g[i, 7]
        cq = q[i, 0]
        sq = q[i, 1]
        for j in range(m):
            CT[j] = cq[j] * c0 - sq[j] * s0  # cos(q + θ)
            ST[j] = sq[j] * c0 + cq[j] * s0
        # the convention a constant in each loop, so that each compiles without a branch (written out: the
        # loops as an inlined helper took 5 s more to compile; numba's literal_unroll kept prange serial; one
        # loop for all four columns, with the axes' behind a flag, made position-only calls 25-40 % slower)
        if conv == 2:
            if first == 0:
                for j in range(m):
                    _turn_column(2, X0, Y0, Z0, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
                    _turn_column(2, X1, Y1, Z1, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
                    _turn_column(2, X2, Y2, Z2, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
            for j in range(m):
                _turn_column(2, X3, Y3, Z3, j, CT[j], ST[j], ca, sa, cb, sb, a, d)
        elif conv == 1:
            if first == 0:
                for j in range(m):
                    _turn_column(1, X0, Y0, Z0, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
                    _turn_column(1, X1, Y1, Z1, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
                    _turn_column(1, X2, Y2, Z2, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
            for j in range(m):
                _turn_column(1, X3, Y3, Z3, j, CT[j], ST[j], ca, sa, cb, sb, a, d)
        else:
            if first == 0:
                for j in range(m):
                    _turn_column(0, X0, Y0, Z0, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
                    _turn_column(0, X1, Y1, Z1, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
                    _turn_column(0, X2, Y2, Z2, j, CT[j], ST[j], ca, sa, cb, sb, 0.0, 0.0)
            for j in range(m):
                _turn_column(0, X3, Y3, Z3, j, CT[j], ST[j], ca, sa, cb, sb, a, d)


@njit(cache=True, inline="always")
def _in_base(base, pm, Rm, use_rot, P, Q):
    """The measurements in the robot's base frame B: P (m, 3) = B_Rᵀ (p_m − b), Q (m, 3, 3) =
    B_Rᵀ R_m.  Distances and rotation angles are the same there, and the chain's frame is then
    compared as it comes out, without a product by B per particle and pose."""
    for j in range(pm.shape[0]):
        for r in range(3):
            P[j, r] = (base[0, r] * (pm[j, 0] - base[0, 3]) + base[1, r] * (pm[j, 1] - base[1, 3])
                       + base[2, r] * (pm[j, 2] - base[2, 3]))
            if use_rot:
                for c in range(3):
                    Q[j, r, c] = base[0, r] * Rm[j, 0, c] + base[1, r] * Rm[j, 1, c] + base[2, r] * Rm[j, 2, c]


@njit(cache=True, inline="always")
def _errors(S, P, Q, use_rot, k, kind):
    """Σ over poses of |δp|² + k θ² (kind 0) or |δp| (kind 1), the chain's frames S (12, m)
    against P and Q of :func:`_in_base`; θ the angle of Q·Rᵀ (R's columns are S's first three),
    from its trace and antisymmetric part at full precision."""
    acc = 0.0
    for j in range(S.shape[1]):
        dx = P[j, 0] - S[9, j]
        dy = P[j, 1] - S[10, j]
        dz = P[j, 2] - S[11, j]
        s = dx * dx + dy * dy + dz * dz
        if kind == 1:
            acc += math.sqrt(s)
            continue
        acc += s
        if use_rot:
            # M[a, b] = Σ_c Q[a, c] R[b, c], R[b, c] = S[3c + b]: its trace and antisymmetric part
            x0, y0, z0 = S[0, j], S[1, j], S[2, j]
            x1, y1, z1 = S[3, j], S[4, j], S[5, j]
            x2, y2, z2 = S[6, j], S[7, j], S[8, j]
            q0, q1, q2 = Q[j, 0, 0], Q[j, 0, 1], Q[j, 0, 2]
            r0, r1, r2 = Q[j, 1, 0], Q[j, 1, 1], Q[j, 1, 2]
            t0, t1, t2 = Q[j, 2, 0], Q[j, 2, 1], Q[j, 2, 2]
            trace = q0 * x0 + q1 * x1 + q2 * x2 + r0 * y0 + r1 * y1 + r2 * y2 + t0 * z0 + t1 * z1 + t2 * z2
            w0 = (t0 * y0 + t1 * y1 + t2 * y2) - (r0 * z0 + r1 * z1 + r2 * z2)  # M21 − M12
            w1 = (q0 * z0 + q1 * z1 + q2 * z2) - (t0 * x0 + t1 * x1 + t2 * x2)  # M02 − M20
            w2 = (r0 * x0 + r1 * x1 + r2 * x2) - (q0 * y0 + q1 * y1 + q2 * y2)  # M10 − M01
            theta = math.atan2(0.5 * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2), 0.5 * (trace - 1.0))
            acc += k * theta * theta
    return acc


@njit(cache=True, inline="always")
def _joints_particle(conv, geom0, cols, x, S0, q, P, Q, use_rot, k, kind):
    """Objective of the particle whose joint deviations x sit at the flat positions ``cols`` of
    the geometry geom0 (n, 5), its chain run on the tool columns S0 (12, m)."""
    n = geom0.shape[0]
    geom = geom0.copy()
    flat = geom.reshape(n * geom.shape[1])
    for c in range(cols.shape[0]):
        flat[cols[c]] += x[c]
    g = np.empty((n, 8))
    _constants_one(geom, g)
    S = S0.copy()
    _chain_columns(conv, g, q, S, 0 if use_rot else 3)
    return _errors(S, P, Q, use_rot, k, kind)


@njit(cache=True, inline="always")
def _frames_particle(conv, geom, base, tools, q, tidx, pm, Rm, use_rot, k, kind):
    """Objective of a particle with its own geometry (n, 5), base (4, 4) and tools (T, 4, 4)."""
    m = tidx.shape[0]
    g = np.empty((geom.shape[0], 8))
    _constants_one(geom, g)
    S = np.empty((12, m))
    _tool_columns(tools, tidx, S)
    _chain_columns(conv, g, q, S, 0 if use_rot else 3)
    P = np.empty((m, 3))
    Q = np.empty((m if use_rot else 1, 3, 3))
    _in_base(base, pm, Rm, use_rot, P, Q)
    return _errors(S, P, Q, use_rot, k, kind)


@njit(cache=True)
def objective(conv, geom, base, tools, q, tidx, pm, Rm, use_rot, k, kind):  # pragma: no cover
    """Objective per particle: kind 0 = Σ |δp|² + k θ², kind 1 = Σ |δp| (θ: angle of R_m Rᵀ).

    geom (P, n, 5), base (P, 4, 4), tools (P, T, 4, 4), q from :func:`joint_trig`.
    """
    out = np.empty(geom.shape[0])
    for p in range(geom.shape[0]):
        out[p] = _frames_particle(conv, geom[p], base[p], tools[p], q, tidx, pm, Rm, use_rot, k, kind)
    return out


@njit(cache=True, parallel=True)
def objective_parallel(conv, geom, base, tools, q, tidx, pm, Rm, use_rot, k, kind):  # pragma: no cover
    """:func:`objective`, particles in parallel."""
    out = np.empty(geom.shape[0])
    for p in prange(geom.shape[0]):
        out[p] = _frames_particle(conv, geom[p], base[p], tools[p], q, tidx, pm, Rm, use_rot, k, kind)
    return out


@njit(cache=True, inline="always")
def _shared(base, tools, tidx, pm, Rm, use_rot):
    """What the particles of :func:`objective_joints` share: the tool columns and the
    measurements in the base frame."""
    m = tidx.shape[0]
    S0 = np.empty((12, m))
    _tool_columns(tools, tidx, S0)
    P = np.empty((m, 3))
    Q = np.empty((m if use_rot else 1, 3, 3))
    _in_base(base, pm, Rm, use_rot, P, Q)
    return S0, P, Q


@njit(cache=True)
def objective_joints(conv, geom0, cols, X, base, tools, q, tidx, pm, Rm, use_rot, k, kind):  # pragma: no cover
    """:func:`objective` when only joint parameters vary: particle p has geometry geom0 (n, 5)
    with X[p] added at the flat positions ``cols``; base (4, 4) and tools (T, 4, 4) are shared.
    No per-generation array of geometries is built."""
    S0, P, Q = _shared(base, tools, tidx, pm, Rm, use_rot)
    out = np.empty(X.shape[0])
    for p in range(X.shape[0]):
        out[p] = _joints_particle(conv, geom0, cols, X[p], S0, q, P, Q, use_rot, k, kind)
    return out


@njit(cache=True, parallel=True)
def objective_joints_parallel(conv, geom0, cols, X, base, tools, q, tidx, pm, Rm, use_rot, k,
                              kind):  # pragma: no cover
    """:func:`objective_joints`, particles in parallel."""
    S0, P, Q = _shared(base, tools, tidx, pm, Rm, use_rot)
    out = np.empty(X.shape[0])
    for p in prange(X.shape[0]):
        out[p] = _joints_particle(conv, geom0, cols, X[p], S0, q, P, Q, use_rot, k, kind)
    return out


@njit(cache=True, parallel=True)
def points(conv, g, base, tool, q):  # pragma: no cover
    """Positions (P, m, 3) mm of the tool point.

    g (P, n, 8) from :func:`chain_constants`, q (n, 2, m) from :func:`joint_trig`,
    base (P, 4, 4), tool (4, 4).
    """
    P = g.shape[0]
    m = q.shape[2]
    out = np.empty((P, m, 3))
    for p in prange(P):
        S = np.empty((12, m))
        for j in range(m):
            for r in range(3):
                S[9 + r, j] = tool[r, 3]
        _chain_columns(conv, g[p], q, S, 3)
        for j in range(m):
            for r in range(3):
                out[p, j, r] = base[p, r, 0] * S[9, j] + base[p, r, 1] * S[10, j] + base[p, r, 2] * S[11, j] \
                    + base[p, r, 3]
    return out


@njit(cache=True, inline="always")
def _right_jacobian_inv_pose(phi, w, out, j):
    """Pose j of :func:`apply_right_jacobian_inv`: w[:, j] (k, 3) into out[:, j]."""
    a0, a1, a2 = phi[j, 0], phi[j, 1], phi[j, 2]
    th = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if th < 1e-4:
        c = 1.0 / 12.0 + th * th / 720.0
    else:
        c = 1.0 / (th * th) - (1.0 + math.cos(th)) / (2.0 * th * math.sin(th))
    for i in range(w.shape[0]):
        b0, b1, b2 = w[i, j, 0], w[i, j, 1], w[i, j, 2]
        p0 = a1 * b2 - a2 * b1
        p1 = a2 * b0 - a0 * b2
        p2 = a0 * b1 - a1 * b0
        out[i, j, 0] = b0 + 0.5 * p0 + c * (a1 * p2 - a2 * p1)
        out[i, j, 1] = b1 + 0.5 * p1 + c * (a2 * p0 - a0 * p2)
        out[i, j, 2] = b2 + 0.5 * p2 + c * (a0 * p1 - a1 * p0)


@njit(cache=True)
def apply_right_jacobian_inv(phi, w):  # pragma: no cover
    """:func:`robocal.math.so3.apply_right_jacobian_inv` for w (k, m, 3), fused."""
    out = np.empty_like(w)
    for j in range(w.shape[1]):
        _right_jacobian_inv_pose(phi, w, out, j)
    return out


@njit(cache=True, parallel=True)
def apply_right_jacobian_inv_parallel(phi, w):  # pragma: no cover
    """:func:`apply_right_jacobian_inv`, poses in parallel."""
    out = np.empty_like(w)
    for j in prange(w.shape[1]):
        _right_jacobian_inv_pose(phi, w, out, j)
    return out


@njit(cache=True, inline="always")
def _walk_tree(feature, threshold, left, right, root, value, X, out, t):
    """Every pose of X down the tree at ``root`` to its leaf (a node with feature < 0), left where
    the joint is not above the threshold (NaN too, as the numpy walk): out[:, t]."""
    for i in range(X.shape[0]):
        node = root
        while feature[node] >= 0:
            node = right[node] if X[i, feature[node]] > threshold[node] else left[node]
        out[i, t] = value[node]


@njit(cache=True)
def tree_walk(feature, threshold, left, right, roots, value, X):  # pragma: no cover
    """:meth:`robocal.model.trees.Ensemble.per_tree`: each tree's leaf value (m, trees) at X (m, n),
    a tree at a time (its nodes stay in the first-level cache while every pose walks it).  The
    ladder's forked workers run this serial one, where an OpenMP layer may not start
    (:func:`robocal.backend.kernel_threads` gives a child process one thread)."""
    out = np.empty((X.shape[0], roots.shape[0]))
    for t in range(roots.shape[0]):
        _walk_tree(feature, threshold, left, right, roots[t], value, X, out, t)
    return out


@njit(cache=True, parallel=True)
def tree_walk_parallel(feature, threshold, left, right, roots, value, X):  # pragma: no cover
    """:func:`tree_walk`, trees in parallel (each tree's column is written by one thread: the same
    values)."""
    out = np.empty((X.shape[0], roots.shape[0]))
    for t in prange(roots.shape[0]):
        _walk_tree(feature, threshold, left, right, roots[t], value, X, out, t)
    return out


#: each serial kernel and its parallel twin (:func:`robocal.backend.run_kernel` picks one per call)
TWINS = ((objective, objective_parallel), (objective_joints, objective_joints_parallel),
         (apply_right_jacobian_inv, apply_right_jacobian_inv_parallel), (tree_walk, tree_walk_parallel))
