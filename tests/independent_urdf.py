"""An independent URDF reader for tests: it shares no code with robocal.

It parses the XML with the standard library and composes 4×4 transforms with scipy's
rotations, link by link, in the file's own units (m, rad), from any link to any other link of
the tree, as a URDF consumer such as ROS's robot_state_publisher does.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
from scipy.spatial.transform import Rotation


def _vec(text, default):
    return np.array([float(v) for v in text.split()]) if text else np.array(default, float)


class Urdf:
    def __init__(self, text: str):
        root = ET.fromstring(text.strip())
        self.joints = {}
        for j in root.findall("joint"):
            origin = j.find("origin")
            axis = j.find("axis")
            T = np.eye(4)
            if origin is not None:
                T[:3, :3] = Rotation.from_euler("xyz", _vec(origin.get("rpy"), [0, 0, 0])).as_matrix()
                T[:3, 3] = _vec(origin.get("xyz"), [0, 0, 0])
            a = _vec(None if axis is None else axis.get("xyz"), [1, 0, 0])
            self.joints[j.find("child").get("link")] = {
                "name": j.get("name"), "type": j.get("type"), "parent": j.find("parent").get("link"),
                "origin": T, "axis": a / np.linalg.norm(a)}

    def movable(self, base: str, tip: str) -> list[str]:
        return [self.joints[link]["name"] for link in self._path(base, tip)
                if self.joints[link]["type"] != "fixed"]

    def _path(self, base, tip):
        out, link = [], tip
        while link != base:
            out.append(link)
            link = self.joints[link]["parent"]
        return out[::-1]

    def frames(self, base: str, q: dict[str, float]) -> dict[str, np.ndarray]:
        """Pose (m) in ``base`` of every link below it: :meth:`transform`'s products, each link's
        from its parent's (the same products in the same order)."""
        out = {base: np.eye(4)}
        pending = [link for link in self.joints if link != base]
        while pending:
            later = []
            for link in pending:
                j = self.joints[link]
                if j["parent"] not in out:
                    later.append(link)
                    continue
                out[link] = out[j["parent"]] @ j["origin"] @ self._motion(j, q)
            if len(later) == len(pending):  # links of another tree than base's
                break
            pending = later
        return out

    def _motion(self, j: dict, q: dict[str, float]) -> np.ndarray:
        M = np.eye(4)
        if j["type"] in ("revolute", "continuous"):
            M[:3, :3] = Rotation.from_rotvec(j["axis"] * q[j["name"]]).as_matrix()
        elif j["type"] == "prismatic":
            M[:3, 3] = j["axis"] * q[j["name"]]
        return M

    def transform(self, base: str, tip: str, q: dict[str, float]) -> np.ndarray:
        """Pose of ``tip`` in ``base`` (m), joint values by joint name (rad or m)."""
        T = np.eye(4)
        for link in self._path(base, tip):
            j = self.joints[link]
            T = T @ j["origin"] @ self._motion(j, q)
        return T
