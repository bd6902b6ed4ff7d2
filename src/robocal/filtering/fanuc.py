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
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..inverse.configuration import TOLERANCE_RAD
from ..inverse.solve import Request
from ..math.so3 import rpy_to_matrix
from .language import DECIMALS, Language, fixed_xyz, set_number, set_text
from .program import NUMBER, Field, Lines, Program, ProgramFile, Target, read_file

_POSITION = re.compile(r"^P\[(\d+)(?::\s*\"?([^\]\"]*)\"?)?\]\s*\{(.*?)\};", re.S | re.M)
_GROUP = re.compile(r"\bGP(\d+)\s*:")
_VALUE = re.compile(r"\b(X|Y|Z|W|P|R|J\d|E\d)\s*=\s*(" + NUMBER + r")\s*(mm|deg)?")
_FRAMES = re.compile(r"\bUF\s*:\s*(\d+)\s*,\s*UT\s*:\s*(\d+)")
_CONFIG = re.compile(r"CONFIG\s*:\s*'([^']*)'")
_LETTER = re.compile(r"[FNUDTB]")
_TURN = re.compile(r"-?\d+")
_MOTION = re.compile(r"^\s*\d+:\s*([JLCA])\s+(P|PR)\[(\d+)(?::[^\]]*)?\](.*?);", re.M)
_MORE = re.compile(r"^\s*:\s*(P|PR)\[(\d+)(?::[^\]]*)?\](.*?);", re.M)
_CHANGING = re.compile(r"\b(Offset|Tool_Offset|INC|VOFFSET|VTOOL)\b", re.I)
POSE_KEYS = ("X", "Y", "Z", "W", "P", "R")
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


def _motions(text: str, lines: Lines) -> dict[str, list[tuple[str | None, int]]]:
    """Position number → [(why its motion changes it at run time or None, line), …]; PR motions
    are listed under ``PR n``."""
    main = text.split("/POS", 1)[0]
    out: dict[str, list] = {}
    for pattern in (_MOTION, _MORE):
        for m in pattern.finditer(main):
            kind, number, rest = (m.group(2), m.group(3), m.group(4)) if pattern is _MOTION else m.groups()
            change = _CHANGING.search(rest)
            key = number if kind == "P" else f"PR {number}"
            out.setdefault(key, []).append((change.group(1) if change else None, lines.of(m.start())))
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
        groups = list(_GROUP.finditer(body))
        first = groups[0] if groups else None
        end = groups[1].start() if len(groups) > 1 else len(body)
        gp1 = body[first.end() if first else 0:end]
        gp1_at = offset + (first.end() if first else 0)
        frames = _FRAMES.search(gp1)
        values = {v.group(1): Field(gp1_at + v.start(2), gp1_at + v.end(2), v.group(2)) for v in _VALUE.finditer(gp1)}
        name = f"P[{number}]" + (f" {m.group(2).strip()}" if m.group(2) and m.group(2).strip() else "")
        if all(k in values for k in POSE_KEYS):
            cfg_fields, config = _config_fields(gp1, gp1_at)
            p = np.array([values[k].value for k in "XYZ"])
            R = rpy_to_matrix(np.radians([values[k].value for k in "WPR"]))
            t = Target(name, line, "pose", {**values, **cfg_fields}, p, R, config=config)
        elif all(k in values for k in JOINT_KEYS):
            t = Target(name, line, "joints", values, q=np.radians([values[k].value for k in JOINT_KEYS]))
        else:
            missing = [k for k in POSE_KEYS if k not in values]
            raise InputError(f"P[{number}]: no number for {', '.join(missing)} (and not a joint position J1…J6)",
                             source=source, where=f"line {line}")
        if frames:
            t.user, t.tool = str(int(frames.group(1))), str(int(frames.group(2)))
        used = motions.get(number, [])
        changing = [(why, at) for why, at in used if why]
        if changing:
            t.unsupported = f"a motion with {changing[0][0]} (line {changing[0][1]}) changes it as the program runs"
        program.targets.append(t)
    for key, used in motions.items():
        if key.startswith("PR "):
            program.targets.append(Target(f"PR[{key[3:]}]", used[0][1], "pose", {},
                                          unsupported="a position register: its value lives in the controller"))
    declared = {t.name.split()[0] for t in program.targets}
    for number, used in motions.items():
        if not number.startswith("PR ") and f"P[{number}]" not in declared:
            raise InputError(f"P[{number}] is used by a motion but has no position in /POS", source=source,
                             where=f"line {used[0][1]}")
    if not program.targets:
        raise InputError("no targets found (positions P[n] of a /POS section)", source=source)
    program.targets.sort(key=lambda t: t.line)
    for t in program.targets:
        for kind, name in (("tool", t.tool), ("user frame", t.user)):
            if name is not None and name != "0":
                program.missing.setdefault(name, f"FANUC keeps {'UT' if kind == 'tool' else 'UF'} {name} in the "
                                                 f"controller: give --{'tool' if kind == 'tool' else 'user-frame'} "
                                                 f"{name}=x,y,z,w,p,r")
    return program


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


def write(t: Target, pose: np.ndarray | None, q: np.ndarray | None, config: dict) -> list[tuple[Field, str]]:
    f, out = t.fields, []
    if t.kind == "joints":
        for i, key in enumerate(JOINT_KEYS[:len(q)]):
            set_number(out, f[key], math.degrees(q[i]), DECIMALS["deg"])
        return out
    for k, v in zip("XYZ", pose[:3, 3]):
        set_number(out, f[k], float(v), DECIMALS["mm"])
    wpr = fixed_xyz(pose[:3, :3], (f["W"].value, f["P"].value, f["R"].value))
    for k, v in zip("WPR", wpr):
        set_number(out, f[k], float(v), DECIMALS["deg"])
    for k, v in config.items():
        if k in f:
            set_text(out, f[k], str(v))
    return out


LANGUAGE = Language(
    name="fanuc", title="FANUC TP (.ls)", suffixes=(".ls",), read=read, write=write, request=request, encode=encode,
    units="mm, deg", orientation="R = Rz(R)·Ry(P)·Rx(W)",
    frames="UF and UT numbers of each position; their values given with --user-frame N=… and --tool N=…")
