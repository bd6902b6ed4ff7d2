"""The typer application, its entry point, and the one place errors become exit codes."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import typer

from ..exceptions import InputError, Interrupted
from . import (
    bench,
    calibrate,
    compensate,
    detect,
    evaluate,
    filter,
    iso9283,
    pkm,
    plan,
    reproduce,
    robots,
    simulate,
    study,
)
from .common import one_line

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Geometric calibration and error compensation of robots.")


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        print(f"robocal {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print the version and exit")) -> None:
    """Geometric calibration and error compensation of robots."""


for module in (robots, simulate, detect, evaluate, calibrate, compensate, filter, plan, reproduce, study, bench):
    module.register(app)
app.add_typer(pkm.app, name="pkm")
iso9283.register(app)


def _one_line_warnings(python_show, held: list[str] | None = None):
    """A warning printer for the command line: robocal's own as one line on stderr, or kept in
    ``held`` to be printed once the command has succeeded (an input error is then the one line
    said).  The libraries' (numpy's overflow RuntimeWarnings, scipy's optimizer notes)
    are not for the user: whatever they flag, robocal checks and says in its own words; set
    ROBOCAL_SHOW_WARNINGS=1 to see them as Python prints them."""
    import os

    from ..exceptions import RobocalWarning

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, RobocalWarning):
            text = f"robocal: warning: {one_line(message)}"
            if held is None:
                print(text, file=sys.stderr)
            else:
                held.append(text)
        elif os.environ.get("ROBOCAL_SHOW_WARNINGS"):
            python_show(message, category, filename, lineno, file, line)

    return show


def _raise_interrupted(signum, frame):
    from ..exceptions import Interrupted

    raise Interrupted()


def main(argv: list[str] | None = None) -> int:
    """Entry point: runs the app and turns input errors into one line and exit code 2, Ctrl-C
    into one line and exit code 130."""
    import signal
    import threading
    import warnings

    own_sigint = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, _raise_interrupted) if own_sigint else None
    held: list[str] = []
    try:
        with warnings.catch_warnings():  # restores Python's printer on the way out
            warnings.showwarning = _one_line_warnings(warnings.showwarning, held)
            code = _run(argv)
    finally:
        if own_sigint:
            signal.signal(signal.SIGINT, previous)
    if code in (0, 3, 4):  # what was noticed on the way (3: written in part, 4: a requirement not met);
        # after an error, the error alone
        for text in held:
            print(text, file=sys.stderr)
    return code


def run() -> None:
    """The ``robocal`` program (console script and ``python -m robocal``): :func:`main`, then the
    process ends at once.

    Tearing down the ~1200 modules a calibration imports (numba's, scipy's) takes 0.2–0.3 s
    of a command's wall time and does nothing a finished command needs.  The exit handlers
    still run, and stdout and stderr are flushed; where another thread is still alive, the
    interpreter ends as usual, so that it is waited for.  ``main`` itself returns, for callers
    in a process that goes on (tests, notebooks).
    """
    import atexit
    import threading

    code = main()
    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        sys.exit(code)
    atexit._run_exitfuncs()  # what Python's own exit runs first (logging's flush, finalizers)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more to say
            pass
    os._exit(code)


#: where a command's JSON document goes to a file: ``--json PATH`` was its old spelling
_JSON_FILE = {"compensate": "--summary", "filter": "--summary", "plan": "--summary", "iso9283": "--summary",
              "calibrate": "--out"}


def _old_spelling(argv: list[str]) -> str | None:
    """The message for ``--json PATH`` (``--json`` is a flag in every command now: it prints the
    document; a file is ``--summary PATH``, or ``--out`` for calibrate's result), else None."""
    command = next((a for a in argv if not a.startswith("-")), None)
    new = _JSON_FILE.get(command or "")
    for i, arg in enumerate(argv):
        value = arg[len("--json="):] if arg.startswith("--json=") else None
        following = argv[i + 1] if arg == "--json" and i + 1 < len(argv) else ""
        if following.lower().endswith(".json") or (following and Path(following).is_dir()):
            value = following
        if value is not None:
            folder = "--json: is a folder; " if value and Path(value).is_dir() else ""
            how = f"use {new} PATH (here {new} {value})" if new else f"redirect it (--json > {value})"
            return f"{folder}--json is a flag: it prints the JSON document on stdout; to write a file, {how}"
    return None


def _narrowed(argv: list[str]) -> typer.Typer:
    """The app with only the command that ``argv`` names, where it names one of the top level
    first: building every command's parameters and help (the others' too) costs 30 ms of a
    command that may take 0.5 s.  Anything else (``--help``, ``--version``, a group, a
    misspelled command and its suggestions) gets the whole app."""
    name = str(argv[0]) if argv else ""
    info = next((c for c in app.registered_commands if c.name == name), None)
    if info is None:
        return app
    import copy

    one = copy.copy(app)  # the same settings, root callback (--version) and help
    one.registered_commands, one.registered_groups = [info], []
    return one


def _run(argv: list[str] | None) -> int:
    given = sys.argv[1:] if argv is None else argv
    old = _old_spelling([str(a) for a in given])
    if old is not None:
        print(f"robocal: usage error: {old}", file=sys.stderr)
        return 2
    try:
        from .coercion import plain_coercion
        from .help import tidy

        command = typer.main.get_command(_narrowed(given))
        tidy(command)  # every command's --help: panels, placeholders, texts as written
        plain_coercion(command)
        result = command.main(args=argv, prog_name="robocal", standalone_mode=False)
    except InputError as exc:
        print(f"robocal: error: {one_line(exc.render(cli=True))}", file=sys.stderr)
        return 2
    except (Interrupted, KeyboardInterrupt) as exc:
        # outputs are written together at the end (io.atomic.together): none was touched
        kept = getattr(exc, "kept", None)
        print(f"robocal: interrupted; {kept or 'nothing written'}", file=sys.stderr)
        return 130
    except Exception as exc:
        # Command-line misuse, raised by typer's click (vendored or not): duck-typed so that
        # either generation of typer gives the same one-line message.
        kind = type(exc).__name__
        if kind == "Abort":
            print("robocal: interrupted; nothing written", file=sys.stderr)
            return 130
        if kind == "Exit":
            return int(getattr(exc, "exit_code", 0) or 0)
        if not hasattr(exc, "format_message"):
            raise
        if kind == "NoArgsIsHelpError":
            print(exc.format_message())
            return 0
        ctx = getattr(exc, "ctx", None)
        where = f" ({ctx.command_path})" if ctx is not None and ctx.command_path != "robocal" else ""
        print(f"robocal: usage error{where}: {one_line(exc.format_message())}", file=sys.stderr)
        return 2
    return result if isinstance(result, int) else 0
