"""The pose and distance characteristics of ISO 9283:1998 from measured cycles.

For a pose j measured in n cycles at x_i, y_i, z_i (mm) and orientation a_i, b_i, c_i (deg,
rotations about x, y, z: R = Rz(c) Ry(b) Rx(a)), commanded at x_c … c_c:

- pose accuracy (§7.2.1): the barycentre x̄ = Σx_i/n …; AP_x = x̄ − x_c, AP_y, AP_z and
  AP_P = √(AP_x² + AP_y² + AP_z²); AP_a = ā − a_c, AP_b = b̄ − b_c, AP_c = c̄ − c_c.
- pose repeatability (§7.2.2): l_i = √((x_i − x̄)² + (y_i − ȳ)² + (z_i − z̄)²),
  l̄ = Σl_i/n, S_l = √(Σ(l_i − l̄)²/(n − 1)), RP_l = l̄ + 3 S_l; RP_a = ±3 S_a with
  S_a = √(Σ(a_i − ā)²/(n − 1)), likewise RP_b, RP_c.
- distance accuracy (§7.3.1), between poses 1 and 2: D_c = |P_c1 − P_c2|, D_i = |P_1i − P_2i|
  of cycle i, D̄ = ΣD_i/n, AD_P = D̄ − D_c.
- distance repeatability (§7.3.2): RD = ±3 √(Σ(D_i − D̄)²/(n − 1)).

Angles are averaged as their differences from the commanded angle, wrapped to (−180°, 180°],
so that a pose near ±180° does not average to 0.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

#: a median pose accuracy beyond this (mm) is two frames, not a robot's error
FRAME_GAP_MM = 50.0


def _wrap(deg: np.ndarray) -> np.ndarray:
    return (np.asarray(deg, float) + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class PoseCharacteristics:
    """AP and RP of one pose: mm and deg (orientation ones None for position-only data)."""

    pose: str
    cycles: int
    AP_x: float
    AP_y: float
    AP_z: float
    AP_p: float
    RP_l: float
    AP_a: float | None = None
    AP_b: float | None = None
    AP_c: float | None = None
    RP_a: float | None = None
    RP_b: float | None = None
    RP_c: float | None = None

    def to_dict(self) -> dict:
        out = {"pose": self.pose, "cycles": self.cycles, "AP_p": self.AP_p, "AP_x": self.AP_x, "AP_y": self.AP_y,
               "AP_z": self.AP_z, "RP_l": self.RP_l}
        if self.AP_a is not None:
            out.update({"AP_a": self.AP_a, "AP_b": self.AP_b, "AP_c": self.AP_c, "RP_a": self.RP_a,
                        "RP_b": self.RP_b, "RP_c": self.RP_c})
        return out


@dataclass(frozen=True)
class DistanceCharacteristics:
    """AD and RD between two poses (mm): AD_p = D̄ − D_c, its components, and RD."""

    poses: tuple[str, str]
    cycles: int
    D_c: float
    AD_p: float
    AD_x: float
    AD_y: float
    AD_z: float
    RD: float

    def to_dict(self) -> dict:
        return {"poses": list(self.poses), "cycles": self.cycles, "D_c": self.D_c, "AD_p": self.AD_p,
                "AD_x": self.AD_x, "AD_y": self.AD_y, "AD_z": self.AD_z, "RD": self.RD}


def pose_characteristics(pose: str, measured: np.ndarray, commanded: np.ndarray, measured_abc: np.ndarray | None = None,
                         commanded_abc: np.ndarray | None = None) -> PoseCharacteristics:
    """AP and RP of one pose from its cycles: measured (n, 3) mm, commanded (3,) mm, and
    optionally the orientations (n, 3) and (3,) as a, b, c in degrees."""
    p = np.asarray(measured, float)
    n = len(p)
    bary = p.mean(axis=0)
    ap = bary - np.asarray(commanded, float)
    l = np.linalg.norm(p - bary, axis=1)
    s_l = float(np.std(l, ddof=1)) if n > 1 else 0.0
    out = dict(pose=pose, cycles=n, AP_x=float(ap[0]), AP_y=float(ap[1]), AP_z=float(ap[2]),
               AP_p=float(np.linalg.norm(ap)), RP_l=float(l.mean() + 3.0 * s_l))
    if measured_abc is not None and commanded_abc is not None:
        d = _wrap(np.asarray(measured_abc, float) - np.asarray(commanded_abc, float))  # a_i − a_c
        mean = d.mean(axis=0)  # ā − a_c
        s = np.std(d, axis=0, ddof=1) if n > 1 else np.zeros(3)
        out.update(AP_a=float(mean[0]), AP_b=float(mean[1]), AP_c=float(mean[2]), RP_a=float(3 * s[0]),
                   RP_b=float(3 * s[1]), RP_c=float(3 * s[2]))
    return PoseCharacteristics(**out)


def distance_characteristics(poses: tuple[str, str], first: np.ndarray, second: np.ndarray, commanded_first: np.ndarray,
                             commanded_second: np.ndarray) -> DistanceCharacteristics:
    """AD and RD between two poses measured in the same cycles: first, second (n, 3) mm, cycle
    by cycle; commanded (3,) mm each."""
    a, b = np.asarray(first, float), np.asarray(second, float)
    delta_c = np.asarray(commanded_first, float) - np.asarray(commanded_second, float)
    delta = a - b  # (n, 3)
    D = np.linalg.norm(delta, axis=1)
    n = len(D)
    D_c = float(np.linalg.norm(delta_c))
    comp = np.abs(delta).mean(axis=0) - np.abs(delta_c)  # per axis: D̄_x − D_cx
    return DistanceCharacteristics(poses, n, D_c, float(D.mean() - D_c), float(comp[0]), float(comp[1]),
                                   float(comp[2]), float(3.0 * np.std(D, ddof=1)) if n > 1 else 0.0)


@dataclass(frozen=True)
class Campaign:
    """One measured ISO 9283 campaign: per pose label, per cycle label, the measured and
    commanded positions (mm) and orientations (a, b, c deg, or None)."""

    name: str
    poses: tuple[str, ...]
    cycles: tuple[str, ...]
    measured: np.ndarray  # (P, C, 3)
    commanded: np.ndarray  # (P, 3)
    measured_abc: np.ndarray | None = None  # (P, C, 3)
    commanded_abc: np.ndarray | None = None  # (P, 3)


@dataclass(frozen=True)
class Iso9283Result:
    """The characteristics of a campaign: per pose, and per pair of poses."""

    name: str
    poses: list[PoseCharacteristics]
    distances: list[DistanceCharacteristics]
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"campaign": self.name, "poses": [p.to_dict() for p in self.poses],
                "distances": [d.to_dict() for d in self.distances], "notes": list(self.notes),
                "figures": self.figures()}

    def figures(self) -> dict[str, float]:
        """What a specification holds a campaign to (mm): the largest AP_p and RP_l over its poses,
        and the largest |AD_p| and RD over its pairs of poses."""
        return {"AP": max(p.AP_p for p in self.poses), "RP": max(p.RP_l for p in self.poses),
                "AD": max((abs(d.AD_p) for d in self.distances), default=0.0),
                "RD": max((d.RD for d in self.distances), default=0.0)}


def characteristics(c: Campaign) -> Iso9283Result:
    """AP, RP of every pose and AD, RD of every pair of poses of a campaign."""
    full = c.measured_abc is not None and c.commanded_abc is not None
    poses = [pose_characteristics(label, c.measured[j], c.commanded[j], c.measured_abc[j] if full else None,
                                  c.commanded_abc[j] if full else None) for j, label in enumerate(c.poses)]
    distances = [distance_characteristics((c.poses[i], c.poses[j]), c.measured[i], c.measured[j], c.commanded[i],
                                          c.commanded[j]) for i, j in itertools.combinations(range(len(c.poses)), 2)]
    notes = []
    gap = float(np.median([p.AP_p for p in poses]))
    if gap > FRAME_GAP_MM:  # a robot misses by millimetres; metres are a frame, not an error
        notes.append(f"{c.name}: the attained poses lie {gap:.4g} mm from the commanded ones (median AP): measured and "
                     "commanded poses look like two frames (the tracker's and the robot's base); give both in the "
                     "base frame, or the commands as joints with --robot whose [base] is the measuring frame")
    return Iso9283Result(c.name, poses, distances, tuple(notes))
