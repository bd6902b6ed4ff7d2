"""A robot program as filtering sees it: its files, and the targets in them as spans of numbers.

Every language reader (:mod:`.krl`, :mod:`.rapid`, :mod:`.urscript`, :mod:`.fanuc`) finds its
targets and records, for each number of a target, where it stands in its file's text (a
:class:`Field`); writing replaces exactly those characters and nothing else, so comments, speeds,
zones, other declarations, line endings, the encoding and the layout stay byte for byte.
"""

from __future__ import annotations

import bisect
import functools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..exceptions import InputError
from ..io.table import split_top  # noqa: F401  (the languages' readers take it from here)

#: a number token, whole: not the tail of a name (P1), nor cut short by a letter or a dot (1.5x)
NUMBER = r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.])"
_NUMBER = re.compile(NUMBER)
#: a number with the spaces around it, as list items are written (``[ 1.5, -2 ]``)
SPACED_NUMBER = r"\s*" + NUMBER + r"\s*"


class Field(NamedTuple):
    """One number of a target: its span [start, end) in its file's text and the text there (a
    tuple: a large program has hundreds of thousands)."""

    start: int
    end: int
    text: str

    @property
    def value(self) -> float:
        return float(self.text)

    def decimals(self) -> int:
        t = self.text
        mantissa = t.lower().partition("e")[0] if "e" in t or "E" in t else t
        dot = mantissa.find(".")
        return len(mantissa) - dot - 1 if dot >= 0 else 0

    def written(self, value: float, decimals: int) -> str:
        """``value`` with ``decimals`` decimals in this field's style: an explicit sign if it had one,
        no leading zero if it had none (FANUC's ``-.500``).  A corrected number keeps at least the
        decimals it had (:func:`~robocal.filtering.language.set_number`)."""
        if "e" in self.text or "E" in self.text:
            return f"{value:.{decimals}e}"
        text = f"{value:.{decimals}f}"
        if text.startswith("-") and float(text) == 0.0:
            text = text[1:]  # no "-0.000"
        if self.text.startswith("+") and not text.startswith("-"):
            text = "+" + text
        if self.text.lstrip("+-").startswith("."):  # written without the leading zero (-.12): so again
            text = text.replace("0.", ".", 1) if text.lstrip("+-").startswith("0.") else text
        return text

    def shows(self, value: float, decimals: int) -> bool:
        """Whether the written number stands for ``value`` at ``decimals`` decimals (within half a unit):
        then its text stays as it is (an identity filter is byte for byte the program)."""
        return abs(value - float(self.text)) < 0.5 * 10.0 ** -decimals


#: a Field of (start, end, text), made at C speed: NamedTuple's own __new__ is a Python call, and a large
#: program's readers make hundreds of thousands
field_of = functools.partial(tuple.__new__, Field)


def in_text_order(t: Target) -> tuple[int, int]:
    """A target's place in its file: its line, then its first number's (a Field is (start, end, text):
    the least is the first)."""
    first = min(t.fields.values(), default=None)
    return t.line, 0 if first is None else first.start


def turn_by_angles(targets: list[Target], keys: tuple[str, str, str]) -> None:
    """The rotation of every pose target read without one, R = Rz(c)·Ry(b)·Rx(a) of its fields ``keys`` =
    (a, b, c) in degrees, all in one batched call (one at a time, a rotation was 50 µs of numpy's
    small-array overhead; batched, the same bits)."""
    from ..math.so3 import rpy_to_matrix

    poses = [t for t in targets if t.kind == "pose" and t.rotation is None and t.fields]
    if poses:
        angles = np.radians([[float(t.fields[k].text) for k in keys] for t in poses])
        for t, R in zip(poses, rpy_to_matrix(angles)):
            t.rotation = R


def fields_in(text: str, offset: int = 0) -> list[Field]:
    """Every number of ``text`` as a Field (spans shifted by ``offset``)."""
    return [field_of((m.start() + offset, m.end() + offset, m.group())) for m in _NUMBER.finditer(text)]


@dataclass
class ProgramFile:
    """One file of a program: where it was read, its text exactly as written, its encoding, and
    the suffix of the file it is written to (None: the --out path itself)."""

    path: str
    text: str
    encoding: str
    out_suffix: str | None = None


@dataclass(frozen=True)
class Offset:
    """A motion that reaches a target through an offset of literal values, which the controller adds
    to the target as the program runs: RAPID ``Offs`` (``kind`` ``frame``: the position moved by D's
    translation in the target's own frame, its orientation kept), ``RelTool`` and URScript
    ``pose_trans`` (``tool``: T · D, about the tool), URScript ``pose_add`` (``add``: the position
    moved by D's translation, the rotation R · R_D).  D: 4×4, mm; ``line`` the motion's; ``text`` as
    written."""

    kind: str
    D: np.ndarray
    line: int
    text: str

    def apply(self, T: np.ndarray) -> np.ndarray:
        """The pose (…, 4, 4) the motion goes to for the target T (…, 4, 4), both in the target's frame."""
        T = np.asarray(T, float)
        if self.kind == "tool":
            return T @ self.D
        out = np.array(T, copy=True)
        out[..., :3, 3] = T[..., :3, 3] + self.D[:3, 3]
        if self.kind == "add":
            out[..., :3, :3] = T[..., :3, :3] @ self.D[:3, :3]
        return out


@dataclass
class Target:
    """A target of a program: ``name`` (the variable, or ``line N`` for an inline one), the file
    (index into :attr:`Program.files`) and line it is on, and its kind: ``pose`` (position mm and
    rotation as the program states them, in its user frame) or ``joints`` (the controller's joint
    values, rad, mm for a sliding joint).  ``fields`` maps each named number to its place;
    ``config`` holds the configuration data as the language writes them (KRL S and T, RAPID cf1
    cf4 cf6 cfx, FANUC's CONFIG string); ``hint`` the joints a pose was taught at or is to be
    solved near (a PolyScope waypoint's NAME_q, URScript's qnear; controller values, rad);
    ``tool`` and ``user`` the names of the frames it is taught in (None: the program names none);
    ``unsupported``: why it cannot be corrected (a position register, an offset, a relative motion);
    ``offsets``: the motions that reach it through an offset of literal values (:class:`Offset`): the
    target is corrected and they take its correction."""

    name: str
    line: int
    kind: str
    fields: dict[str, Field]
    position: np.ndarray | None = None
    rotation: np.ndarray | None = None
    q: np.ndarray | None = None
    config: dict = field(default_factory=dict)
    hint: np.ndarray | None = None
    file: int = 0
    tool: str | None = None
    user: str | None = None
    unsupported: str | None = None
    offsets: list = field(default_factory=list)


@dataclass
class Program:
    """A program's language, files, targets in order of appearance, the frames it declares (TCPs
    in the flange frame, user frames in the controller's world; 4×4 mm) and what it does not
    say of frames it names (``missing``: name → why), and what was said on reading it."""

    language: str
    source: str
    files: list[ProgramFile]
    targets: list[Target]
    tools: dict[str, np.ndarray] = field(default_factory=dict)
    users: dict[str, np.ndarray] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def text(self) -> str:
        return self.files[0].text


def rewrite(text: str, changes: list[tuple[Field, str]]) -> str:
    """The text with each field's characters replaced by its new text (spans must not overlap)."""
    out, last = [], 0
    for f, new in sorted(changes, key=lambda c: c[0].start):
        out.append(text[last:f.start])
        out.append(new)
        last = f.end
    out.append(text[last:])
    return "".join(out)


def blank_comments(text: str, marker: str) -> str:
    """The text with strings and comments (``marker`` to the end of a line) blanked by spaces, so
    that patterns find only code and every index still points into the original text."""
    out = []
    for line in text.splitlines(keepends=True):
        body = line.rstrip("\r\n")
        newline = line[len(body):]
        if '"' in body:
            body = re.sub(r'"[^"]*"', lambda m: " " * len(m.group()), body)
        cut = body.find(marker)
        if cut >= 0:
            body = body[:cut] + " " * (len(body) - cut)
        out.append(body + newline)
    return "".join(out)


def keyword_matches(pattern: re.Pattern, code: str, keywords: tuple[str, ...]):
    """``pattern.finditer(code)`` for a pattern that can match only where one of ``keywords`` (lower
    case) begins, case aside: the same matches, the pattern tried only there.  A case-insensitive
    pattern has no literal prefix for ``re`` to scan for, so it is tried at every character of the
    module (30–45 ms a pattern for a module of 10 000 targets, against ~2 ms for ``str.find``).
    Where the code is not ASCII, Unicode's case folding could match a keyword ``str.lower`` does not
    give (``ı``, ``ſ``): the pattern scans as usual."""
    if not code.isascii():
        yield from pattern.finditer(code)
        return
    low = code.lower()
    starts = []
    for word in keywords:
        i = low.find(word)
        while i >= 0:
            starts.append(i)
            i = low.find(word, i + 1)
    yield from matches_at(pattern, code, sorted(starts))


def matches_at(pattern: re.Pattern, code: str, starts):
    """``pattern.finditer(code)`` for a pattern that can match only at ``starts`` (ascending): the
    same matches, the pattern tried only there."""
    end = 0
    for i in starts:
        if i < end:  # finditer goes on where the last match ended
            continue
        m = pattern.match(code, i)
        if m is not None:
            yield m
            end = max(m.end(), i + 1)


class Lines:
    """Line numbers of a text's character indices, its line breaks found once."""

    def __init__(self, text: str):
        self.breaks = [m.start() for m in re.finditer("\n", text)]

    def of(self, index: int) -> int:
        """1-based line number of a character index."""
        return bisect.bisect_left(self.breaks, index) + 1


def line_of(text: str, index: int) -> int:
    """1-based line number of a character index (once; a reader that asks often keeps a :class:`Lines`)."""
    return text.count("\n", 0, index) + 1


#: byte order marks, longest first (UTF-32's LE mark begins with UTF-16's)
_BOMS = ((b"\xff\xfe\x00\x00", "utf-32-le"), (b"\x00\x00\xfe\xff", "utf-32-be"), (b"\xef\xbb\xbf", "utf-8"),
         (b"\xff\xfe", "utf-16-le"), (b"\xfe\xff", "utf-16-be"))


def decode(raw: bytes, source) -> tuple[str, str]:
    """A file's text and its encoding: by its byte order mark (UTF-8/16/32), else UTF-8, else
    Windows-1252 (KUKA and ABB files often are), else Latin-1.  The encoding's name records the
    mark (``utf-16-le+bom``) so that :func:`encode` writes the same bytes back."""
    for bom, codec in _BOMS:
        if raw.startswith(bom):
            try:
                return raw[len(bom):].decode(codec), f"{codec}+bom"
            except UnicodeDecodeError:
                raise InputError(f"is marked {codec.upper()} but does not decode as such", source=source) from None
    wide = _without_mark(raw)
    if wide is not None:
        return raw.decode(wide), wide
    for codec in ("utf-8", "cp1252"):
        try:
            return raw.decode(codec), codec
        except UnicodeDecodeError:
            continue
    return raw.decode("latin-1"), "latin-1"


def _without_mark(raw: bytes) -> str | None:
    """UTF-16 or UTF-32 written without a byte order mark, told by where the zero bytes of its
    ASCII fall (a program is mostly ASCII; no 8-bit text has a zero byte), or None."""
    head = raw[:4096]
    if len(head) < 4 or b"\x00" not in head:
        return None
    for codec, width, where in (("utf-32-le", 4, (1, 2, 3)), ("utf-32-be", 4, (0, 1, 2)), ("utf-16-le", 2, (1,)),
                                ("utf-16-be", 2, (0,))):
        n = len(head) // width * width
        units = [head[i:i + width] for i in range(0, n, width)]
        if sum(all(u[k] == 0 for k in where) for u in units) >= 0.9 * len(units):
            try:
                raw.decode(codec)
            except UnicodeDecodeError:
                continue
            return codec
    return None


def check_finite(program: Program) -> None:
    """Every number a target or frame of the program holds must be finite: 1e999 reads as
    infinity, and a target there would be flagged unreachable rather than refused."""
    for t in program.targets:
        for key, f in t.fields.items():  # (text fields, FANUC's CONFIG letters, are not numbers)
            text = f.text
            # only an exponent or over 300 digits reaches 1.8e308: the rest need no parsing again
            if (len(text) > 300 or "e" in text or "E" in text) and _NUMBER.fullmatch(text) and \
                    not math.isfinite(f.value):
                raise InputError(f"{t.name}: its {key} {f.text} is not a finite number",
                                 source=program.files[t.file].path, where=f"line {t.line}")
    for kind, frames in (("tool", program.tools), ("user frame", program.users)):
        for name, T in frames.items():
            if not np.all(np.isfinite(T)):
                raise InputError(f"the {kind} {name} holds a number that is not finite", source=program.source)


def encode(text: str, encoding: str) -> bytes:
    """The bytes of a text in the encoding :func:`decode` found (its byte order mark included)."""
    codec, _, bom = encoding.partition("+")
    if not bom:
        return text.encode(codec)
    mark = next(b for b, c in _BOMS if c == codec)
    return mark + text.encode(codec)


def read_file(path: Path, what: str = "program file") -> tuple[str, str]:
    if not path.is_file():
        raise InputError(f"no such {what}", source=path)
    return decode(path.read_bytes(), path)
