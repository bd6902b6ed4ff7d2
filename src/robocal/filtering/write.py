"""Writing corrected targets back: only their numbers change, each in its language's style
(:attr:`~robocal.filtering.language.Language.write`), every file of the program in its encoding."""

from __future__ import annotations

from .correct import Correction
from .language import Language
from .program import Program, rewrite


def filtered_texts(program: Program, language: Language, corrections: list[Correction]) -> list[str]:
    """The text of each of the program's files with its corrected targets."""
    changes: list[list] = [[] for _ in program.files]
    for c in corrections:
        if c.corrected:
            changes[c.target.file] += language.write(c.target, c.pose, c.q, c.config_after)
    return [rewrite(f.text, ch) for f, ch in zip(program.files, changes)]
