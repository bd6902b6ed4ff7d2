"""``robocal robots``: the built-in robots."""

from __future__ import annotations

import typer


def robots_cmd() -> None:
    """List the built-in robots and the published source of each table."""
    from ..io.robotfile import builtin_names, builtin_source, load_robot
    from .common import console, table

    rows = []
    for name in builtin_names():
        r = load_robot(name)
        rows.append((name, r.name, r.convention, str(r.n_joints), builtin_source(name)))
    console().print(table("built-in robots", ("name", "robot", "convention", "joints", "source"), rows, "left"))


def register(app: typer.Typer) -> None:
    app.command("robots")(robots_cmd)
