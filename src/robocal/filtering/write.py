"""Writing corrected targets back: only their numbers change, each in its own style.

Numbers keep their decimals, with at least enough for the correction (mm: 3, deg: 4, a
quaternion: 8, URScript's m and rad: 7).  An orientation is written in the spelling nearest
the original (KRL's A B C among its two solutions and ±360°, a quaternion's sign, a rotation
vector's turn), so that a small correction reads as one.  Configuration flags follow the
corrected joints: KRL's T, RAPID's cf1 cf4 cf6.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from ..math.so3 import matrix_to_rpy
from .correct import Correction
from .program import Field, Program, rewrite

DECIMALS = {"mm": 3, "deg": 4, "quat": 8, "ur": 7}


def _near(value: float, original: float) -> float:
    """``value`` (deg) plus the multiple of 360 that brings it nearest ``original``."""
    return value + 360.0 * round((original - value) / 360.0)


def krl_abc(R: np.ndarray, original: tuple[float, float, float]) -> tuple[float, float, float]:
    """A, B, C (deg) of R = Rz(A) Ry(B) Rx(C), the spelling nearest the original's."""
    rx, ry, rz = np.degrees(matrix_to_rpy(R))
    candidates = [(rz, ry, rx), (rz + 180.0, 180.0 - ry, rx + 180.0)]
    best = None
    for a, b, c in candidates:
        abc = (_near(a, original[0]), _near(b, original[1]), _near(c, original[2]))
        d = sum((x - y) ** 2 for x, y in zip(abc, original))
        if best is None or d < best[0]:
            best = (d, abc)
    return best[1]


def rapid_quaternion(R: np.ndarray, original: np.ndarray) -> np.ndarray:
    """q1..q4 (scalar first) of R, with the sign of the original."""
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return -q if q @ original < 0 else q


def ur_rotvec(R: np.ndarray, original: np.ndarray) -> np.ndarray:
    """The rotation vector of R nearest the original's (a turn of θ or of θ − 2π the other way)."""
    r = Rotation.from_matrix(R).as_rotvec()
    angle = np.linalg.norm(r)
    if angle > 1e-12:
        other = r * (1.0 - 2.0 * math.pi / angle)
        if np.linalg.norm(other - original) < np.linalg.norm(r - original):
            return other
    return r


def _set(changes: list, f: Field, value: float, decimals: int) -> None:
    changes.append((f, f.formatted(value, decimals)))


def _set_int(changes: list, f: Field, value: int) -> None:
    if int(f.value) != value:
        changes.append((f, str(value)))


def target_changes(language: str, c: Correction) -> list[tuple[Field, str]]:
    """The new text of a corrected target's numbers."""
    t, f, out = c.target, c.target.fields, []
    if not c.corrected:
        return out
    if t.kind == "joints":
        q = c.q
        for i in range(len(q)):
            key = f"A{i + 1}" if language == "krl" else f"q{i + 1}"
            if key in f:
                if language == "urscript":
                    _set(out, f[key], float(q[i]), DECIMALS["ur"])
                else:
                    _set(out, f[key], math.degrees(q[i]), DECIMALS["deg"])
        return out
    p, R = c.pose[:3, 3], c.pose[:3, :3]
    if language == "krl":
        for k, v in zip("XYZ", p):
            _set(out, f[k], float(v), DECIMALS["mm"])
        abc = krl_abc(R, (f["A"].value, f["B"].value, f["C"].value))
        for k, v in zip("ABC", abc):
            _set(out, f[k], float(v), DECIMALS["deg"])
        if "T" in f and c.q is not None:
            _set_int(out, f["T"], sum(1 << i for i in range(min(6, len(c.q))) if c.q[i] < 0))
    elif language == "rapid":
        for k, v in zip("xyz", p):
            _set(out, f[k], float(v), DECIMALS["mm"])
        q = rapid_quaternion(R, np.array([f[k].value for k in ("q1", "q2", "q3", "q4")]))
        for k, v in zip(("q1", "q2", "q3", "q4"), q):
            _set(out, f[k], float(v), DECIMALS["quat"])
        if c.q is not None:
            for j, k in ((0, "cf1"), (3, "cf4"), (5, "cf6")):
                _set_int(out, f[k], int(math.floor(math.degrees(c.q[j]) / 90.0)))
    else:
        for k, v in zip(("x", "y", "z"), p / 1000.0):
            _set(out, f[k], float(v), DECIMALS["ur"])
        r = ur_rotvec(R, np.array([f[k].value for k in ("rx", "ry", "rz")]))
        for k, v in zip(("rx", "ry", "rz"), r):
            _set(out, f[k], float(v), DECIMALS["ur"])
    return out


def filtered_texts(program: Program, corrections: list[Correction]) -> tuple[str, str | None]:
    """The program's text with its corrected targets (and, for KRL, its .dat's)."""
    split = len(corrections) if program.split is None else program.split
    main = [ch for c in corrections[:split] for ch in target_changes(program.language, c)]
    text = rewrite(program.text, main)
    if program.dat is None:
        return text, None
    dat = [ch for c in corrections[split:] for ch in target_changes(program.language, c)]
    return text, rewrite(program.dat, dat)
