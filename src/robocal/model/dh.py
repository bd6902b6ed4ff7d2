"""The DH family of conventions: batched forward kinematics and the twist Jacobian.

Conventions (MODEL §1); lengths in mm, angles in rad, joint value ``q_i`` adds to the
joint offset ``theta_i``:

- ``dh``     ``A_i = Rz(q_i+θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)``
- ``hayati`` ``A_i = Rz(q_i+θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i) · Ry(β_i)``
- ``craig``  ``A_i = Rx(α_{i-1}) · Tx(a_{i-1}) · Rz(q_i+θ_i) · Tz(d_i)``; row i holds
  ``(a_{i-1}, α_{i-1}, θ_i, d_i)``.

The geometry of a chain is one array ``geom`` of shape (..., n, 6) whose last axis holds
:data:`KINDS` = (a, alpha, theta, d, beta) and 1.0 for a prismatic joint, whose joint
value (mm) adds to d instead of θ (linear tracks, gantry axes).  Leading axes are free: a
swarm passes (particles, n, 6) with joint values (poses, n) and gets (particles, poses, …)
in one call; the only Python loop is over the joints.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ..math.se3 import end_frame

KINDS: tuple[str, ...] = ("a", "alpha", "theta", "d", "beta")
CONVENTIONS: tuple[str, ...] = ("dh", "hayati", "craig")
A, ALPHA, THETA, D, BETA, PRISMATIC = range(6)
WIDTH = 6


def _joint_values(g: np.ndarray, q: np.ndarray):
    """(q + θ, d) for a revolute joint, (θ, d + q) for a prismatic one; a geometry of five
    columns has turning joints only."""
    if g.shape[-1] <= PRISMATIC:
        return q + g[..., THETA], g[..., D] + 0 * q
    slide = g[..., PRISMATIC]
    return q * (1 - slide) + g[..., THETA], g[..., D] + q * slide


def joint_kinds(convention: str) -> tuple[str, ...]:
    """Geometric parameter kinds of one joint: β only in the hayati convention."""
    return KINDS if convention == "hayati" else KINDS[:4]


def _joint_rotation_translation(convention: str, g: np.ndarray, q: np.ndarray):
    """Rotation (..., 3, 3) and translation (..., 3) of one joint transform.

    g: (..., 5) geometry of the joint with a trailing singleton inserted by the caller
    so that it broadcasts against q (..., m).  Entries are written into preallocated
    arrays, which broadcast by themselves (cheap for small batches).
    """
    a, al, be = g[..., A], g[..., ALPHA], g[..., BETA]
    t, d = _joint_values(g, q)
    ct, st = np.cos(t), np.sin(t)
    ca, sa = np.cos(al), np.sin(al)
    shape = np.broadcast_shapes(ct.shape, ca.shape, a.shape)
    R = np.empty(shape + (3, 3))
    p = np.empty(shape + (3,))
    if convention == "craig":
        # Rx(α) Rz(t); translation Rx(α) (a, 0, 0)ᵀ + Rx(α) Rz(t) (0, 0, d)ᵀ = (a, −sα d, cα d)
        R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = ct, -st, 0.0
        R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = ca * st, ca * ct, -sa
        R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = sa * st, sa * ct, ca
        p[..., 0], p[..., 1], p[..., 2] = a, -sa * d, ca * d
        return R, p
    # Rz(t) Rx(α), columns c0 = (ct, st, 0), c1 = (−st cα, ct cα, sα), c2 = (st sα, −ct sα, cα)
    if convention == "hayati":
        cb, sb = np.cos(be), np.sin(be)
        # · Ry(β): c0' = c0 cβ − c2 sβ, c2' = c0 sβ + c2 cβ
        R[..., 0, 0], R[..., 1, 0], R[..., 2, 0] = ct * cb - st * sa * sb, st * cb + ct * sa * sb, -ca * sb
        R[..., 0, 2], R[..., 1, 2], R[..., 2, 2] = ct * sb + st * sa * cb, st * sb - ct * sa * cb, ca * cb
    else:
        R[..., 0, 0], R[..., 1, 0], R[..., 2, 0] = ct, st, 0.0
        R[..., 0, 2], R[..., 1, 2], R[..., 2, 2] = st * sa, -ct * sa, ca
    R[..., 0, 1], R[..., 1, 1], R[..., 2, 1] = -st * ca, ct * ca, sa
    p[..., 0], p[..., 1], p[..., 2] = a * ct, a * st, d
    return R, p


def chain_frames(convention: str, geom: np.ndarray, q: np.ndarray, base: np.ndarray | None = None):
    """Frames of the chain (rotation, origin) from the base frame to the flange.

    geom: (..., n, 5); q: (..., m, n) rad; base: (..., 4, 4) or None.  Returns lists
    ``Rs``, ``origins`` of length n+1 with shapes (..., m, 3, 3), (..., m, 3) mm: index 0
    is the base frame, index i the frame after joint i.
    """
    n = geom.shape[-2]
    if base is None:
        R, o = np.eye(3), np.zeros(3)
    else:
        R, o = base[..., None, :3, :3], base[..., None, :3, 3]
    Rs, origins = [R], [o]
    for i in range(n):
        Ri, pi = _joint_rotation_translation(convention, geom[..., None, i, :], q[..., i])
        o = o + (R @ pi[..., None])[..., 0]
        R = R @ Ri
        Rs.append(R)
        origins.append(o)
    return Rs, origins


def _turning(geom: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """cos and sin of each joint's angle t = q + θ (q·(1 − slide) + θ with a sliding joint) and
    its d, (..., m, n), by the addition theorem from the sines and cosines of q (m, n) and of θ
    (..., n): a swarm's particles share the poses, and numpy's cos costs ten times a product."""
    if geom.shape[-1] > PRISMATIC:
        slide = geom[..., PRISMATIC]
        kind = slide.reshape(-1, slide.shape[-1])[0]
        if np.any(slide != kind):  # a joint sliding in one chain and turning in another: as written
            t, d = _joint_values(geom[..., None, :, :], q)
            return np.cos(t), np.sin(t), d
        q_turn, d = q * (1 - kind), geom[..., None, :, D] + q * kind
    else:
        q_turn, d = q, geom[..., None, :, D] + 0 * q
    cq, sq = np.cos(q_turn), np.sin(q_turn)
    theta = geom[..., None, :, THETA]
    c0, s0 = np.cos(theta), np.sin(theta)
    return cq * c0 - sq * s0, sq * c0 + cq * s0, d


#: the chain's factor arrays of swarm-sized calls, kept per thread for the next call of the same
#: shape: laid out afresh each call, half a megabyte came and went, past the allocator's trim
#: threshold, and every call took its pages from the system again (50 µs a factor, 40 % of a
#: numpy swarm's time, depending on what the process had allocated before)
_SCRATCH = threading.local()
#: factor arrays up to this size are kept (a swarm's: 20 particles × 32 poses × 6 joints × 4 columns is 120 kB)
SCRATCH_BYTES = 1 << 20
SCRATCH_ENTRIES = 12


def _laid_out(slot: str, values: np.ndarray, shape: tuple) -> np.ndarray:
    """``values`` broadcast to ``shape``, C-contiguous: in this thread's kept array for (slot,
    shape) where it is small, else a new one (what np.ascontiguousarray of the broadcast gives)."""
    if 8 * math.prod(shape) > SCRATCH_BYTES:
        return np.ascontiguousarray(np.broadcast_to(values, shape))
    kept = _SCRATCH.__dict__.setdefault("arrays", {})
    out = kept.pop((slot, shape), None)
    if out is None:
        out = np.empty(shape)
        while len(kept) >= SCRATCH_ENTRIES:
            kept.pop(next(iter(kept)))
    kept[(slot, shape)] = out  # most recent last
    np.copyto(out, values)
    return out


def _joint_first(values: np.ndarray) -> np.ndarray:
    """The view of (..., n) with its last axis first (np.moveaxis without its argument checks,
    a tenth of a swarm call's overhead)."""
    return values.transpose((values.ndim - 1,) + tuple(range(values.ndim - 1)))


def apply_chain(convention: str, geom: np.ndarray, q: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Apply A_1 ⋯ A_n to the column vectors of V, from the flange back to the base.

    V: (..., m, 3, c) vectors in the flange frame; its last column is a point
    (translations apply to it), the others are directions.  Working backwards on
    vectors needs only elementwise rotations about x, y, z (no 3×3 products), and
    for positions alone V is a single column.  A swarm's call holds a few thousand numbers,
    where each numpy operation costs its overhead and a broadcast operand twice a full one:
    every factor is laid out once at the full shape, joint first, and translations are added
    in place to the point column.
    """
    n = geom.shape[-2]
    ct, st, d = _turning(geom, q)  # (..., m, n)
    full = np.broadcast_shapes(ct.shape[:-1] + V.shape[-1:], V.shape[:-2] + V.shape[-1:])

    def per_joint(slot, values):  # (..., m or 1, n) → (n, ..., m, c), contiguous
        return _laid_out(slot, _joint_first(values)[..., None], (n,) + full)

    def per_chain(slot, values):  # (..., 1, n): the same at every pose
        if 8 * n * math.prod(full) > SCRATCH_BYTES:  # a large call: broadcast by each product, not copied
            return _joint_first(values)[..., None]
        return per_joint(slot, values)

    CT, ST = per_joint("ct", ct), per_joint("st", st)
    alpha = geom[..., None, :, ALPHA]
    CA, SA = per_chain("ca", np.cos(alpha)), per_chain("sa", np.sin(alpha))
    if convention == "hayati":
        beta = geom[..., None, :, BETA]
        CB, SB = per_chain("cb", np.cos(beta)), per_chain("sb", np.sin(beta))
    a = _joint_first(np.broadcast_to(geom[..., None, :, A], full[:-1] + (n,)))
    d = _joint_first(np.broadcast_to(d, full[:-1] + (n,)))
    x, y, z = (np.array(np.broadcast_to(V[..., r, :], full)) for r in range(3))  # own copies: added to in place
    for i in range(n - 1, -1, -1):
        if convention == "craig":
            # Rx(α) · Tx(a) · Rz(t) · Tz(d)
            z[..., -1] += d[i]
            x, y = CT[i] * x - ST[i] * y, ST[i] * x + CT[i] * y
            x[..., -1] += a[i]
            y, z = CA[i] * y - SA[i] * z, SA[i] * y + CA[i] * z
        else:
            if convention == "hayati":
                x, z = CB[i] * x + SB[i] * z, CB[i] * z - SB[i] * x
            # Rz(t) · Tz(d) · Tx(a) · Rx(α)
            y, z = CA[i] * y - SA[i] * z, SA[i] * y + CA[i] * z
            x[..., -1] += a[i]
            z[..., -1] += d[i]
            x, y = CT[i] * x - ST[i] * y, ST[i] * x + CT[i] * y
    return np.stack((x, y, z), axis=-2)


def twist_jacobian(convention: str, geom: np.ndarray, q: np.ndarray, base=None, tool=None):
    """Jacobian of the end pose with respect to each joint's geometric parameters.

    Returns ``(J, R_e, p_e, R_flange)`` where J has shape (n, 5, ..., m, 6), one
    contiguous block per parameter: the end-point velocity (mm per unit of the
    parameter) and the angular velocity (rad per unit) in the measuring frame, so that
    a small change ε of parameter k moves the point by ``J[:3] ε`` and rotates the end
    frame by ``Exp(J[3:] ε)`` applied on the left.  Columns for ``beta`` are zero unless
    the convention is hayati.  The ``theta`` column (``d`` for a prismatic joint) is also the
    column of the joint value.
    """
    Rs, origins = chain_frames(convention, geom, q, base)
    R_f = Rs[-1]
    R_e, p_e, shape = end_frame(R_f, origins[-1], tool)
    n = geom.shape[-2]
    J = np.zeros((n, 5) + shape + (6,))

    def rotation_column(i, kind, axis, point):
        r = p_e - point
        out = J[i, kind]
        out[..., 0] = axis[..., 1] * r[..., 2] - axis[..., 2] * r[..., 1]
        out[..., 1] = axis[..., 2] * r[..., 0] - axis[..., 0] * r[..., 2]
        out[..., 2] = axis[..., 0] * r[..., 1] - axis[..., 1] * r[..., 0]
        out[..., 3:] = axis

    def translation_column(i, kind, axis):
        J[i, kind, ..., :3] = axis

    for i in range(n):
        R0, o0, R1, o1 = Rs[i], origins[i], Rs[i + 1], origins[i + 1]
        if convention == "craig":
            x0 = R0[..., :, 0]
            rotation_column(i, ALPHA, x0, o0)
            translation_column(i, A, x0)
            z1 = R1[..., :, 2]
            rotation_column(i, THETA, z1, o1)
            translation_column(i, D, z1)
        else:
            z0 = R0[..., :, 2]
            rotation_column(i, THETA, z0, o0)
            translation_column(i, D, z0)
            t, _ = _joint_values(geom[..., None, i, :], q[..., i])
            # x axis after Rz(q+θ): the direction of Tx(a) and the axis of Rx(α)
            xp = R0[..., :, 0] * np.cos(t)[..., None] + R0[..., :, 1] * np.sin(t)[..., None]
            translation_column(i, A, xp)
            rotation_column(i, ALPHA, xp, o1)
            if convention == "hayati":
                rotation_column(i, BETA, R1[..., :, 1], o1)
    return J, R_e, p_e, R_f
