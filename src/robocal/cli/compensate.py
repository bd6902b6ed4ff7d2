"""``robocal compensate``: corrected joint commands and Cartesian goals."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import base_link_option, json_flag, quiet_flag, summary_option, tip_link_option


def compensate_cmd(
    nominal: str = typer.Argument(..., help="nominal robot (what the controller runs): file or built-in name"),
    calibrated: str = typer.Argument(..., help="calibrated robot file"),
    goals: Path = typer.Argument(
        ..., metavar="TARGETS", help="goals CSV: q1..qn and/or x, y, z[, rx, ry, rz] (deg, mm)"
    ),
    out: Path = typer.Option(..., "--out", help="commands CSV to write"),
    truth: str | None = typer.Option(None, "--truth", help="simulated true robot: report its errors"),
    position_only: bool = typer.Option(
        False, "--position-only", help="match positions only (use for models calibrated from position data)"
    ),
    payload: float | None = typer.Option(None, "--payload", help="payload mass, kg, at goals without a payload "
                                         "column"),
    tool: str | None = typer.Option(None, "--tool", help="the TCP the commands are for, in the nominal model's "
                                    "tool frame (its flange): x,y,z[,rx,ry,rz] mm, deg (default: that frame); "
                                    "calibrated (or x,y,z[,rx,ry,rz],calibrated): the calibration measured that "
                                    "tool, and its calibrated tool stands in for it"),
    as_json: bool = json_flag("the summary (counts per status, validation against --truth)"),
    summary: Path | None = summary_option("the summary"),
    column: list[str] | None = typer.Option(None, "--column", help="map file columns: FILE=ROBOCAL[,FILE=ROBOCAL…]"),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    quiet: bool = quiet_flag(),
) -> None:
    """Corrected joint commands and Cartesian goals that make the calibrated robot reach its goals.
    Exit status 3: the commands were written but some goals were not reached (each said, with why)."""
    import json
    import sys

    from .. import options as opt
    from ..compensation import compensate
    from ..io.atomic import atomic_write, together
    from ..io.goals import load_goals
    from ..io.robotfile import load_robot
    from .common import check_outputs, console, metrics_table, one_line, print_json, print_said

    check_outputs((nominal, calibrated, goals, truth), out=out, summary=summary)
    tcp, _, measured = opt.tool_frames([tool] if tool else None, "tool")  # checked before any work

    # the chain's links choose the nominal's chain (and the truth's); a calibrated URDF export
    # runs from its measuring_frame to its target, robocal's defaults
    nom, cal = load_robot(nominal, base_link=base_link, tip_link=tip_link), load_robot(calibrated)
    tru = None if truth is None else load_robot(truth, base_link=base_link, tip_link=tip_link)
    g = load_goals(goals, n_joints=nom.n_joints, columns=opt.column_map(column),
                   prismatic=tuple(map(bool, nom.prismatic)) if nom.prismatic.any() else None)
    from ..math.se3 import frame_from_values

    result = compensate(nom, cal, g, truth=tru, position_only=position_only or None, payload=payload,
                        tool=None if tcp is None else frame_from_values(tcp), calibrated_tool=bool(measured))
    document, summary_path = result.summary(), summary
    with together():
        result.save(out)
        if summary_path is not None:
            atomic_write(summary_path, json.dumps(document, indent=2) + "\n")
    print_said(result.warnings, quiet)
    missed = [i for i, s in enumerate(result.status) if s != "ok"]
    for i in missed[:10]:
        print(f"robocal: not reached: goal {g.ids[i]}: {result.status[i]}: {one_line(result.reasons[i])}",
              file=sys.stderr)
    if len(missed) > 10:
        print(f"robocal: … and {len(missed) - 10} more goals not reached (the status column of {out})",
              file=sys.stderr)
    if as_json:
        print_json(document)
    elif not quiet:
        c = console()
        c.print(f"{g.n} goals: " + ", ".join(f"{v} {k}" for k, v in document["status"].items()) + f"; wrote {out}")
        val = result.validation()
        if val is not None and "nominal_commands" in val:
            c.print(metrics_table("true robot at the goals (rows with status ok)",
                                  {"nominal commands": val["nominal_commands"],
                                   "compensated commands": val["compensated_commands"]}))
    if missed:  # written, but not every goal reached: a script must not take it for a full success
        raise typer.Exit(3)


def register(app: typer.Typer) -> None:
    app.command("compensate")(compensate_cmd)
