"""``robocal bench``: time the workloads of robocal's speed targets."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import json_flag, quiet_flag


def _load_peers(folder: Path):
    """The peers module of a source checkout (``benchmarks/peers.py``), or None."""
    import importlib.util

    path = folder / "peers.py"
    if not path.is_file():
        return None
    spec = importlib.util.spec_from_file_location("robocal_bench_peers", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def bench_cmd(
    quick: bool = typer.Option(False, "--quick", help="fewer repeats, no 100 000-pose LM, no W6"),
    peers: Path = typer.Option(Path("benchmarks"), "--peers", help="folder of the peer benchmarks (source tree)"),
    as_json: bool = json_flag("every workload's figures"),
    quiet: bool = quiet_flag(),
) -> None:
    """Time the workloads W1–W8 (medians), with the peers side by side where they are installed."""
    from rich.console import Console

    from ..bench.timing import format_value
    from ..bench.workloads import run_all
    from .common import console, print_json, say_on_stderr, table

    say = say_on_stderr(quiet or as_json)
    rows = run_all(quick=quick, say=say)
    module = _load_peers(peers)
    if module is None:
        say(f"no peer benchmarks at {peers / 'peers.py'} (they live in the source tree's benchmarks/)")
    else:
        rows += module.run_all(quick=quick, say=say)
    if as_json:
        from dataclasses import asdict

        print_json([asdict(r) for r in rows])
        return
    if quiet:
        return
    shown = [(r.workload, format_value(r), r.target, "" if r.met is None else ("yes" if r.met else "falls short"),
              r.peer, r.note) for r in rows]
    Console(width=max(console().width, 160)).print(
        table("robocal bench" + (" (quick)" if quick else ""), ("workload", "median", "target", "met", "peer", "note"),
              shown, "left"))


def register(app: typer.Typer) -> None:
    app.command("bench")(bench_cmd)
