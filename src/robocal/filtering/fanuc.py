"""FANUC TP in its text form (``.ls``): the positions of the ``/POS`` section.

A Cartesian position ``P[n]{ GP1: UF : u, UT : t, CONFIG : 'F U T, t1, t4, t6', X = … mm, Y, Z,
W = … deg, P, R };`` is the TCP of tool frame t in user frame u, R = Rz(R)·Ry(P)·Rx(W); a joint
position lists ``J1 = … deg, …``.  Other motion groups (``GP2:``) and extended axes stay as they are.
The motions of ``/MN`` (``J``, ``L``, ``C``, ``A``) name them; a motion through a position register
(``PR[n]``) or with ``Offset``, ``Tool_Offset``, ``INC``, ``VOFFSET`` or ``VTOOL`` changes its
target as the program runs, so it is flagged and its position left unchanged.

Frames: UF and UT are numbered frames the controller keeps (``$MNUFRAME``, ``$MNUTOOL``), not the
program: robocal is given them (``--user-frame N=…``, ``--tool N=…``); UF 0 is the world and UT 0
the faceplate.  A position taught in a frame robocal was not given is flagged.

Configuration: F (flip) when J5 > 0, N when J5 < 0; U/D the elbow up or down; T/B the wrist
centre in front of or behind the J1 axis; t1, t4, t6 the turns of J1, J4, J6 (0 for
(−180°, 180°], 1 for (180°, 540°], …).  Joint values are the controller's: its J3 is the forearm's
angle against the horizontal, so a robot file says ``[controller] coupling = [{joint = 3, plus =
2, factor = 1.0}]`` for the model's joint 3 to be J2 + J3 (see MODEL §5).
"""

from __future__ import annotations

import math
import re
from functools import partial
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..inverse.configuration import TOLERANCE_RAD
from ..inverse.solve import Request
from .language import DECIMALS, Language, corrected_angles, set_number, set_text
from .program import NUMBER, Field, Lines, Program, ProgramFile, Target, field_of, read_file, turn_by_angles

_POSITION = re.compile(r"^P\[(\d+)(?::\s*\"?([^\]\"]*)\"?)?\]\s*\{(.*?)\};", re.S | re.M)
_GROUP = re.compile(r"\bGP(\d+)\s*:")
_VALUE = re.compile(r"\b(X|Y|Z|W|P|R|J\d|E\d)\s*=\s*(" + NUMBER + r")\s*(mm|deg)?")
_FRAMES = re.compile(r"\bUF\s*:\s*(\d+|F)\s*,\s*UT\s*:\s*(\d+|F)", re.I)
_CONFIG = re.compile(r"CONFIG\s*:\s*'([^']*)'")
_LETTER = re.compile(r"[FNUDTB]")
_TURN = re.compile(r"-?\d+")
_UNTAUGHT = re.compile(r"\*{3,}")
_NUMBERED = re.compile(r"^\s*(\d+)\s*:(.*)$")
_CONTINUED = re.compile(r"^\s*:(.*)$")
_REF = r"\[\s*(?:\d+|R\[\d+(?::[^\]]*)?\])\s*(?::[^\]]*)?\]"  # [n], [n:comment], [R[m]] (indirect)
#: a motion instruction: its kind, its position(s) (a circular motion names two) and the rest
_INSTRUCTION = re.compile(r"^\s*([JLCA])\s+((?:PR|P)" + _REF + r")(?:\s+((?:PR|P)" + _REF + r"))?(.*)$", re.S)
_POSITION_REF = re.compile(r"(PR|P)\[\s*(\d+|R\[\d+(?::[^\]]*)?\])\s*(?::[^\]]*)?\]")
_REG = r"R\[\d+(?::[^\]]*)?\]"
_LABEL = r"LBL\[\d+(?::[^\]]*)?\]"
_PR = r"PR\[\d+(?::[^\]]*)?\]"
_SIGNAL = r"(?:DO|RO|GO|AO|F|UO|SO|R)\[\d+(?::[^\]]*)?\]\s*=\s*[\w.+-]+(?:\([^)]*\))?"
#: the options of a motion that leave its target as written (a speed, a termination, timing and
#: application options): anything else on a motion line is flagged, its target left as written
_HARMLESS = re.compile(
    r"\s*(?:"
    r"(?:\d+(?:\.\d*)?|\.\d+|" + _REG + r")\s*(?:%|mm/sec|cm/min|inch/min|deg/sec|sec|msec)"  # speed
    r"|max_speed|FINE|CNT\s*(?:\d+|" + _REG + r")|CD\s*\d+|CR\s*\d+"  # termination
    r"|ACC\s*(?:\d+|" + _REG + r")|Wjnt|PTH|AP_LD\s*\d+|RT_LD\s*\d+|(?:Ind\.)?EV\s*\d+%"
    r"|(?:TB|TA|DB)\s*(?:\d+(?:\.\d*)?|\.\d+|" + _REG + r")\s*(?:sec|mm)\s*,\s*(?:P-SPS|POINT_LOGIC|CALL\s+\w+"
    r"(?:\([^)]*\))?|" + _SIGNAL + r")"  # timing: a signal or a call before or after the point
    r"|Time\s+(?:Before|After)\s+[\d.]+\s*sec\s*,?\s*(?:CALL\s+\w+(?:\([^)]*\))?|" + _SIGNAL + r")"
    r"|Distance\s+Before\s+[\d.]+\s*mm\s*,?\s*(?:CALL\s+\w+(?:\([^)]*\))?|" + _SIGNAL + r")"
    r"|Skip\s*,\s*" + _LABEL + r"(?:\s*,\s*" + _PR + r"\s*=\s*[LJ]POS)?"  # high-speed skip: the target stays
    r"|Arc\s+(?:Start|End)\s*\[[^\]]*\]|Weld\s+(?:Start|End)\s*\[[^\]]*\]|SPOT\s*\[[^\]]*\]|Weave\s*\[[^\]]*\]"
    r")(?=\s|$)", re.I)
#: options that change a motion's target as the program runs (named as such)
_CHANGING = re.compile(r"^\s*(Offset|Tool_Offset|INC|VOFFSET|VTOOL|RTCP|COORD)\b", re.I)
POSE_KEYS = ("X", "Y", "Z", "W", "P", "R")
#: (a, b, c) of R = Rz(c)·Ry(b)·Rx(a): FANUC's W, P, R
ANGLE_KEYS = ("W", "P", "R")
JOINT_KEYS = ("J1", "J2", "J3", "J4", "J5", "J6")


def _config_fields(body: str, offset: int) -> tuple[dict[str, Field], dict]:
    """The CONFIG string's letters and turns as fields (``flip``, ``elbow``, ``side``, ``t1``…)."""
    m = _CONFIG.search(body)
    if m is None:
        return {}, {}
    text, start = m.group(1), offset + m.start(1)
    head, _, tail = text.partition(",")
    fields, config = {}, {}
    for letter in _LETTER.finditer(head):
        key = {"F": "flip", "N": "flip", "U": "elbow", "D": "elbow", "T": "side", "B": "side"}[letter.group()]
        fields[key] = Field(start + letter.start(), start + letter.end(), letter.group())
        config[key] = letter.group()
    for key, turn in zip(("t1", "t4", "t6"), _TURN.finditer(tail)):
        at = start + len(head) + 1 + turn.start()
        fields[key] = Field(at, at + len(turn.group()), turn.group())
        config[key] = int(turn.group())
    return fields, config


def _instructions(text: str, lines: Lines):
    """The ``/MN`` section's instructions, continuation lines (``   :  …``) joined to the numbered
    line they continue: (text, line of its number), the text without its trailing ``;``."""
    main_end = text.find("/POS")
    main = text[:main_end if main_end >= 0 else len(text)]
    start = main.find("/MN")
    body, at = (main[start:], start) if start >= 0 else (main, 0)
    current, first = None, 0
    for raw in body.splitlines(keepends=True):
        numbered, continued = _NUMBERED.match(raw), _CONTINUED.match(raw)
        if numbered:
            if current is not None:
                yield current, first
            current, first = numbered.group(2), lines.of(at)
        elif continued and current is not None:
            current = current.rstrip().rstrip(";") + " " + continued.group(1)
        at += len(raw)
    if current is not None:
        yield current, first


def _unsupported_option(rest: str) -> tuple[str, bool] | None:
    """The first option of a motion robocal does not take as leaving the target as written, and
    whether it is one that changes the target as the program runs; None when every one is harmless."""
    rest = rest.strip().rstrip(";").strip()
    while rest:
        changing = _CHANGING.match(rest)
        if changing:
            return changing.group(1), True
        m = _HARMLESS.match(rest)
        if m is None or not m.group().strip():
            return rest.split()[0], False
        rest = rest[m.end():].lstrip().lstrip(",").strip()
    return None


def _motions(text: str, lines: Lines) -> dict[str, list[tuple[str | None, int]]]:
    """Position number → [(why its motion leaves it as written or None, line), …]; position
    register and indirect motions are listed under ``PR n`` and ``P[R[n]]``."""
    out: dict[str, list] = {}
    for instruction, line in _instructions(text, lines):
        body = instruction.split("//", 1)[0]  # a commented-out instruction (//) moves nothing
        m = _INSTRUCTION.match(body)
        if m is None:
            continue
        option = _unsupported_option(m.group(4).rstrip().rstrip(";"))
        why = None
        if option is not None:
            name, changing = option
            why = (f"a motion with {name} (line {line}) changes it as the program runs" if changing else
                   f"a motion with the option {name!r} (line {line}), which robocal does not know to leave the "
                   "target as written")
        for ref in (m.group(2), m.group(3)):
            if ref is None:
                continue
            r = _POSITION_REF.match(ref)
            kind, number = r.group(1), r.group(2)
            key = f"PR {number}" if kind == "PR" else number if number.isdigit() else f"P[{number}]"
            out.setdefault(key, []).append((why, line))
    return out


def read(path: Path, frames_file: Path | None = None) -> Program:
    if frames_file is not None:
        raise InputError("FANUC's UF and UT are given with --user-frame N=… and --tool N=…", option="controller_frames")
    text, enc = read_file(path)
    source = str(path)
    program = Program("fanuc", source, [ProgramFile(source, text, enc)], [])
    program.tools["0"], program.users["0"] = np.eye(4), np.eye(4)
    lines = Lines(text)
    motions = _motions(text, lines)
    pos = text.find("/POS")
    for m in _POSITION.finditer(text, max(pos, 0)):
        number, body, offset = m.group(1), m.group(3), m.start(3)
        line = lines.of(m.start())
        name = f"P[{number}]" + (f" {m.group(2).strip()}" if m.group(2) and m.group(2).strip() else "")
        program.targets.append(_position(number, name, body, offset, line, source, motions.get(number, [])))
    for key, used in motions.items():
        if key.startswith("PR "):
            program.targets.append(Target(f"PR[{key[3:]}]", used[0][1], "pose", {},
                                          unsupported="a position register: its value lives in the controller"))
        elif key.startswith("P["):
            program.targets.append(Target(key, used[0][1], "pose", {}, unsupported="an indirect position: the "
                                          "register that numbers it is set as the program runs"))
    declared = {t.name.split()[0] for t in program.targets}
    for number, used in motions.items():
        if number.isdigit() and f"P[{number}]" not in declared:
            raise InputError(f"P[{number}] is used by a motion but has no position in /POS", source=source,
                             where=f"line {used[0][1]}")
    if not program.targets:
        raise InputError("no targets found (positions P[n] of a /POS section)", source=source)
    program.targets.sort(key=lambda t: t.line)
    turn_by_angles(program.targets, ANGLE_KEYS)
    for t in program.targets:
        for kind, name in (("tool", t.tool), ("user", t.user)):
            if name is not None and name != "0":
                program.missing.setdefault(f"{kind}:{name}", f"FANUC keeps {'UT' if kind == 'tool' else 'UF'} {name} "
                                           f"in the controller: give --{'tool' if kind == 'tool' else 'user-frame'} "
                                           f"{name}=x,y,z,w,p,r")
    return program


def _position(number: str, name: str, body: str, offset: int, line: int, source: str, used: list) -> Target:
    """One position of /POS as a target: its group 1's pose or joints, its frames, what its motions
    say of it.  An untaught position (asterisks), one with no group 1 (another group's alone) and
    one taught in the frames active at run time (``UF : F``) are targets left as written, with why."""
    groups = list(_GROUP.finditer(body))
    first = next((g for g in groups if g.group(1) == "1"), None)
    if groups and first is None:
        return Target(name, line, "pose", {}, unsupported=f"it holds no group 1 position, only group "
                      f"{', '.join(g.group(1) for g in groups)}'s: nothing of the arm to correct")
    end = next((g.start() for g in groups if first is not None and g.start() > first.start()), len(body))
    gp1 = body[first.end() if first else 0:end]
    gp1_at = offset + (first.end() if first else 0)
    if _UNTAUGHT.search(gp1):
        return Target(name, line, "pose", {}, unsupported="untaught: the controller prints its numbers as asterisks "
                      "(a motion that reaches it stops the program there)")
    values = {v.group(1): field_of((gp1_at + v.start(2), gp1_at + v.end(2), v.group(2))) for v in _VALUE.finditer(gp1)}
    if all(k in values for k in POSE_KEYS):
        cfg_fields, config = _config_fields(gp1, gp1_at)
        p = np.array([values[k].value for k in "XYZ"])  # (its rotation: turn_by_angles, once all are read)
        t = Target(name, line, "pose", {**values, **cfg_fields}, p, None, config=config)
    elif all(k in values for k in JOINT_KEYS):
        t = Target(name, line, "joints", values, q=np.radians([values[k].value for k in JOINT_KEYS]))
    else:
        missing = [k for k in POSE_KEYS if k not in values]
        raise InputError(f"P[{number}]: no number for {', '.join(missing)} (and not a joint position J1…J6)",
                         source=source, where=f"line {line}")
    frames = _FRAMES.search(gp1)
    if frames:
        uf, ut = frames.group(1), frames.group(2)
        if "F" in (uf.upper(), ut.upper()):
            t.unsupported = (f"taught in the frames active at run time (UF : {uf}, UT : {ut}): which they are, the "
                             "program does not say")
        else:
            t.user, t.tool = str(int(uf)), str(int(ut))
    changing = [why for why, _ in used if why]
    if changing and t.unsupported is None:
        t.unsupported = changing[0]
    return t


def _turn_bounds(t: int) -> tuple[float, float]:
    return (-math.pi + 2 * math.pi * t, math.pi + 2 * math.pi * t)


def request(t: Target) -> Request | None:
    c = t.config
    if t.kind != "pose" or not c:
        return None
    joints: list = [None] * 6
    for j, k in ((0, "t1"), (3, "t4"), (5, "t6")):
        if k in c:
            joints[j] = _turn_bounds(c[k])
    if "flip" in c:
        joints[4] = (0.0, np.inf) if c["flip"] == "F" else (-np.inf, 0.0)
    return Request(front={"T": 1, "B": -1}.get(c.get("side"), 0), elbow={"U": 1, "D": -1}.get(c.get("elbow"), 0),
                   joints=tuple(joints))


def _turn(angle: float, original: int | None) -> int:
    """The turn number of an angle (rad); the target's own on a boundary (±180° + k·360°)."""
    t = math.ceil((angle - math.pi) / (2 * math.pi))
    edge = abs(((angle - math.pi) / (2 * math.pi)) - round((angle - math.pi) / (2 * math.pi))) * 2 * math.pi
    if edge <= TOLERANCE_RAD and original in (t, t + 1, t - 1):
        return original
    return t


def encode(q: np.ndarray, facts: dict | None, config: dict) -> dict:
    out = {}
    if "flip" in config:
        out["flip"] = config["flip"] if abs(q[4]) <= TOLERANCE_RAD else ("F" if q[4] > 0 else "N")
    if facts:  # on a boundary (0) the target's own letter stays
        if "elbow" in config:
            out["elbow"] = {1: "U", -1: "D", 0: config["elbow"]}[int(facts["elbow"])]
        if "side" in config:
            out["side"] = {1: "T", -1: "B", 0: config["side"]}[int(facts["front"])]
    for j, k in ((0, "t1"), (3, "t4"), (5, "t6")):
        if k in config:
            out[k] = _turn(float(q[j]), config[k])
    return out


def write(t: Target, pose: np.ndarray | None, q: np.ndarray | None, config: dict,
          angles: tuple | None = None) -> list[tuple[Field, str]]:
    f, out = t.fields, []
    if t.kind == "joints":
        for i, key in enumerate(JOINT_KEYS[:len(q)]):
            set_number(out, f[key], math.degrees(q[i]), DECIMALS["deg"])
        return out
    for k, v in zip("XYZ", pose[:3, 3]):
        set_number(out, f[k], float(v), DECIMALS["mm"])
    # the angles, in the file's own decimals where they carry the correction
    wpr, places = angles or corrected_angles([(t, pose)], ANGLE_KEYS)[0]
    for k, v in zip("WPR", wpr):
        set_number(out, f[k], float(v), places)
    for k, v in config.items():
        if k in f:
            set_text(out, f[k], str(v))
    return out


LANGUAGE = Language(
    name="fanuc", title="FANUC TP (.ls)", suffixes=(".ls",), read=read, write=write, request=request, encode=encode,
    write_angles=partial(corrected_angles, keys=ANGLE_KEYS),
    units="mm, deg", orientation="R = Rz(R)·Ry(P)·Rx(W)",
    frames="UF and UT numbers of each position; their values given with --user-frame N=… and --tool N=…")
