"""``robocal evaluate``: error metrics of a model on measured data."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import base_link_option, tip_link_option


def evaluate_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    data: Path = typer.Argument(..., help="measurement CSV"),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    as_json: bool = typer.Option(False, "--json", help="print the metrics as JSON"),
    frames: str = typer.Option("none", "--frames", help="none | auto | base | base+tool: fit frames first"),
    column: list[str] | None = typer.Option(None, "--column", help="map file columns: FILE=ROBOCAL[,FILE=ROBOCAL…]"),
    joint_unit: str | None = typer.Option(None, "--joint-unit", help="deg | rad (default: deg, checked)"),
    length_unit: str | None = typer.Option(None, "--length-unit", help="mm | m (default: mm)"),
    payload: float | None = typer.Option(None, "--payload", help="payload mass, kg, for data without a payload "
                                         "column"),
) -> None:
    """Error metrics (MODEL §6) of a robot model on measured data."""
    import json

    from .. import options as opt
    from ..evaluation import evaluate
    from .common import console, load, metrics_table, print_warnings

    ev = evaluate(load(robot, base_link, tip_link), data, columns=opt.column_map(column), frames=frames,
                  joint_unit=joint_unit, length_unit=length_unit, payload=payload)
    print_warnings(ev.notes)
    if as_json:
        print(json.dumps(ev.to_dict(), indent=2))
        return
    title = f"{robot} on {data} ({ev.metrics.n} poses{'' if ev.frames == 'none' else ', frames ' + ev.frames})"
    columns = {"error": ev.metrics, **(ev.per_target if len(ev.per_target) > 1 else {})}
    console().print(metrics_table(title, columns))


def register(app: typer.Typer) -> None:
    app.command("evaluate")(evaluate_cmd)
