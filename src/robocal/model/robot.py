"""The serial arm: geometry, joint limits, base and tool frames."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..math.se3 import homogeneous
from . import coupled as coupling_
from .camera import CameraMount
from .corrections import Correction
from .covariance import ParameterCovariance
from .dh import ALPHA, BETA, THETA, A, D
from .kinematic_tree import TreeSpec
from .kinematics import chain_pose, check_convention, geometry_width, prismatic_mask
from .kinematics import reach as chain_reach
from .prior import Prior
from .region import Region
from .terms import JointInputs, JointTerms, joint_offsets


@dataclass(frozen=True, eq=False)
class Robot:
    """A serial arm.

    geometry: per joint, (a mm, alpha rad, theta rad, d mm, beta rad, prismatic) for the DH
    family ((n, 5) is taken as all revolute), or the 14 columns of :mod:`robocal.model.urdf`.
    limits: (n, 2) rad (mm for a prismatic joint), ±inf where a joint has none.  base: measuring frame → robot base
    (4×4, mm).  tool: flange → measured point (4×4).  targets: further named tool frames,
    one per reflector on the flange (the unnamed target "" is ``tool``).  terms: joint terms
    beyond geometry (:mod:`robocal.model.terms`); residual: a learned correction of the pose
    in the measuring frame (:mod:`robocal.model.corrections`).  joint_names: as a URDF or robot
    file names them; urdf: what a robot read from a URDF keeps of it for a faithful export
    (:class:`robocal.io.urdf.UrdfChain`).  region: the joint ranges of the data it was
    calibrated on (:mod:`robocal.model.region`); the whole model is used everywhere, its
    predicted uncertainty says where it is less known (:mod:`robocal.model.uncertainty`).
    uncertainty: the covariance of the parameters its calibration identified
    (:mod:`robocal.model.uncertainty`), for the uncertainty of its predictions.
    coupling: how the controller's joint values map to the model's, ``(joint, plus, factor)``
    triples (0-based): the model's ``joint`` is the controller's plus ``factor`` × the controller's
    ``plus`` (FANUC's J3 is the forearm against the horizontal: the model's joint 3 is J2 + J3);
    robot programs state the controller's values (:meth:`from_controller`, :meth:`to_controller`).
    """

    convention: str
    geometry: np.ndarray
    limits: np.ndarray | None = None
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    tool: np.ndarray = field(default_factory=lambda: np.eye(4))
    targets: Mapping[str, np.ndarray] = field(default_factory=dict)
    name: str = ""
    source: str = ""  # where it was loaded from (file path or "built-in NAME"), for messages
    terms: JointTerms | None = None
    residual: Correction | None = None
    joint_names: tuple[str, ...] | None = None
    urdf: object | None = field(default=None, repr=False)
    region: Region | None = None
    uncertainty: ParameterCovariance | None = field(default=None, repr=False)
    coupling: tuple[tuple[int, int, float], ...] = ()
    #: what is known of its parameters before measuring (a robot file's ``[prior]``): the widths
    #: a calibration's prior takes over the defaults (:mod:`robocal.model.prior`), or None
    prior: Prior | None = None
    #: the cell's cameras by name: where each is (fixed in the measuring frame or on a link) and
    #: its pose there (:class:`robocal.model.camera.CameraMount`); a camera calibration finds them
    cameras: Mapping[str, CameraMount] = field(default_factory=dict)
    #: the measuring frame of each session where the instrument moved between them (label → the
    #: base, 4 × 4 mm, as :attr:`base` is in its own session); empty: one measuring frame
    session_bases: Mapping[str, np.ndarray] = field(default_factory=dict)
    #: a kinematic tree (:mod:`robocal.model.kinematic_tree`): each joint's parent and each chain's joints;
    #: None for a serial chain
    tree: TreeSpec | None = None
    #: joints whose value follows others (:mod:`robocal.model.coupled`): a torso that keeps its chest
    #: level; their values are computed, not commanded
    coupled: tuple[coupling_.CoupledJoint, ...] = ()

    def __post_init__(self) -> None:
        check_convention(self.convention)
        g = np.array(self.geometry, dtype=float)
        width = geometry_width(self.convention)
        if g.ndim == 2 and self.convention != "urdf" and g.shape[1] == 5:  # all joints turn
            g = np.column_stack([g, np.zeros(len(g))])
        if g.ndim != 2 or g.shape[1] != width:
            raise ValueError(f"geometry of a {self.convention} robot must have shape (n, {width})")
        object.__setattr__(self, "geometry", g)
        lim = np.tile([-np.inf, np.inf], (g.shape[0], 1)) if self.limits is None else np.array(self.limits, float)
        object.__setattr__(self, "limits", lim)
        object.__setattr__(self, "base", np.array(self.base, dtype=float))
        object.__setattr__(self, "tool", np.array(self.tool, dtype=float))
        object.__setattr__(self, "targets", {k: np.array(v, float) for k, v in self.targets.items()})
        if self.joint_names is not None:
            object.__setattr__(self, "joint_names", tuple(self.joint_names))
            if len(self.joint_names) != g.shape[0]:
                raise ValueError(f"{len(self.joint_names)} joint names for {g.shape[0]} joints")
        object.__setattr__(self, "coupled", tuple(self.coupled))
        coupling_.check(self.coupled, g.shape[0])
        if self.tree is not None:
            if self.convention != "urdf":  # a DH row turns about its parent's z: siblings would share one axis
                raise ValueError("a tree's joints are urdf origins (xyz, rpy, axis): in the DH family every child "
                                 "of a joint turns about that joint's frame's z, so two branches could not part")
            if self.tree.n_joints != g.shape[0]:
                raise ValueError(f"a tree of {self.tree.n_joints} joints for {g.shape[0]} joints")
            if self.residual is not None:  # a correction learned of one chain's poses
                raise ValueError("a learned correction runs along one chain: it is not supported on a tree")

    @classmethod
    def from_dh(cls, convention: str, a, alpha, theta, d, beta=None, prismatic=None, **kw) -> Robot:
        """Build from per-joint sequences (mm, rad); prismatic: per joint, True where it slides."""
        beta = np.zeros(len(a)) if beta is None else beta
        slide = np.zeros(len(a)) if prismatic is None else np.asarray(prismatic, float)
        return cls(convention, np.column_stack([a, alpha, theta, d, beta, slide]), **kw)

    @property
    def n_joints(self) -> int:
        return self.geometry.shape[0]

    a = property(lambda self: self.geometry[:, A])
    alpha = property(lambda self: self.geometry[:, ALPHA])
    theta = property(lambda self: self.geometry[:, THETA])
    d = property(lambda self: self.geometry[:, D])
    beta = property(lambda self: self.geometry[:, BETA])

    @property
    def prismatic(self) -> np.ndarray:
        """(n,) True where a joint slides: its values are in mm, not rad."""
        return prismatic_mask(self.convention, self.geometry)

    @property
    def dh_family(self) -> bool:
        """Whether a, α, θ, d, β describe the joints (not urdf origins)."""
        return self.convention != "urdf"

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

    def effective_joints(self, q, inputs: JointInputs | None = None) -> np.ndarray:
        """Joint values (m, n) rad the arm reaches for commanded q: q + Δq of its joint terms."""
        q = np.atleast_2d(np.asarray(q, float))
        return q + joint_offsets(self.terms, self.convention, self.geometry, q, inputs,
                                 None if self.tree is None else self.tree.parents)

    def fk(self, q, targets: Sequence[str] | None = None, inputs: JointInputs | None = None,
           chains: Sequence[str] | None = None, *, rotations: bool = True) -> np.ndarray:
        """End poses (m, 4, 4) in the measuring frame for commanded joints q (m, n) rad, with the
        robot's joint terms (on the poses' :class:`~robocal.model.terms.JointInputs`: torques,
        payload, directions of motion, time, where they need them) and its residual correction
        (:mod:`robocal.model.residual`).  A tree's rows name their chain (``chains``).  ``rotations``
        False: the positions alone (what :meth:`positions` asks for): a residual correction's
        orientation outputs are not worked out, and where it has them the rotations are NaN."""
        q = np.atleast_2d(np.asarray(q, float))
        qe = self.effective_joints(q, inputs)
        if self.tree is not None and chains is not None:  # a row without a target is on its chain's own tool
            targets = list(chains) if targets is None else [t or c for t, c in zip(targets, chains)]
        tools = self.tool_frames(targets)
        if self.tree is not None:
            R, p = np.empty((len(q), 3, 3)), np.empty((len(q), 3))
            for rows, path in self.tree.groups(self.tree.index(chains), len(q)):
                R[rows], p[rows] = chain_pose(self.convention, self.geometry[path], qe[rows][:, path], self.base,
                                              tools if len(tools) == 1 else tools[rows])
            return homogeneous(R, p)
        R, p = chain_pose(self.convention, self.geometry, qe, self.base, tools)
        if self.residual is not None:
            R, p = self.residual.correct(q, R, p, self.base[:3, :3], rotations)
        return homogeneous(R, p)

    def positions(self, q, targets: Sequence[str] | None = None, inputs: JointInputs | None = None,
                  chains: Sequence[str] | None = None) -> np.ndarray:
        """Measured-point positions (m, 3) mm in the measuring frame for commanded joints q (m, n) rad."""
        return self.fk(q, targets, inputs, chains, rotations=False)[:, :3, 3]

    def flange_frames(self, q, chains: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Each row's flange (the frame after its chain's last joint) in the robot's base frame, as
        rotations (m, 3, 3) and positions (m, 3) mm at joints q (m, n) rad taken as they are."""
        q = np.atleast_2d(np.asarray(q, float))
        if self.tree is None:
            return chain_pose(self.convention, self.geometry, q)
        R, p = np.empty((len(q), 3, 3)), np.empty((len(q), 3))
        for rows, path in self.tree.groups(self.tree.index(chains), len(q)):
            R[rows], p[rows] = chain_pose(self.convention, self.geometry[path], q[rows][:, path])
        return R, p

    def link_frames(self, q, link: int) -> tuple[np.ndarray, np.ndarray]:
        """Link ``link``'s frame (the frame after joint ``link``) in the base frame at joints q (m, n)
        rad taken as they are: rotations (m, 3, 3), positions (m, 3) mm."""
        path = self.link_path(link)
        return chain_pose(self.convention, self.geometry[path], np.atleast_2d(np.asarray(q, float))[:, path])

    def link_path(self, link: int) -> np.ndarray:
        """The joints (0-based) from the base to link ``link`` (the frame after joint ``link``)."""
        return np.arange(link) if self.tree is None else np.array(self.tree.path(link - 1), int)

    def camera_frames(self, cameras: Sequence[str], q, inputs: JointInputs | None = None) -> np.ndarray:
        """Each row's camera frame (m, 4, 4) in the measuring frame: a fixed camera's pose, or the
        base, the chain up to its link (with the joint terms) and its mounting."""
        q = np.atleast_2d(np.asarray(q, float))
        out = np.empty((len(q), 4, 4))
        names = np.asarray(cameras, dtype=object)
        for name in dict.fromkeys(cameras):
            if name not in self.cameras:
                raise ValueError(f"robot has no pose for camera {name!r}")
            mount, rows = self.cameras[name], names == name
            pose = mount.pose
            if mount.of:  # fixed to another camera: its pose composed with that one's
                pose, mount = self.cameras[mount.of].pose @ pose, self.cameras[mount.of]
            if mount.link == 0:
                out[rows] = pose
                continue
            path = self.link_path(mount.link)
            R, p = chain_pose(self.convention, self.geometry[path], self.effective_joints(q, inputs)[rows][:, path],
                              self.base, pose[None])
            out[rows] = homogeneous(R, p)
        return out

    @property
    def geometric(self) -> bool:
        """True when the model is geometry alone (no joint terms, no residual correction)."""
        return (self.terms is None or self.terms.empty) and self.residual is None

    def from_controller(self, J: np.ndarray) -> np.ndarray:
        """The model's joint values (..., n) of the controller's J (rad; mm for a sliding joint)."""
        q = np.array(J, dtype=float, copy=True)
        for joint, plus, factor in self.coupling:
            q[..., joint] += factor * np.asarray(J)[..., plus]
        return q

    def couple(self, q: np.ndarray) -> np.ndarray:
        """q (…, n) rad with every coupled joint's value set from the joints it follows."""
        return coupling_.couple(self.coupled, q) if self.coupled else np.asarray(q, float)

    @property
    def n_free(self) -> int:
        """The joints a pose commands: all but the coupled ones."""
        return self.n_joints - len(self.coupled)

    def to_controller(self, q: np.ndarray) -> np.ndarray:
        """The controller's joint values (..., n) of the model's q (the inverse of :meth:`from_controller`)."""
        J = np.array(q, dtype=float, copy=True)
        for joint, plus, factor in reversed(self.coupling):
            J[..., joint] -= factor * J[..., plus]
        return J

    def in_sessions(self, poses: np.ndarray, sessions) -> np.ndarray:
        """Poses (m, 4, 4) computed through :attr:`base`, each row of a session with a measuring frame
        of its own (:attr:`session_bases`) moved into that frame."""
        if not self.session_bases or sessions is None:
            return poses
        out = np.array(poses, float)
        back = np.linalg.inv(self.base)
        labels = np.asarray(sessions, dtype=object)
        for label, base in self.session_bases.items():
            rows = labels == label
            if rows.any():
                out[rows] = (base @ back) @ out[rows]
        return out

    def without_sessions(self) -> Robot:
        """The robot as a file carries it: without the measuring frames and tools of a calibration's later
        sessions (:attr:`session_bases`, targets named ``NAME@SESSION``) and their rows of the covariance
        (its marginal: what it says of the rest is unchanged)."""
        if not self.session_bases:
            return self
        labels = tuple(self.session_bases)
        own = {t: T for t, T in self.targets.items() if not t.endswith(tuple(f"@{s}" for s in labels))}
        uncertainty = self.uncertainty
        if uncertainty is not None:
            keep = [i for i, n in enumerate(uncertainty.names) if not n.startswith("base[")
                    and not any(n.startswith("tool[") and f"@{s}]" in n for s in labels)]
            uncertainty = type(uncertainty)(tuple(uncertainty.names[i] for i in keep),
                                            uncertainty.matrix[np.ix_(keep, keep)])
        return replace(self, session_bases={}, targets=own, uncertainty=uncertainty)

    def chain(self, name: str) -> Robot:
        """One chain of a tree as a serial robot (:func:`robocal.model.kinematic_tree.chain_robot`)."""
        from .kinematic_tree import chain_robot

        return chain_robot(self, name)

    def replace(self, **changes) -> Robot:
        return replace(self, **changes)

    def with_tool(self, tool: np.ndarray) -> Robot:
        """The robot with another flange → tool frame."""
        return replace(self, tool=np.asarray(tool, float))

    def reach(self) -> float:
        """A length scale of the arm (mm): sum of |a| and |d| (urdf: of the origins), at least 1."""
        return chain_reach(self.convention, self.geometry)
