"""The program languages robocal filters, as a registry: one :class:`Language` entry per format.

An entry holds everything filtering needs to know of a language: its files (suffixes, the
reader, which finds targets, frames and configuration data), its writer (the new text of a
corrected target's numbers), the decoder of its configuration data into a
:class:`~robocal.inverse.solve.Request` and the encoder back from joints, its units and its
orientation convention.  :mod:`.correct` speaks to languages only through these entries, so adding
a language is one module that defines ``LANGUAGE`` and one line in :data:`MODULES`.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..math.so3 import matrix_quaternion, matrix_to_rpy
from .program import Field, Program, Target

#: the modules that define a language, in the order they are listed
MODULES = ("krl", "rapid", "urscript", "fanuc")


@dataclass(frozen=True)
class Language:
    """One program language.

    read(path, frames_file) → :class:`~.program.Program` (frames_file: a controller's file of
    frames given on the command line, or None); write(target, pose, q, config[, angles]) → the
    changes of a corrected target's numbers (pose: 4×4 mm in its user frame, for a Cartesian target;
    q: the controller's joints, rad, for a joint target; config: as :attr:`encode` gives it; angles:
    its orientation numbers from :attr:`write_angles`, where the language has it);
    request(target) → what its configuration data say of its solution, or None; encode(q,
    facts, config) → its configuration data at the controller's joints q (rad) with the arm's
    facts (``front``, ``elbow``, ``lower``: ±1, 0 on a boundary, where the target's own ``config``
    is kept)."""

    name: str
    title: str
    suffixes: tuple[str, ...]
    read: Callable
    write: Callable
    request: Callable
    encode: Callable
    #: units of positions and angles as the files write them
    units: str
    #: the rotation a Cartesian target's angles or quaternion stand for
    orientation: str
    #: where the language declares its TCPs and user frames
    frames: str
    #: a stamp's place and comment mark: (the line after which it goes, as a regular expression; the mark
    #: that begins a comment line), or None where a comment line would renumber the program (FANUC)
    stamp: tuple[str, str] | None = None
    #: the orientation numbers of many Cartesian targets at once, [(target, pose)] → one value a target (made
    #: in batched calls: one at a time, numpy's and scipy's small-array overhead was most of the writing),
    #: which write takes as ``angles``; None where write makes its own
    write_angles: Callable | None = None


def languages() -> dict[str, Language]:
    """name → :class:`Language`, every registered language."""
    return {name: importlib.import_module(f"{__package__}.{name}").LANGUAGE for name in MODULES}


def language_of(path: Path, fmt: str = "auto") -> Language:
    """The language a program is in: ``fmt``, or told by the file's suffix."""
    from .. import options as opt

    registry = languages()
    opt.choice(fmt, ("auto", *registry), "format", "program format")
    if fmt != "auto":
        return registry[fmt]
    suffix = Path(path).suffix.lower()
    for language in registry.values():
        if suffix in language.suffixes:
            return language
    known = ", ".join(f"{'/'.join(lang.suffixes)} {lang.title}" for lang in registry.values())
    raise InputError(f"cannot tell the language from the suffix {Path(path).suffix!r} ({known}): give --format",
                     source=path)


# --- writing helpers shared by the languages ----------------------------------------------------

#: decimals written at least: mm 3 (µm), deg 4, a quaternion 8, URScript's m and rad 7
DECIMALS = {"mm": 3, "deg": 4, "quat": 8, "ur": 7}


#: a Cartesian target's angles keep the file's own decimals where, rounded to them, they still turn the
#: tool to within this of the corrected orientation (half the filter's 0.001° check), deg
ANGLE_KEEP_DEG = 5e-4


def angle_decimals_many(fields: list[list[Field]], values: list) -> list[int]:
    """The decimals to write each Cartesian target's three angles (deg, R = Rz(c)·Ry(b)·Rx(a) of its
    ``values`` a, b, c) with: the file's own (the least of its ``fields``') where they carry the
    correction, else :data:`DECIMALS` ``deg``.  The rotations of all the targets are made in batched
    calls (the same bits as one at a time, which took a second for ten thousand targets)."""
    from ..math.so3 import rpy_to_matrix

    own = [min(f.decimals() for f in fs) for fs in fields]
    out = [DECIMALS["deg"]] * len(own)
    for d in sorted({o for o in own if o < DECIMALS["deg"]}):
        rows = [i for i, o in enumerate(own) if o == d]
        v = np.array([values[i] for i in rows], float)
        R, Q = rpy_to_matrix(np.radians(v)), rpy_to_matrix(np.radians(np.round(v, d)))
        for i, trace in zip(rows, np.trace(R @ np.swapaxes(Q, -1, -2), axis1=-2, axis2=-1).tolist()):
            turned = math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1.0) / 2.0))))
            out[i] = d if turned <= ANGLE_KEEP_DEG else DECIMALS["deg"]
    return out


def corrected_angles(items: list, keys: tuple[str, str, str]) -> list[tuple[tuple[float, float, float], int]]:
    """Per (target, pose) of ``items``, the pose's angles (a, b, c) of R = Rz(c)·Ry(b)·Rx(a), nearest the
    target's own fields ``keys`` (:func:`fixed_xyz`), and the decimals to write them in
    (:func:`angle_decimals_many`)."""
    values = [fixed_xyz(pose[:3, :3], tuple(t.fields[k].value for k in keys)) for t, pose in items]
    return list(zip(values, angle_decimals_many([[t.fields[k] for k in keys] for t, _ in items], values)))


def set_number(changes: list, f: Field, value: float, decimals: int) -> None:
    """Change a number unless the new value would not show at the precision written."""
    places = max(f.decimals(), decimals)  # the field's own decimals at least, counted once
    if not f.shows(value, places):
        changes.append((f, f.written(value, places)))


def set_text(changes: list, f: Field, text: str) -> None:
    if f.text != text:
        changes.append((f, text))


def near_turn(value: float, original: float) -> float:
    """``value`` (deg) plus the multiple of 360 that brings it nearest ``original``."""
    return value + 360.0 * round((original - value) / 360.0)


def fixed_xyz(R: np.ndarray, original: tuple[float, float, float]) -> tuple[float, float, float]:
    """Angles (deg) of R = Rz(c)·Ry(b)·Rx(a) as (a, b, c) nearest ``original`` among the two
    spellings and whole turns: KUKA's (C, B, A) and FANUC's (W, P, R) both are this rotation."""
    rx, ry, rz = np.degrees(matrix_to_rpy(R))
    best = None
    for a, b, c in ((rx, ry, rz), (rx + 180.0, 180.0 - ry, rz + 180.0)):
        abc = (near_turn(a, original[0]), near_turn(b, original[1]), near_turn(c, original[2]))
        d = sum((x - y) ** 2 for x, y in zip(abc, original))
        if best is None or d < best[0]:
            best = (d, abc)
    return best[1]


def quaternion(R: np.ndarray, original: np.ndarray) -> np.ndarray:
    """q1..q4 (scalar first) of R, with the sign of the original."""
    q = matrix_quaternion(R)
    return -q if q @ original < 0 else q


def rotation_vectors(items: list, keys: tuple[str, str, str]) -> list[np.ndarray]:
    """Per (target, pose) of ``items``, the rotation vector of the pose's rotation nearest the target's own
    fields ``keys`` (a turn of θ, or of θ − 2π the other way), the rotations converted in one batched call
    (the same bits as one at a time)."""
    from scipy.spatial.transform import Rotation  # only URScript's targets: its import is a large share of a run

    if not items:
        return []
    r = Rotation.from_matrix(np.array([pose[:3, :3] for _, pose in items])).as_rotvec()
    return [_nearest_turn(v, np.array([t.fields[k].value for k in keys])) for (t, _), v in zip(items, r)]


def _nearest_turn(r: np.ndarray, original: np.ndarray) -> np.ndarray:
    """The rotation vector r, or the same rotation turned θ − 2π the other way, whichever is nearer the original."""
    angle = np.linalg.norm(r)
    if angle > 1e-12:
        other = r * (1.0 - 2.0 * math.pi / angle)
        if np.linalg.norm(other - original) < np.linalg.norm(r - original):
            return other
    return r


def keep_on_boundary(new: int, fact: int, original: int | None) -> int:
    """A flag computed from a fact: the target's own where the fact is on its boundary (0)."""
    return original if fact == 0 and original is not None else new


__all__ = ["DECIMALS", "Language", "Program", "Target", "languages", "language_of"]


def stamped(text: str, language: Language, lines: list[str]) -> str:
    """``text`` with ``lines`` as comment lines at the top of its module or routine (after the line the
    language's stamp names, with that body's indentation and the file's line ends); as it is where the
    language takes no stamp."""
    import re

    if language.stamp is None or not lines:
        return text
    opener, mark = language.stamp
    newline = "\r\n" if "\r\n" in text else "\n"
    found = re.search(opener, text, re.MULTILINE)
    at = 0 if found is None else (text.find("\n", found.end()) + 1 or len(text))
    if at == len(text) and not text.endswith("\n"):
        text, at = text + newline, len(text) + len(newline)
    following = text[at:].split("\n", 1)[0]
    indent = following[:len(following) - len(following.lstrip(" \t"))] if found is not None else ""
    return text[:at] + "".join(f"{indent}{mark} {line}{newline}" for line in lines) + text[at:]
