"""ABB RAPID: robtarget and jointtarget data in a module (.mod, .prg).

A robtarget ``[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax_a,…,eax_f]]`` is a TCP pose (mm; the
quaternion scalar first) in the work object of the motion; a jointtarget
``[[j1,…,j6],[eax_a,…]]`` the joints (deg).  They are targets where declared
(``CONST|PERS|VAR robtarget NAME:=…``) and where a motion takes them inline.  cf1, cf4, cf6
are the quadrants of joints 1, 4 and 6 (⌊q/90°⌋); cfx, the arm's configuration, is kept.
``tooldata`` gives the TCP ([robhold,[[x,y,z],[q]],…]) of the tool the motions name, and a
``wobjdata`` the work object (user frame · object frame) they are in; ``!`` starts a comment.
"""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from ..exceptions import InputError
from ..math.se3 import homogeneous
from .program import Program, Target, blank_comments, fields_in, first_of, line_of

_N = r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*"
_LIST = lambda k: r"\[" + ",".join([_N] * k) + r"\]"  # noqa: E731
ROBTARGET = re.compile(r"\[\s*" + _LIST(3) + r"\s*,\s*" + _LIST(4) + r"\s*,\s*" + _LIST(4) + r"\s*,\s*" + _LIST(6)
                       + r"\s*\]")
JOINTTARGET = re.compile(r"\[\s*" + _LIST(6) + r"\s*,\s*" + _LIST(6) + r"\s*\]")
_DECL = re.compile(r"\b(?:CONST|PERS|VAR|LOCAL\s+\w+)?\s*(robtarget|jointtarget)\s+(\w+)\s*:=\s*$", re.I)
_TOOL = re.compile(r"\btooldata\s+(\w+)\s*:=\s*\[\s*\w+\s*,\s*\[\s*(" + _LIST(3) + r")\s*,\s*(" + _LIST(4) + r")", re.I)
_WOBJ = re.compile(r"\bwobjdata\s+(\w+)\s*:=\s*\[\s*\w+\s*,\s*\w+\s*,\s*,\s*\[\s*(" + _LIST(3)
                   + r")\s*,\s*(" + _LIST(4) + r")\s*\]\s*,\s*\[\s*(" + _LIST(3) + r")\s*,\s*(" + _LIST(4) + r")",
                   re.I)
_MOVE = re.compile(r"\bMove(?:L|J|C|AbsJ|LDO|JDO|LSync|JSync|Ext)?\b([^;]*);", re.I)
KEYS_POSE = ("x", "y", "z", "q1", "q2", "q3", "q4", "cf1", "cf4", "cf6", "cfx")


def _numbers(text: str) -> np.ndarray:
    return np.array([f.value for f in fields_in(text)])


def _frame(xyz: str, quat: str) -> np.ndarray:
    q = _numbers(quat)
    return homogeneous(Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix(), _numbers(xyz))


def _code(text: str) -> str:
    """The text with comments (``!`` to the end of the line) and strings blanked, same length."""
    return blank_comments(text, "!")


def _tool_and_wobj(arguments: str) -> tuple[str | None, str | None]:
    """The tool (the last positional argument) and the work object (``\\WObj:=``) of a motion."""
    flat = arguments
    while "[" in flat:  # aggregates out, innermost first
        flat = re.sub(r"\[[^\[\]]*\]", "0", flat)
    wobj = re.search(r"\\WObj\s*:=\s*(\w+)", flat, re.I)
    flat = re.sub(r"\\\w+(?:\s*:=\s*\w+)?", "", flat)  # switches and optional arguments
    positional = [a.strip() for a in flat.split(",") if a.strip()]
    tool = positional[-1] if positional and re.fullmatch(r"[A-Za-z_]\w*", positional[-1]) else None
    return tool, wobj.group(1) if wobj else None


def load_rapid(text: str, source: str) -> Program:
    code = _code(text)
    targets: list[Target] = []
    notes: list[str] = []
    for m in ROBTARGET.finditer(code):
        f = fields_in(text[m.start():m.end()], m.start())
        items = dict(zip(KEYS_POSE, f[:11]))
        decl = _DECL.search(code[max(0, m.start() - 200):m.start()])
        line = line_of(text, m.start())
        name = decl.group(2) if decl and decl.group(1).lower() == "robtarget" else f"line {line}"
        q = np.array([items[k].value for k in ("q1", "q2", "q3", "q4")])
        R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
        config = {k: int(items[k].value) for k in ("cf1", "cf4", "cf6", "cfx")}
        targets.append(Target(name, line, "pose", items, np.array([items[k].value for k in "xyz"]), R,
                              config=config))
    for m in JOINTTARGET.finditer(code):
        f = fields_in(text[m.start():m.end()], m.start())
        items = {f"q{i + 1}": f[i] for i in range(6)}
        decl = _DECL.search(code[max(0, m.start() - 200):m.start()])
        line = line_of(text, m.start())
        name = decl.group(2) if decl and decl.group(1).lower() == "jointtarget" else f"line {line}"
        targets.append(Target(name, line, "joints", items, q=np.radians([items[f"q{i + 1}"].value for i in range(6)])))
    targets.sort(key=lambda t: min(x.start for x in t.fields.values()))
    read = {t.name for t in targets}
    for m in re.finditer(r"\b(robtarget|jointtarget)\s+(\w+)\s*:=", code, re.I):
        if m.group(2) not in read:
            raise InputError(f"{m.group(1)} {m.group(2)}: its value is not [[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],"
                             "[eax…]] (robtarget) or [[j1,…,j6],[eax…]] (jointtarget) of numbers", source=source,
                             where=f"line {line_of(text, m.start())}")
    if not targets:
        raise InputError("no targets found (robtarget or jointtarget data)", source=source)
    tools = {m.group(1): _frame(m.group(2), m.group(3)) for m in _TOOL.finditer(code)}
    wobjs = {m.group(1): _frame(m.group(2), m.group(3)) @ _frame(m.group(4), m.group(5)) for m in _WOBJ.finditer(code)}
    # the unit name string of a wobjdata is blanked with the comments: its comma stays
    used = [_tool_and_wobj(m.group(1)) for m in _MOVE.finditer(code)]
    used_tools = {t for t, _ in used if t}
    used_wobjs = {w for _, w in used if w}
    tool, flange = first_of(used_tools, tools, "tool0", "tool", source, notes,
                            "the TCP is --tool's or the robot file's")
    tool = np.eye(4) if flange else tool
    base, _ = first_of(used_wobjs, wobjs, "wobj0", "work object", source, notes,
                       "targets are taken in the robot's base frame")
    return Program(text, "rapid", source, targets, tool, notes, base)
