"""Measured poses: the data a calibration is given."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from .camera import Camera


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measured poses.

    q: (m, n) commanded joint values, rad.  position: (m, 3) measured point, mm, in the
    measuring frame.  rotation: (m, 3, 3) measured orientation, or None for position-only
    data.  targets: target (reflector) name per pose, or None.  pose_ids: the file's
    pose_id per pose, or None.  rows: line number in the source file of each pose (first
    line of an averaged group; header = line 1).  n_raw: rows before averaging.
    torques: (m, n) joint torques in N·m (the robot controller's measured or commanded
    torques), or None.  payload: (m,) payload mass in kg, or None.  directions: (m, n) the
    sign of each joint's move into the pose (+1, −1; 0 unknown), or None.  time: (m,) when
    each pose was measured, s, or None; temperature: (m,) °C, or None.  order: where the
    directions came from (``dir columns``, ``time order``, ``row order``); without them they
    are worked out from the time column's order, else from the rows' order.
    pixels (m, 2) px, camera (m,): the pixel where the camera named saw the row's target (a
    marker; NaN and "" at rows no camera saw), intrinsics: each camera's lens by name.
    sigma_position (m, 3) mm and sigma_orientation (m, 3) rad: the instrument's own standard
    deviation of each measured value (orientation: rotation-vector components about the
    measuring frame's axes), or None; sigma_source says where they came from.
    """

    q: np.ndarray
    position: np.ndarray
    rotation: np.ndarray | None = None
    targets: tuple[str, ...] | None = None
    pose_ids: tuple[str, ...] | None = None
    rows: np.ndarray | None = None
    source: str = "<data>"
    n_raw: int = 0
    torques: np.ndarray | None = None
    payload: np.ndarray | None = None
    directions: np.ndarray | None = None
    time: np.ndarray | None = None
    temperature: np.ndarray | None = None
    order: str = ""
    sigma_position: np.ndarray | None = None
    sigma_orientation: np.ndarray | None = None
    sigma_source: str = ""
    point: tuple[str, ...] | None = None
    plane: tuple[str, ...] | None = None
    setup: tuple[str, ...] | None = None
    distances: tuple[tuple[str, str, float], ...] = ()
    distance_sigma: float = 0.05
    pixels: np.ndarray | None = None
    camera: tuple[str, ...] | None = None
    intrinsics: Mapping[str, Camera] = field(default_factory=dict)
    #: bodies of markers whose offsets are identified, each of a known shape: (its markers' names,
    #: their places (N, 3) mm in the body's own frame); a square marker of known size, a board, a
    #: marker cube whose place on the flange is unknown (:mod:`robocal.model.shapes`); shape_sigma:
    #: how closely the markers keep it (mm)
    shapes: tuple[tuple[tuple[str, ...], np.ndarray], ...] = ()
    shape_sigma: float = 0.05
    #: each row's session (any label), or None: one session.  Between sessions the instrument, the
    #: markers or the cameras may have moved: cross-validation holds out whole sessions
    session: tuple[str, ...] | None = None
    #: each row's chain of a tree robot (:mod:`robocal.model.kinematic_tree`): its point is on that chain's tip
    chain: tuple[str, ...] | None = None

    @property
    def sessions(self) -> tuple[str, ...]:
        """The sessions' labels in order of first appearance (one "" where the rows name none)."""
        return ("",) if self.session is None else tuple(dict.fromkeys(self.session))

    @property
    def views(self):
        """The rows a camera saw (:class:`robocal.model.views.Views`), or None: no camera row."""
        if self.camera is None or not any(self.camera):
            return None
        cached = self.__dict__.get("_views")
        if cached is None:
            from .views import Views

            cached = Views.of(self.camera, self.pixels, self.intrinsics)
            object.__setattr__(self, "_views", cached)
        return cached

    @property
    def length_rows(self) -> np.ndarray:
        """Mask (m,) of the rows whose errors are lengths (mm): every row but a camera's."""
        if self.camera is None:
            return np.ones(self.n_poses, bool)
        return np.array([not c for c in self.camera])

    @property
    def unit(self) -> str:
        """The unit of the position errors: px where every row is a camera's, else mm."""
        return "px" if self.camera is not None and all(self.camera) else "mm"

    @property
    def constraints(self):
        """The rows that touched unknown points or planes (:class:`robocal.model.constraints.Constraints`),
        with the stated distances, or None: every row measured."""
        if self.point is None and self.plane is None:
            return None
        cached = self.__dict__.get("_constraints")
        if cached is None:
            from .constraints import constraints_of

            cached = constraints_of(self.point, self.plane, self.setup, self.n_poses,
                                    {(a, b): d for a, b, d in self.distances}, self.distance_sigma, self.source,
                                    strict=False)
            object.__setattr__(self, "_constraints", cached)
        return cached

    def with_distances(self, distances, sigma: float | None = None) -> Measurements:
        """The same rows with stated distances ((point a, point b, mm), …) between the points of a
        setup; a distance whose points no setup has is an error."""
        from .constraints import constraints_of

        distances = tuple((str(a), str(b), float(d)) for a, b, d in distances)
        if distances:
            if self.point is None:
                from ..exceptions import InputError

                raise InputError(f"{self.source} has no point column: a distance is between two of its points",
                                 option="point_distance")
            constraints_of(self.point, self.plane, self.setup, self.n_poses, {(a, b): d for a, b, d in distances},
                           source=self.source)
        return replace(self, distances=distances, distance_sigma=self.distance_sigma if sigma is None else sigma)

    @property
    def inputs(self):
        """What joint terms act on besides the joints (:class:`robocal.model.terms.JointInputs`)."""
        from .terms import JointInputs

        if self.time is not None:
            return JointInputs(self.torques, self.payload, self.directions, self.time, "s")
        # without a time column the measuring order stands for time: this file's row numbers
        return JointInputs(self.torques, self.payload, self.directions, np.asarray(self.rows, float),
                           f"row:{self.source}")

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", np.atleast_2d(np.asarray(self.q, dtype=float)))
        object.__setattr__(self, "position", np.atleast_2d(np.asarray(self.position, dtype=float)))
        if self.rows is None:
            object.__setattr__(self, "rows", np.arange(2, 2 + len(self.q)))
        if not self.n_raw:
            object.__setattr__(self, "n_raw", len(self.q))
        if self.directions is None:
            # the rows as given are the measuring order; fixed here, so that a subset (a fold of
            # cross-validation) keeps each pose's true predecessor
            sequence = None if self.time is None else np.argsort(self.time, kind="stable")
            object.__setattr__(self, "directions", move_directions(self.q, sequence))
            object.__setattr__(self, "order", "row order" if self.time is None else "time order")

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def full_pose(self) -> bool:
        return self.rotation is not None

    @property
    def target_names(self) -> tuple[str, ...]:
        return ("",) if self.targets is None else tuple(dict.fromkeys(self.targets))

    def describe(self) -> str:
        """How many poses and reflectors: "500 poses × 3 reflectors (1500 measured points)"; of camera
        rows, "2246 camera rows: 18 markers seen by 2 cameras at 150 poses"; over several sessions,
        ", over 2 sessions" after it (a reflector of a session with tools of its own counted once)."""
        text = self._describe()
        return text if len(self.sessions) < 2 else f"{text}, over {len(self.sessions)} sessions"

    def _describe(self) -> str:
        if self.session is not None and self.targets is not None and len(self.sessions) >= 2:
            # a session's own tool of target m1 is m1@SESSION: the same reflector
            own = tuple(t.rsplit("@", 1)[0] if "@" in t and t.rsplit("@", 1)[1] == s else t
                        for t, s in zip(self.targets, self.session))
            if own != self.targets:
                return replace(self, targets=own, session=None)._describe()
        if self.camera is not None and all(self.camera):
            configs = len(np.unique(np.round(self.q, 9), axis=0))
            cams = len(set(self.camera))
            on = "" if self.chain is None else f" on {len(set(self.chain))} chains"
            return (f"{self.n_poses} camera rows: {len(self.target_names)} marker{'s' * (len(self.target_names) > 1)}"
                    f"{on} seen by {cams} camera{'s' * (cams > 1)} at {configs} poses")
        if self.chain is not None:  # a tree's rows: each chain's points at its poses
            configs = len(np.unique(np.round(self.q, 9), axis=0))
            chains = len(set(self.chain))
            return f"{self.n_poses} measured points on {chains} chain{'s' * (chains > 1)} at {configs} poses"
        if self.targets is None or len(self.target_names) == 1:
            return f"{self.n_poses} poses"
        configs = len(np.unique(np.round(self.q, 9), axis=0))
        k = len(self.target_names)
        if configs * k == self.n_poses:
            return f"{configs} poses × {k} reflectors ({self.n_poses} measured points)"
        return f"{self.n_poses} measured points of {k} reflectors at {configs} poses"

    def by_target(self) -> dict[str, Measurements]:
        """The measurements of each reflector, by name ("" for the default tool)."""
        if self.targets is None:
            return {"": self}
        return {t: self.subset([i for i, x in enumerate(self.targets) if x == t]) for t in self.target_names}

    def label(self, i: int) -> str:
        """How messages name pose i: its pose_id where the file has them, else its file row."""
        if self.pose_ids is not None:
            return f"pose_id {self.pose_ids[i]}"
        return f"row {int(self.rows[i])}"

    def labels(self, index, limit: int = 10) -> str:
        """Comma list of :meth:`label` for the poses in ``index`` (at most ``limit``, then …)."""
        index = list(index)
        if self.pose_ids is not None:
            text = "pose_ids " + ", ".join(self.pose_ids[i] for i in index[:limit])
        else:
            text = "rows " + ", ".join(str(int(self.rows[i])) for i in index[:limit])
        return text + (" …" if len(index) > limit else "")

    def subset(self, index) -> Measurements:
        index = np.asarray(index)
        if index.dtype == bool:
            index = np.flatnonzero(index)

        def pick(seq):
            return None if seq is None else tuple(seq[i] for i in index)

        return replace(
            self,
            q=self.q[index],
            position=self.position[index],
            rotation=None if self.rotation is None else self.rotation[index],
            targets=pick(self.targets),
            pose_ids=pick(self.pose_ids),
            rows=self.rows[index],
            n_raw=len(index),
            torques=None if self.torques is None else self.torques[index],
            payload=None if self.payload is None else self.payload[index],
            directions=None if self.directions is None else self.directions[index],
            time=None if self.time is None else self.time[index],
            temperature=None if self.temperature is None else self.temperature[index],
            sigma_position=None if self.sigma_position is None else self.sigma_position[index],
            sigma_orientation=None if self.sigma_orientation is None else self.sigma_orientation[index],
            point=pick(self.point),
            plane=pick(self.plane),
            setup=pick(self.setup),
            pixels=None if self.pixels is None else self.pixels[index],
            camera=pick(self.camera),
            session=pick(self.session),
            chain=pick(self.chain),
        )

    def position_only(self) -> Measurements:
        return replace(self, rotation=None, sigma_orientation=None)

    def in_session(self, label: str) -> Measurements:
        """The same rows, every one of them in session ``label``."""
        return replace(self, session=(str(label),) * self.n_poses)


def concatenate(parts: list[Measurements], source: str | None = None) -> Measurements:
    """The rows of several measurements one after another (each keeps its file's row numbers and
    its sessions): every part must have the same joints and the same kinds of columns."""
    first = parts[0]
    if len(parts) == 1:
        return first

    # where one part lacks what another has: labels "" (no camera, no point), no pixel, and a pose
    # of its own for each row (a file without pose_ids)
    fill = {"camera": lambda p: ("",) * p.n_poses, "point": lambda p: ("",) * p.n_poses,
            "plane": lambda p: ("",) * p.n_poses, "setup": lambda p: ("",) * p.n_poses,
            "targets": lambda p: ("",) * p.n_poses, "session": lambda p: ("",) * p.n_poses,
            "pose_ids": lambda p: tuple(f"{p.source}:row {int(r)}" for r in p.rows),
            "pixels": lambda p: np.full((p.n_poses, 2), np.nan)}

    def stack(name):
        values = [getattr(p, name) for p in parts]
        if all(v is None for v in values):
            return None
        if any(v is None for v in values):
            if name not in fill:
                from ..exceptions import InputError

                lacking = next(p for p, v in zip(parts, values) if v is None)
                having = next(p for p, v in zip(parts, values) if v is not None)
                raise InputError(f"has no {name} where {having.source} has: files calibrated together give the "
                                 "same kinds of columns", source=lacking.source)
            values = [fill[name](p) if v is None else v for p, v in zip(parts, values)]
        if isinstance(values[0], tuple):
            return tuple(x for v in values for x in v)
        return np.concatenate(values)

    sigma_source = next((p.sigma_source for p in parts if p.sigma_source), "")
    return replace(
        first, q=stack("q"), position=stack("position"), rotation=stack("rotation"), targets=stack("targets"),
        pose_ids=stack("pose_ids"), rows=stack("rows"), source=source or " + ".join(p.source for p in parts),
        n_raw=sum(p.n_raw for p in parts), torques=stack("torques"), payload=stack("payload"),
        directions=stack("directions"), time=stack("time"), temperature=stack("temperature"),
        sigma_position=stack("sigma_position"), sigma_orientation=stack("sigma_orientation"),
        sigma_source=sigma_source, point=stack("point"), plane=stack("plane"), setup=stack("setup"),
        pixels=stack("pixels"), camera=stack("camera"), session=stack("session"), chain=stack("chain"),
        intrinsics={k: v for p in parts for k, v in p.intrinsics.items()})


def move_directions(q: np.ndarray, order: np.ndarray | None = None, still: float = 1e-7) -> np.ndarray:
    """The sign of each joint's move into each pose, (m, n), from the poses in measuring order
    (``order``: the rows sorted by when they were measured; default as given).  A joint that
    did not move keeps the direction of its last move (the gear stays on that flank); before
    a joint's first move the direction is unknown (0).  ``still``: rad (mm) below which a joint
    did not move."""
    q = np.asarray(q, float)
    order = np.arange(len(q)) if order is None else np.asarray(order)
    qs = q[order]
    moved = np.zeros_like(qs)  # the move into pose k: from pose k − 1
    step = np.diff(qs, axis=0)
    moved[1:] = np.where(np.abs(step) > still, np.sign(step), 0.0)
    # carry each joint's last move forward: the index of the latest pose with a move, per joint
    last = np.where(moved != 0, np.arange(len(qs))[:, None], 0)
    np.maximum.accumulate(last, axis=0, out=last)
    out = np.take_along_axis(moved, last, axis=0)
    directions = np.empty_like(out)
    directions[order] = out
    return directions
