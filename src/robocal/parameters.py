"""Named geometric error parameters and the map between a flat error vector and a robot.

Names (1-based joints): ``a1``, ``alpha1``, ``theta1``, ``d1`` for every joint, ``beta1``…
for hayati robots; ``base_x, base_y, base_z`` (mm) and ``base_rx, base_ry, base_rz``
(rad); ``tool_x … tool_rz`` for the default measured point and ``tool[NAME]_x …`` for a
named target.  For craig robots ``a{i}``/``alpha{i}`` name the values held in row i
(that is a_{i-1}, α_{i-1} of Craig's notation).

Every parameter is an additive error on its nominal value, except the frame
rotations: the base rotates about the measuring-frame axes through the base origin,
``R_base = Exp(δ) · R_base°``, and a tool rotates about its own axes,
``R_tool = R_tool° · Exp(δ)``; both are rotation vectors, so no Euler singularity
can hide in them.  Units: mm for lengths, rad for angles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .kinematics import KINDS, Robot, chain_points, chain_pose, chain_twist_jacobian
from .transforms import exp_so3, homogeneous, left_jacobian

FRAME_AXES = ("x", "y", "z", "rx", "ry", "rz")


def joint_kinds(convention: str) -> tuple[str, ...]:
    return KINDS if convention == "hayati" else KINDS[:4]


def tool_prefix(target: str) -> str:
    return "tool" if target == "" else f"tool[{target}]"


def is_angle(name: str) -> bool:
    """True for parameters in rad, False for mm."""
    base = name.rsplit("_", 1)[-1] if name.startswith(("base", "tool")) else name.rstrip("0123456789")
    return base in ("alpha", "theta", "beta", "rx", "ry", "rz")


@dataclass(frozen=True, eq=False)
class ParameterSpace:
    """All geometric error parameters of a robot, in a fixed order.

    ``delta = 0`` is the reference robot itself.  Vectors may carry leading axes
    (a swarm's particles): every method maps (..., k) to (..., …).
    """

    robot: Robot
    names: tuple[str, ...]
    targets: tuple[str, ...]

    @classmethod
    def of(cls, robot: Robot, targets: Sequence[str] | None = None) -> ParameterSpace:
        """The full space of ``robot``: joints, base, and a tool for each target
        (default: the robot's own targets)."""
        targets = tuple(robot.target_names if targets is None else dict.fromkeys(targets))
        kinds = joint_kinds(robot.convention)
        names = [f"{k}{i + 1}" for i in range(robot.n_joints) for k in kinds]
        names += [f"base_{ax}" for ax in FRAME_AXES]
        for t in targets:
            names += [f"{tool_prefix(t)}_{ax}" for ax in FRAME_AXES]
        return cls(robot, tuple(names), targets)

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
        """Flat error vector from a {name: value} mapping (others zero)."""
        x = np.zeros(self.size)
        if values:
            x[self.index(list(values))] = list(values.values())
        return x

    def as_dict(self, delta: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, delta)}

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

    # --- delta → geometry --------------------------------------------------------
    def _split(self, delta: np.ndarray):
        delta = np.asarray(delta, dtype=float)
        if delta.shape[-1] != self.size:
            raise ValueError(f"error vector has {delta.shape[-1]} entries, the space has {self.size}")
        nj = self.n_joint_params
        kinds = joint_kinds(self.robot.convention)
        joints = delta[..., :nj].reshape(delta.shape[:-1] + (self.robot.n_joints, len(kinds)))
        base = delta[..., nj : nj + 6]
        tools = delta[..., nj + 6 :].reshape(delta.shape[:-1] + (len(self.targets), 6))
        return joints, base, tools

    def expand(self, delta: np.ndarray):
        """(…, k) → geometry (…, n, 5), base (…, 4, 4), tools (…, T, 4, 4)."""
        delta = np.asarray(delta, dtype=float)
        joints, db, dt = self._split(delta)
        r = self.robot
        geom = np.broadcast_to(r.geometry, joints.shape[:-2] + r.geometry.shape).copy()
        geom[..., : joints.shape[-1]] += joints
        nominal_tools = np.stack([r.tool_frames([t])[0] for t in self.targets])
        if not np.any(db) and not np.any(dt):  # the common case: frames as given, no SO(3) algebra
            lead = delta.shape[:-1]
            return (
                geom,
                np.broadcast_to(r.base, lead + (4, 4)).copy(),
                np.broadcast_to(nominal_tools, lead + nominal_tools.shape).copy(),
            )
        base = homogeneous(exp_so3(db[..., 3:]) @ r.base[:3, :3], r.base[:3, 3] + db[..., :3])
        tools = homogeneous(nominal_tools[:, :3, :3] @ exp_so3(dt[..., 3:]), nominal_tools[:, :3, 3] + dt[..., :3])
        return geom, base, tools

    def apply(self, delta: np.ndarray) -> Robot:
        """The robot with errors ``delta`` (k,) added: nominal + error = real."""
        geom, base, tools = self.expand(np.asarray(delta, dtype=float))
        named = {t: tools[i] for i, t in enumerate(self.targets) if t != ""}
        default = tools[self.targets.index("")] if "" in self.targets else self.robot.tool
        extra = {t: v for t, v in self.robot.targets.items() if t not in named}
        return self.robot.replace(geometry=geom, base=base, tool=default, targets={**extra, **named})

    def pose(self, delta: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None):
        """End rotation (…, m, 3, 3) and position (…, m, 3) for error vectors (…, k).

        One batched call over all leading axes of ``delta`` and all poses of ``q``.
        """
        geom, base, tools = self.expand(delta)
        tool = tools[..., :1, :, :] if target_idx is None else tools[..., target_idx, :, :]
        return chain_pose(self.robot.convention, geom, q, base, tool)

    def points(self, delta: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None) -> np.ndarray:
        """Measured-point positions (…, m, 3) only: the cheap path of position-only objectives."""
        geom, base, tools = self.expand(delta)
        tool = tools[..., :1, :, :] if target_idx is None else tools[..., target_idx, :, :]
        return chain_points(self.robot.convention, geom, q, base, tool)

    def jacobian(self, delta: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None):
        """Exact derivative of the end pose with respect to ``delta`` (k,).

        Returns ``(J, R, p)``: J (m, 6, k) with rows (position mm, rotation rad about
        the measuring-frame axes, left perturbation), R (m, 3, 3), p (m, 3).  J is a
        view of a (k, m, 6) array: each parameter's column is contiguous.
        """
        Jc, R_e, p_e = self.jacobian_columns(delta, q, target_idx)
        return np.moveaxis(Jc, 0, -1), R_e, p_e

    def jacobian_columns(
        self, delta: np.ndarray, q: np.ndarray, target_idx: np.ndarray | None = None, frames: bool = True
    ):
        """As :meth:`jacobian` with J laid out (k, m, 6); ``frames=False`` leaves the base and
        tool columns zero (cheaper when none of them is estimated)."""
        delta = np.asarray(delta, dtype=float)
        geom, base, tools = self.expand(delta)
        tool = tools[:1] if target_idx is None else tools[target_idx]
        Jj, R_e, p_e, R_f = chain_twist_jacobian(self.robot.convention, geom, q, base, tool)
        m = p_e.shape[0]
        kinds = len(joint_kinds(self.robot.convention))
        J = np.zeros((self.size, m, 6))
        nj = self.n_joint_params
        J[:nj] = Jj[:, :kinds].reshape(nj, m, 6)
        if not frames:
            return J, R_e, p_e
        _, db, dt = self._split(delta)
        Jb = J[nj : nj + 6]
        for k in range(3):
            Jb[k, :, k] = 1.0
        Wb = left_jacobian(db[3:])  # Exp(δ+ε) = Exp(J_l ε) Exp(δ)
        r = p_e - base[:3, 3]
        for k in range(3):
            w = Wb[:, k]
            Jb[3 + k, :, :3] = np.cross(w, r)
            Jb[3 + k, :, 3:] = w
        for t in range(len(self.targets)):
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
            c = nj + 6 + 6 * t
            Rf = R_f[rows]
            for k in range(3):
                J[c + k, rows, :3] = Rf[:, :, k]
                J[c + 3 + k, rows, 3:] = Wt[:, :, k]
        return J, R_e, p_e
