"""Writing corrected targets back: only their numbers change, each in its language's style
(:attr:`~robocal.filtering.language.Language.write`), every file of the program in its encoding."""

from __future__ import annotations

from .correct import Correction
from .language import Language
from .program import Program, rewrite


def target_changes(language: Language, corrections: list[Correction]) -> list[list | None]:
    """Each corrected target's changes of its numbers (None for a target left as it was)."""
    angles: dict[int, object] = {}
    if language.write_angles is not None:
        poses = [c for c in corrections if c.corrected and c.target.kind == "pose"]
        angles = dict(zip(map(id, poses), language.write_angles([(c.target, c.pose) for c in poses])))
    out: list[list | None] = []
    for c in corrections:
        if not c.corrected:
            out.append(None)
        elif id(c) in angles:
            out.append(language.write(c.target, c.pose, c.q, c.config_after, angles=angles[id(c)]))
        else:
            out.append(language.write(c.target, c.pose, c.q, c.config_after))
    return out


def filtered_texts(program: Program, language: Language, corrections: list[Correction],
                   changes: list[list | None] | None = None) -> list[str]:
    """The text of each of the program's files with its corrected targets (``changes``: those of
    :func:`target_changes`, already computed; those of targets no longer corrected are left out)."""
    changes = target_changes(language, corrections) if changes is None else changes
    per_file: list[list] = [[] for _ in program.files]
    for c, ch in zip(corrections, changes):
        if c.corrected and ch:
            per_file[c.target.file] += ch
    return [rewrite(f.text, ch) for f, ch in zip(program.files, per_file)]
