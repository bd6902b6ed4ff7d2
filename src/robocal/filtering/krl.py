"""KUKA KRL: targets in a .src and its .dat.

Aggregates ``{X …, Y …, Z …, A …, B …, C …, S …, T …, E1 …}`` (E6POS, POS; mm and degrees,
R = Rz(A) Ry(B) Rx(C)) and ``{A1 …, …, A6 …, E1 …}`` (E6AXIS, AXIS; degrees) are targets where
a ``DECL E6POS|POS|E6AXIS|AXIS`` declares them, where a motion (PTP, LIN, CIRC, SPTP, SLIN,
SCIRC) takes them inline, and where a variable is assigned one.  ``$TOOL`` / ``TOOL_DATA[n]``
aggregates give the TCP and ``$BASE`` / ``BASE_DATA[n]`` the base frame the targets are in; FRAME
declarations, relative motions (``…_REL``) and everything after ``;`` on a line (comments,
folds) are left alone.  S (status) and T (turn) name the configuration: T's bit i is set when
joint i + 1 is negative.
"""

from __future__ import annotations

import re

import numpy as np

from ..exceptions import InputError
from ..math.se3 import homogeneous
from ..math.so3 import rpy_to_matrix
from .program import Field, Program, Target, line_of

_AGGREGATE = re.compile(r"\{([^{}]*)\}")
_ITEM = re.compile(r"([A-Za-z_$][\w$]*)\s+([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_DECL = re.compile(r"\bDECL\s+(?:GLOBAL\s+)?(E6POS|POS|E6AXIS|AXIS|FRAME)\s+(\w+)\s*=\s*$", re.I)
_MOTION = re.compile(r"\b(PTP|LIN|CIRC|SPTP|SLIN|SCIRC)(_REL)?\s+$", re.I)
_ASSIGN = re.compile(r"(\$?[\w\[\]]+)\s*=\s*$")
POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")
JOINT_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")


def _items(body: str, offset: int) -> dict[str, Field]:
    """KEY value pairs of an aggregate body (an optional ``TYPE:`` prefix skipped)."""
    out = {}
    for m in _ITEM.finditer(body):
        key = m.group(1).upper()
        out[key] = Field(offset + m.start(2), offset + m.end(2), m.group(2))
    return out


def pose_matrix(f: dict[str, Field]) -> tuple[np.ndarray, np.ndarray]:
    """Position mm and rotation of X Y Z A B C."""
    abc = np.radians([f["C"].value, f["B"].value, f["A"].value])  # rpy: R = Rz(A) Ry(B) Rx(C)
    return np.array([f[k].value for k in "XYZ"]), rpy_to_matrix(abc)


def _frame(f: dict[str, Field]) -> np.ndarray:
    p, R = pose_matrix(f)
    return homogeneous(R, p)


def parse_krl(text: str, source: str, targets: list[Target], notes: list[str]) -> tuple[np.ndarray | None,
                                                                                         np.ndarray | None]:
    """Targets of one KRL file appended to ``targets``; its TCP and base frame (4×4) if it sets them."""
    frames: dict[str, np.ndarray] = {}
    start = 0
    for raw in text.splitlines(keepends=True):
        code = raw.split(";", 1)[0]  # KRL comments and folds run from ';' to the end of the line
        for m in _AGGREGATE.finditer(code):
            before = code[:m.start()]
            body_offset = start + m.start(1)
            items = _items(m.group(1), body_offset)
            is_pose = all(k in items for k in POSE_KEYS)
            is_joints = all(k in items for k in JOINT_KEYS)
            decl, motion, assign = _DECL.search(before), _MOTION.search(before), _ASSIGN.search(before)
            line = line_of(text, start + m.start())
            if not (is_pose or is_joints):
                if decl and decl.group(1).upper() != "FRAME":
                    keys = JOINT_KEYS if "AXIS" in decl.group(1).upper() else POSE_KEYS
                    missing = [k for k in keys if k not in items]
                    raise InputError(f"{decl.group(1)} {decl.group(2)}: no number for {', '.join(missing)}",
                                     source=source, where=f"line {line}")
                continue
            if assign and not decl:
                target = assign.group(1).upper()
                kind = "tool" if target.startswith(("$TOOL", "TOOL_DATA")) else \
                    ("base" if target.startswith(("$BASE", "BASE_DATA")) else None)
                if kind and is_pose:
                    T, first = _frame(items), frames.get(kind)
                    if first is not None and not np.allclose(first, T):
                        notes.append(f"{source} line {line}: another {kind} ({assign.group(1)}); the first one is "
                                     "taken for every target")
                    frames.setdefault(kind, T)
                    continue
                if target.startswith("$"):
                    continue
            if decl and decl.group(1).upper() == "FRAME":
                continue  # a frame (a base or tool), not a target
            if motion and motion.group(2):
                notes.append(f"{source} line {line}: a relative motion ({motion.group(1)}_REL) is left as it is")
                continue
            if not (decl or motion or assign):
                continue
            name = decl.group(2) if decl else (assign.group(1) if assign and not motion else f"line {line}")
            if is_pose:
                p, R = pose_matrix(items)
                config = {k: int(items[k].value) for k in ("S", "T") if k in items}
                targets.append(Target(name, line, "pose", items, p, R, config=config))
            else:
                q = np.radians([items[k].value for k in JOINT_KEYS])
                targets.append(Target(name, line, "joints", items, q=q))
        start += len(raw)
    return frames.get("tool"), frames.get("base")


def load_krl(src_text: str, dat_text: str | None, source: str) -> Program:
    """A KRL program: its .src and, when there is one, its .dat (targets of both)."""
    targets: list[Target] = []
    notes: list[str] = []
    tool, base = parse_krl(src_text, source, targets, notes)
    src_count = len(targets)
    if dat_text is not None:
        t2, b2 = parse_krl(dat_text, source.rsplit(".", 1)[0] + ".dat", targets, notes)
        tool, base = tool if tool is not None else t2, base if base is not None else b2
    for t in targets[src_count:]:
        t.name = f"{t.name} (.dat)" if t.name.startswith("line ") else t.name
    if not targets:
        raise InputError("no targets found (E6POS, POS, E6AXIS or AXIS aggregates)", source=source)
    return Program(src_text, "krl", source, targets, tool, notes, base, dat_text, src_count)


