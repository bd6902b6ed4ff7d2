"""``robocal study``: a Monte-Carlo comparison of methods, locally or on a Dask cluster."""

from __future__ import annotations

from pathlib import Path

import typer


def study_cmd(
    study: Path = typer.Argument(..., help="study file (TOML): robot, errors, poses, noise, methods, seeds, …"),
    out: Path = typer.Option(..., "--out", help="folder for runs.csv, summary.md and figures (resumes a study)"),
    workers: int | None = typer.Option(None, "--workers", help="local worker processes (default: all cores)"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="a Dask scheduler's address, tcp://HOST:PORT, "
                                         "instead of local workers"),
    batch: int | None = typer.Option(None, "--batch", help="runs per task (default: sized to the workers)"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar, no summary line"),
) -> None:
    """Run every seeded run of a study (each one: simulate, calibrate, validate) and summarise them."""
    from .. import options as opt
    from ..study.driver import run_study
    from ..study.spec import load_study
    from .common import console, progress_bar

    spec = load_study(study)  # every key checked before the first run
    if batch is not None:
        opt.integer(batch, "batch", minimum=1)
    total = len(spec.runs())
    with progress_bar(not quiet, "runs", total, best=False) as bar:
        progress = None if bar is None else (lambda done, n: bar(done, n, float("nan")))
        result = run_study(spec, out, workers=workers, scheduler=scheduler, batch=batch, progress=progress)
    if not quiet:
        rate = f", {result.ran / result.elapsed_s:.3g} runs/s on {result.executor}" if result.ran else ""
        console().print(f"{result.ran} runs done, {result.skipped} already in {out / 'runs.csv'}{rate}; "
                        f"wrote {out / 'summary.md'}")


def register(app: typer.Typer) -> None:
    app.command("study")(study_cmd)
