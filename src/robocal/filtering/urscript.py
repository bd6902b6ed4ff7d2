"""Universal Robots URScript: poses ``p[x, y, z, rx, ry, rz]`` (m; a rotation vector, rad) and
joint lists ``[j1, …, j6]`` (rad).

They are targets where a motion (movej, movel, movep, movec, servoj) takes them inline, or where
a variable is assigned one and a motion (or the get_inverse_kin inside one) names that
variable.  PolyScope's waypoints come as NAME_p (the pose) and NAME_q (the joints it was
taught at); the joints give the pose's configuration.  ``set_tcp(p[…])`` gives the TCP; offsets
(pose_trans operands), payloads and references are not targets; ``#`` starts a comment.
"""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from ..exceptions import InputError
from ..math.se3 import homogeneous
from .program import Program, Target, blank_comments, fields_in, line_of

_N = r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*"
POSE = re.compile(r"\bp\[(" + ",".join([_N] * 6) + r")\]")
JOINTS = re.compile(r"(?<![\w\]])\[(" + ",".join([_N] * 6) + r")\]")
_ASSIGN = re.compile(r"(?:\bglobal\s+|\blocal\s+)?\b(\w+)\s*=\s*$")
_MOVE = re.compile(r"\b(movej|movel|movep|movec|servoj)\s*\(")
_TCP = re.compile(r"\bset_tcp\s*\(\s*p\[(" + ",".join([_N] * 6) + r")\]")
POSE_KEYS = ("x", "y", "z", "rx", "ry", "rz")


def _code(text: str) -> str:
    """Comments (``#`` on) and strings blanked, lengths kept."""
    return blank_comments(text, "#")


def _statement(code: str, index: int) -> tuple[int, int]:
    """The line around a character index."""
    start = code.rfind("\n", 0, index) + 1
    end = code.find("\n", index)
    return start, len(code) if end < 0 else end


def _in_motion(code: str, start: int) -> bool:
    """Whether the character at ``start`` is inside the parentheses of a motion call."""
    s, _ = _statement(code, start)
    for m in _MOVE.finditer(code, s, start):
        depth = code.count("(", m.end() - 1, start) - code.count(")", m.end() - 1, start)
        if depth > 0:
            return True
    return False


def _arguments(code: str, open_paren: int) -> tuple[list[str], int]:
    """The top-level arguments of the call whose ``(`` is at ``open_paren``, and its end."""
    depth, i, parts, last = 1, open_paren + 1, [], open_paren + 1
    while i < len(code) and depth:
        c = code[i]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        elif c == "," and depth == 1:
            parts.append(code[last:i])
            last = i + 1
        i += 1
    parts.append(code[last:i - 1])
    return [p.strip() for p in parts], i


def _names_in_motions(code: str) -> tuple[set[str], set[str]]:
    """Variables a motion goes to: a bare argument, or get_inverse_kin's first argument (and its
    qnear, the joints it was taught at); and those it only reaches through another call
    (pose_trans operands: relative, left alone)."""
    names, indirect = set(), set()
    for m in _MOVE.finditer(code):
        args, _ = _arguments(code, m.end() - 1)
        for a in args[:2 if m.group(1) == "movec" else 1]:
            if re.fullmatch(r"[A-Za-z_]\w*", a):
                names.add(a)
            elif (k := re.match(r"get_inverse_kin\s*\(", a)):
                inner, _ = _arguments(a, k.end() - 1)
                names |= {x for x in (inner[0], *(v.split("=", 1)[1].strip() for v in inner[1:] if "=" in v))
                          if re.fullmatch(r"[A-Za-z_]\w*", x)}
            else:
                indirect |= set(re.findall(r"\b([A-Za-z_]\w*)\b", a))
    return names, indirect - names


def _changed_at_run_time(code: str, name: str) -> bool:
    assignments = len(re.findall(r"\b" + re.escape(name) + r"\s*=(?!=)", code))
    return assignments > 1 or re.search(r"\b" + re.escape(name) + r"\s*\[[^\]]*\]\s*=(?!=)", code) is not None


def load_urscript(text: str, source: str) -> Program:
    code = _code(text)
    moved, indirect = _names_in_motions(code)
    targets: list[Target] = []
    notes: list[str] = []
    spans = []
    for kind, pattern in (("pose", POSE), ("joints", JOINTS)):
        for m in pattern.finditer(code):
            s, _ = _statement(code, m.start())
            assign = _ASSIGN.search(code[s:m.start()])
            inline = _in_motion(code, m.start())
            if not inline and not (assign and assign.group(1) in moved):
                continue
            if not inline and _changed_at_run_time(code, assign.group(1)):
                notes.append(f"{assign.group(1)} is assigned again or changed element by element as the program runs: "
                             "left unchanged")
                continue
            f = fields_in(text[m.start(1):m.end(1)], m.start(1))
            line = line_of(text, m.start())
            name = assign.group(1) if assign and not inline else f"line {line}"
            if kind == "pose":
                items = dict(zip(POSE_KEYS, f))
                v = np.array([x.value for x in f])
                targets.append(Target(name, line, "pose", items, v[:3] * 1000.0,
                                      Rotation.from_rotvec(v[3:]).as_matrix()))
            else:
                items = {f"q{i + 1}": x for i, x in enumerate(f)}
                targets.append(Target(name, line, "joints", items, q=np.array([x.value for x in f])))
            spans.append(m.start())
    for name in sorted(indirect):
        if re.search(r"\b" + name + r"\s*=\s*p\[", code):
            notes.append(f"{name} reaches the motions only through another call (e.g. pose_trans): left unchanged")
    order = np.argsort(spans)
    targets = [targets[i] for i in order]
    if not targets:
        raise InputError("no targets found (p[…] poses or joint lists of motions)", source=source)
    tcps = [m for m in _TCP.finditer(code)]
    tool = None
    if tcps:
        v = np.array([x.value for x in fields_in(tcps[0].group(1))])
        tool = homogeneous(Rotation.from_rotvec(v[3:]).as_matrix(), v[:3] * 1000.0)
        if any(not np.allclose([x.value for x in fields_in(t.group(1))], v) for t in tcps[1:]):
            notes.append(f"{source} sets several TCPs; the first (line {line_of(text, tcps[0].start())}) is the TCP of "
                         "every target")
    # a PolyScope waypoint's pose takes the configuration of the joints it was taught at
    joints = {t.name: t for t in targets if t.kind == "joints"}
    for t in targets:
        if t.kind == "pose" and t.name.endswith("_p") and t.name[:-2] + "_q" in joints:
            t.taught = joints[t.name[:-2] + "_q"].q
    return Program(text, "urscript", source, targets, tool, notes)
