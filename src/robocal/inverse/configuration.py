"""A serial arm's configuration at given joints: which of its inverse solutions the joints are.

Controllers name a Cartesian target's solution by configuration data (KUKA S and T, ABB cf,
FANUC's CONFIG string, the UR branch): encodings of a few geometric facts and of the joints'
turns.  The facts are measured here once, on the robot's own chain, whatever its convention:

- ``front``: the wrist centre lies in front of axis 1 (+1) or behind it (−1), front being the
  side it takes at zero joints (where KUKA, ABB and FANUC arms face forward), across axes 1 and 2,
  turned with joint 1 (KUKA S bit 0, ABB cfx, FANUC T/B, the UR shoulder);
- ``elbow``: the elbow (axis 3) lies above (+1) or below (−1) the line from the shoulder (axis 2)
  to the wrist centre, "above" being the side a forward-reaching arm has up, the turn counted
  about axis 2 so that it keeps its sign when the arm reaches back over the top (KUKA S bit 1,
  "A3 ≥ φ", FANUC U/D, the UR elbow);
- ``lower``: the wrist centre in front of (+1) or behind (−1) the lower arm, the line from axis 2
  to axis 3, counted the same way (ABB cfx);
- the joint values themselves, for signs (A5, KUKA's T), quadrants (ABB) and turns (FANUC).

"Up" is the side of axis 1 away from the robot's foot: where the shoulder stands above the
model's base origin, else where the wrist centre rises at zero joints, else the measuring frame's
z.  Each fact is 0 where the joints lie on its boundary within :data:`TOLERANCE_RAD` (an angle
that comes back as −2·10⁻¹⁴°, or −0.0004° from a program's rounded numbers, is 0°): there either
value holds, and a target keeps its own.
The wrist centre is the point of axis 5 nearest axis 4 (their crossing on a spherical wrist).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.kinematics import joint_axes
from ..model.robot import Robot

#: a joint value or an angle within this (rad, 0.003°) of a boundary is on it.  Not round-off
#: alone: a program stores its targets to a resolution (FANUC 0.001°, KUKA 0.0001°, 0.001 mm),
#: and the joints of a target taught exactly on a boundary come back from its rounded numbers
#: up to about 10⁻⁵ rad either side; within this, the target's own bit is the right one
TOLERANCE_RAD = 5e-5
#: a point within this (mm) of a boundary plane is on it (the same resolution, in position)
TOLERANCE_MM = 0.01


@dataclass(frozen=True)
class Arm:
    """Configuration facts per pose (m,): +1, −1, or 0 on the boundary; ``q`` the joints (m, n) rad."""

    front: np.ndarray
    elbow: np.ndarray
    lower: np.ndarray
    q: np.ndarray

    def row(self, i: int) -> Arm:
        return Arm(self.front[i:i + 1], self.elbow[i:i + 1], self.lower[i:i + 1], self.q[i:i + 1])


def _sign(value: np.ndarray, tolerance: float) -> np.ndarray:
    return np.where(np.abs(value) <= tolerance, 0, np.sign(value)).astype(int)


def _nearest_points(p1, u1, p2, u2):
    """The point of line 2 nearest line 1 (batched; parallel lines give p2)."""
    w = p1 - p2
    b = np.einsum("...i,...i", u1, u2)
    d, e = np.einsum("...i,...i", u1, w), np.einsum("...i,...i", u2, w)
    den = 1.0 - b * b
    t2 = np.where(np.abs(den) > 1e-12, (e - b * d) / np.where(np.abs(den) > 1e-12, den, 1.0), 0.0)
    return p2 + t2[..., None] * u2


def arm_configuration(robot: Robot, q: np.ndarray) -> Arm | None:
    """The configuration facts of joints q (m, n) rad of a revolute arm of at least five joints
    (None for others: only their joint values name a solution)."""
    q = np.atleast_2d(np.asarray(q, float))
    m, n = q.shape
    if n < 5 or robot.prismatic[:5].any():
        return None
    zero = np.zeros((1, n))
    axes, points = joint_axes(robot.convention, robot.geometry, np.vstack([zero, q]), robot.base)
    u, p = axes[:, :5], points[:, :5]
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    wc = _nearest_points(p[:, 3], u[:, 3], p[:, 4], u[:, 4])  # (m+1, 3)
    u1, p1 = u[0, 0], p[0, 0]  # axis 1 does not move

    def across(x):  # the part of x − p1 perpendicular to axis 1
        r = x - p1
        return r - np.outer(r @ u1, u1) if r.ndim == 2 else r - (r @ u1) * u1

    # forward: perpendicular to axes 1 and 2 (a lateral offset along axis 2 is no side), on the side
    # the wrist centre takes at zero joints
    normal = np.cross(u1, u[:, 1])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    side0 = np.sign(normal[0] @ across(wc[0])) or 1.0
    forward = side0 * normal[1:]
    front = _sign(np.einsum("mi,mi->m", across(wc[1:]), forward), TOLERANCE_MM)
    shoulder = _nearest_points(p1, u1, p[0, 1], u[0, 1])
    rises = [u1 @ (shoulder - robot.base[:3, 3]), u1 @ (wc[0] - shoulder)]  # mm
    up = next((np.sign(r) for r in rises if abs(r) > 1.0), np.sign(u1[2]) or 1.0)
    u2, c2, c3 = u[1:, 1], p[1:, 1], p[1:, 2]
    reference = np.sign(np.einsum("mi,mi->m", np.cross(forward, np.broadcast_to(up * u1, forward.shape)), u2))
    elbow = _turn(wc[1:] - c2, c3 - c2, u2) * reference  # from the shoulder–wrist line to the elbow
    lower = -_turn(c3 - c2, wc[1:] - c2, u2) * reference  # from the lower arm to the wrist centre
    return Arm(front, elbow.astype(int), lower.astype(int), q)


def _turn(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Sign of the turn from a to b about axis (rows), 0 within the tolerance."""
    cross = np.einsum("mi,mi->m", np.cross(a, b), axis)
    scale = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    return _sign(cross / np.maximum(scale, 1e-300), TOLERANCE_RAD)


def joint_sign(q: np.ndarray) -> np.ndarray:
    """Sign of joint values (rad), 0 within the tolerance."""
    return _sign(np.asarray(q, float), TOLERANCE_RAD)
