"""KUKA KRL: targets in a .src and its .dat, frames from the program and ``$config.dat``.

Aggregates ``{X …, Y …, Z …, A …, B …, C …, S …, T …, E1 …}`` (E6POS, POS; mm and degrees,
R = Rz(A)·Ry(B)·Rx(C)) and ``{A1 …, …, A6 …, E1 …}`` (E6AXIS, AXIS; degrees) are targets where a
``DECL E6POS|POS|E6AXIS|AXIS`` declares them, where a motion (PTP, LIN, CIRC, SPTP, SLIN, SCIRC, SPL)
takes them inline, and where a variable is assigned one.  Everything after ``;`` on a line
(comments, folds) is left alone.

Frames: a Cartesian target is the ``$TOOL`` pose in ``$BASE``.  The .src is read in order: the
tool and base in force at each motion (``$TOOL = TOOL_DATA[n]``, ``BAS(#TOOL, n)``, an inline
``$TOOL = {…}``, ``FDAT_ACT = Fxx`` with its TOOL_NO, BASE_NO and IPO_FRAME from the .dat; the same
for the base) are the frames of the targets it names.  TOOL_DATA[n] and BASE_DATA[n] are read from
``$config.dat`` (given, or found beside the program or in a folder above it, as a KRC backup lays
it out); number 0 is the flange and the world.  A motion with ``IPO_FRAME #TCP`` (a stationary
tool), a relative motion (``…_REL``) and a target the motions reach in two different frames are
left unchanged and flagged.

Configuration (KUKA's Status and Turn): S bit 0 the wrist point behind axis 1 ("overhead"),
bit 1 the elbow up (A3 beyond the angle where the forearm is stretched), bit 2 A5 ≤ 0; T bit i
set when axis i + 1 is negative.  Higher bits are kept as written.
"""

from __future__ import annotations

import re
from functools import partial
from pathlib import Path

import numpy as np

from ..exceptions import InputError, Note
from ..inverse.configuration import TOLERANCE_RAD
from ..inverse.solve import Request
from ..math.se3 import homogeneous
from ..math.so3 import rpy_to_matrix
from .language import DECIMALS, Language, corrected_angles, keep_on_boundary, set_number, set_text
from .program import (
    NUMBER,
    Field,
    Program,
    ProgramFile,
    Target,
    field_of,
    keyword_matches,
    line_of,
    read_file,
    turn_by_angles,
)

_AGGREGATE = re.compile(r"\{([^{}]*)\}")
#: an integer in KRL's binary or hex notation (Status and Turn are often written so): 'B110', 'H1A'
_BASED = r"'[BbHh][0-9A-Fa-f]+'"
_ITEM = re.compile(r"([A-Za-z_$][\w$]*)\s+(" + NUMBER + r"|#\w+|" + _BASED + r")")
_DECL = re.compile(r"\bDECL\s+(?:GLOBAL\s+)?(E6POS|POS|E6AXIS|AXIS|FRAME|FDAT)\s+(\w+)\s*=\s*$", re.I)
_MOTION = re.compile(r"\b(PTP|LIN|CIRC|SPTP|SLIN|SCIRC|SPL)(_REL)?\s+", re.I)
_ASSIGN = re.compile(r"(\$?[\w\[\]]+)\s*=\s*$")
_DATA = re.compile(r"\b(TOOL|BASE)_DATA\s*\[\s*(\d+)\s*\]\s*=\s*\{([^{}]*)\}", re.I)
_SELECT = re.compile(r"\$(TOOL|BASE)\s*=\s*(?:(TOOL|BASE)_DATA\s*\[\s*(\d+)\s*\]|\$NULLFRAME|(\{[^{}]*\}))", re.I)
_BAS = re.compile(r"\bBAS\s*\(\s*#(TOOL|BASE)\s*,\s*(\d+)\s*\)", re.I)
_FDAT = re.compile(r"\bFDAT_ACT\s*=\s*(\w+|\{[^{}]*\})", re.I)
#: a spline motion's frames from an FDAT: ``$TOOL = STOOL2(FP1)``, ``$BASE = SBASE(FP1.BASE_NO)``,
#: ``$IPO_MODE = SIPO_MODE(FP1.IPO_FRAME)``
_SPLINE_FRAMES = re.compile(r"\$(?:TOOL|BASE|IPO_MODE)\s*=\s*(?:STOOL2?|SBASE2?|SIPO_MODE)\s*\(\s*(\w+)", re.I)
#: a declaration, initialised or not: its type and name (arrays too)
_TYPED = re.compile(r"\bDECL\s+(?:GLOBAL\s+)?(?:CONST\s+)?(\w+)\s+(\w+)\s*(?:\[|=|$)", re.I | re.M)
#: what may follow a motion's target(s) and leave them as written: approximation and a CIRC's angle,
#: and the WITH clause of a spline motion (its speeds, frames read above, approximation)
_HARMLESS = re.compile(r"^(?:\s*(?:C_PTP|C_DIS|C_VEL|C_ORI|C_SPL|CA\s+" + NUMBER + r")\b)*\s*(?:WITH\b.*)?$",
                       re.I | re.S)
#: the types whose aggregates are targets (a FRAME is a frame: measured points, base calibrations)
TARGET_TYPES = ("E6POS", "POS", "E6AXIS", "AXIS")
POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")
#: (a, b, c) of R = Rz(c)·Ry(b)·Rx(a): KUKA's C, B, A
ANGLE_KEYS = ("C", "B", "A")
JOINT_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")
CONFIG_FILE = "$config.dat"


def krl_int(text: str) -> int:
    """A KRL integer in any notation: decimal, binary ``'B110'`` or hex ``'H1A'``."""
    text = text.strip()
    if text.startswith("'") and text.endswith("'") and len(text) > 3:
        return int(text[2:-1], 2 if text[1] in "Bb" else 16)
    return int(float(text))


def krl_spelled(value: int, like: str) -> str:
    """``value`` written as ``like`` is: decimal, or binary/hex with at least its digits (a Status
    'B010' stays three bits wide)."""
    like = like.strip()
    if like.startswith("'") and len(like) > 3:
        width = len(like) - 3
        digits = format(value, "b" if like[1] in "Bb" else "X" if like[2:-1].isupper() or
                        not any(c.isalpha() for c in like[2:-1]) else "x")
        return f"'{like[1]}{digits.zfill(width)}'"
    return str(value)


def _items(body: str, offset: int) -> dict[str, Field]:
    """KEY value pairs of an aggregate body (an optional ``TYPE:`` prefix skipped)."""
    return {m.group(1).upper(): field_of((offset + m.start(2), offset + m.end(2), m.group(2)))
            for m in _ITEM.finditer(body)}


def pose_matrix(f: dict[str, Field]) -> tuple[np.ndarray, np.ndarray]:
    """Position mm and rotation of X Y Z A B C (R = Rz(A)·Ry(B)·Rx(C))."""
    abc = np.radians([f["C"].value, f["B"].value, f["A"].value])
    return np.array([f[k].value for k in "XYZ"]), rpy_to_matrix(abc)


def _frame_of(body: str, source: str, line: int) -> np.ndarray:
    items = _items(body, 0)
    missing = [k for k in POSE_KEYS if k not in items]
    if missing:
        raise InputError(f"a frame with no number for {', '.join(missing)}", source=source, where=f"line {line}")
    p, R = pose_matrix(items)
    return homogeneous(R, p)


def find_config(program: Path) -> Path | None:
    """``$config.dat`` beside the program, or in a folder above it (KRC/R1/System/$config.dat)."""
    folder = program.resolve().parent
    for level in [folder, *list(folder.parents)[:3]]:
        for candidate in (level, level / "System", level / "R1" / "System", level / "KRC" / "R1" / "System"):
            if candidate.is_dir():
                for f in candidate.iterdir():
                    if f.name.lower() == CONFIG_FILE:
                        return f
    return None


def _config_frames(path: Path, program: Program) -> None:
    text, _ = read_file(path, "controller frames file")
    code = "\n".join(line.split(";", 1)[0] for line in text.splitlines())
    found = 0
    for m in _DATA.finditer(code):
        kind, number = m.group(1).lower(), str(int(m.group(2)))
        frame = _frame_of(m.group(3), str(path), line_of(code, m.start()))
        (program.tools if kind == "tool" else program.users).setdefault(number, frame)
        found += 1
    program.notes.append(Note(f"frames read from {path}: {found} TOOL_DATA/BASE_DATA"))


class _State:
    """The tool and base in force as the .src runs, and the external-TCP flag."""

    def __init__(self):
        self.tool, self.base, self.external = None, None, False


def _fdat(body: str, state: _State) -> None:
    items = {m.group(1).upper(): m.group(2) for m in _ITEM.finditer(body)}
    if "TOOL_NO" in items:
        state.tool = str(int(float(items["TOOL_NO"])))
    if "BASE_NO" in items:
        state.base = str(int(float(items["BASE_NO"])))
    if "IPO_FRAME" in items:
        state.external = items["IPO_FRAME"].upper() == "#TCP"


def _parse(text: str, file: int, source: str, program: Program, fdats: dict, uses: dict, state: _State,
           types: dict) -> None:
    """Targets of one file appended to the program; the frames each motion of it uses in ``uses``."""
    start = 0
    for line, raw in enumerate(text.splitlines(keepends=True), 1):
        code = raw.split(";", 1)[0]  # KRL comments and folds run from ';' to the end of the line
        # what each pattern needs in the line, looked for before the pattern runs (a program of ten
        # thousand points has thirty thousand lines, most of them one statement); ASCII only, where
        # the lower case is the case folding of re.I
        if code.isascii():
            low = code.lower()
            system, bas, fdat = "$" in low, "bas" in low, "fdat_act" in low
            moves = "ptp" in low or "lin" in low or "circ" in low or "spl" in low  # (SPTP, SLIN, SCIRC too)
        else:
            system = bas = fdat = moves = True
        for m in (_SELECT.finditer(code) if system else ()):  # $TOOL = TOOL_DATA[n] | $NULLFRAME | {…}
            kind = m.group(1).lower()
            if m.group(4):
                name = f"${kind.upper()} (line {line})"
                (program.tools if kind == "tool" else program.users)[name] = _frame_of(m.group(4)[1:-1], source, line)
            else:
                name = str(int(m.group(3))) if m.group(3) else "0"
            setattr(state, "tool" if kind == "tool" else "base", name)
        for m in (_BAS.finditer(code) if bas else ()):
            setattr(state, m.group(1).lower(), str(int(m.group(2))))
        for m in (_FDAT.finditer(code) if fdat else ()):
            ref = m.group(1)
            if ref.startswith("{"):
                _fdat(ref[1:-1], state)
            elif ref.upper() in fdats:
                _fdat(fdats[ref.upper()], state)
        for m in (_SPLINE_FRAMES.finditer(code) if system else ()):
            if m.group(1).upper() in fdats:
                _fdat(fdats[m.group(1).upper()], state)
        motion = _MOTION.search(code) if moves else None
        why = None
        if motion:
            rest = code[motion.end():]
            circ = motion.group(1).upper() in ("CIRC", "SCIRC")
            named = re.match(r"\s*(\$?[A-Za-z_]\w*(?:\[[^\]]*\])?)" + (r"(?:\s*,\s*(\$?[A-Za-z_]\w*(?:\[[^\]]*\])?))?"
                             if circ else ""), rest)
            after = rest[named.end():] if named else re.sub(r"^\s*\{[^{}]*\}(?:\s*,\s*\{[^{}]*\})?", "", rest)
            if not _HARMLESS.match(after):
                token = after.strip().split()[0] if after.strip() else after.strip()
                why = f"its motion (line {line}) goes on with {token!r}, which robocal does not take as leaving the " \
                      "target as written"
            for w in (g for g in (named.groups() if named else ()) if g):
                uses.setdefault(re.sub(r"\s", "", w).upper(), []).append(
                    (state.tool, state.base, state.external, bool(motion.group(2)), line, why))
        for m in (_AGGREGATE.finditer(code) if "{" in code else ()):
            before = code[:m.start()]
            items = _items(m.group(1), start + m.start(1))
            is_pose = all(k in items for k in POSE_KEYS)
            is_joints = all(k in items for k in JOINT_KEYS)
            decl, assign = _DECL.search(before), _ASSIGN.search(before)
            inline = _MOTION.search(before)
            if decl and decl.group(1).upper() == "FDAT":
                fdats[decl.group(2).upper()] = m.group(1)
                continue
            if not (is_pose or is_joints):
                if decl and decl.group(1).upper() != "FRAME":
                    keys = JOINT_KEYS if "AXIS" in decl.group(1).upper() else POSE_KEYS
                    missing = [k for k in keys if k not in items]
                    raise InputError(f"{decl.group(1)} {decl.group(2)}: no number for {', '.join(missing)}",
                                     source=source, where=f"line {line}")
                continue
            if decl and decl.group(1).upper() == "FRAME":
                continue  # a frame, not a target
            if assign and not decl and assign.group(1).startswith("$"):
                continue  # a system variable ($TOOL, $BASE, $POS_ACT …), read above where it is a frame
            if assign and not decl and not inline and types.get(assign.group(1).split("[")[0].upper(), "E6POS") \
                    not in TARGET_TYPES:
                continue  # a FRAME (measured points of a base calibration) or other data: not a target
            if not (decl or inline or assign):
                continue
            if inline:
                name = f"line {line}" + (" (.dat)" if file else "")
                frames = (state.tool, state.base, state.external, bool(inline.group(2)), line, why)
            else:
                name = decl.group(2) if decl else assign.group(1)
                frames = None
            t = _target(items, is_pose, name, line, file)
            if frames is not None:
                uses.setdefault(f"#{id(t)}", []).append(frames)
                t.config["_key"] = f"#{id(t)}"
            program.targets.append(t)
        start += len(raw)


def _target(items: dict[str, Field], is_pose: bool, name: str, line: int, file: int) -> Target:
    if is_pose:  # its rotation made with every other's once the files are read (turn_by_angles)
        config = {k: krl_int(items[k].text) for k in ("S", "T") if k in items}
        return Target(name, line, "pose", items, np.array([items[k].value for k in "XYZ"]), None, config=config,
                      file=file)
    return Target(name, line, "joints", items, q=np.radians([items[k].value for k in JOINT_KEYS]), file=file)


def _assign_frames(program: Program, uses: dict) -> None:
    """Each target's tool and base: those of the motions that reach it."""
    everything = {(u[0], u[1]) for us in uses.values() for u in us if not u[3]}
    for t in program.targets:
        key = t.config.pop("_key", t.name.upper())
        used = uses.get(key, [])
        if not used:
            if len(everything) == 1:
                t.tool, t.user = next(iter(everything))
            elif everything:
                t.unsupported = "no motion of the program reaches it, and its motions use several tools or bases"
            continue
        frames = {(u[0], u[1]) for u in used}
        said = next((u[5] for u in used if u[5]), None)
        if said:
            t.unsupported = said
        elif any(u[3] for u in used):
            t.unsupported = f"a relative motion ({'line ' + str(used[0][4])}) reaches it"
        elif any(u[2] for u in used):
            t.unsupported = "a motion with IPO_FRAME #TCP (a stationary tool) reaches it"
        elif len(frames) > 1:
            listed = ", ".join(f"tool {a}, base {b}" for a, b in sorted(frames, key=str))
            t.unsupported = f"the motions reach it with different frames ({listed})"
        else:
            t.tool, t.user = next(iter(frames))


def read(path: Path, frames_file: Path | None = None) -> Program:
    """A KRL program: its .src, its .dat when there is one (said when it is not), and the frames
    of ``$config.dat`` (``frames_file``, else found beside the program)."""
    src = path.with_suffix(".src") if path.suffix.lower() == ".dat" else path
    text, enc = read_file(src)
    program = Program("krl", str(src), [ProgramFile(str(src), text, enc)], [])
    program.tools["0"], program.users["0"] = np.eye(4), np.eye(4)
    dat = src.with_suffix(".dat")
    fdats: dict[str, str] = {}
    uses: dict[str, list] = {}
    dat_text = None
    if dat.is_file():
        dat_text, dat_enc = read_file(dat)
        program.files.append(ProgramFile(str(dat), dat_text, dat_enc, ".dat"))
        for m in _AGGREGATE.finditer(dat_text):  # the .dat's FDATs serve the .src's motions
            before = dat_text[max(0, m.start() - 200):m.start()]
            if before.isascii() and "fdat" not in before.lower():
                continue  # (no FDAT declaration can end there)
            decl = _DECL.search(before)
            if decl and decl.group(1).upper() == "FDAT":
                fdats[decl.group(2).upper()] = m.group(1)
    types = {m.group(2).upper(): m.group(1).upper() for body in (text, dat_text or "")
             for m in keyword_matches(_TYPED, "\n".join(line.split(";", 1)[0] for line in body.splitlines()),
                                      ("decl",))}
    _parse(text, 0, str(src), program, fdats, uses, _State(), types)
    if dat_text is not None:
        _parse(dat_text, 1, str(dat), program, fdats, uses, _State(), types)
    turn_by_angles(program.targets, ANGLE_KEYS)  # R = Rz(A)·Ry(B)·Rx(C)
    declared = {t.name.upper() for t in program.targets}
    undeclared = [(name, used) for name, used in uses.items() if not name.startswith("#") and name not in declared]
    if undeclared and dat_text is None:
        program.notes.append(f"{dat.name} not found beside {src.name}: the targets its motions name there cannot "
                             "be corrected")
    for name, used in undeclared:  # a motion to a target the program's files do not hold: said, never skipped
        why = (f"declared in {dat.name}, which is missing" if dat_text is None else
               "a system variable, computed as the program runs" if name.startswith("$") else
               f"declared neither in {src.name} nor in {dat.name} (a global, e.g. of $config.dat: robocal corrects "
               "the targets a program's own files hold)")
        program.targets.append(Target(name, used[0][4], "pose", {}, unsupported=why))
    if not program.targets:
        raise InputError("no targets found (E6POS, POS, E6AXIS or AXIS aggregates)", source=src)
    _assign_frames(program, uses)
    config = frames_file or find_config(src)
    if config is not None:
        _config_frames(Path(config), program)
    named = {t.tool for t in program.targets if t.tool} | {t.user for t in program.targets if t.user}
    if config is None and named - {"0"} - set(program.tools) - set(program.users):
        for n in named:
            program.missing[n] = f"it is in {CONFIG_FILE}, which was not found beside the program " \
                                 f"(give --controller-frames, or --tool/--user-frame {n}=x,y,z,rx,ry,rz)"
    return program


def request(t: Target) -> Request | None:
    """KUKA's S and T as a :class:`Request`."""
    c = t.config
    if not c:
        return None
    joints: list = [None] * 6
    front = elbow = 0
    if "S" in c:
        s = c["S"]
        front, elbow = (-1 if s & 1 else 1), (1 if s & 2 else -1)
        joints[4] = (-np.inf, 0.0) if s & 4 else (0.0, np.inf)
    if "T" in c:
        for i in range(6):
            bounds = (-np.inf, 0.0) if c["T"] >> i & 1 else (0.0, np.inf)
            joints[i] = bounds if joints[i] is None else (max(joints[i][0], bounds[0]), min(joints[i][1], bounds[1]))
    return Request(front=front, elbow=elbow, joints=tuple(joints))


def encode(q: np.ndarray, facts: dict | None, config: dict) -> dict:
    """S and T at joints q (the target's own bit where a fact or a joint is on its boundary)."""
    out = {}
    on_zero = np.abs(q) <= TOLERANCE_RAD
    if "S" in config:
        s0 = config["S"]
        bit0 = keep_on_boundary(int(facts["front"] < 0), facts["front"], s0 & 1) if facts else s0 & 1
        bit1 = keep_on_boundary(int(facts["elbow"] > 0), facts["elbow"], s0 >> 1 & 1) if facts else s0 >> 1 & 1
        bit2 = (s0 >> 2 & 1) if on_zero[4] else int(q[4] <= 0)
        out["S"] = (s0 & ~7) | bit0 | bit1 << 1 | bit2 << 2
    if "T" in config:
        t0 = config["T"]
        bits = [(t0 >> i & 1) if on_zero[i] else int(q[i] < 0) for i in range(min(6, len(q)))]
        out["T"] = (t0 & ~63) | sum(b << i for i, b in enumerate(bits))
    return out


def write(t: Target, pose: np.ndarray | None, q: np.ndarray | None, config: dict,
          angles: tuple | None = None) -> list[tuple[Field, str]]:
    f, out = t.fields, []
    if t.kind == "joints":
        for i, key in enumerate(JOINT_KEYS[:len(q)]):
            set_number(out, f[key], float(np.degrees(q[i])), DECIMALS["deg"])
        return out
    for k, v in zip("XYZ", pose[:3, 3]):
        set_number(out, f[k], float(v), DECIMALS["mm"])
    # the angles, in the file's own decimals where they carry the correction
    (c, b, a), places = angles or corrected_angles([(t, pose)], ANGLE_KEYS)[0]
    for k, v in zip("ABC", (a, b, c)):
        set_number(out, f[k], float(v), places)
    for k in ("S", "T"):
        if k in config and k in f:
            set_text(out, f[k], krl_spelled(config[k], f[k].text))
    return out


LANGUAGE = Language(
    name="krl", title="KUKA KRL", suffixes=(".src", ".dat"), read=read, write=write, request=request,
    encode=encode, units="mm, deg", orientation="R = Rz(A)·Ry(B)·Rx(C)",
    write_angles=partial(corrected_angles, keys=ANGLE_KEYS),
    frames="$TOOL/$BASE: TOOL_DATA[n], BASE_DATA[n] from $config.dat, BAS(#TOOL|#BASE, n), FDAT_ACT, inline frames",
    stamp=(r"^\s*DEF(?:FCT)?\b[^\n]*", ";"))
