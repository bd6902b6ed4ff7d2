"""``robocal evaluate``: error metrics of a model on measured data."""

from __future__ import annotations

from pathlib import Path

import typer


def evaluate_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    data: Path = typer.Argument(..., help="measurement CSV"),
    as_json: bool = typer.Option(False, "--json", help="print the metrics as JSON"),
    column: list[str] | None = typer.Option(None, "--column", help="map file columns: FILE=ROBOCAL[,FILE=ROBOCAL…]"),
) -> None:
    """Error metrics (SPEC §8) of a robot model on measured data."""
    import json

    from .. import options as opt
    from ..evaluation import evaluate
    from .common import console, metrics_table

    metrics = evaluate(robot, data, columns=opt.column_map(column))
    if as_json:
        print(json.dumps(metrics.to_dict(), indent=2))
    else:
        console().print(metrics_table(f"{robot} on {data} ({metrics.n} poses)", {"error": metrics}))


def register(app: typer.Typer) -> None:
    app.command("evaluate")(evaluate_cmd)
