"""What the commands share: consoles, tables, the progress bar, warnings on stderr."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path


def one_line(text: str) -> str:
    return " ".join(str(text).split())


def console():
    """The stdout console; tables stay readable when the output goes to a file or a pipe."""
    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else 140)


def print_warnings(messages) -> None:
    """Something to act on, or a reason to doubt a figure: on stderr, even with --quiet."""
    for m in messages:
        print(f"robocal: warning: {one_line(m)}", file=sys.stderr)


def print_said(messages, quiet: bool = False) -> None:
    """A command's messages: its warnings, then its notes (:class:`~robocal.exceptions.Note`,
    hidden by --quiet)."""
    from ..exceptions import split_notes

    warnings, notes = split_notes(messages)
    print_warnings(warnings)
    print_notes(notes, quiet)


def print_notes(messages, quiet: bool = False) -> None:
    """Information for the user (a file written and what it holds): on stderr, so that stdout
    stays the command's document; hidden by --quiet."""
    if quiet:
        return
    for m in messages:
        print(f"robocal: note: {one_line(m)}", file=sys.stderr)


def _titled(title: str, body):
    """A table under its title on a line of its own, never folded: a file's path in a title stays whole
    (rich would break it at the table's width)."""
    from rich.console import Group
    from rich.text import Text

    return Group(Text(title, style="italic", no_wrap=True, overflow="ignore"), body)


def metrics_table(title: str, columns: dict):
    """A before/after style table: one column per Metrics."""
    from rich.table import Table

    table = Table()
    table.add_column("error")
    for name in columns:
        table.add_column(name, justify="right")
    from ..model.metrics import table_rows

    for label, values in table_rows(columns):
        table.add_row(label, *values)
    return _titled(title, table)


def table(title: str, columns, rows, justify: str = "right", text_columns: tuple[int, ...] = ()):
    """A rich table; ``text_columns`` (names, notes) stay left whatever ``justify`` says."""
    from rich.table import Table

    t = Table()
    for i, c in enumerate(columns):
        t.add_column(c, justify="left" if i in text_columns else justify)
    from rich.markup import escape

    for r in rows:  # cells are text: tool[NAME] and camera[NAME] are names, not markup
        t.add_row(*(escape(c) if isinstance(c, str) else c for c in r))
    return _titled(title, t)


@contextlib.contextmanager
def progress_bar(enabled: bool, label: str, total: int | None, best: bool = True):
    """Yields a progress callback (iteration, total, best) drawing a bar on a TTY, or None;
    best=False leaves out the best-objective column."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    columns = [TextColumn(f"[bold]{label}"), BarColumn(), TextColumn("{task.completed}/{task.total}")]
    if best:
        columns.append(TextColumn("best {task.fields[best]:.6g}"))
    bar = Progress(*columns, TimeRemainingColumn(), console=Console(stderr=True), transient=True)
    with bar:
        task = bar.add_task(label, total=total, best=float("nan"))

        def callback(t, n, best):
            bar.update(task, completed=t, total=n or total, best=best)

        yield callback


@contextlib.contextmanager
def stage_status(enabled: bool):
    """Yields a callback (done, total, text) showing a long job's stage on a TTY, with the time
    so far and an estimate of what is left from the stages done; or None."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    import time

    from rich.console import Console

    start = time.perf_counter()
    with Console(stderr=True).status("starting") as status:

        def callback(done, total, text):
            elapsed = time.perf_counter() - start
            left = f", about {elapsed / done * (total - done):.0f} s left" if done else ""
            status.update(f"{text} ({elapsed:.0f} s{left})")

        yield callback


def say_on_stderr(quiet: bool):
    """A ``say`` callback printing dim progress lines on stderr, or nothing when quiet."""
    if quiet:
        return lambda message: None
    from rich.console import Console

    err = Console(stderr=True)
    return lambda message: err.print(f"[dim]{message}[/dim]")


@contextlib.contextmanager
def many_small_objects():
    """The cyclic garbage collector held off while a command builds some 10⁶ small objects that
    hold no cycles (a program of 10 000 targets: their numbers' places, frames, corrections): its
    passes over them were a sixth of such a run.  Only a command's own run, in its own process."""
    import gc

    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def delimiter_option():
    import typer

    return typer.Option(",", "--delimiter", help="cell separator of data files: , | ; | tab | space")


def decimal_option():
    import typer

    return typer.Option(".", "--decimal", help="decimal mark of data files: . | , (with --delimiter ';')")


def euler_option():
    import typer

    return typer.Option("xyz", "--euler", help="sequence of the rx, ry, rz angles, scipy's notation: upper case "
                        "intrinsic (XYZ), lower case extrinsic (xyz, robocal's own: R = Rz Ry Rx)")


def camera_option(what: str):
    """``--camera NAME=FILE[,link=K]``, repeatable: a camera's intrinsics file (OpenCV YAML/JSON or ROS
    camera_info) and its link (a number, a URDF link or a joint; 0: fixed in the cell)."""
    import typer

    return typer.Option(None, "--camera", help=f"NAME=FILE or NAME=FILE,link=K: {what}; repeatable")


def camera_pose_option(what: str):
    """``--camera-pose NAME=x,y,z,rx,ry,rz`` (mm, deg), repeatable: where a camera is."""
    import typer

    return typer.Option(None, "--camera-pose", help=f"NAME=x,y,z,rx,ry,rz: {what} (mm, deg; in the measuring frame, "
                        "or its link's frame); RIGHT@LEFT=x,y,z,rx,ry,rz: camera RIGHT fixed to camera LEFT (a stereo "
                        "rig), its pose in LEFT's frame, known; repeatable")


def markers_option(what: str):
    """``--markers M.csv``: the markers on the flange (marker, x, y, z mm; rx, ry, rz, size for squares)."""
    import typer

    return typer.Option(None, "--markers", help=f"CSV marker,x,y,z (mm, flange frame; rx,ry,rz,size for square "
                        f"markers): {what}")


def base_link_option():
    import typer

    return typer.Option(None, "--base-link", help="URDF robot: the chain's first link (default: the root)")


def tip_link_option():
    import typer

    return typer.Option(None, "--tip-link", help="URDF robot: the chain's last link (default: the leaf with the "
                                                 "most movable joints, said on stderr); several, A,B: the tree of "
                                                 "their chains, each row naming its chain (a chain column)")


def load(robot, base_link=None, tip_link=None):
    """A robot argument of the command line: a robot TOML, a URDF (with its chain's links) or a
    built-in name."""
    from ..io.robotfile import load_robot

    return load_robot(robot, base_link=base_link, tip_link=tip_link)


def check_outputs(inputs=(), **paths) -> None:
    """Every output file of a command, checked before any work (keyword: the option's name):
    not a folder, its folder existing and writable, no two options naming one file, and none
    of the command's ``inputs`` (a result written over its own data would destroy them)."""
    from ..exceptions import InputError
    from ..io.atomic import check_output

    read = {Path(p).resolve(): p for p in inputs if p is not None and Path(p).is_file()}
    seen: dict = {}
    named = [(option, p) for option, value in paths.items()
             for p in (value if isinstance(value, list | tuple) else [value])]  # a repeatable option: each file
    for option, path in named:
        if path is None:
            continue
        check_output(path, option)
        key = Path(path).resolve()
        if key in seen:
            raise InputError(f"the same file as --{seen[key].replace('_', '-')}", source=path, option=option)
        if key in read:
            raise InputError("is also an input of this command: it would be overwritten", source=path,
                             option=option)
        seen[key] = option


def json_flag(what: str):
    """``--json``: the command's JSON document on stdout, the same in every command."""
    import typer

    return typer.Option(False, "--json", help=f"print {what} as JSON on stdout (instead of the tables)")


def summary_option(what: str):
    """``--summary PATH``: the document ``--json`` prints, written to a file."""
    import typer

    return typer.Option(None, "--summary", help=f"write {what} as JSON to this file (what --json prints)")


def seed_option(what: str):
    """``--seed N``: what it seeds; the same seed, the same result."""
    import typer

    return typer.Option(0, "--seed", help=f"seeds {what} (the same seed, the same result)")


def quiet_flag():
    import typer

    return typer.Option(False, "--quiet", "-q", help="no tables or progress on the terminal (warnings and errors "
                                                    "still on stderr)")


def print_json(document) -> None:
    """A JSON document on stdout (a dict, or text already JSON)."""
    import json

    text = document if isinstance(document, str) else json.dumps(document, indent=2) + "\n"
    sys.stdout.write(text if text.endswith("\n") else text + "\n")


def verdict(requirements, figures: dict) -> None:
    """Exit with status FAILED (naming each on stderr) when a requirement is not met."""
    from ..requirements import FAILED, unmet

    failed = unmet(requirements, figures)
    for line in failed:
        print(f"robocal: {line}", file=sys.stderr)
    if failed:
        import typer

        raise typer.Exit(FAILED)
