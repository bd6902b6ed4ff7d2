"""An independent tree cell for planted-truth tests: it shares no code with robocal.

The robot is a URDF text (m, rad) written here: a turntable carrying two 6-axis arms and a
pan-tilt neck whose head holds a camera.  Its forward kinematics is :mod:`tests.independent_urdf`'s
(standard-library XML, scipy's rotations, link by link); the projection with its distortion is
OpenCV's ``cv2.projectPoints``.  The truth is the same text with its joints' origins moved and
each joint's zero off by a planted angle: the commanded q the rows carry, q + zero the robot turns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from tests.independent_urdf import Urdf

#: (name, parent link, child link, type, origin xyz m, origin rpy rad, axis)
_ARM = [("1", (0.0, 0.0, 0.0), "z"), ("2", (0.0, 0.0, 0.15), "y"), ("3", (0.0, 0.0, 0.45), "y"),
        ("4", (0.0, 0.0, 0.40), "z"), ("5", (0.0, 0.0, 0.08), "y"), ("6", (0.0, 0.0, 0.08), "z")]
_AXES = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
#: where each arm's shoulder sits on the torso, and how it is turned (rpy)
_SHOULDERS = {"left": ((0.05, 0.25, 0.50), (-np.pi / 2, 0.0, 0.0)),
              "right": ((0.05, -0.25, 0.50), (np.pi / 2, 0.0, 0.0))}
#: the tools (markers' bodies) on each arm's last link, and the camera on the head (optical frame:
#: z forward along the head's x, x to the image's right)
_TOOL = (0.0, 0.0, 0.10)
_CAMERA = ((0.06, 0.0, 0.04), (-np.pi / 2, 0.0, -np.pi / 2))


def joints(neck: bool = True) -> list[tuple]:
    """The tree's joints (name, parent, child, type, xyz, rpy, axis) in the order the rows' q take them."""
    out = [("turntable", "base_link", "torso", "revolute", (0.0, 0.0, 0.40), (0.0, 0.0, 0.0), "z")]
    for side, (xyz, rpy) in _SHOULDERS.items():
        parent = "torso"
        for i, (k, origin, axis) in enumerate(_ARM):
            child = f"{side}_link{k}"
            out.append((f"{side}_{k}", parent, child, "revolute", xyz if i == 0 else origin,
                        rpy if i == 0 else (0.0, 0.0, 0.0), axis))
            parent = child
    if neck:
        out += [("neck_pan", "torso", "neck", "revolute", (0.10, 0.0, 0.70), (0.0, 0.0, 0.0), "z"),
                ("neck_tilt", "neck", "head", "revolute", (0.0, 0.0, 0.10), (0.0, 0.0, 0.0), "y")]
    return out


def movable(neck: bool = True) -> list[str]:
    return [j[0] for j in joints(neck)]


def urdf(moves: dict[str, tuple] | None = None, neck: bool = True) -> str:
    """The URDF text; ``moves``: joint name → (Δxyz m, Δrpy rad) added to its origin."""
    moves = moves or {}
    fixed = [("left_tool_joint", "left_link6", "left_tool", "fixed", _TOOL, (0.0, 0.0, 0.0), "z"),
             ("right_tool_joint", "right_link6", "right_tool", "fixed", _TOOL, (0.0, 0.0, 0.0), "z")]
    if neck:
        fixed.append(("head_camera_joint", "head", "head_camera", "fixed", *_CAMERA, "z"))
    links = {"base_link"}
    body = []
    for name, parent, child, kind, xyz, rpy, axis in joints(neck) + fixed:
        dxyz, drpy = moves.get(name, ((0, 0, 0), (0, 0, 0)))
        xyz = np.add(xyz, dxyz)
        rpy = np.add(rpy, drpy)
        links |= {parent, child}
        limit = '<limit lower="-3.0" upper="3.0" effort="10" velocity="1"/>' if kind != "fixed" else ""
        body.append(f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                    f'<origin xyz="{xyz[0]:.9f} {xyz[1]:.9f} {xyz[2]:.9f}" rpy="{rpy[0]:.9f} {rpy[1]:.9f} '
                    f'{rpy[2]:.9f}"/><axis xyz="{_AXES[axis]}"/>{limit}</joint>')
    head = ['<?xml version="1.0"?>', '<robot name="dual_arm">'] + [f'  <link name="{n}"/>' for n in sorted(links)]
    return "\n".join(head + body + ["</robot>"]) + "\n"


@dataclass
class Truth:
    """The planted cell: the true URDF, each joint's zero (rad), the tracker's frame (4 × 4, mm)."""

    model: Urdf
    zeros: dict[str, float]
    tracker: np.ndarray
    neck: bool = True

    def pose(self, tip: str, q: np.ndarray) -> np.ndarray:
        """(m, 4, 4) mm: ``tip``'s frame in the tracker's frame at commanded joints q (m, n) rad."""
        names = movable(self.neck)
        out = []
        for row in np.atleast_2d(q):
            values = {n: v + self.zeros.get(n, 0.0) for n, v in zip(names, row)}
            T = self.model.transform("base_link", tip, values)
            T[:3, 3] *= 1000.0
            out.append(self.tracker @ T)
        return np.array(out)


def plant(rng: np.random.Generator, length: float = 0.3e-3, angle: float = 0.5e-3, zero: float = 1e-3,
          neck: bool = True) -> Truth:
    """A truth: every movable joint's origin moved (σ ``length`` m, ``angle`` rad) and its zero off
    (σ ``zero`` rad), the tracker's frame somewhere near the robot's base."""
    moves = {n: (rng.normal(0, length, 3), rng.normal(0, angle, 3)) for n in movable(neck)}
    zeros = {n: float(rng.normal(0, zero)) for n in movable(neck)}
    return Truth(Urdf(urdf(moves, neck)), zeros, tracker(rng), neck)


def tracker(rng: np.random.Generator) -> np.ndarray:
    """The robot's base in a tracker's frame (4 × 4, mm): somewhere beside it, turned a little."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix()
    T[:3, 3] = rng.normal(0, 50.0, 3) + [1500.0, 200.0, -300.0]
    return T


def joint_sets(rng: np.random.Generator, m: int, neck: bool = True, spread: float = 1.3) -> np.ndarray:
    """(m, n) rad: arms anywhere within ±spread, the turntable and neck within ±0.5."""
    names = movable(neck)
    q = rng.uniform(-spread, spread, (m, len(names)))
    for i, n in enumerate(names):
        if n == "turntable" or n.startswith("neck"):
            q[:, i] = rng.uniform(-0.5, 0.5, m)
    return q


def tracker_rows(truth: Truth, q: np.ndarray, rng: np.random.Generator, noise: float) -> list[dict]:
    """Each arm's tool seen by the tracker at every joint set (mm, noise σ per axis)."""
    rows = []
    for side in ("left", "right"):
        p = truth.pose(f"{side}_tool", q)[:, :3, 3] + rng.normal(0, noise, (len(q), 3))
        for i, (qi, pi) in enumerate(zip(q, p)):
            rows.append({"pose_id": f"p{i}", "chain": f"{side}_tool", "q": qi, "xyz": pi})
    return rows


def write_rows(rows: list[dict], path, names: list[str]) -> None:
    """The rows as robocal's CSV (joints in deg, mm; pixel rows with a camera and a target)."""
    pix = any("uv" in r for r in rows)
    head = ["pose_id", "chain"] + [f"q{i + 1}" for i in range(len(names))] + \
        (["target", "camera", "u", "v"] if pix else ["x", "y", "z"])
    lines = [",".join(head)]
    for r in rows:
        q = ",".join(f"{v:.12f}" for v in np.degrees(r["q"]))
        tail = f"{r['target']},{r['camera']},{r['uv'][0]:.6f},{r['uv'][1]:.6f}" if pix else \
            ",".join(f"{v:.9f}" for v in r["xyz"])
        lines.append(f"{r['pose_id']},{r['chain']},{q},{tail}")
    path.write_text("\n".join(lines) + "\n")


def facing_the_hands(truth: Truth, q: np.ndarray) -> np.ndarray:
    """The joint sets with the neck turned so that the head's camera looks at the midpoint of the
    hands (as a head tracks them; the truth's own kinematics)."""
    names = movable()
    pan, tilt = names.index("neck_pan"), names.index("neck_tilt")
    out = np.array(q, float)
    for row in out:
        for _ in range(3):
            mid = 0.5 * (truth.pose("left_tool", row[None])[0, :3, 3] + truth.pose("right_tool", row[None])[0, :3, 3])
            d = np.linalg.inv(truth.pose("head_camera", row[None])[0]) @ np.append(mid, 1.0)
            row[pan] -= np.arctan2(d[0], d[2])  # the optical frame's x is the image's right
            row[tilt] += np.arctan2(d[1], d[2])
    return out


def camera_rows(truth: Truth, camera, markers: dict, q: np.ndarray, rng: np.random.Generator,
                noise: float) -> list[dict]:
    """The head camera's pixels of the markers on each hand (mm in its last link's frame), where they
    lie in front of it and fall on its image, with Gaussian noise ``noise`` px."""
    rows = []
    w, h = camera.size
    for i, row in enumerate(q):
        T_cam = truth.pose("head_camera", row[None])[0]
        for side in ("left", "right"):
            T_tip = truth.pose(f"{side}_link6", row[None])[0]
            for name, p in markers.items():
                pc = T_cam[:3, :3].T @ (T_tip[:3, :3] @ p + T_tip[:3, 3] - T_cam[:3, 3])
                if pc[2] < 200.0:
                    continue
                uv = camera.project(pc[None])[0] + rng.normal(0.0, noise, 2)
                if 10 <= uv[0] <= w - 10 and 10 <= uv[1] <= h - 10:
                    rows.append({"pose_id": f"p{i}", "chain": f"{side}_tool", "q": row, "target": name,
                                 "camera": camera.name, "uv": uv})
    return rows
