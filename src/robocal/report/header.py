"""The run header every report opens with: who made it, when, from what (file digests), and how."""

from __future__ import annotations

import html
from pathlib import Path


def digest(path) -> str:
    """The SHA-256 of a file, or why there is none."""
    import hashlib

    p = Path(str(path))
    return hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "(not a file)"


def run_header(command: str | None, api: str, files: list[tuple[str, str]], rows: list[tuple[str, str]]) -> str:
    """A table: robocal's version, the date, the command (or the Python call ``api``), each input
    file with its SHA-256, then ``rows`` (name, value)."""
    import datetime

    from .. import __version__

    head = [("robocal", __version__), ("date", datetime.datetime.now().astimezone().isoformat(timespec="seconds")),
            ("command", command or f"Python API ({api})"),
            *((f"{k} file", f"{v} — SHA-256 {digest(v)}") for k, v in files), *rows]
    body = "".join(f"<tr><td>{html.escape(k)}</td><td class='l'>{html.escape(str(v))}</td></tr>" for k, v in head)
    return f"<table class='head'>{body}</table>"
