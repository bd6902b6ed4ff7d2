"""ABB RAPID: robtarget and jointtarget data in a module (.mod, .modx, .prg, .sys).

A robtarget ``[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax_a,…,eax_f]]`` is a TCP pose (mm; a unit
quaternion, scalar first) in the work object of the motion; a jointtarget ``[[j1,…,j6],[eax_a,…]]``
the joints (deg).  They are targets where declared (``CONST|PERS|VAR robtarget NAME:=…``) and where
a motion takes them inline.  ``!`` starts a comment.

Frames: each motion names its tool (its last positional argument) and work object (``\\WObj:=``,
default ``wobj0``): the targets it reaches are in them.  ``tooldata`` gives a TCP
(``[robhold,[[x,y,z],[q]],…]``), ``wobjdata`` a work object (``uframe · oframe``); ``tool0`` is the
flange and ``wobj0`` the world.  A stationary tool (tooldata robhold FALSE), a work object the
robot holds or a mechanical unit moves (robhold TRUE, ufprog FALSE), a target computed by a
function of values the program computes and a target the motions reach in two frames are flagged.
``Offs(p, dx, dy, dz)`` and ``RelTool(p, dx, dy, dz [\\Rx:=…] [\\Ry:=…] [\\Rz:=…])`` of literal numbers
are offset motions of ``p`` (:class:`~.program.Offset`): ``p`` is corrected and they take its correction.

Configuration: cf1, cf4, cf6 are the quadrants ⌊q/90°⌋ of axes 1, 4 and 6; cfx is 4 × (wrist
centre behind axis 1) + 2 × (wrist centre behind the lower arm) + (axis 5 negative).
"""

from __future__ import annotations

import bisect
import math
import re
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..inverse.configuration import TOLERANCE_RAD
from ..inverse.solve import Request
from ..math.se3 import homogeneous
from ..math.so3 import quaternion_matrix, rot_x, rot_y, rot_z
from .language import DECIMALS, Language, keep_on_boundary, quaternion, set_number, set_text
from .program import (
    NUMBER,
    SPACED_NUMBER,
    Field,
    Lines,
    Offset,
    Program,
    ProgramFile,
    Target,
    blank_comments,
    field_of,
    fields_in,
    in_text_order,
    keyword_matches,
    matches_at,
    read_file,
    split_top,
)

_N = SPACED_NUMBER
_LIST = lambda k: r"\[" + ",".join([_N] * k) + r"\]"  # noqa: E731
ROBTARGET = re.compile(r"\[\s*" + _LIST(3) + r"\s*,\s*" + _LIST(4) + r"\s*,\s*" + _LIST(4) + r"\s*,\s*" + _LIST(6)
                       + r"\s*\]")
JOINTTARGET = re.compile(r"\[\s*" + _LIST(6) + r"\s*,\s*" + _LIST(6) + r"\s*\]")
#: a declaration ``[CONST|PERS|VAR] robtarget NAME :=``, ending where its value begins
_DECL = re.compile(r"\b(robtarget|jointtarget)\s+(\w+)\s*:=\s*", re.I)
_TOOL = re.compile(r"\btooldata\s+(\w+)\s*:=\s*\[\s*(TRUE|FALSE)\s*,\s*\[\s*(" + _LIST(3) + r")\s*,\s*(" + _LIST(4)
                   + r")", re.I)
_WOBJ = re.compile(r"\bwobjdata\s+(\w+)\s*:=\s*\[\s*(TRUE|FALSE)\s*,\s*(TRUE|FALSE)\s*,[^,\[]*,\s*\[\s*(" + _LIST(3)
                   + r")\s*,\s*(" + _LIST(4) + r")\s*\]\s*,\s*\[\s*(" + _LIST(3) + r")\s*,\s*(" + _LIST(4) + r")",
                   re.I)
_MOVE = re.compile(r"\b(Move(?:L|J|C|AbsJ|LDO|JDO|CDO|LSync|JSync|CSync|Ext)?)\b([^;]*);", re.I)
#: what an aggregate argument of a motion reads as once its brackets are taken out
AGGREGATE = "\u00a7"
KEYS_POSE = ("x", "y", "z", "q1", "q2", "q3", "q4", "cf1", "cf4", "cf6", "cfx")
#: a quaternion's norm may miss 1 by this much (its printed decimals' rounding)
QUATERNION_NORM = 1e-6


def _numbers(text: str) -> np.ndarray:
    return np.array([f.value for f in fields_in(text)])


def _rotations(q: np.ndarray, source: str, lines: list[int]) -> np.ndarray:
    """R (n, 3, 3) of quaternions (n, 4) as written, each of norm 1 to its decimals' rounding."""
    norm = np.linalg.norm(q, axis=-1)
    bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUATERNION_NORM))
    if bad.size:
        k = int(bad[0])
        raise InputError(f"the quaternion [{', '.join(f'{v:g}' for v in q[k])}] has norm {norm[k]:.9g}, not 1 "
                         f"(within {QUATERNION_NORM:g})", source=source, where=f"line {lines[k]}")
    return quaternion_matrix(q / norm[:, None])


def _frame(xyz: str, quat: str, source: str, line: int) -> np.ndarray:
    return homogeneous(_rotations(_numbers(quat)[None], source, [line])[0], _numbers(xyz))


#: the optional arguments of a motion that leave its target as written (timing, zones, loads, its
#: work object); any other (``\\Corr``: a path correction written as the program runs) flags it
HARMLESS_SWITCHES = frozenset(("conc", "id", "v", "t", "z", "inpos", "tload", "wobj", "noeoffs", "movestepon",
                               "signal", "time", "dodelay", "posn"))


_INNERMOST = re.compile(r"\[[^\[\]]*\]")
_WOBJ_ARG = re.compile(r"\\WObj\s*:=\s*(\w+)", re.I)
_SWITCH = re.compile(r"\\(\w+)")
_OPTIONAL = re.compile(r"\\\w+(?:\s*:=\s*[\w\[\]]+)?")
_NAME = re.compile(r"[A-Za-z_]\w*")


#: RelTool's own optional arguments, kept away from the motion's switches while they are read
_SHIELD = "\u00b6"


_RELTOOL = re.compile(r"RelTool\s*\([^;]*?\)", re.I)
_OFFSET = re.compile(r"\s*(Offs|RelTool)\s*\((.*)\)\s*", re.I | re.S)


def _protected(arguments: str) -> str:
    """A motion's arguments with the backslashes inside its RelTool(…) calls shielded (``\\Rz:=25`` is
    RelTool's, not the motion's)."""
    if "reltool" not in arguments.lower():
        return arguments
    return _RELTOOL.sub(lambda m: m.group().replace("\\", _SHIELD), arguments)


def _offset(argument: str, line: int) -> tuple[str, Offset] | None:
    """``Offs(NAME, dx, dy, dz)`` or ``RelTool(NAME, dx, dy, dz [\\Rx:=a] [\\Ry:=b] [\\Rz:=c])`` of literal
    numbers (mm, deg): the target's name and the offset; None for anything else (a variable offset
    changes the target as the program runs)."""
    m = _OFFSET.fullmatch(argument) if "(" in argument else None
    if m is None:
        return None
    parts = split_top(m.group(2))
    if len(parts) != 4 or not _NAME.fullmatch(parts[0].strip()):
        return None
    last, _, rest = parts[3].partition(_SHIELD)
    values = [p.strip() for p in (*parts[1:3], last)]
    if not all(re.fullmatch(NUMBER, v) for v in values):
        return None
    d = np.array([float(v) for v in values])
    R = np.eye(3)
    if m.group(1).lower() == "offs":
        if rest:
            return None
        kind = "frame"
    else:
        kind, angles = "tool", {"rx": 0.0, "ry": 0.0, "rz": 0.0}
        for option in filter(None, (_SHIELD + rest).split(_SHIELD)):
            o = re.fullmatch(r"\s*(Rx|Ry|Rz)\s*:=\s*(" + NUMBER + r")\s*", option, re.I)
            if o is None:
                return None
            angles[o.group(1).lower()] = math.radians(float(o.group(2)))
        # ABB: about the tool's x, then its y, then its z (each about the axes the last one left)
        R = rot_x(angles["rx"]) @ rot_y(angles["ry"]) @ rot_z(angles["rz"])
    return parts[0].strip(), Offset(kind, homogeneous(R, d), line, argument.strip().replace(_SHIELD, "\\"))


def _arguments(arguments: str) -> tuple[list[str], str | None, str | None, list[str]]:
    """The positional arguments of a motion (aggregates as AGGREGATE), its tool (the last positional
    one), its work object (``\\WObj:=``) and its optional arguments robocal does not take as
    leaving the target as written."""
    flat = arguments
    while "[" in flat:  # aggregates out, innermost first
        flat = _INNERMOST.sub(AGGREGATE, flat)
    wobj = _WOBJ_ARG.search(flat)
    odd = [s for s in _SWITCH.findall(flat) if s.lower() not in HARMLESS_SWITCHES]
    flat = _OPTIONAL.sub("", flat)  # switches and optional arguments
    positional = [a.strip() for a in split_top(flat) if a.strip()]
    tool = positional[-1] if positional and _NAME.fullmatch(positional[-1]) else None
    return positional, tool, wobj.group(1) if wobj else "wobj0", odd


def read(path: Path, frames_file: Path | None = None) -> Program:
    if frames_file is not None:
        raise InputError("RAPID declares its tools and work objects in the module: --controller-frames is for KRL",
                         option="controller_frames")
    text, enc = read_file(path)
    source = str(path)
    code = blank_comments(text, "!")
    lines = Lines(text)
    program = Program("rapid", source, [ProgramFile(source, text, enc)], [])
    program.tools["tool0"], program.users["wobj0"] = np.eye(4), np.eye(4)
    for m in keyword_matches(_TOOL, code, ("tooldata",)):
        program.tools[m.group(1)] = _frame(m.group(3), m.group(4), source, lines.of(m.start()))
        if m.group(2).upper() == "FALSE":
            program.missing[m.group(1)] = "a stationary tool (robhold FALSE): the robot holds the work object"
            del program.tools[m.group(1)]
    for m in keyword_matches(_WOBJ, code, ("wobjdata",)):
        line = lines.of(m.start())
        program.users[m.group(1)] = _frame(m.group(4), m.group(5), source, line) @ \
            _frame(m.group(6), m.group(7), source, line)
        if m.group(2).upper() == "TRUE" or m.group(3).upper() == "FALSE":
            program.missing[m.group(1)] = "a work object the robot holds or a mechanical unit moves"
            del program.users[m.group(1)]
    uses: dict[str, list] = {}
    spans = []
    offsets: dict[str, list[Offset]] = {}
    for m in keyword_matches(_MOVE, code, ("move",)):
        positional, tool, wobj, odd = _arguments(_protected(m.group(2)))
        line = lines.of(m.start())
        why = None if not odd else f"its motion (line {line}) has \\{odd[0]}, which robocal does not take as " \
            "leaving the target as written" + (" (a path correction written as the program runs)"
                                               if odd[0].lower() == "corr" else "")
        reach = positional[:2] if m.group(1).lower().startswith("movec") else positional[:1]
        for a in reach:
            offset = _offset(a, line)
            if _NAME.fullmatch(a):
                uses.setdefault(a.lower(), []).append((tool, wobj, line, why))
            elif offset is not None:  # Offs(p10, 0, 0, 50): p10 is corrected, and the motion takes its correction
                uses.setdefault(offset[0].lower(), []).append((tool, wobj, line, why))
                offsets.setdefault(offset[0].lower(), []).append(offset[1])
            elif a != AGGREGATE:
                program.targets.append(Target(f"line {line}", line, "pose", {},
                                              unsupported=f"the target {a.strip()} is computed as the program runs"))
                call = re.match(r"(\w+)\s*\(\s*([A-Za-z_]\w*)\b", a)
                if call:  # Offs(p10, …), RelTool(p10, …): p10 is reached only through the function
                    uses.setdefault(call.group(2).lower(), []).append(
                        (tool, wobj, line, f"a motion reaches it through {call.group(1)}() (line {line}), which "
                                           "changes it as the program runs"))
        spans.append((m.start(2), m.end(2), tool, wobj, line, why))
    _targets(code, program, spans, uses, lines)
    for t in program.targets:
        t.offsets = offsets.get(t.name.lower(), [])
    declared = {t.name.lower() for t in program.targets}
    for name, used in uses.items():  # a motion to a target this module does not hold: said, never skipped
        if name not in declared:
            program.targets.append(Target(name, used[0][2], "pose", {}, unsupported="not declared in this module "
                                          "(another module of the task, or computed as the program runs): robocal "
                                          "corrects the targets the module holds"))
    if not program.targets:
        raise InputError("no targets found (robtarget or jointtarget data)", source=source)
    program.targets.sort(key=in_text_order)
    return program


#: a robtarget or jointtarget with each of its numbers captured (a large module has tens of thousands)
_CAPTURED = r"\s*(" + NUMBER + r")\s*"
_CAPTURED_LIST = lambda k: r"\[" + ",".join([_CAPTURED] * k) + r"\]"  # noqa: E731
_ROBTARGET_FIELDS = re.compile(r"\[\s*" + _CAPTURED_LIST(3) + r"\s*,\s*" + _CAPTURED_LIST(4) + r"\s*,\s*"
                               + _CAPTURED_LIST(4) + r"\s*,\s*" + _LIST(6) + r"\s*\]")
_JOINTTARGET_FIELDS = re.compile(r"\[\s*" + _CAPTURED_LIST(6) + r"\s*,\s*" + _LIST(6) + r"\s*\]")


#: where a robtarget or jointtarget can begin: a bracket that opens another
_NESTED = re.compile(r"\[(?=\s*\[)")


def _targets(code: str, program: Program, spans: list, uses: dict, lines: Lines) -> None:
    everything = {(u[0], u[1]) for us in uses.values() for u in us}
    starts = [sp[0] for sp in spans]  # motions in order of the text
    poses: list[Target] = []
    # value's start → its declaration
    declarations = {m.end(): m for m in keyword_matches(_DECL, code, ("robtarget", "jointtarget"))}
    numbers: list[list[float]] = []  # the poses' numbers, made arrays once at the end
    robtargets: set[int] = set()
    for kind, pattern, keys in (("pose", _ROBTARGET_FIELDS, KEYS_POSE),
                                ("joints", _JOINTTARGET_FIELDS, tuple(f"q{i + 1}" for i in range(6)))):
        word = "robtarget" if kind == "pose" else "jointtarget"
        # both begin "[[" (spaces between); where a robtarget's three numbers stand, six cannot
        found = pattern.finditer(code) if kind == "pose" else matches_at(pattern, code, (
            i for i in (m.start() for m in _NESTED.finditer(code)) if i not in robtargets))
        for m in found:
            texts = m.groups()
            items = dict(zip(keys, [field_of((a, b, s)) for (a, b), s in zip(m.regs[1:], texts)]))
            values = list(map(float, texts))
            at = m.start()
            decl = declarations.get(at)
            line = lines.of(at)
            declared = decl is not None and decl.group(1).lower() == word
            name = decl.group(2) if declared else f"line {line}"
            if kind == "pose":
                t = Target(name, line, "pose", items, config=dict(zip(KEYS_POSE[7:], map(int, values[7:]))))
                poses.append(t)
                numbers.append(values)
                robtargets.add(at)
            else:
                t = Target(name, line, "joints", items, q=np.radians(values))
            if declared:
                used = uses.get(name.lower(), [])
            else:
                k = bisect.bisect_right(starts, at) - 1
                used = [(s[2], s[3], s[4], s[5]) for s in spans[k:k + 1] if k >= 0 and at < s[1]]
            frames = {(u[0], u[1]) for u in used}
            said = next((u[3] for u in used if u[3]), None)
            if said:
                t.unsupported = said
            elif len(frames) == 1:
                t.tool, t.user = next(iter(frames))
            elif len(frames) > 1:
                listed = ", ".join(f"{a} in {b}" for a, b in sorted(frames, key=str))
                t.unsupported = f"the motions reach it with different tools or work objects ({listed})"
            elif len(everything) == 1:
                t.tool, t.user = next(iter(everything))
            elif everything:
                t.unsupported = "no motion of the module reaches it, and its motions use several tools or work objects"
            program.targets.append(t)
    if poses:  # positions and quaternions, all at once
        V = np.array(numbers)
        P = V[:, :3].copy()
        R = _rotations(V[:, 3:7], program.source, [t.line for t in poses])
        for t, p, r in zip(poses, P, R):
            t.position, t.rotation = p, r
    read_names = {t.name for t in program.targets}
    for m in declarations.values():
        if m.group(2) not in read_names:
            raise InputError(f"{m.group(1)} {m.group(2)}: its value is not [[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],"
                             "[eax…]] (robtarget) or [[j1,…,j6],[eax…]] (jointtarget) of numbers",
                             source=program.source, where=f"line {lines.of(m.start())}")


def _quadrant(angle: float, original: int | None) -> int:
    """⌊angle/90°⌋, the target's own quadrant where the angle lies on a boundary."""
    quarter = angle / (math.pi / 2)
    nearest = round(quarter)
    if abs(quarter - nearest) * (math.pi / 2) <= TOLERANCE_RAD and original in (nearest - 1, nearest):
        return original
    return int(math.floor(quarter))


def request(t: Target) -> Request | None:
    c = t.config
    if t.kind != "pose" or "cf1" not in c:
        return None
    quarter = math.pi / 2
    joints: list = [None] * 6
    for j, k in ((0, "cf1"), (3, "cf4"), (5, "cf6")):
        joints[j] = (c[k] * quarter, (c[k] + 1) * quarter)
    cfx = c["cfx"]
    joints[4] = (-np.inf, 0.0) if cfx & 1 else (0.0, np.inf)
    return Request(front=-1 if cfx & 4 else 1, lower=-1 if cfx & 2 else 1, joints=tuple(joints))


def encode(q: np.ndarray, facts: dict | None, config: dict) -> dict:
    if "cf1" not in config:
        return {}
    out = {k: _quadrant(float(q[j]), config.get(k)) for j, k in ((0, "cf1"), (3, "cf4"), (5, "cf6"))}
    x0 = config.get("cfx", 0)
    behind = keep_on_boundary(int(facts["front"] < 0), facts["front"], x0 >> 2 & 1) if facts else x0 >> 2 & 1
    lower = keep_on_boundary(int(facts["lower"] < 0), facts["lower"], x0 >> 1 & 1) if facts else x0 >> 1 & 1
    wrist = (x0 & 1) if abs(q[4]) <= TOLERANCE_RAD else int(q[4] < 0)
    out["cfx"] = behind << 2 | lower << 1 | wrist
    return out


def write(t: Target, pose: np.ndarray | None, q: np.ndarray | None, config: dict) -> list[tuple[Field, str]]:
    f, out = t.fields, []
    if t.kind == "joints":
        for i in range(len(q)):
            set_number(out, f[f"q{i + 1}"], math.degrees(q[i]), DECIMALS["deg"])
        return out
    for k, v in zip("xyz", pose[:3, 3]):
        set_number(out, f[k], float(v), DECIMALS["mm"])
    quat = quaternion(pose[:3, :3], np.array([float(f[k].text) for k in ("q1", "q2", "q3", "q4")]))
    for k, v in zip(("q1", "q2", "q3", "q4"), quat):
        set_number(out, f[k], float(v), DECIMALS["quat"])
    for k, v in config.items():
        set_text(out, f[k], str(v))
    return out


LANGUAGE = Language(
    name="rapid", title="ABB RAPID", suffixes=(".mod", ".modx", ".prg", ".sys"), read=read, write=write,
    request=request, encode=encode, units="mm, deg", orientation="unit quaternion [q1 q2 q3 q4], scalar first",
    frames="tooldata and wobjdata (uframe · oframe) the motions name; tool0, wobj0",
    stamp=(r"^\s*MODULE\b[^\n]*", "!"))
