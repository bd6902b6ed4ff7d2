"""Program filtering: the targets of a KUKA KRL, ABB RAPID or URScript program rewritten so that
the uncalibrated controller drives the real robot where the programmer meant (:mod:`.correct`),
nothing else in the file touched (:mod:`.program`, :mod:`.write`)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from .correct import Correction, filter_targets
from .program import Program

FORMATS = ("auto", "krl", "rapid", "urscript")
SUFFIXES = {".src": "krl", ".dat": "krl", ".mod": "rapid", ".modx": "rapid", ".prg": "rapid", ".sys": "rapid",
            ".script": "urscript", ".urscript": "urscript"}


def read_program_text(path: Path) -> tuple[str, str]:
    """A program file's text exactly as written (line endings kept) and its encoding."""
    if not path.is_file():
        raise InputError("no such program file", source=path)
    raw = path.read_bytes()
    for encoding in ("utf-8", "cp1252"):  # KUKA and ABB files are often Windows-1252
        try:
            return raw.decode(encoding), encoding
        except UnicodeDecodeError:
            continue
    return raw.decode("latin-1"), "latin-1"


def language_of(path: Path, fmt: str = "auto") -> str:
    from .. import options as opt

    opt.choice(fmt, FORMATS, "format", "program format")
    if fmt != "auto":
        return fmt
    language = SUFFIXES.get(path.suffix.lower())
    if language is None:
        raise InputError(f"cannot tell the language from the suffix {path.suffix!r} (.src/.dat KRL, .mod/.prg RAPID, "
                         ".script URScript): give --format", source=path)
    return language


def load_program(path: str | Path, fmt: str = "auto") -> tuple[Program, dict[str, str]]:
    """A program and the encodings of its files (``main``, and ``dat`` for KRL)."""
    path = Path(path)
    language = language_of(path, fmt)
    if language == "krl":
        from .krl import load_krl

        src = path.with_suffix(".src") if path.suffix.lower() == ".dat" else path
        dat = src.with_suffix(".dat")
        text, enc = read_program_text(src)
        dat_text, dat_enc = read_program_text(dat) if dat.is_file() else (None, None)
        return load_krl(text, dat_text, str(src)), {"main": enc, "dat": dat_enc}
    text, enc = read_program_text(path)
    if language == "rapid":
        from .rapid import load_rapid

        return load_rapid(text, str(path)), {"main": enc}
    from .urscript import load_urscript

    return load_urscript(text, str(path)), {"main": enc}


@dataclass
class FilterResult:
    """A filtered program: its texts (the program, and a KRL program's .dat), the correction of
    every target, and what was said."""

    program: Program
    text: str
    dat: str | None
    corrections: list[Correction]
    notes: list[str]
    #: the encodings the files were read in (``main``, and ``dat`` for KRL), to write them back in
    encodings: dict

    @property
    def flagged(self) -> list[Correction]:
        return [c for c in self.corrections if not c.corrected]

    def to_dict(self) -> dict:
        ok = [c for c in self.corrections if c.corrected]
        return {"program": self.program.source, "language": self.program.language,
                "targets": [c.to_dict() for c in self.corrections], "corrected": len(ok),
                "flagged": len(self.flagged),
                "largest_correction_mm": max((c.moved_mm for c in ok), default=0.0),
                "largest_joint_change_deg": max((c.joints_deg for c in ok), default=0.0), "notes": self.notes}

    def json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"


def filter_program(calibrated, program: str | Path, nominal, *, tool: np.ndarray | None = None,
                   fmt: str = "auto", seed: int = 0) -> FilterResult:
    """Filter ``program`` for the accurate model ``calibrated`` (a robot file or Robot, its whole
    model) on a controller running ``nominal`` (name, file or Robot); tool: the TCP (4×4,
    flange frame, mm), default the program's tool data, else the nominal model's tool."""
    from ..io.robotfile import load_robot
    from .write import filtered_texts

    accurate, nom = load_robot(calibrated), load_robot(nominal)
    if accurate.n_joints != nom.n_joints:
        raise InputError(f"the calibrated model has {accurate.n_joints} joints, the nominal {nom.n_joints}",
                         source=str(calibrated))
    prog, encodings = load_program(program, fmt)
    corrections, notes = filter_targets(prog, nom, accurate, tool, seed)
    text, dat = filtered_texts(prog, corrections)
    return FilterResult(prog, text, dat, corrections, notes, encodings)
