"""``robocal robots``: the built-in robots."""

from __future__ import annotations

import typer


def robots_cmd() -> None:
    """List the built-in robots and the published source of each table."""
    from ..io.builtins import builtin_summaries
    from .common import console, table

    rows = [(r["name"], r["robot"], r["convention"], str(r["joints"]), r["source"]) for r in builtin_summaries()]
    console().print(table("built-in robots", ("name", "robot", "convention", "joints", "source"), rows, "left"))


def register(app: typer.Typer) -> None:
    app.command("robots")(robots_cmd)
