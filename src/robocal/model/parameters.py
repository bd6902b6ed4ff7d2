"""Named deviation parameters and the map between a flat deviation vector and a robot.

A *deviation* is a parameter's departure from its nominal value (real = nominal +
deviation).  Names (1-based joints): ``a1``, ``alpha1``, ``theta1``, ``d1`` for every
joint, ``beta1``… for hayati robots; ``base_x, base_y, base_z`` (mm) and ``base_rx,
base_ry, base_rz`` (rad); ``tool_x … tool_rz`` for the default measured point and
``tool[NAME]_x …`` for a named target (reflector).  For craig robots ``a{i}``/``alpha{i}``
name the values held in row i (a_{i-1}, α_{i-1} of Craig's notation).

Every deviation is additive, except the frame rotations: the base rotates about the
measuring-frame axes through the base origin, ``R_base = Exp(δ) · R_base°``, and a tool
rotates about its own axes, ``R_tool = R_tool° · Exp(δ)``; both are rotation vectors,
so no Euler singularity can hide in them.  Units: mm for lengths, rad for angles.

Joint terms (:mod:`robocal.model.terms`) come last, named by their :class:`TermSpec`
(``compliance2``, ``gravity2_3x``, ``harmonic4_cos1``, …); they move the joints, q_eff = q +
Δq, so every pose and Jacobian takes the per-pose :class:`JointData` they need.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..math.se3 import homogeneous
from ..math.so3 import exp_so3, left_jacobian
from .kinematics import (
    chain_points,
    chain_pose,
    chain_twist_jacobian,
    joint_kinds,
    joint_parameter_names,
    joint_value_columns,
)
from .robot import Robot
from .terms import JointInputs, JointTerms, TermSpec, basis, joint_offsets, term_of, term_unit

FRAME_AXES = ("x", "y", "z", "rx", "ry", "rz")
_ANGLE_KINDS = frozenset(("alpha", "theta", "beta", "rx", "ry", "rz"))


def tool_prefix(target: str) -> str:
    """Parameter-name prefix of a target's tool frame: ``tool`` or ``tool[NAME]``."""
    return "tool" if target == "" else f"tool[{target}]"


def camera_prefix(camera: str) -> str:
    """Parameter-name prefix of a camera's frame: ``camera[NAME]``."""
    return f"camera[{camera}]"


def session_prefix(label: str) -> str:
    """Parameter-name prefix of a session's own measuring frame: ``base[LABEL]``."""
    return f"base[{label}]"


def is_frame(name: str) -> bool:
    return name.startswith(("base_", "base[", "tool", "camera["))


def is_term(name: str) -> bool:
    """A joint-term parameter (:data:`robocal.model.terms.TERMS`)."""
    return term_of(name) is not None


def unit(name: str) -> str:
    """The unit of a parameter's value: mm, rad, or a joint term's own (rad/(N·m) for a compliance)."""
    return term_unit(name) or ("rad" if is_angle(name) else "mm")


@dataclass(frozen=True, eq=False)
class JointData:
    """Per-pose inputs of the joint terms: the robot's own offsets Δq0 (m, n) rad and the basis
    B (m, n, T) of the space's term parameters, so that q_eff = q + Δq0 + B · p_terms."""

    offset: np.ndarray
    basis: np.ndarray

    @classmethod
    def of(cls, robot: Robot, spec: TermSpec, q: np.ndarray, inputs: JointInputs | None = None) -> JointData | None:
        """The joint data of ``robot`` at commanded q, or None when there is nothing to add."""
        if (robot.terms is None or robot.terms.empty) and spec.empty:
            return None
        q = np.atleast_2d(q)
        parents = None if robot.tree is None else robot.tree.parents
        return cls(joint_offsets(robot.terms, robot.convention, robot.geometry, q, inputs, parents),
                   basis(spec, robot.convention, robot.geometry, q, inputs, robot.terms, parents))

    def subset(self, index) -> JointData:
        return JointData(self.offset[index], self.basis[index])


def is_angle(name: str) -> bool:
    """True for parameters in rad (angles, gravity and harmonic terms), False for mm (and compliances)."""
    if is_term(name):
        return term_unit(name) == "rad"
    kind = name.rsplit("_", 1)[-1] if is_frame(name) else name.rstrip("0123456789")
    return kind in _ANGLE_KINDS


@dataclass(frozen=True, eq=False)
class ParameterSpace:
    """All geometric deviation parameters of a robot, in a fixed order.

    A zero deviation vector is the reference robot itself.  Vectors may carry leading
    axes (a swarm's particles): every method maps (..., k) to (..., …).
    """

    robot: Robot
    names: tuple[str, ...]
    targets: tuple[str, ...]
    terms: TermSpec = TermSpec()
    #: the cameras whose frames the space holds (the robot's, :attr:`Robot.cameras`)
    cameras: tuple[str, ...] = ()
    #: the sessions whose measuring frame is their own (the robot's :attr:`Robot.session_bases`):
    #: a row of session s is seen through its base ``base@s``, rows of no such session through the base
    sessions: tuple[str, ...] = ()

    @classmethod
    def of(cls, robot: Robot, targets: Sequence[str] | None = None, terms: TermSpec | None = None) -> ParameterSpace:
        """The full space of ``robot``: joints, base, a tool for each target (default: the robot's
        own targets), and the joint terms of ``terms``."""
        targets = tuple(robot.target_names if targets is None else dict.fromkeys(targets))
        terms = terms or TermSpec()
        names = [n for joint in joint_parameter_names(robot.convention, robot.geometry) for n in joint]
        names += [f"base_{ax}" for ax in FRAME_AXES]
        for t in targets:
            names += [f"{tool_prefix(t)}_{ax}" for ax in FRAME_AXES]
        cameras = tuple(robot.cameras)
        for c in cameras:
            names += [f"{camera_prefix(c)}_{ax}" for ax in FRAME_AXES]
        sessions = tuple(robot.session_bases)
        for label in sessions:
            names += [f"{session_prefix(label)}_{ax}" for ax in FRAME_AXES]
        names += terms.names(robot.n_joints)
        return cls(robot, tuple(names), targets, terms, cameras, sessions)

    @property
    def n_term_params(self) -> int:
        return len(self.terms.names(self.robot.n_joints))

    def joint_data(self, q: np.ndarray, inputs: JointInputs | None = None) -> JointData | None:
        """The per-pose term inputs of this space's robot at commanded q (None without terms)."""
        return JointData.of(self.robot, self.terms, q, inputs)

    # --- indexing --------------------------------------------------------------
    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def n_joint_params(self) -> int:
        return self.robot.n_joints * len(joint_kinds(self.robot.convention))

    def index(self, names: Sequence[str]) -> np.ndarray:
        lookup = {n: i for i, n in enumerate(self.names)}
        missing = [n for n in names if n not in lookup]
        if missing:
            raise KeyError(", ".join(missing))
        return np.array([lookup[n] for n in names], dtype=int)

    def vector(self, values: dict[str, float]) -> np.ndarray:
        """Flat deviation vector from a {name: value} mapping (others zero)."""
        x = np.zeros(self.size)
        if values:
            x[self.index(list(values))] = list(values.values())
        return x

    def as_dict(self, deviation: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, deviation)}

    def angle_mask(self) -> np.ndarray:
        return np.array([is_angle(n) for n in self.names])

    def target_index(self, targets: Sequence[str] | None) -> np.ndarray | None:
        if targets is None:
            return None
        lookup = {t: i for i, t in enumerate(self.targets)}
        try:
            return np.array([lookup[t] for t in targets], dtype=int)
        except KeyError as exc:
            raise ValueError(f"no tool frame for target {exc.args[0]!r}") from None

    # --- deviation → geometry --------------------------------------------------
    def _split(self, deviation: np.ndarray):
        deviation = np.asarray(deviation, dtype=float)
        if deviation.shape[-1] != self.size:
            raise ValueError(f"deviation vector has {deviation.shape[-1]} entries, the space has {self.size}")
        nj = self.n_joint_params
        kinds = joint_kinds(self.robot.convention)
        joints = deviation[..., :nj].reshape(deviation.shape[:-1] + (self.robot.n_joints, len(kinds)))
        base = deviation[..., nj : nj + 6]
        nt = 6 * len(self.targets)
        tools = deviation[..., nj + 6 : nj + 6 + nt].reshape(deviation.shape[:-1] + (len(self.targets), 6))
        return joints, base, tools

    def term_values(self, deviation: np.ndarray) -> np.ndarray:
        """The joint-term part (…, T) of deviation vectors."""
        return np.asarray(deviation, dtype=float)[..., self.size - self.n_term_params:]

    def effective_joints(self, deviation: np.ndarray, q: np.ndarray, joints: JointData | None) -> np.ndarray:
        """q_eff = q + Δq0 + B · p_terms, (…, m, n); q itself without joint data."""
        if joints is None:
            return q
        dq = joints.offset
        if self.n_term_params:
            dq = dq + np.einsum("mit,...t->...mi", joints.basis, self.term_values(deviation))
        return q + dq

    def nominal_tools(self) -> np.ndarray:
        """Tool frames of the reference robot, one per target of the space, (T, 4, 4); worked out
        once (every expansion of a deviation vector starts from them), not to be written to."""
        if self.__dict__.get("_nominal_tools") is None:
            tools = np.stack([self.robot.tool_frames([t])[0] for t in self.targets])
            tools.flags.writeable = False
            self.__dict__["_nominal_tools"] = tools
        return self.__dict__["_nominal_tools"]

    def expand(self, deviation: np.ndarray):
        """(…, k) → geometry (…, n, width), base (…, 4, 4), tools (…, T, 4, 4)."""
        deviation = np.asarray(deviation, dtype=float)
        joints, db, dt = self._split(deviation)
        r = self.robot
        geom = np.broadcast_to(r.geometry, joints.shape[:-2] + r.geometry.shape).copy()
        geom[..., : joints.shape[-1]] += joints
        tools0 = self.nominal_tools()
        if not np.any(db) and not np.any(dt):  # the common case: frames as given, no SO(3) algebra
            lead = deviation.shape[:-1]
            return (
                geom,
                np.broadcast_to(r.base, lead + (4, 4)).copy(),
                np.broadcast_to(tools0, lead + tools0.shape).copy(),
            )
        base = homogeneous(exp_so3(db[..., 3:]) @ r.base[:3, :3], r.base[:3, 3] + db[..., :3])
        tools = homogeneous(tools0[:, :3, :3] @ exp_so3(dt[..., 3:]), tools0[:, :3, 3] + dt[..., :3])
        return geom, base, tools

    def apply(self, deviation: np.ndarray) -> Robot:
        """The robot with deviations (k,) added: nominal + deviation = real (joint terms included)."""
        deviation = np.asarray(deviation, dtype=float)
        geom, base, tools = self.expand(deviation)
        named = {t: tools[i] for i, t in enumerate(self.targets) if t != ""}
        default = tools[self.targets.index("")] if "" in self.targets else self.robot.tool
        extra = {t: v for t, v in self.robot.targets.items() if t not in named}
        changes = {"geometry": geom, "base": base, "tool": default, "targets": {**extra, **named}}
        if self.sessions:
            bases = self.session_bases(deviation)
            changes["session_bases"] = {label: bases[i] for i, label in enumerate(self.sessions)}
        if self.cameras:
            poses = self.camera_poses(deviation, composed=False)
            changes["cameras"] = {**self.robot.cameras, **{c: self.robot.cameras[c].moved(poses[i])
                                                          for i, c in enumerate(self.cameras)}}
        if self.n_term_params:
            n = self.robot.n_joints
            own = self.robot.terms or JointTerms()
            changes["terms"] = own.with_vector(self.terms, n, own.vector(self.terms, n) + self.term_values(deviation))
        return self.robot.replace(**changes)

    # --- cameras -------------------------------------------------------------------
    def _camera_slice(self) -> slice:
        start = self.n_joint_params + 6 + 6 * len(self.targets)
        return slice(start, start + 6 * len(self.cameras))

    # --- sessions -------------------------------------------------------------------
    def _session_slice(self) -> slice:
        start = self._camera_slice().stop
        return slice(start, start + 6 * len(self.sessions))

    def session_index(self, labels: Sequence[str] | None) -> np.ndarray | None:
        """Each row's session as an index into :attr:`sessions` (−1: a row of no session with a base
        of its own), or None where the space has no such sessions."""
        if not self.sessions or labels is None:
            return None
        lookup = {s: i for i, s in enumerate(self.sessions)}
        return np.array([lookup.get(s, -1) for s in labels], int)

    def session_bases(self, deviation: np.ndarray) -> np.ndarray:
        """Each session's base (…, S, 4, 4) with its deviation (as the base's: R = Exp(δ)R°, t = t° + δt)."""
        d = np.asarray(deviation, float)[..., self._session_slice()]
        d = d.reshape(d.shape[:-1] + (len(self.sessions), 6))
        nominal = np.stack([self.robot.session_bases[s] for s in self.sessions])
        return homogeneous(exp_so3(d[..., 3:]) @ nominal[:, :3, :3], nominal[:, :3, 3] + d[..., :3])

    def _through_sessions(self, deviation, session: np.ndarray | None, base: np.ndarray):
        """(…, m, 4, 4) for each row: the move from the base the chain was computed with to the row's
        session's own (identity for a row of no session), or None."""
        if session is None or not self.sessions:
            return None
        B = self.session_bases(deviation)  # (…, S, 4, 4)
        D = B @ np.linalg.inv(base)[..., None, :, :]
        eye = np.broadcast_to(np.eye(4), D.shape[:-3] + (1, 4, 4))
        return np.concatenate([D, eye], axis=-3)[..., np.where(session >= 0, session, len(self.sessions)), :, :]

    def camera_link(self, camera: str) -> int:
        """The link a camera rides on (that of the camera it is fixed to, for one of a rig)."""
        mount = self.robot.cameras[camera]
        return self.robot.cameras[mount.of].link if mount.of else mount.link

    def camera_poses(self, deviation: np.ndarray, composed: bool = True) -> np.ndarray:
        """Each camera's pose in its parent frame (…, C, 4, 4): the measuring frame for a fixed
        camera, its link's frame for one on the robot.  Its deviation turns it about its own origin
        by a rotation vector in the parent's axes, R = Exp(δ) R°, and moves it, t = t° + δt.  A
        camera fixed to another (a rig) is that one's pose composed with its own (``composed``; else
        its own, in the other's frame)."""
        d = np.asarray(deviation, float)[..., self._camera_slice()]
        d = d.reshape(d.shape[:-1] + (len(self.cameras), 6))
        nominal = np.stack([self.robot.cameras[c].pose for c in self.cameras])
        poses = homogeneous(exp_so3(d[..., 3:]) @ nominal[:, :3, :3], nominal[:, :3, 3] + d[..., :3])
        if composed:
            for c, name in enumerate(self.cameras):
                of = self.robot.cameras[name].of
                if of:
                    poses[..., c, :, :] = poses[..., self.cameras.index(of), :, :] @ poses[..., c, :, :]
        return poses

    def camera_frames(self, deviation: np.ndarray, q: np.ndarray, index: np.ndarray,
                      joints: JointData | None = None) -> np.ndarray:
        """Each row's camera frame (…, m, 4, 4) in the measuring frame, ``index`` (m,) the row's
        camera (−1: none; the identity there) at commanded joints q (m, n) rad."""
        deviation = np.asarray(deviation, dtype=float)
        poses = self.camera_poses(deviation)
        lead = deviation.shape[:-1]
        out = np.broadcast_to(np.eye(4), lead + (len(q), 4, 4)).copy()
        linked = [c for c, name in enumerate(self.cameras) if self.camera_link(name) > 0]
        if linked:
            geom, base, _ = self.expand(deviation)
            qe = np.broadcast_to(self.effective_joints(deviation, q, joints), lead + np.shape(q))
        for c, name in enumerate(self.cameras):
            rows = index == c
            if not rows.any():
                continue
            link = self.camera_link(name)
            if link == 0:
                out[..., rows, :, :] = poses[..., c:c + 1, :, :]
                continue
            path = self.robot.link_path(link)
            R, p = chain_pose(self.robot.convention, geom[..., path, :], qe[..., rows, :][..., path], base,
                              poses[..., c:c + 1, :, :])
            out[..., rows, :, :] = homogeneous(R, p)
        return out

    def camera_frame_columns(self, deviation: np.ndarray, q: np.ndarray, index: np.ndarray,
                             joints: JointData | None = None, active: np.ndarray | None = None):
        """The camera frames of :meth:`camera_frames` (m, 4, 4) and their twist Jacobian (k, m, 6)
        (origin mm, rotation about the measuring frame's axes) for one deviation vector (k,);
        ``active`` as in :meth:`jacobian_columns`."""
        deviation = np.asarray(deviation, dtype=float)
        frames = self.camera_frames(deviation, q, index, joints)
        m = len(q)
        at, size = self._rows(active)
        J = np.zeros((size + 1, m, 6))
        poses = self.camera_poses(deviation)
        d = deviation[self._camera_slice()].reshape(len(self.cameras), 6)
        geom, base, _ = self.expand(deviation)
        qe = self.effective_joints(deviation, q, joints)
        kinds = len(joint_kinds(self.robot.convention))
        for c, name in enumerate(self.cameras):
            rows = index == c
            if not rows.any():
                continue
            link = self.camera_link(name)
            of = self.robot.cameras[name].of
            own = self.cameras.index(of) if of else c  # a rig's camera moves with the one it is fixed to
            col = self._camera_slice().start + 6 * own
            Wc = left_jacobian(d[own, 3:])  # Exp(δ+ε) = Exp(J_l ε) Exp(δ): about the parent's axes
            if link == 0:
                R_parent = np.eye(3)[None]
            else:
                path = self.robot.link_path(link)
                Jj, _, _, R_parent = chain_twist_jacobian(self.robot.convention, geom[path], qe[rows][:, path], base,
                                                          poses[c][None])
                where = np.flatnonzero(rows)
                cols = (path[:, None] * kinds + np.arange(kinds)).ravel()
                J[at[cols, None], where] = Jj[:, :kinds].reshape(len(cols), -1, 6)
                nj = self.n_joint_params
                if np.any(at[nj:nj + 6] < size):
                    Jb = np.zeros((6, len(where), 6))
                    self._base_columns(Jb, deviation[nj:nj + 6], frames[rows, :3, 3] - base[:3, 3])
                    J[at[nj:nj + 6, None], where] = Jb
                if self.n_term_params:
                    value = joint_value_columns(self.robot.convention, self.robot.geometry)[path]
                    Jq = Jj[np.arange(len(path)), value]
                    J[at[self.size - self.n_term_params:, None], where] = np.einsum(
                        "imk,mit->tmk", Jq, joints.basis[rows][:, path])
            arm = 0.0
            if of:  # turning the camera it is fixed to swings this one about that one's origin
                sub = None if joints is None else joints.subset(rows)
                ref = self.camera_frames(deviation, q[rows], np.full(int(rows.sum()), own), sub)
                arm = frames[rows, :3, 3] - ref[:, :3, 3]
                # its own deviation, in the frame of the camera it is fixed to
                mine, W = self._camera_slice().start + 6 * c, ref[:, :3, :3] @ left_jacobian(d[c, 3:])
                for k in range(3):
                    J[at[mine + k], rows, :3] = ref[:, :3, k]
                    J[at[mine + 3 + k], rows, 3:] = W[:, :, k]
            for k in range(3):
                J[at[col + k], rows, :3] = R_parent[:, :, k]
                w = (R_parent @ Wc)[:, :, k]
                J[at[col + 3 + k], rows, 3:] = w
                if of:
                    J[at[col + 3 + k], rows, :3] = np.cross(w, arm)
        return frames, J[:size]

    def _tree_columns(self, J, at, geom, q, base, tool, joints, chain):
        """A tree's joint columns of J (k + 1, m, 6), each chain's rows through its own joints;
        returns the end rotations, positions and flange rotations of every row."""
        m, kinds = q.shape[0], len(joint_kinds(self.robot.convention))
        value = joint_value_columns(self.robot.convention, self.robot.geometry)
        R_e, p_e, R_f = np.empty((m, 3, 3)), np.empty((m, 3)), np.empty((m, 3, 3))
        for rows, path in self.robot.tree.groups(chain, m):
            Jj, R_e[rows], p_e[rows], R_f[rows] = chain_twist_jacobian(
                self.robot.convention, geom[path], q[rows][:, path], base, tool if len(tool) == 1 else tool[rows])
            cols = (path[:, None] * kinds + np.arange(kinds)).ravel()
            where = np.flatnonzero(rows)
            J[at[cols, None], where] = Jj[:, :kinds].reshape(len(cols), -1, 6)
            if self.n_term_params:
                Jq = Jj[np.arange(len(path)), value[path]]
                J[at[self.size - self.n_term_params:, None], where] = np.einsum("imk,mit->tmk", Jq,
                                                                                 joints.basis[rows][:, path])
        return R_e, p_e, R_f

    def _tools_for(self, tools: np.ndarray, target_idx: np.ndarray | None) -> np.ndarray:
        return tools[..., :1, :, :] if target_idx is None else tools[..., target_idx, :, :]

    def _chains(self, function, geom, q, base, tools, chain: np.ndarray | None):
        """``function`` (:func:`chain_pose` or :func:`chain_points`) of every row: for a tree, each
        chain's rows through that chain's joints (``chain``: each row's chain, :meth:`TreeSpec.index`)."""
        tree = self.robot.tree
        if tree is None:
            return function(self.robot.convention, geom, q, base, tools)
        m = q.shape[-2]
        R = p = None
        for rows, path in tree.groups(chain, m):
            t = tools if tools.shape[-3] == 1 else tools[..., rows, :, :]
            out = function(self.robot.convention, geom[..., path, :], q[..., rows, :][..., path], base, t)
            Rc, pc = out if isinstance(out, tuple) else (None, out)
            if p is None:
                p = np.empty(pc.shape[:-2] + (m, 3))
                R = None if Rc is None else np.empty(Rc.shape[:-3] + (m, 3, 3))
            p[..., rows, :] = pc
            if R is not None:
                R[..., rows, :, :] = Rc
        return p if R is None else (R, p)

    def pose(self, deviation: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None,
             joints: JointData | None = None, session: np.ndarray | None = None, chain: np.ndarray | None = None):
        """End rotation (…, m, 3, 3) and position (…, m, 3) mm for deviation vectors (…, k) at
        commanded joints q (m, n) rad; ``session`` (m,): each row's session, seen through its own
        base (:meth:`session_index`).

        One batched call over all leading axes of ``deviation`` and all poses of ``q``.
        """
        geom, base, tools = self.expand(deviation)
        q = self.effective_joints(deviation, q, joints)
        R, p = self._chains(chain_pose, geom, q, base, self._tools_for(tools, target_idx), chain)
        D = self._through_sessions(deviation, session, base)
        if D is None:
            return R, p
        return D[..., :3, :3] @ R, np.einsum("...ij,...j->...i", D[..., :3, :3], p) + D[..., :3, 3]

    def points(self, deviation: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None,
               joints: JointData | None = None, session: np.ndarray | None = None,
               chain: np.ndarray | None = None) -> np.ndarray:
        """Measured-point positions (…, m, 3) mm only: the cheap path of position-only objectives."""
        geom, base, tools = self.expand(deviation)
        q = self.effective_joints(deviation, q, joints)
        p = self._chains(chain_points, geom, q, base, self._tools_for(tools, target_idx), chain)
        D = self._through_sessions(deviation, session, base)
        return p if D is None else np.einsum("...ij,...j->...i", D[..., :3, :3], p) + D[..., :3, 3]

    def jacobian(self, deviation: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None,
                 joints: JointData | None = None, chain: np.ndarray | None = None):
        """Exact derivative of the end pose with respect to the deviation vector (k,).

        Returns ``(J, R, p)``: J (m, 6, k) with rows (position mm, rotation rad about the
        measuring-frame axes, left perturbation), R (m, 3, 3), p (m, 3).  J is a view of
        a (k, m, 6) array: each parameter's column is contiguous.
        """
        Jc, R_e, p_e = self.jacobian_columns(deviation, q, target_idx, joints=joints, chain=chain)
        return np.moveaxis(Jc, 0, -1), R_e, p_e

    def _rows(self, active: np.ndarray | None) -> tuple[np.ndarray, int]:
        """Where each parameter's column goes in a Jacobian of the ``active`` ones (all: None): its
        row, or the last row (k, a scratch row dropped at the end) where it is not active."""
        if active is None:
            return np.arange(self.size), self.size
        rows = np.full(self.size, len(active))
        rows[np.asarray(active, int)] = np.arange(len(active))
        return rows, len(active)

    def jacobian_columns(self, deviation: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None,
                         frames: bool = True, joints: JointData | None = None, active: np.ndarray | None = None,
                         session: np.ndarray | None = None, chain: np.ndarray | None = None):
        """As :meth:`jacobian` with J laid out (k, m, 6); ``frames=False`` leaves the base and
        tool columns zero (cheaper when none of them is estimated); ``active``: the parameters whose
        columns are wanted, in that order (default all; a tool nothing estimates costs nothing).  A
        joint term's column is the joints' θ columns (the joint-value columns) weighted by its basis."""
        deviation = np.asarray(deviation, dtype=float)
        geom, base, tools = self.expand(deviation)
        tool = tools[:1] if target_idx is None else tools[target_idx]
        q = self.effective_joints(deviation, q, joints)
        m = q.shape[0]
        kinds = len(joint_kinds(self.robot.convention))
        at, k = self._rows(active)
        J = np.zeros((k + 1, m, 6))
        nj = self.n_joint_params
        value = joint_value_columns(self.robot.convention, self.robot.geometry)
        if self.robot.tree is None:
            Jj, R_e, p_e, R_f = chain_twist_jacobian(self.robot.convention, geom, q, base, tool)
            J[at[:nj]] = Jj[:, :kinds].reshape(nj, m, 6)
            if self.n_term_params:
                Jq = Jj[np.arange(self.robot.n_joints), value]
                J[at[self.size - self.n_term_params:]] = np.einsum("imk,mit->tmk", Jq, joints.basis)
        else:
            R_e, p_e, R_f = self._tree_columns(J, at, geom, q, base, tool, joints, chain)
        if frames:
            _, db, dt = self._split(deviation)
            if np.any(at[nj:nj + 6] < k):
                Jb = np.zeros((6, m, 6))
                self._base_columns(Jb, db, p_e - base[:3, 3])
                J[at[nj:nj + 6]] = Jb
            self._tool_columns(J, dt, R_e, R_f, target_idx, at, k)
        D = self._through_sessions(deviation, session, base)
        if D is not None:  # a session's rows through its own base: their twists turned with it
            own = session >= 0
            J[:, own, :3] = np.einsum("mij,kmj->kmi", D[own, :3, :3], J[:, own, :3])
            J[:, own, 3:] = np.einsum("mij,kmj->kmi", D[own, :3, :3], J[:, own, 3:])
            R_e = np.where(own[:, None, None], D[:, :3, :3] @ R_e, R_e)
            p_e = np.where(own[:, None], np.einsum("mij,mj->mi", D[:, :3, :3], p_e) + D[:, :3, 3], p_e)
            J[at[nj:nj + 6, None], np.flatnonzero(own)] = 0.0  # the base does not reach them
            if frames:
                bases = self.session_bases(deviation)
                d = deviation[self._session_slice()].reshape(len(self.sessions), 6)
                first = self._session_slice().start
                for i in range(len(self.sessions)):
                    rows = session == i
                    if not rows.any() or not np.any(at[first + 6 * i:first + 6 * i + 6] < k):
                        continue
                    Jb = np.zeros((6, int(rows.sum()), 6))
                    self._base_columns(Jb, d[i], p_e[rows] - bases[i, :3, 3])
                    J[at[first + 6 * i:first + 6 * i + 6, None], np.flatnonzero(rows)] = Jb
        return J[:k], R_e, p_e

    @staticmethod
    def _base_columns(Jb: np.ndarray, db: np.ndarray, r: np.ndarray) -> None:
        for k in range(3):
            Jb[k, :, k] = 1.0
        Wb = left_jacobian(db[3:])  # Exp(δ+ε) = Exp(J_l ε) Exp(δ)
        for k in range(3):
            w = Wb[:, k]
            Jb[3 + k, :, :3] = np.cross(w, r)
            Jb[3 + k, :, 3:] = w

    def _tool_columns(self, J, dt, R_e, R_f, target_idx, at: np.ndarray, k: int) -> None:
        nj = self.n_joint_params
        for t in range(len(self.targets)):
            c = nj + 6 + 6 * t
            if not np.any(at[c:c + 6] < k):  # nothing estimates this tool
                continue
            if target_idx is None:
                if t > 0:
                    break
                rows = slice(None)
            else:
                rows = target_idx == t
                if not np.any(rows):
                    continue
            # R_tool° Exp(δ+ε) = R_tool° Exp(δ) Exp(J_r(δ) ε), J_r(δ) = J_l(−δ)
            Wt = R_e[rows] @ left_jacobian(-dt[t, 3:])
            Rf = R_f[rows]
            for axis in range(3):
                J[at[c + axis], rows, :3] = Rf[:, :, axis]
                J[at[c + 3 + axis], rows, 3:] = Wt[:, :, axis]
