"""A robot program as filtering sees it: its text, and the targets in it as spans of numbers.

Every language reader (:mod:`.krl`, :mod:`.rapid`, :mod:`.urscript`) finds its targets and
records, for each number of a target, where it stands in the text (a :class:`Field`); writing
replaces exactly those characters and nothing else, so comments, speeds, zones, other
declarations, line endings and the layout stay byte for byte.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@dataclass(frozen=True)
class Field:
    """One number of a target: its span [start, end) in the text and the text there."""

    start: int
    end: int
    text: str

    @property
    def value(self) -> float:
        return float(self.text)

    def formatted(self, value: float, minimum_decimals: int) -> str:
        """``value`` written in this field's style: as many decimals as it had, at least
        ``minimum_decimals`` (enough for the correction), an explicit sign if it had one."""
        mantissa = self.text.lower().split("e")[0]
        decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
        if "e" in self.text.lower():
            return f"{value:.{max(decimals, minimum_decimals)}e}"
        decimals = max(decimals, minimum_decimals)
        text = f"{value:.{decimals}f}"
        if text.startswith("-") and float(text) == 0.0:
            text = text[1:]  # no "-0.000"
        if self.text.startswith("+") and not text.startswith("-"):
            text = "+" + text
        if re.match(r"[-+]?\.", self.text):  # written without the leading zero (-.12): so again
            text = re.sub(r"^([-+]?)0\.", r"\1.", text)
        return text


def fields_in(text: str, offset: int = 0) -> list[Field]:
    """Every number of ``text`` as a Field (spans shifted by ``offset``)."""
    return [Field(m.start() + offset, m.end() + offset, m.group()) for m in _NUMBER.finditer(text)]


@dataclass
class Target:
    """A target of a program: ``name`` (the variable, or ``line N`` for an inline one), the
    line it is on, and its kind: ``pose`` (position mm and rotation in the robot's base frame
    as the program states it) or ``joints`` (q rad, n).  ``fields`` maps each named number
    (x, y, z, a, b, c, q1 … or a language's own) to its place; ``config`` holds what the
    language says of the arm's configuration (KRL S and T, RAPID cf1 cf4 cf6 cfx)."""

    name: str
    line: int
    kind: str
    fields: dict[str, Field]
    position: np.ndarray | None = None
    rotation: np.ndarray | None = None
    q: np.ndarray | None = None
    config: dict[str, int] = field(default_factory=dict)
    #: for a pose, the joints it was taught at, where the program keeps them (rad)
    taught: np.ndarray | None = None


@dataclass
class Program:
    """A program's text, its language, its targets in order of appearance, and the TCP (4×4,
    flange frame, mm) its tool data declare, if any."""

    text: str
    language: str
    source: str
    targets: list[Target]
    tool: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    #: the frame the targets are stated in, in the robot's base frame (KRL $BASE, RAPID wobj)
    base: np.ndarray | None = None
    #: KRL: the .dat's text, and the index of its first target in ``targets``
    dat: str | None = None
    split: int | None = None


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
        body = re.sub(r'"[^"]*"', lambda m: " " * len(m.group()), body)
        cut = body.find(marker)
        if cut >= 0:
            body = body[:cut] + " " * (len(body) - cut)
        out.append(body + newline)
    return "".join(out)


def first_of(used: set[str], declared: dict, default: str, what: str, source: str, notes: list[str],
             missing: str) -> tuple[object | None, bool]:
    """The declared value of the first (sorted) name in ``used`` other than ``default``, saying
    when it is not declared (``missing``: what happens then) or when there are several; and
    whether ``default`` alone is used."""
    named = sorted(used - {default})
    if not named:
        return None, default in used
    if len(named) > 1:
        notes.append(f"the motions use several {what}s ({', '.join(named)}); {named[0]} is taken for every target")
    if named[0] in declared:
        return declared[named[0]], False
    notes.append(f"the motions use {what} {named[0]}, which {source} does not declare: {missing}")
    return None, False


def line_of(text: str, index: int) -> int:
    """1-based line number of a character index."""
    return text.count("\n", 0, index) + 1
