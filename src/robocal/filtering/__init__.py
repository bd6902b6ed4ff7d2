"""Program filtering: the targets of a KUKA KRL, ABB RAPID, URScript or FANUC TP program rewritten
so that the uncalibrated controller drives the real robot where the programmer meant
(:mod:`.correct`), nothing else in the files touched (:mod:`.program`, :mod:`.write`).  The
languages are a registry (:mod:`.language`): one module each."""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..exceptions import InputError, Note
from .correct import Correction, Frames, check, plan, summary_notes
from .language import Language, language_of, languages, stamped
from .program import Program, check_finite, encode


def load_program(path: str | Path, fmt: str = "auto", frames_file: str | Path | None = None) -> Program:
    """A program in the language ``fmt`` (or its suffix's), with its companion files."""
    path = Path(path)
    program = language_of(path, fmt).read(path, None if frames_file is None else Path(frames_file))
    check_finite(program)
    return program


@dataclass
class FilterResult:
    """A filtered program: the texts of its files, the correction of every target, and what was said."""

    program: Program
    language: Language
    texts: list[str]
    corrections: list[Correction]
    notes: list[str]

    @property
    def text(self) -> str:
        return self.texts[0]

    @property
    def flagged(self) -> list[Correction]:
        return [c for c in self.corrections if not c.corrected]

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for c in self.corrections:
            out[c.status] = out.get(c.status, 0) + 1
        return out

    def outputs(self, out: str | Path, stamp: list[str] | None = None) -> list[tuple[Path, bytes]]:
        """(path, bytes) of every file to write for ``--out``: the program, and its companions beside it;
        ``stamp``: comment lines at the top of the program's module or routine where a number changed and
        the language has comment lines (:func:`~.language.stamped`)."""
        out = Path(out)
        texts = list(self.texts)
        if stamp and any(text != f.text for text, f in zip(texts, self.program.files)):  # a number changed
            texts[0] = stamped(texts[0], self.language, stamp)
        return [(out if f.out_suffix is None else out.with_suffix(f.out_suffix), encode(text, f.encoding))
                for f, text in zip(self.program.files, texts)]

    def to_dict(self) -> dict:
        ok = [c for c in self.corrections if c.corrected]
        return {"program": self.program.source, "language": self.language.name,
                "files": [f.path for f in self.program.files], "targets": [c.to_dict() for c in self.corrections],
                "corrected": len(ok), "flagged": len(self.flagged), "status": self.counts(),
                "largest_correction_mm": max((c.moved_mm or 0.0 for c in ok), default=0.0),
                "largest_joint_change_deg": max((c.joints_deg or 0.0 for c in ok), default=0.0), "notes": self.notes}

    def json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"


def _reread(program: Program, language: Language, texts: list[str], frames_file) -> Program:
    """The written files read back as the controller gets them (same names, in a scratch folder)."""
    with tempfile.TemporaryDirectory() as folder:
        paths = []
        for f, text in zip(program.files, texts):
            p = Path(folder) / Path(f.path).name
            p.write_bytes(encode(text, f.encoding))
            paths.append(p)
        return language.read(paths[0], frames_file)


def filter_program(calibrated, program: str | Path | Program, nominal, *, frames: Frames | None = None,
                   fmt: str = "auto", frames_file: str | Path | None = None, seed: int = 0) -> FilterResult:
    """Filter ``program`` (a path, or a :class:`~.program.Program` read by :func:`load_program`) for
    the accurate model ``calibrated`` (a robot file or Robot, its whole model) on a controller
    running ``nominal`` (name, file or Robot).  frames: TCPs and user frames
    given beside the program's own (:class:`~robocal.filtering.correct.Frames`); frames_file: a
    controller's file of frames (KRL ``$config.dat``; else found beside the program)."""
    from ..io.robotfile import load_robot

    accurate, nom = load_robot(calibrated), load_robot(nominal)
    if accurate.n_joints != nom.n_joints:
        raise InputError(f"the calibrated model has {accurate.n_joints} joints, the nominal {nom.n_joints}",
                         source=str(calibrated))
    frames = frames or Frames()
    frames_path = None if frames_file is None else Path(frames_file)
    if isinstance(program, Program):
        prog, language = program, languages()[program.language]
    else:
        language = language_of(Path(program), fmt)
        prog = language.read(Path(program), frames_path)
    corrections, notes = plan(prog, language, nom, accurate, frames, seed)
    from .write import filtered_texts, target_changes

    changes = target_changes(language, corrections)
    texts = filtered_texts(prog, language, corrections, changes)
    if any(c.corrected for c in corrections):
        again = _reread(prog, language, texts, frames_path)
        if len(again.targets) != len(prog.targets):
            raise RuntimeError("the filtered program reads back with another number of targets")
        check(prog, again, language, corrections, nom, accurate, frames, seed)
        if any(c.status == "check failed" for c in corrections):
            texts = filtered_texts(prog, language, corrections, changes)  # failed checks left as they were
    if any(c.corrected and c.target.kind == "pose" for c in corrections):
        notes = notes + [Note("a linear or circular motion is corrected at its taught points: the path between them "
                              "is the controller's interpolation of the corrected points")]
    return FilterResult(prog, language, texts, corrections, summary_notes(corrections, notes))


__all__ = ["Correction", "FilterResult", "Frames", "filter_program", "language_of", "languages", "load_program"]
