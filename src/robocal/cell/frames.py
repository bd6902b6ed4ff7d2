"""The one frame algebra of a robot cell: every use of a calibrated model on a robot goes through it.

The chain, stated once (4×4 transforms, mm)::

    world ──base──▶ robot base ──joints──▶ flange ──tool──▶ TCP
    world ──user──▶ program frame ──target──▶ TCP

- *world* is the frame a model's poses are in.  For the nominal model it is the controller's
  world (robot root) frame: its ``base`` holds the pedestal or the axis convention (KUKA's A1
  about −Z is a base rotation of 180° about x), so ``nominal.fk(q)`` is what the controller
  computes for joints q.  For a calibrated model it is the measuring instrument's frame.  Both
  models share the robot base, so a pose goes from the nominal's world to the calibrated one's as
  ``B_cal · B_nom⁻¹`` (:meth:`Cell.to_accurate`).
- *user* is the frame a program states its targets in, in the controller's world: KRL ``$BASE``
  (BASE_DATA[n]), RAPID's work object (uframe · oframe), a URScript feature, FANUC UF n.  A
  Cartesian target T_p is the goal ``user · T_p`` (:meth:`Cell.goal`); a pose P in the world is
  written back as ``user⁻¹ · P`` (:meth:`Cell.in_user`).
- *flange* is the nominal model's tool frame: the frame the controller's tool data are stated in
  (KUKA's $FLANGE, ABB's tool0, UR's tool flange, FANUC's faceplate; a URDF's tool0).  The TCP is
  ``flange · tool data`` (``--tool``, the program's: KRL $TOOL (TOOL_DATA[n]), RAPID tooldata,
  URScript set_tcp, FANUC UT n), or the flange itself where none is given: the controller's TCP,
  which the calibrated robot reaches on its calibrated joints and base.  The calibrated model's
  own tool is the point its calibration measured (a tracker's reflector, a probe); it stands in
  for a program's tool only where the user says that this is the tool it measured
  (``--tool NAME=calibrated``), never by how near the two are: which tool is the real one is the
  user's knowledge.

``compensate`` and ``filter`` build their robots with :func:`make_cell`, so that the same goal with
the same tool gives the same joints in both.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..exceptions import Note
from ..math.se3 import invert
from ..math.so3 import orientation_error
from ..model.robot import Robot

#: a calibrated tool nearer than this to the TCP (mm, deg) may be that tool, measured: said, with
#: how to use it (it is used only where the user says so)
TOOL_NEAR_MM, TOOL_NEAR_DEG = 5.0, 2.0


def frame_gap(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (mm) and rotation angle (deg) between frames a and b ((..., 4, 4))."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    mm = np.linalg.norm(a[..., :3, 3] - b[..., :3, 3], axis=-1)
    shape = np.broadcast_shapes(a.shape, b.shape)[:-2]
    Ra = np.broadcast_to(a[..., :3, :3], shape + (3, 3)).reshape(-1, 3, 3)
    Rb = np.broadcast_to(b[..., :3, :3], shape + (3, 3)).reshape(-1, 3, 3)
    deg = np.degrees(np.linalg.norm(orientation_error(Ra, Rb), axis=1)).reshape(shape)
    return mm, deg


@dataclass(frozen=True)
class Cell:
    """The nominal model (the controller's) and the calibrated one, each with the TCP the goals
    are for, and what was said on the way (``notes``)."""

    nominal: Robot
    accurate: Robot
    #: the TCP in the frame after the last joint (the nominal flange's frame · the tool data)
    tcp: np.ndarray
    tcp_source: str
    #: the calibrated model's tool stands in for the TCP (asked for), else the TCP is on its chain
    refined: bool
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def label(self) -> str:
        """Which TCP the goals are for, as a result's rows say it."""
        return self.tcp_source + (" (the calibrated model's tool standing in)" if self.refined else "")

    def to_accurate(self, T: np.ndarray) -> np.ndarray:
        """Poses (..., 4, 4) from the controller's world into the calibrated model's."""
        return self.accurate.base @ invert(self.nominal.base) @ T

    def from_accurate(self, T: np.ndarray) -> np.ndarray:
        return self.nominal.base @ invert(self.accurate.base) @ T

    @staticmethod
    def goal(user, target: np.ndarray) -> np.ndarray:
        """Targets (..., 4, 4) stated in user frames (4×4, or one per target, None for the world) as
        poses in the controller's world."""
        return target if user is None else users_of(user, target) @ target

    @staticmethod
    def in_user(user, T: np.ndarray) -> np.ndarray:
        """Poses in the controller's world (..., 4, 4) stated in user frames (as :meth:`goal`)."""
        return T if user is None else invert(users_of(user, T)) @ T

    def on(self, robot: Robot) -> Robot:
        """Another model of this robot (a simulated truth) with the TCP the calibrated one uses."""
        return robot if self.refined else robot.with_tool(self.tcp)


def users_of(user, T: np.ndarray) -> np.ndarray:
    """User frames as an array for poses T: one 4×4 for all, or a list with None for the world."""
    if isinstance(user, np.ndarray):
        return user
    eye = np.eye(4)
    return np.stack([eye if u is None else u for u in user]).reshape(T.shape)


def make_cell(nominal: Robot, accurate: Robot, tool: np.ndarray | None = None, source: str = "",
              calibrated: bool = False) -> Cell:
    """The cell of a controller running ``nominal`` on a robot the calibrated model ``accurate``
    describes, for the tool data ``tool`` (4×4 mm in the flange frame, the nominal model's tool;
    default none: the TCP is the flange) named by ``source`` (said in the notes: ``the --tool
    given``, ``the program's tool tool1``).  ``calibrated``: the user says the calibrated model's
    tool is this tool, measured: it stands in for the TCP on the calibrated robot; else the TCP is
    put on the calibrated joints and base."""
    if tool is None:
        tcp, source = nominal.tool, source or "the nominal model's tool"
    else:
        tcp, source = nominal.tool @ np.asarray(tool, float), source or "the TCP given"
    mm, deg = (float(x) for x in frame_gap(accurate.tool, tcp))
    notes = []
    if calibrated:
        if mm > 1e-9 or deg > 1e-9:
            notes.append(Note(f"the calibrated model's tool stands in for {source}, as asked: it is {mm:.3g} mm "
                              f"and {deg:.3g}° from that tool's data"))
        return Cell(nominal.with_tool(tcp), accurate, tcp, source, True, tuple(notes))
    if (mm > 1e-9 or deg > 1e-9) and mm <= TOOL_NEAR_MM and deg <= TOOL_NEAR_DEG:
        notes.append(f"the calibrated model's tool is {mm:.3g} mm and {deg:.3g}° from {source}: the goals are for "
                     f"{source} as the program states it, on the calibrated joints and base; if the calibration "
                     "measured that tool, say so (--tool NAME=calibrated, or --tool calibrated) and its measured "
                     "tool stands in")
    elif mm > TOOL_NEAR_MM or deg > TOOL_NEAR_DEG:
        notes.append(Note(f"the calibrated model's tool is {mm:.4g} mm and {deg:.3g}° from {source}: it is the point "
                          f"the calibration measured, not the TCP; the goals are for {source} on the calibrated joints "
                          "and base" + (" (give --tool to name another TCP)" if "nominal model" in source else "")))
    return Cell(nominal.with_tool(tcp), accurate.with_tool(tcp), tcp, source, False, tuple(notes))
