"""``robocal reproduce``: re-run a paper's experiment."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import quiet_flag


def reproduce_cmd(
    scenario: str = typer.Argument(..., help="wen2019 | kou2022 | chen2023 | all"),
    out: Path = typer.Option(..., "--out", help="folder for summary.md, results.json and figures"),
    quick: bool = typer.Option(False, "--quick", help="shortened settings (a smoke test, not the paper's)"),
    runs: int = typer.Option(10, "--runs", help="runs per swarm method (kou2022)"),
    seed: int = typer.Option(0, "--seed", help="seeds the runs: run k uses seed + k"),
    workers: int | None = typer.Option(None, "--workers", help="local worker processes for the repeated runs "
                                       "(default: this process, the fairest timing)"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="a Dask scheduler's address for the repeated "
                                         "runs, tcp://HOST:PORT"),
    quiet: bool = quiet_flag(),
) -> None:
    """Re-run a paper's experiment and write what it published beside what robocal measures."""
    from ..papers.reproduce import reproduce
    from .common import console, say_on_stderr

    reproduce(scenario, out, quick=quick, runs=runs, seed=seed, say=say_on_stderr(quiet), workers=workers,
              scheduler=scheduler)
    if quiet:
        return
    from ..papers.reproduce import SCENARIOS, verdict_counts

    for name in SCENARIOS if scenario == "all" else (scenario,):
        summary = (out / name if scenario == "all" else out) / "summary.md"
        counts = verdict_counts(summary.read_text(encoding="utf-8"))
        said = ", ".join(f"{n} {label}" for label, n in counts.items() if n)
        console().print(f"{name}: {sum(counts.values())} published figures: {said} (see {summary})")


def register(app: typer.Typer) -> None:
    app.command("reproduce")(reproduce_cmd)
