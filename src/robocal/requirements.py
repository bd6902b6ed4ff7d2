"""Requirements a plant's CI puts on a result: ``--require "validation_rms<=0.5"``.

A requirement names a figure of the command (mm), a comparison and a value.  Parsing is strict (a
malformed or unknown one is bad input); checking gives the requirements not met, which the
command line turns into exit status :data:`FAILED` and one line each on stderr, as FIGAROH's
``verify()`` gives a verdict a script can read.
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass

from .exceptions import InputError

#: the exit status of a command whose requirements were not met (2 is bad input, 3 a partial result)
FAILED = 4
#: the figures each command can be held to (mm)
FIGURES = {
    "calibrate": ("rms", "max", "cv_rms", "validation_rms", "validation_max"),
    "evaluate": ("rms", "mean", "std", "max", "point_spread_rms", "distance_error_rms", "plane_rms"),
    # ISO 9283, of the last campaign given (the one after compensation): the largest over its poses
    # (pairs of poses) of pose accuracy AP_p, repeatability RP_l, |distance accuracy AD_p| and RD
    "iso9283": ("AP", "RP", "AD", "RD"),
}
#: verdicts a command can be held to, by a bare word: its figures hold True or False under the
#: word, and the reason under ``WORD_reason``
VERDICTS = {"calibrate": ("physical",), "evaluate": (), "iso9283": ()}
_OPS = {"<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt}
_PATTERN = re.compile(r"^\s*([A-Za-z_]+)\s*(<=|>=|<|>)\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*$")


@dataclass(frozen=True)
class Requirement:
    figure: str
    op: str
    value: float

    def met(self, figures: dict) -> bool:
        if not self.op:  # a verdict
            return bool(figures[self.figure])
        return bool(_OPS[self.op](figures[self.figure], self.value))

    def __str__(self) -> str:
        return self.figure if not self.op else f"{self.figure}{self.op}{self.value:g}"


def parse_requirements(items, command: str) -> list[Requirement]:
    """``FIGURE<=VALUE`` items (each may be a comma list) as requirements of ``command``."""
    out = []
    for item in items or ():
        for text in str(item).split(","):
            if text.strip() in VERDICTS[command]:
                out.append(Requirement(text.strip(), "", math.nan))
                continue
            m = _PATTERN.match(text)
            if m is None:
                words = "".join(f" or {w}" for w in VERDICTS[command])
                raise InputError(f"expected FIGURE<=VALUE (or <, >=, >), e.g. rms<=0.5{words}, got {text.strip()!r}",
                                 option="require")
            figure, op, value = m.group(1), m.group(2), float(m.group(3))
            if figure not in FIGURES[command]:
                raise InputError(f"unknown figure {figure!r} (expected {' | '.join(FIGURES[command])})",
                                 option="require")
            if not math.isfinite(value):
                raise InputError(f"the value of {figure} must be finite, got {m.group(3)!r}", option="require")
            out.append(Requirement(figure, op, value))
    return out


def unmet(requirements: list[Requirement], figures: dict) -> list[str]:
    """One line per requirement not met, naming it and the figure reached (a verdict: its reason)."""
    out = []
    for r in requirements:
        if r.met(figures):
            continue
        if not r.op:
            out.append(f"requirement not met: {r} ({figures.get(f'{r.figure}_reason', 'not so')})")
        elif math.isfinite(figures[r.figure]):
            out.append(f"requirement not met: {r} ({r.figure} = {figures[r.figure]:.4g} mm)")
        else:
            out.append(f"requirement not met: {r} (this run has no {r.figure})")
    return out
