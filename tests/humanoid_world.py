"""An independent humanoid upper body for planted-truth tests: it shares no code with robocal.

A 4-joint torso whose last joint turns against the one before it (a URDF ``<mimic>``: the chest
stays level as the torso bends) carries two 7-axis arms on fixed shoulder frames; an external
camera system sees a marker on each hand.  The truth is the same URDF text with its joints' origins
moved and zeros off, and every joint elastic: it gives way by c_i τ_i, τ_i the moment of gravity
about its axis of every link it carries, both arms' for a torso joint (point masses at the links'
centres, summed link by link with :mod:`tests.independent_urdf`'s forward kinematics).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from tests.independent_urdf import Urdf

G = 9.80665
_AXES = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
#: (name, parent, child, xyz m, rpy rad, axis) of the torso's joints
_TORSO = [("torso_1", "base_link", "t1", (0.0, 0.0, 0.30), "z"), ("torso_2", "t1", "t2", (0.0, 0.0, 0.10), "y"),
          ("torso_3", "t2", "t3", (0.0, 0.0, 0.35), "y"), ("torso_4", "t3", "chest", (0.0, 0.0, 0.35), "y")]
_ARM = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.10), (0.0, 0.0, 0.15), (0.0, 0.0, 0.15), (0.0, 0.0, 0.15), (0.0, 0.0, 0.12),
        (0.0, 0.0, 0.08)]
_ARM_AXES = "zyzyzyz"
_SHOULDERS = {"left": ((0.0, 0.20, 0.25), (-np.pi / 2, 0.0, 0.0)), "right": ((0.0, -0.20, 0.25), (np.pi / 2, 0.0, 0.0))}
_MARKER = (0.02, 0.0, 0.10)
_UNIT = {k: np.array([float(v) for v in text.split()]) for k, text in _AXES.items()}
#: the coupled joint: torso_4 = −torso_3
MIMIC = ("torso_4", "torso_3", -1.0)


def joints() -> list[tuple]:
    """(name, parent, child, type, xyz, rpy, axis) of every joint, fixed ones included."""
    out = [(n, p, c, "revolute", xyz, (0.0, 0.0, 0.0), a) for n, p, c, xyz, a in _TORSO]
    for side, (xyz, rpy) in _SHOULDERS.items():
        out.append((f"{side}_mount", "chest", f"{side}_shoulder", "fixed", xyz, rpy, "z"))
        parent = f"{side}_shoulder"
        for k, (origin, axis) in enumerate(zip(_ARM, _ARM_AXES)):
            out.append((f"{side}_{k + 1}", parent, f"{side}_link{k + 1}", "revolute", origin, (0.0, 0.0, 0.0), axis))
            parent = f"{side}_link{k + 1}"
        out.append((f"{side}_marker_joint", parent, f"{side}_hand", "fixed", _MARKER, (0.0, 0.0, 0.0), "z"))
    return out


def movable() -> list[str]:
    """The movable joints in the order robocal's reader meets them (torso, left arm, right arm)."""
    return [j[0] for j in joints() if j[3] != "fixed"]


def free() -> list[str]:
    """The joints a row commands: all but the coupled one."""
    return [n for n in movable() if n != MIMIC[0]]


def urdf(moves: dict[str, tuple] | None = None) -> str:
    moves = moves or {}
    links, body = {"base_link"}, []
    for name, parent, child, kind, xyz, rpy, axis in joints():
        dxyz, drpy = moves.get(name, ((0, 0, 0), (0, 0, 0)))
        xyz, rpy = np.add(xyz, dxyz), np.add(rpy, drpy)
        links |= {parent, child}
        extra = ""
        if kind != "fixed":
            extra = '<limit lower="-3.0" upper="3.0" effort="10" velocity="1"/>'
            if name == MIMIC[0]:
                extra += f'<mimic joint="{MIMIC[1]}" multiplier="{MIMIC[2]}" offset="0"/>'
        body.append(f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                    f'<origin xyz="{xyz[0]:.9f} {xyz[1]:.9f} {xyz[2]:.9f}" rpy="{rpy[0]:.9f} {rpy[1]:.9f} '
                    f'{rpy[2]:.9f}"/><axis xyz="{_AXES[axis]}"/>{extra}</joint>')
    head = ['<?xml version="1.0"?>', '<robot name="upper_body">'] + [f'  <link name="{n}"/>' for n in sorted(links)]
    return "\n".join(head + body + ["</robot>"]) + "\n"


def _masses() -> dict[str, tuple[float, np.ndarray]]:
    """Each moving link's mass (kg) and centre (m, in its own frame): half-way to the next joint."""
    out = {}
    for name, _, child, kind, *_ in joints():
        if kind == "fixed":
            continue
        after = next((j for j in joints() if j[1] == child), None)
        centre = 0.5 * np.array(after[4]) if after is not None else np.zeros(3)
        out[child] = (12.0 if name.startswith("torso") else 2.5, centre)
    return out


@dataclass
class Truth:
    """The planted body: its URDF, each joint's zero (rad), compliance (rad/(N·m)), the camera system's
    frame (4 × 4, mm)."""

    model: Urdf
    zeros: dict[str, float]
    compliance: dict[str, float] = field(default_factory=dict)
    frame: np.ndarray = field(default_factory=lambda: np.eye(4))

    def values(self, q: np.ndarray) -> dict[str, float]:
        """Every joint's commanded value (rad) from the free joints' row ``q``."""
        values = dict(zip(free(), q))
        values[MIMIC[0]] = MIMIC[2] * values[MIMIC[1]]
        return values

    def torques(self, values: dict[str, float]) -> dict[str, float]:
        """The moment of gravity (N·m) about each joint's axis of the links it carries."""
        masses, carried = self._layout()
        frames = self.model.frames("base_link", values)
        weight = np.array([0.0, 0.0, -G])
        # each link's centre and weight, once: the moments about every joint that carries it
        centres = {link: frames[link][:3, :3] @ centre + frames[link][:3, 3] for link, (_, centre) in masses.items()}
        out = {}
        for name, child, axis in carried:
            T = frames[child]
            a, p = T[:3, :3] @ _UNIT[axis], T[:3, 3]
            moment = sum(np.cross(centres[link] - p, masses[link][0] * weight) for link in carried[(name, child, axis)])
            out[name] = float(a @ moment)
        return out

    def _layout(self):
        """The links' masses and, per movable joint (name, child link, axis), the links it carries
        in the order of :func:`_masses` (worked out once: they do not move)."""
        if "_carried" not in self.__dict__:
            masses = _masses()
            self.__dict__["_carried"] = (masses, {
                (name, child, axis): [link for link in masses if link == child or self._below(link, child)]
                for name, _, child, kind, _, _, axis in joints() if kind != "fixed"})
        return self.__dict__["_carried"]

    def _below(self, link: str, above: str) -> bool:
        j = self.model.joints.get(link)
        while j is not None:
            if j["parent"] == above:
                return True
            j = self.model.joints.get(j["parent"])
        return False

    def marker(self, side: str, q: np.ndarray) -> np.ndarray:
        """(m, 3) mm: the ``side`` hand's marker in the camera system's frame at the free joints q (m, k)."""
        out = []
        for row in np.atleast_2d(q):
            values = self.values(row)
            tau = self.torques(values) if self.compliance else {}
            reached = {n: v + self.zeros.get(n, 0.0) + self.compliance.get(n, 0.0) * tau.get(n, 0.0)
                       for n, v in values.items()}
            T = self.model.transform("base_link", f"{side}_hand", reached)
            out.append((self.frame @ np.append(1000.0 * T[:3, 3], 1.0))[:3])
        return np.array(out)


def plant(rng: np.random.Generator, length: float = 0.5e-3, angle: float = 1e-3, zero: float = 2e-3,
          torso: float = 1.5e-4, arm: float = 3e-4) -> Truth:
    """Origins moved (σ ``length`` m, ``angle`` rad), zeros off (σ ``zero`` rad), torso joints giving
    ``torso`` rad/(N·m), the arms' ``arm``; the camera system's frame near the body."""
    moves = {n: (rng.normal(0, length, 3), rng.normal(0, angle, 3)) for n in movable()}
    zeros = {n: float(rng.normal(0, zero)) for n in movable()}
    compliance = {n: torso if n.startswith("torso") else arm for n in movable()}
    frame = np.eye(4)
    frame[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.02, 3)).as_matrix()
    frame[:3, 3] = rng.normal(0, 50.0, 3) + [2000.0, 0.0, 500.0]
    return Truth(Urdf(urdf(moves)), zeros, compliance, frame)


def joint_sets(rng: np.random.Generator, m: int) -> np.ndarray:
    """(m, k) rad of the free joints: the torso within ±0.4 (its pitch within ±0.3), the arms ±1.5."""
    q = rng.uniform(-1.5, 1.5, (m, len(free())))
    for i, n in enumerate(free()):
        if n.startswith("torso"):
            q[:, i] = rng.uniform(-0.3, 0.3, m)
    return q


def write_rows(truth: Truth, q: np.ndarray, rng: np.random.Generator, noise: float, path, every: bool = False) -> None:
    """Both markers at every joint set as robocal's CSV (joints deg, mm; σ ``noise`` mm per axis); the
    coupled joint's column only with ``every``."""
    names = movable() if every else free()
    lines = [",".join(["pose_id", "chain"] + [f"q{i + 1}" for i in range(len(names))] + ["x", "y", "z"])]
    for side in ("left", "right"):
        p = truth.marker(side, q) + rng.normal(0, noise, (len(q), 3))
        for i, (row, pi) in enumerate(zip(q, p)):
            values = truth.values(row)
            lines.append(",".join([f"p{i}", f"{side}_hand"] + [f"{np.degrees(values[n]):.12f}" for n in names] +
                                  [f"{v:.9f}" for v in pi]))
    path.write_text("\n".join(lines) + "\n")
