"""robocal's own error and warning types.

Every problem with user input (a file, a command-line value, data that cannot
determine what was asked) is raised as :class:`InputError`.  The command line
turns it into one line on stderr and exit code 2; the Python API lets it
propagate so a notebook user sees the same message.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


class InputError(ValueError):
    """Bad input: the message names the file, the row/column or key, and what is wrong."""

    def __init__(self, what: str, *, source: str | os.PathLike | None = None, where: str | None = None):
        self.what = what
        self.source = None if source is None else str(source)
        self.where = where
        parts = [p for p in (self.source, where) if p]
        prefix = ": ".join(parts)
        super().__init__(f"{prefix}: {what}" if prefix else what)


class RobocalWarning(UserWarning):
    """A degenerate-but-valid situation: robocal still answers, but says what is off."""


def atomic_write(path: str | os.PathLike, data: str | bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    A crash or an error half-way never leaves a truncated output file, and an
    existing file is only replaced once the new content is complete.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError("output folder does not exist", source=path)
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, mode, **({} if mode == "wb" else {"encoding": "utf-8", "newline": ""})) as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; outputs get ordinary permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
