"""robocal's own exception and warning types.

Every problem with user input (a file, an option value, data that cannot determine
what was asked) is raised as :class:`InputError`.  The command line turns it into one
line on stderr and exit code 2; the Python API lets it propagate, so a notebook user
sees the same message.
"""

from __future__ import annotations

import os
import re


class InputError(ValueError):
    """Bad input: the message names the file (or option), the row/column or key, and what is wrong.

    ``option`` is set when the culprit is an option value (``"loss"``, ``"box"``): the
    command line names it ``--loss``, the Python API ``loss``.  An option the message advises
    is written in backquotes (``"state it with `joint_unit` rad"``) and rendered the same way.
    """

    def __init__(
        self,
        what: str,
        *,
        source: str | os.PathLike | None = None,
        where: str | None = None,
        option: str | None = None,
    ):
        self.what = what
        self.source = None if source is None else str(source)
        self.where = where
        self.option = option
        super().__init__(self.render())

    def render(self, cli: bool = False) -> str:
        """The one-line message; ``cli=True`` names an option as its command-line flag."""
        label = None
        if self.option is not None:
            label = f"--{self.option.replace('_', '-')}" if cli else f"option '{self.option}'"
        parts = [p for p in (self.source, label, self.where) if p]
        prefix = ": ".join(parts)
        what = re.sub(r"`(\w+)`", (lambda m: "--" + m.group(1).replace("_", "-")) if cli else (lambda m: m.group(1)),
                      self.what)
        return f"{prefix}: {what}" if prefix else what


class Interrupted(BaseException):
    """Ctrl-C on the command line (raised by its SIGINT handler, so that no library in between
    turns it into something else); ``kept`` says what a command kept of its work (a study's
    finished runs), None when it wrote nothing."""

    def __init__(self, kept: str | None = None):
        self.kept = kept
        super().__init__(kept or "interrupted")


class RobocalWarning(UserWarning):
    """A degenerate-but-valid situation: robocal still answers, and says what is off."""


class Note(str):
    """A message that informs (a choice made, a frame registered, a source read), where a plain
    message in a result's list is a warning: something to act on, or a reason to doubt a
    figure.  The command line prints it as ``robocal: note:`` (hidden by ``--quiet``), a result
    keeps it in ``notes``, and it is never raised as a Python warning."""

    __slots__ = ()


def split_notes(messages) -> tuple[list[str], list[str]]:
    """(warnings, notes) of a list of messages, each in its order, as plain strings."""
    warnings = [str(m) for m in messages if not isinstance(m, Note)]
    notes = [str(m) for m in messages if isinstance(m, Note)]
    return warnings, notes

