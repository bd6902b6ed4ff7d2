"""The standard-DH equivalent of any revolute chain, for the closed-form inverses.

Every revolute serial chain, whatever its convention (DH, Hayati with β, Craig, URDF origins
and axes), is exactly ``base_e · Π Rz(s_i q_i + θ_i) Tz(d_i) Tx(a_i) Rx(α_i) · tool_e``: the
frames are placed on the joint axes as they lie at q = 0 (common normals between consecutive
axes), and a joint whose axis runs against its neighbour's parallel axis turns with s_i = −1,
so that parallel axes always have α = 0 there.  The closed forms of :mod:`.closed_form` are
written once for that form.  Lengths mm, angles rad, frames in the robot's measuring frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..math.se3 import invert
from ..model.kinematics import chain_pose, joint_axes
from ..model.robot import Robot

#: two axes closer than this to parallel (|sin| of their angle) are parallel
PARALLEL = 1e-9
#: the equivalent must reproduce the chain to this (mm; rad) at random joint values
EXACT_MM, EXACT_RAD = 1e-7, 1e-10


@dataclass(frozen=True)
class DHEquivalent:
    """``a, alpha, theta, d`` per joint (mm, rad; standard DH), the joint signs ``s`` (±1), and
    the frames ``base`` (measuring frame → frame 0) and ``tool`` (frame n → the robot's tool),
    4×4 mm.  ``phi(q) = s·q + theta`` are the DH joint angles."""

    a: np.ndarray
    alpha: np.ndarray
    theta: np.ndarray
    d: np.ndarray
    s: np.ndarray
    base: np.ndarray
    tool: np.ndarray

    @property
    def geometry(self) -> np.ndarray:
        """(n, 6) rows for :mod:`robocal.model.dh` with θ = 0 (the angles are φ)."""
        n = len(self.a)
        return np.column_stack([self.a, self.alpha, np.zeros(n), self.d, np.zeros(n), np.zeros(n)])

    def phi(self, q: np.ndarray) -> np.ndarray:
        return self.s * q + self.theta

    def q(self, phi: np.ndarray) -> np.ndarray:
        """Joint values (rad) of DH angles φ, wrapped into (−π, π]."""
        return wrap(self.s * (phi - self.theta))

    def pose(self, phi: np.ndarray) -> np.ndarray:
        """End poses (..., 4, 4) of DH angles φ (..., n), in the measuring frame."""
        R, p = chain_pose("dh", self.geometry, phi, self.base, self.tool[None])
        T = np.zeros(R.shape[:-2] + (4, 4))
        T[..., :3, :3], T[..., :3, 3], T[..., 3, 3] = R, p, 1.0
        return T


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) into (−π, π]."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _signed_angle(u: np.ndarray, v: np.ndarray, axis: np.ndarray) -> float:
    return float(np.arctan2(np.cross(u, v) @ axis, u @ v))


def _feet(p1, u1, p2, u2) -> tuple[np.ndarray, np.ndarray]:
    """The closest points of two skew lines (point, unit direction)."""
    w = p1 - p2
    b, d, e = u1 @ u2, u1 @ w, u2 @ w
    den = 1.0 - b * b
    t1, t2 = (b * e - d) / den, (e - b * d) / den
    return p1 + t1 * u1, p2 + t2 * u2


def dh_equivalent(robot: Robot) -> DHEquivalent | None:
    """The robot's geometry (base, joints, tool; not its joint terms or residual) as a standard
    DH chain, or None for a chain with a sliding joint or one the construction does not
    reproduce exactly (checked at random joint values)."""
    if robot.prismatic.any() or robot.n_joints < 2:
        return None
    n = robot.n_joints
    u_raw, p = (x[0] for x in joint_axes(robot.convention, robot.geometry, np.zeros((1, n)), robot.base))
    s = np.ones(n)
    for i in range(1, n):
        if np.linalg.norm(np.cross(u_raw[i - 1], u_raw[i])) < PARALLEL:
            s[i] = s[i - 1] * np.sign(u_raw[i - 1] @ u_raw[i])
    z = s[:, None] * u_raw / np.linalg.norm(u_raw, axis=1)[:, None]
    a, alpha, theta, d = (np.zeros(n) for _ in range(4))
    x_prev = o_prev = None
    for i in range(n - 1):  # the common normal of axes i and i+1 is x of frame i+1
        cross = np.cross(z[i], z[i + 1])
        if np.linalg.norm(cross) >= PARALLEL:
            x = _unit(cross)
            c1, c2 = _feet(p[i], z[i], p[i + 1], z[i + 1])
        else:
            c1 = o_prev if o_prev is not None else p[i] + ((p[i + 1] - p[i]) @ z[i]) * z[i]
            v = (p[i + 1] - c1) - ((p[i + 1] - c1) @ z[i + 1]) * z[i + 1]
            if np.linalg.norm(v) > 1e-9:
                x, c2 = _unit(v), c1 + v
            else:
                x, c2 = (x_prev if x_prev is not None else _unit(np.cross(z[i], [1.0, 0.0, 0.0]) + 1e-300)), c1
        if x_prev is None:  # frame 0 sits where the first normal leaves axis 1: θ1 = d1 = 0
            x_prev, o_prev = x, c1
            base = np.eye(4)
            base[:3, 0], base[:3, 1], base[:3, 2], base[:3, 3] = x, np.cross(z[0], x), z[0], c1
        theta[i] = _signed_angle(x_prev, x, z[i])
        d[i] = (c1 - o_prev) @ z[i]
        a[i] = (c2 - c1) @ x
        alpha[i] = _signed_angle(z[i], z[i + 1], x)
        x_prev, o_prev = x, c2
    frame = np.eye(4)  # the last frame: on the last axis, where the previous normal meets it
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = x_prev, np.cross(z[-1], x_prev), z[-1], o_prev
    R_end, p_end = chain_pose(robot.convention, robot.geometry, np.zeros((1, n)), robot.base, robot.tool[None])
    end = np.eye(4)
    end[:3, :3], end[:3, 3] = R_end[0], p_end[0]
    eq = DHEquivalent(a, alpha, theta, d, s, base, invert(frame) @ end)
    return eq if _reproduces(robot, eq) else None


def _reproduces(robot: Robot, eq: DHEquivalent) -> bool:
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (8, robot.n_joints))
    R, p = chain_pose(robot.convention, robot.geometry, q, robot.base, robot.tool[None])
    T = eq.pose(eq.phi(q))
    return bool(np.abs(T[:, :3, 3] - p).max() < EXACT_MM * max(1.0, robot.reach() / 1e3)
                and np.abs(T[:, :3, :3] - R).max() < EXACT_RAD * 1e3)

