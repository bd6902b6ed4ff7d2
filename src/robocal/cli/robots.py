"""``robocal robots``: the built-in robots."""

from __future__ import annotations

import typer


def robots_cmd(
    urdf: str | None = typer.Option(None, "--urdf", metavar="ROBOT",
                                    help="print this robot (built-in name or file) as URDF instead"),
) -> None:
    """List the built-in robots and the published source of each table, or print one as URDF."""
    if urdf is not None:
        from ..io.robotfile import load_robot
        from ..io.urdf import urdf_text

        robot = load_robot(urdf)
        print(urdf_text(robot, comment=f"{robot.name}, written by robocal from {robot.source or urdf}; lengths in m, "
                                       "angles in rad; measuring_frame and target carry the robot file's base and "
                                       "tool"), end="")
        return
    from ..io.builtins import builtin_summaries
    from .common import console, table

    rows = [(r["name"], r["robot"], r["convention"], str(r["joints"]), r["source"]) for r in builtin_summaries()]
    console().print(table("built-in robots", ("name", "robot", "convention", "joints", "source"), rows, "left"))


def register(app: typer.Typer) -> None:
    app.command("robots")(robots_cmd)
