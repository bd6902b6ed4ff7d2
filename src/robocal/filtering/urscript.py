"""Universal Robots URScript: poses ``p[x, y, z, rx, ry, rz]`` (m; a rotation vector, rad) and
joint lists ``[j1, …, j6]`` (rad).

They are targets where a motion (movej, movel, movep, movec, servoj) takes them inline or names a
variable assigned one (once: a variable the program assigns again or element by element is
flagged).  ``movej(get_inverse_kin(X, qnear=Q))`` goes to the pose X on the solution nearest the
joints Q: Q is the branch hint of X, never a target itself.  PolyScope exports a waypoint as
``NAME_p`` (the pose) and ``NAME_q`` (the joints it was taught at): ``NAME_q`` is the hint of
``NAME_p`` whether or not a motion names it (``movel(NAME_p)`` uses the pose alone).  A pose with
no hint is solved nearest the previous target.  ``#`` starts a comment.

Frames: ``set_tcp(p[…])`` sets the TCP of the motions after it; ``pose_trans(F, X)`` with ``F`` a
pose variable (a PolyScope feature) puts the target X in the user frame F.  ``pose_trans(X, p[…])``
with X a pose some motion also goes to, and ``pose_add(X, p[…])``, are offset motions of X
(:class:`~.program.Offset`): X is corrected and they take its correction.  A target the motions
reach through any other computation is flagged.
"""

from __future__ import annotations

import re
from functools import partial
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..math.se3 import homogeneous
from .language import DECIMALS, Language, rotation_vectors, set_number
from .program import (
    SPACED_NUMBER,
    Field,
    Lines,
    Offset,
    Program,
    ProgramFile,
    Target,
    blank_comments,
    fields_in,
    in_text_order,
    read_file,
    split_top,
)

_N = SPACED_NUMBER
POSE = re.compile(r"\bp\[(" + ",".join([_N] * 6) + r")\]")
JOINTS = re.compile(r"(?<![\w\]])\[(" + ",".join([_N] * 6) + r")\]")
_ASSIGN = re.compile(r"(?:\bglobal\s+|\blocal\s+)?\b([A-Za-z_]\w*)\s*=(?!=)\s*")
_MOVE = re.compile(r"\b(movej|movel|movep|movec|servoj)\s*\(")
_TCP = re.compile(r"\bset_tcp\s*\(\s*p\[(" + ",".join([_N] * 6) + r")\]")
_NAME = re.compile(r"[A-Za-z_]\w*")
_BRACKET = re.compile(r"[()\[\]]")
#: a variable assigned element by element, ``x[i] = …`` (a look-ahead: at every word's start, overlapping)
_SUBSCRIPTED = re.compile(r"\b(?=([A-Za-z_]\w*)\s*\[[^\]]*\]\s*=(?!=))")
POSE_KEYS = ("x", "y", "z", "rx", "ry", "rz")
ROTATION_KEYS = POSE_KEYS[3:]


def _call_arguments(code: str, open_paren: int) -> tuple[list[str], list[int]]:
    """The top-level arguments of the call whose ``(`` is at ``open_paren`` and where each starts."""
    depth, i = 1, len(code)  # (unclosed: to the end, less its last character, as the walk it replaces)
    for m in _BRACKET.finditer(code, open_paren + 1):  # only the brackets move the depth
        depth += 1 if m.group() in "([" else -1
        if not depth:
            i = m.end()
            break
    body = code[open_paren + 1:i - 1]
    parts = split_top(body)
    starts, at = [], open_paren + 1
    for p in parts:
        starts.append(at + len(p) - len(p.lstrip()))
        at += len(p) + 1
    return [p.strip() for p in parts], starts


def _pose_of(values: list[float]) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial.transform import Rotation  # here: every language is imported on any filter run

    v = np.array(values)
    return v[:3] * 1000.0, Rotation.from_rotvec(v[3:]).as_matrix()


class _Reader:
    def __init__(self, text: str, source: str):
        self.text, self.source, self.code = text, source, blank_comments(text, "#")
        self.lines = Lines(text)
        self.program = Program("urscript", source, [ProgramFile(source, text, "")], [])
        self.tcps = [(m.start(), homogeneous(*_pose_of([f.value for f in fields_in(m.group(1))])[::-1]))
                     for m in _TCP.finditer(self.code)]
        self.literals: dict[str, list] = {}  # variable → [(kind, match), …] of its literal assignments
        self.assignments: dict[str, int] = {}
        for m in _ASSIGN.finditer(self.code):
            name = m.group(1)
            self.assignments[name] = self.assignments.get(name, 0) + 1
            for kind, pattern in (("pose", POSE), ("joints", JOINTS)):
                # (matched where the value begins, not on the rest of the code sliced off: that copied the
                # program once an assignment, quadratic in its length; what the patterns look behind is
                # the assignment's "=" or a space either way)
                lit = pattern.match(self.code, m.end())
                if lit:
                    self.literals.setdefault(name, []).append((kind, lit.start(), lit.end()))
        # the variables changed element by element (x[i] = …), each name at a word's start: one pass
        self.subscripted = set(_SUBSCRIPTED.findall(self.code))
        self.uses: dict[str, list] = {}  # variable → [(tool, user, hint, line)]
        self.through: dict[str, str] = {}  # variable → how a motion reaches it through a computation
        self.offsets: dict[str, list] = {}  # variable → the motions that reach it through a literal offset
        self.turning: list = []  # (pose target, its rotation vector): their rotations made at the end, at once

    def tool_at(self, index: int) -> str | None:
        before = [i for i, (at, _) in enumerate(self.tcps) if at < index]
        return f"set_tcp line {self.lines.of(self.tcps[before[-1]][0])}" if before else None

    def changed(self, name: str) -> bool:
        return self.assignments.get(name, 0) > 1 or name in self.subscripted

    def target(self, kind: str, start: int, end: int, name: str, line: int) -> Target:
        inner = self.code[start:end]
        body = inner[inner.index("[") + 1:inner.rindex("]")]
        f = fields_in(self.text[start:end], start)
        if len(f) != 6:
            raise InputError(f"{name}: expected six numbers in {body.strip()!r}", source=self.source,
                             where=f"line {line}")
        if kind == "pose":  # its rotation made with every other's at the end of the reading (the same bits)
            v = np.array([x.value for x in f])
            t = Target(name, line, "pose", dict(zip(POSE_KEYS, f)), v[:3] * 1000.0, None)
            self.turning.append((t, v[3:]))
            return t
        return Target(name, line, "joints", {f"q{i + 1}": x for i, x in enumerate(f)}, q=np.array([x.value for x in f]))

    def flag(self, what: str, index: int, why: str) -> None:
        line = self.lines.of(index)
        self.program.targets.append(Target(f"line {line}", line, "pose", {}, unsupported=f"{what}: {why}"))

    def motion_target(self, arg: str, at: int, tool: str | None, user: str | None = None, hint=None) -> None:
        """One motion argument: a literal target, a variable, or a call robocal understands."""
        line = self.lines.of(at)
        if _NAME.fullmatch(arg):
            self.uses.setdefault(arg, []).append((tool, user, hint, line))
            return
        for kind, pattern in (("pose", POSE), ("joints", JOINTS)):
            lit = pattern.fullmatch(arg)
            if lit:
                t = self.target(kind, at, at + len(arg), f"line {line}", line)
                t.tool, t.user, t.hint = tool, user, hint
                self.program.targets.append(t)
                return
        call = re.match(r"(get_inverse_kin|pose_trans)\s*\(", arg)
        if call and call.group(1) == "get_inverse_kin" and user is None:
            args, starts = _call_arguments(self.code, at + call.end() - 1)
            near = next((a.split("=", 1)[1].strip() for a in args[1:] if re.match(r"qnear\s*=", a)), None)
            near_at = next((s + a.index("=") + 1 for a, s in zip(args[1:], starts[1:]) if re.match(r"qnear\s*=", a)),
                           None)
            if near is None and len(args) > 1 and "=" not in args[1]:
                near, near_at = args[1], starts[1]
            self.motion_target(args[0], starts[0], tool, None, self.joints_of(near, near_at))
            return
        if call and call.group(1) == "pose_trans":
            args, starts = _call_arguments(self.code, at + call.end() - 1)
            # a pose variable some motion goes to itself is a target (the literal its offset), else a feature
            if len(args) == 2 and _NAME.fullmatch(args[0]) and args[0] not in self.direct and \
                    self.feature(args[0]):
                self.motion_target(args[1], starts[1], tool, args[0], hint)
                return
        offset = self.offset(arg, at, line)
        if offset is not None:  # pose_trans(X, p[…]), pose_add(X, p[…]): X is corrected, the motion takes it along
            self.uses.setdefault(offset[0], []).append((tool, user, hint, line))
            self.offsets.setdefault(offset[0], []).append(offset[1])
            return
        self.flag(arg.split("(")[0].strip() or arg, at, "the target is computed as the program runs")
        call = re.match(r"(\w+)\s*\(", arg)
        if call:  # pose_add(X, d), pose_trans(X, d) with X no feature: X is reached only through it
            for name in _call_arguments(self.code, at + call.end() - 1)[0]:
                if _NAME.fullmatch(name):
                    self.through.setdefault(name, f"a motion reaches it through {call.group(1)}() (line {line}), "
                                                  "which changes it as the program runs")

    def offset(self, arg: str, at: int, line: int):
        """``pose_trans(X, p[…])`` (about X's tool: X · D) or ``pose_add(X, p[…])`` (X's position moved by D's, its
        rotation R_X · R_D) with X a target variable and D a literal pose: (X, the :class:`Offset`), else None."""
        call = re.match(r"(pose_trans|pose_add)\s*\(", arg)
        if call is None:
            return None
        args, _ = _call_arguments(self.code, at + call.end() - 1)
        if len(args) != 2 or not _NAME.fullmatch(args[0]) or not POSE.fullmatch(args[1]) or \
                (call.group(1) == "pose_trans" and args[0] not in self.direct):
            return None
        p, R = _pose_of([f.value for f in fields_in(args[1])])
        return args[0], Offset("tool" if call.group(1) == "pose_trans" else "add", homogeneous(R, p), line,
                               arg.strip())

    def joints_of(self, text: str | None, at: int | None):
        """A hint: joints written inline or a variable assigned a joint list once."""
        if text is None:
            return None
        text = text.strip()
        lit = JOINTS.fullmatch(text)
        if lit:
            return np.array([f.value for f in fields_in(text)])
        if _NAME.fullmatch(text) and not self.changed(text):
            kinds = self.literals.get(text, [])
            if kinds and kinds[0][0] == "joints":
                return np.array([f.value for f in fields_in(self.text[kinds[0][1]:kinds[0][2]])])
        return None

    def feature(self, name: str) -> bool:
        """A pose variable assigned once: a user frame (PolyScope's feature)."""
        kinds = self.literals.get(name, [])
        if not kinds or kinds[0][0] != "pose" or self.changed(name):
            return False
        if name not in self.program.users:
            p, R = _pose_of([f.value for f in fields_in(self.text[kinds[0][1]:kinds[0][2]])])
            self.program.users[name] = homogeneous(R, p)
        return True

    def read(self) -> Program:
        self.direct = {arg for m in _MOVE.finditer(self.code)  # the variables a motion goes to as they are
                       for arg in _call_arguments(self.code, m.end() - 1)[0][:2] if _NAME.fullmatch(arg)} | \
            set(re.findall(r"get_inverse_kin\s*\(\s*([A-Za-z_]\w*)\s*[,)]", self.code))
        for m in _MOVE.finditer(self.code):
            args, starts = _call_arguments(self.code, m.end() - 1)
            for arg, at in list(zip(args, starts))[:2 if m.group(1) == "movec" else 1]:
                self.motion_target(arg, at, self.tool_at(m.start()))
        for name, used in self.uses.items():
            kinds = self.literals.get(name, [])
            if not kinds:
                self.flag(name, self.code.index(name), "the target is computed as the program runs")
                continue
            kind, start, end = kinds[0]
            t = self.target(kind, start, end, name, self.lines.of(start))
            frames = {(u[0], u[1]) for u in used}
            hints = [u[2] for u in used if u[2] is not None]
            pair = self.joints_of(name[:-2] + "_q", None) if name.endswith("_p") else None
            t.hint = hints[0] if hints else pair
            t.offsets = self.offsets.get(name, [])
            if name in self.through:
                t.unsupported = self.through[name]
            elif self.changed(name):
                t.unsupported = f"{name} is assigned again or changed element by element as the program runs"
            elif len(frames) > 1:
                t.unsupported = f"the motions reach {name} with different TCPs or features"
            else:
                t.tool, t.user = next(iter(frames))
            self.program.targets.append(t)
        if self.turning:
            from scipy.spatial.transform import Rotation

            turned = Rotation.from_rotvec(np.array([v for _, v in self.turning])).as_matrix()
            for (t, _), R in zip(self.turning, turned):
                t.rotation = R
        self.program.targets.sort(key=in_text_order)
        if not self.program.targets:
            raise InputError("no targets found (p[…] poses or joint lists of motions)", source=self.source)
        self.program.tools.update({f"set_tcp line {self.lines.of(at)}": T for at, T in self.tcps})
        return self.program


def read(path: Path, frames_file: Path | None = None) -> Program:
    if frames_file is not None:
        raise InputError("a URScript program sets its TCP with set_tcp: --controller-frames is for KRL",
                         option="controller_frames")
    text, enc = read_file(path)
    program = _Reader(text, str(path)).read()
    program.files[0].encoding = enc
    return program


def request(t: Target):
    return None  # URScript targets name no configuration: the hint (qnear, NAME_q, the previous target) does


def encode(q: np.ndarray, facts: dict | None, config: dict) -> dict:
    """The UR branch, for the report (the program holds no configuration data)."""
    if not facts:
        return {}
    word = {1: "+", -1: "-", 0: "0"}
    return {"shoulder": word[int(facts["front"])], "elbow": word[int(facts["elbow"])],
            "wrist": word[int(np.sign(round(q[4], 12)))]}


def write(t: Target, pose: np.ndarray | None, q: np.ndarray | None, config: dict,
          angles: np.ndarray | None = None) -> list[tuple[Field, str]]:
    f, out = t.fields, []
    if t.kind == "joints":
        for i in range(len(q)):
            set_number(out, f[f"q{i + 1}"], float(q[i]), DECIMALS["ur"])
        return out
    for k, v in zip(("x", "y", "z"), pose[:3, 3] / 1000.0):
        set_number(out, f[k], float(v), DECIMALS["ur"])
    r = angles if angles is not None else rotation_vectors([(t, pose)], ROTATION_KEYS)[0]
    for k, v in zip(("rx", "ry", "rz"), r):
        set_number(out, f[k], float(v), DECIMALS["ur"])
    return out


LANGUAGE = Language(
    name="urscript", title="URScript", suffixes=(".script", ".urscript"), read=read, write=write, request=request,
    encode=encode, units="m, rad", orientation="rotation vector (axis × angle, rad)",
    write_angles=partial(rotation_vectors, keys=ROTATION_KEYS),
    frames="set_tcp(p[…]); pose_trans(FEATURE, target) with FEATURE a pose variable",
    stamp=(r"^\s*def\s+\w+\s*\([^\n]*", "#"))
