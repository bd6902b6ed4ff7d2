"""Reading text files with one-line errors, and writing outputs atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..exceptions import InputError


def read_text(path: str | os.PathLike, what: str) -> str:
    """A text file's content (UTF-8, a byte-order mark tolerated), or an InputError naming it."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such {what}", source=path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {what} ({exc.__class__.__name__})", source=path) from None


def atomic_write(path: str | os.PathLike, data: str | bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    A crash or an error half-way never leaves a truncated output file, and an existing
    file is only replaced once the new content is complete.
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
