"""The ISO 9283 test cube and its five poses, placed in a robot's workspace and checked for reach.

ISO 9283:1998 §6.2: a cube with edges parallel to the base frame, in the part of the workspace
most used; the poses lie in one of its diagonal planes, here the plane through the edge C1C2
(y and z low) and the opposite edge C7C8 (y and z high).  P1 is the cube's centre; P2, P3, P4,
P5 lie on the plane's diagonals at 10 % of the diagonal's length from the corners C1, C2, C7,
C8.  All five share one orientation.  A cycle visits P1, P2, P3, P4, P5 (§7.2.3: 30 cycles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError
from ..math.so3 import matrix_to_rpy
from ..model.jointspace import ready_configurations
from ..model.robot import Robot

LABELS = ("P1", "P2", "P3", "P4", "P5")
#: the corners of the measuring plane, relative to the centre in half-edges: C1, C2, C7, C8
CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]], float)
#: where P2..P5 sit: this fraction of the plane's diagonal from their corners (ISO: 10 % ± 2 %)
FROM_CORNER = 0.10
#: default cube edge as a fraction of the arm's length scale (sum of |a| and |d|)
DEFAULT_EDGE = 0.15
#: poses reached within these count as reached
REACH_MM, REACH_RAD = 1e-3, 1e-6


def cube_positions(centre: np.ndarray, edge: float) -> np.ndarray:
    """P1..P5 (5, 3) mm for a cube of edge ``edge`` mm centred at ``centre``."""
    centre = np.asarray(centre, float)
    corners = centre + 0.5 * edge * CORNERS
    opposite = corners[[2, 3, 0, 1]]  # the plane's diagonals: C1–C7, C2–C8
    return np.vstack([centre, corners + FROM_CORNER * (opposite - corners)])


@dataclass(frozen=True)
class TestPlan:
    """The five poses: labels, positions (5, 3) mm and rotation (3, 3) in the base frame of
    the nominal model, the joints (5, n) rad reaching them, and the cube (centre mm, edge mm)."""

    labels: tuple[str, ...]
    position: np.ndarray
    rotation: np.ndarray
    q: np.ndarray
    centre: np.ndarray
    edge: float

    def rpy_deg(self) -> np.ndarray:
        return np.degrees(matrix_to_rpy(self.rotation))


def plan_cube(robot: Robot, edge: float | None = None, centre: np.ndarray | None = None,
              start: np.ndarray | None = None) -> TestPlan:
    """The ISO 9283 poses of ``robot`` (its nominal model, base frame: its [base] is left out, as
    the test is stated in the robot's base frame): the cube of ``edge`` mm (default
    :data:`DEFAULT_EDGE` of the arm's length scale) at ``centre`` (default where the tool is at
    the start), the orientation the tool has at the start: ``start``, or the best conditioned
    of :func:`ready_configurations` from which all five are reached.  Every pose must be reached
    within the joint limits on the start's configuration branch, else an input error names it."""
    robot = robot.replace(base=np.eye(4), residual=None)
    if start is not None and np.shape(start) != (robot.n_joints,):
        raise InputError(f"--start needs {robot.n_joints} joint values", option="start")
    starts = ready_configurations(robot) if start is None else [np.asarray(start, float)]
    edge = DEFAULT_EDGE * robot.reach() if edge is None else float(edge)
    if not (edge > 0 and math.isfinite(edge)):
        raise InputError(f"the cube's edge must be > 0 mm, got {edge:g}", option="cube-size")
    failure = ""
    for q0 in starts:  # the first start from which every pose is reached
        plan, failure = _try(robot, q0, edge, centre)
        if plan is not None:
            return plan
    raise InputError(failure + ": choose a smaller --cube-size, another --center or a --start configuration",
                     option="cube-size")


def _try(robot: Robot, q0: np.ndarray, edge: float, centre: np.ndarray | None) -> tuple[TestPlan | None, str]:
    from ..inverse.local import solve_ik

    T0 = robot.fk(q0[None])[0]
    centre = T0[:3, 3] if centre is None else np.asarray(centre, float)
    positions = cube_positions(centre, edge)
    R = np.repeat(T0[None, :3, :3], len(LABELS), axis=0)
    sol = solve_ik(robot, positions, R, np.repeat(q0[None], len(LABELS), axis=0))
    for k, label in enumerate(LABELS):
        if sol.status[k] != "ok" and not (sol.position_error[k] <= REACH_MM and sol.rotation_error[k] <= REACH_RAD):
            where = ", ".join(f"{v:.1f}" for v in positions[k])
            return None, f"{label} at ({where}) mm is not reached ({sol.status[k]}, {sol.position_error[k]:.3g} mm off)"
    return TestPlan(LABELS, positions, T0[:3, :3], sol.q, centre, edge), ""
