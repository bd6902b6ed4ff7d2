"""Reading text files with one-line errors, and writing outputs atomically.

A command that writes several files (a result, an export and its residual sidecar, a report)
writes them inside :func:`together`: each goes to a temporary file beside its destination,
and only when every one is complete are they all renamed.  A failure (or Ctrl-C) on the way
leaves every existing output as it was and no new one.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import tempfile
from collections.abc import Iterator
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


#: the temporary files of the :func:`together` block in effect: (temporary, destination)
_STAGED: contextvars.ContextVar[list[tuple[str, Path]] | None] = contextvars.ContextVar("staged", default=None)


def check_output(path: str | os.PathLike | None, option: str | None = None) -> Path | None:
    """An output file's path, checked before any work: not a folder, in a folder that exists
    and can be written.  ``option`` names the command-line option in the message."""
    if path is None:
        return None
    path = Path(path)
    where = {"source": path, "option": option}
    if path.is_dir():
        raise InputError("is a folder; give a file name", **where)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError("output folder does not exist", **where)
    if not os.access(directory, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise InputError("cannot be written (permission denied)", **where)
    return path


@contextlib.contextmanager
def together() -> Iterator[None]:
    """Every :func:`atomic_write` inside the block lands at once, when the block ends without
    an error; otherwise none does and the temporary files go."""
    outer = _STAGED.get()
    if outer is not None:  # nested: the outer block decides
        yield
        return
    staged: list[tuple[str, Path]] = []
    token = _STAGED.set(staged)
    try:
        yield
    except BaseException:
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
        raise
    finally:
        _STAGED.reset(token)
    for tmp, path in staged:
        os.replace(tmp, path)


def atomic_write(path: str | os.PathLike, data: str | bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    A crash or an error half-way never leaves a truncated output file, and an existing
    file is only replaced once the new content is complete; inside :func:`together` the
    rename waits for the block's end.
    """
    path = check_output(path)
    directory = path.parent if str(path.parent) else Path(".")
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, mode, **({} if mode == "wb" else {"encoding": "utf-8", "newline": ""})) as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; outputs get ordinary permissions
        staged = _STAGED.get()
        if staged is None:
            os.replace(tmp, path)
        else:
            staged.append((tmp, path))
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
