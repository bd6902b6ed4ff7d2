"""Serial-arm forward kinematics and the twist Jacobian, batched over any leading shape.

Conventions (SPEC §2); lengths in mm, angles in rad, joint value ``q_i`` adds to
the joint offset ``theta_i``:

- ``dh``     ``A_i = Rz(q_i+θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)``
- ``hayati`` ``A_i = Rz(q_i+θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i) · Ry(β_i)``
- ``craig``  ``A_i = Rx(α_{i-1}) · Tx(a_{i-1}) · Rz(q_i+θ_i) · Tz(d_i)``; row i holds
  ``(a_{i-1}, α_{i-1}, θ_i, d_i)``.

End pose ``T = Base · A_1 ⋯ A_n · Tool``; the measured point is the origin of Tool.

The geometry of a chain is one array ``geom`` of shape (..., n, 5) whose last axis
holds :data:`KINDS` = (a, alpha, theta, d, beta).  Leading axes are free: a swarm
passes (particles, n, 5) with joint values (poses, n) and gets (particles, poses, …)
in one call; the only Python loop is over the joints.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from .transforms import homogeneous

KINDS: tuple[str, ...] = ("a", "alpha", "theta", "d", "beta")
CONVENTIONS: tuple[str, ...] = ("dh", "hayati", "craig")
A, ALPHA, THETA, D, BETA = range(5)


def _joint_rotation_translation(convention: str, g: np.ndarray, q: np.ndarray):
    """Rotation (..., 3, 3) and translation (..., 3) of one joint transform.

    g: (..., 5) geometry of the joint with a trailing singleton inserted by the
    caller so that it broadcasts against q (..., m).  Entries are written into
    preallocated arrays, which broadcast by themselves (cheap for small batches).
    """
    a, al, th, d, be = (g[..., k] for k in range(5))
    t = q + th
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


def _check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise ValueError(f"unknown convention {convention!r}; expected one of {', '.join(CONVENTIONS)}")


def _chain_inputs(convention: str, geom, q):
    _check_convention(convention)
    geom = np.asarray(geom, dtype=float)
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != geom.shape[-2]:
        raise ValueError(f"joint values have {q.shape[-1]} columns but the robot has {geom.shape[-2]} joints")
    return geom, q


def chain_frames(convention: str, geom: np.ndarray, q: np.ndarray, base: np.ndarray | None = None):
    """Frames of the chain (rotation, origin) from the base frame to the flange.

    geom: (..., n, 5); q: (..., m, n) rad; base: (..., 4, 4) or None.
    Returns lists ``Rs``, ``os`` of length n+1 with shapes (..., m, 3, 3), (..., m, 3):
    index 0 is the base frame, index i the frame after joint i.
    """
    geom, q = _chain_inputs(convention, geom, q)
    n = geom.shape[-2]
    if base is None:
        R = np.eye(3)
        o = np.zeros(3)
    else:
        base = np.asarray(base, dtype=float)
        R = base[..., None, :3, :3]
        o = base[..., None, :3, 3]
    Rs, os_ = [R], [o]
    for i in range(n):
        Ri, pi = _joint_rotation_translation(convention, geom[..., None, i, :], q[..., i])
        o = o + (R @ pi[..., None])[..., 0]
        R = R @ Ri
        Rs.append(R)
        os_.append(o)
    return Rs, os_


def _apply_chain(convention: str, geom: np.ndarray, q: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Apply A_1 ⋯ A_n to the column vectors of V, from the flange back to the base.

    V: (..., m, 3, c) vectors in the flange frame; its last column is a point
    (translations apply to it), the others are directions.  Working backwards on
    vectors needs only elementwise rotations about x, y, z — no 3×3 products — and
    for positions alone V is a single column.
    """
    n = geom.shape[-2]
    V = np.asarray(V, dtype=float)
    x, y, z = V[..., 0, :], V[..., 1, :], V[..., 2, :]
    e = np.zeros(V.shape[-1])
    e[-1] = 1.0  # translations act on the last column only
    for i in range(n - 1, -1, -1):
        g = geom[..., i, :]
        a, d = g[..., A, None], g[..., D, None]  # (..., 1): broadcast over poses
        ca, sa = np.cos(g[..., ALPHA])[..., None, None], np.sin(g[..., ALPHA])[..., None, None]
        t = q[..., i] + g[..., THETA, None]
        ct, st = np.cos(t)[..., None], np.sin(t)[..., None]
        if convention == "craig":
            # Rx(α) · Tx(a) · Rz(t) · Tz(d)
            z = z + d[..., None] * e
            x, y = ct * x - st * y, st * x + ct * y
            x = x + a[..., None] * e
            y, z = ca * y - sa * z, sa * y + ca * z
        else:
            if convention == "hayati":
                cb, sb = np.cos(g[..., BETA])[..., None, None], np.sin(g[..., BETA])[..., None, None]
                x, z = cb * x + sb * z, cb * z - sb * x
            # Rz(t) · Tz(d) · Tx(a) · Rx(α)
            y, z = ca * y - sa * z, sa * y + ca * z
            x = x + a[..., None] * e
            z = z + d[..., None] * e
            x, y = ct * x - st * y, st * x + ct * y
    return np.stack(np.broadcast_arrays(x, y, z), axis=-2)


def _tool_vectors(tool, columns: slice) -> np.ndarray:
    if tool is None:
        tool = np.eye(4)[None]
    return np.asarray(tool, dtype=float)[..., :3, columns]


def _to_base(V: np.ndarray, base) -> np.ndarray:
    if base is None:
        return V
    base = np.asarray(base, dtype=float)
    out = base[..., None, :3, :3] @ V
    out[..., 3 if V.shape[-1] == 4 else 0] += base[..., None, :3, 3]
    return out


def chain_pose(convention: str, geom, q, base=None, tool=None):
    """End pose of the chain: rotation (..., m, 3, 3) and position (..., m, 3) in mm.

    geom (..., n, 5); q (..., m, n) rad; base (..., 4, 4) or None; tool (..., m, 4, 4)
    or (..., 1, 4, 4) (one tool per pose allows several targets on one flange), or
    None for the flange itself.
    """
    geom, q = _chain_inputs(convention, geom, q)
    V = _to_base(_apply_chain(convention, geom, q, _tool_vectors(tool, slice(0, 4))), base)
    return V[..., :3], V[..., 3]


def chain_points(convention: str, geom, q, base=None, tool=None) -> np.ndarray:
    """Positions (..., m, 3) in mm of the measured point only: the cheap path for swarms."""
    geom, q = _chain_inputs(convention, geom, q)
    V = _to_base(_apply_chain(convention, geom, q, _tool_vectors(tool, slice(3, 4))), base)
    return V[..., 0]


def chain_twist_jacobian(convention: str, geom, q, base=None, tool=None):
    """Jacobian of the end pose with respect to each joint's geometric parameters.

    Returns ``(J, R_e, p_e, R_flange)`` where J has shape (n, 5, ..., m, 6) — one
    contiguous block per parameter, the layout least-squares wants: entries are
    the end-point velocity (mm per unit of the parameter) and the angular velocity
    (rad per unit) in the base-of-measurement frame, so that a small change ε of
    parameter k moves the point by ``J[:3] ε`` and rotates the end frame by
    ``Exp(J[3:] ε)`` applied on the left.  Columns for ``beta`` are zero unless the
    convention is hayati.  The ``theta`` column is also the column of the joint value.
    """
    Rs, os_ = chain_frames(convention, geom, q, base)
    geom = np.asarray(geom, dtype=float)
    q = np.asarray(q, dtype=float)
    R_f, o_f = Rs[-1], os_[-1]
    if tool is not None:
        tool = np.asarray(tool, dtype=float)
        p_e = o_f + (R_f @ tool[..., :3, 3:])[..., 0]
        R_e = R_f @ tool[..., :3, :3]
    else:
        p_e, R_e = o_f, R_f
    n = geom.shape[-2]
    shape = np.broadcast_shapes(p_e.shape, R_f.shape[:-1])[:-1]
    J = np.zeros((n, 5) + shape + (6,))

    def rot(col_i, kind, axis, point):
        r = p_e - point
        out = J[col_i, kind]
        out[..., 0] = axis[..., 1] * r[..., 2] - axis[..., 2] * r[..., 1]
        out[..., 1] = axis[..., 2] * r[..., 0] - axis[..., 0] * r[..., 2]
        out[..., 2] = axis[..., 0] * r[..., 1] - axis[..., 1] * r[..., 0]
        out[..., 3:] = axis

    def trans(col_i, kind, axis):
        J[col_i, kind, ..., :3] = axis

    for i in range(n):
        R0, o0, R1, o1 = Rs[i], os_[i], Rs[i + 1], os_[i + 1]
        if convention == "craig":
            x0 = R0[..., :, 0]
            rot(i, ALPHA, x0, o0)
            trans(i, A, x0)
            z1 = R1[..., :, 2]
            rot(i, THETA, z1, o1)
            trans(i, D, z1)
        else:
            z0 = R0[..., :, 2]
            rot(i, THETA, z0, o0)
            trans(i, D, z0)
            t = q[..., i] + geom[..., None, i, THETA]
            # x axis after Rz(q+θ): the direction of Tx(a) and the axis of Rx(α)
            xp = R0[..., :, 0] * np.cos(t)[..., None] + R0[..., :, 1] * np.sin(t)[..., None]
            trans(i, A, xp)
            rot(i, ALPHA, xp, o1)
            if convention == "hayati":
                rot(i, BETA, R1[..., :, 1], o1)
    return J, R_e, p_e, R_f


@dataclass(frozen=True, eq=False)
class Robot:
    """A serial arm: geometry, joint limits, base and tool frames.

    geometry: (n, 5) array of (a mm, alpha rad, theta rad, d mm, beta rad) per joint.
    limits: (n, 2) rad, ±inf where a joint has none.  base: measuring/world frame →
    robot base (4×4, mm).  tool: flange → measured point (4×4).  targets: further
    named tool frames for several reflectors on one flange (the unnamed target ""
    is ``tool``).
    """

    convention: str
    geometry: np.ndarray
    limits: np.ndarray | None = None
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    tool: np.ndarray = field(default_factory=lambda: np.eye(4))
    targets: Mapping[str, np.ndarray] = field(default_factory=dict)
    name: str = ""
    source: str = ""  # where it was loaded from (file path or "built-in NAME"), for messages

    def __post_init__(self) -> None:
        _check_convention(self.convention)
        g = np.array(self.geometry, dtype=float)
        if g.ndim != 2 or g.shape[1] != 5:
            raise ValueError("geometry must have shape (n, 5)")
        object.__setattr__(self, "geometry", g)
        lim = np.tile([-np.inf, np.inf], (g.shape[0], 1)) if self.limits is None else np.array(self.limits, float)
        object.__setattr__(self, "limits", lim)
        object.__setattr__(self, "base", np.array(self.base, dtype=float))
        object.__setattr__(self, "tool", np.array(self.tool, dtype=float))
        object.__setattr__(self, "targets", {k: np.array(v, float) for k, v in self.targets.items()})

    @classmethod
    def from_dh(cls, convention: str, a, alpha, theta, d, beta=None, **kw) -> Robot:
        """Build from per-joint sequences (mm, rad)."""
        n = len(a)
        beta = np.zeros(n) if beta is None else beta
        return cls(convention, np.column_stack([a, alpha, theta, d, beta]), **kw)

    @property
    def n_joints(self) -> int:
        return self.geometry.shape[0]

    a = property(lambda self: self.geometry[:, A])
    alpha = property(lambda self: self.geometry[:, ALPHA])
    theta = property(lambda self: self.geometry[:, THETA])
    d = property(lambda self: self.geometry[:, D])
    beta = property(lambda self: self.geometry[:, BETA])

    @property
    def target_names(self) -> tuple[str, ...]:
        return ("",) + tuple(self.targets)

    def tool_frames(self, targets: Sequence[str] | None = None) -> np.ndarray:
        """Tool frame per pose, (m, 4, 4), or (1, 4, 4) when no targets are given."""
        if targets is None:
            return self.tool[None]
        table = {"": self.tool, **self.targets}
        try:
            return np.stack([table[t] for t in targets])
        except KeyError as exc:
            raise ValueError(f"robot has no tool frame for target {exc.args[0]!r}") from None

    def fk(self, q, targets: Sequence[str] | None = None) -> np.ndarray:
        """End poses (m, 4, 4) for joint values q (m, n) in rad."""
        R, p = chain_pose(self.convention, self.geometry, np.atleast_2d(q), self.base, self.tool_frames(targets))
        return homogeneous(R, p)

    def positions(self, q, targets: Sequence[str] | None = None) -> np.ndarray:
        """Measured-point positions (m, 3) in mm for joint values q (m, n) in rad."""
        _, p = chain_pose(self.convention, self.geometry, np.atleast_2d(q), self.base, self.tool_frames(targets))
        return p

    def replace(self, **changes) -> Robot:
        return replace(self, **changes)

    def reach(self) -> float:
        """A length scale of the arm (mm): sum of |a| and |d|, at least 1."""
        return float(max(1.0, np.abs(self.a).sum() + np.abs(self.d).sum()))
