"""How the command line starts and ends: the one command built, plain values read without
pydantic (checked against typer's own reader), and a process that ends without tearing its
modules down but loses nothing on the way."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import typer

from robocal.cli.app import _narrowed, app
from robocal.cli.coercion import plain_coercion

_coercion = pytest.importorskip("typer._coercion", reason="this typer parses with click alone")

# spellings a user may type, usual and not: each is read by robocal's reader where it is plain,
# by typer's where not; the value or the message must be typer's own either way
TEXTS = ["12", "-3", "+7", "007", "1.0", "1.5", "1e3", "1E-3", ".5", "5.", "-0", "-0.0", "1_000", " 12 ", "12\n",
         "inf", "-inf", "nan", "NaN", "Infinity", "1e400", "9" * 18, "9" * 19, "9" * 400, "0x10", "١٢", "１２",
         "abc", "", " ", "true", "no", "--", "1.0_0", "+_1", "~/data.csv", "a b.csv", "-", ".", "é/ü.mod"]


def _command(annotation, default):
    """A one-option typer command whose option has ``annotation`` and ``default``."""
    one = typer.Typer(add_completion=False)

    def cmd(value=typer.Option(default, "--value")):
        pass

    cmd.__annotations__ = {"value": annotation}
    one.command()(cmd)
    return typer.main.get_command(one)


def _read(command, value):
    """What the command's option makes of ``value``: ("ok", value) or ("error", message)."""
    param = next(p for p in command.params if p.name == "value")
    ctx = command.context_class(command, info_name="x")
    try:
        return "ok", param.get_runtime_param().coerce(value, param=param, ctx=ctx)
    except Exception as exc:  # typer's BadParameter: compare its message
        return "error", type(exc).__name__, exc.format_message() if hasattr(exc, "format_message") else str(exc)


@pytest.mark.parametrize("annotation,default", [(str, "x"), (int, 0), (float, 0.0), (Path, Path(".")),
                                                (list[str], []), (list[Path], []), (bool, False)])
def test_plain_reader_reads_as_typer_does(annotation, default, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "exists.csv").write_text("x")
    values = [*TEXTS, "exists.csv", default, 3, 2.5, True]
    if get_list := (getattr(annotation, "__origin__", None) is list):
        values = [(t,) for t in TEXTS] + [("a", "b"), ("exists.csv", "1.5"), (), "lone"]
    ours = _command(annotation, default)
    plain_coercion(ours)
    param = next(p for p in ours.params if p.name == "value")
    assert type(param._runtime_param).__name__ == "Plain"
    for value in values:
        theirs = _command(annotation, default)  # typer's reader, built afresh
        a, b = _read(ours, value), _read(theirs, value)
        assert repr(a) == repr(b), (annotation, value, a, b)  # repr: nan as nan
        if a[0] == "ok" and not get_list:
            assert type(a[1]) is type(b[1]), (annotation, value)


def test_plain_reader_leaves_bounded_and_parsed_options_to_typer():
    one = typer.Typer(add_completion=False)

    @one.command()
    def cmd(n: int = typer.Option(1, "--n", min=0), k: float = typer.Option(1.0, "--k", parser=float),
            s: str = typer.Option("a", "--s")):
        pass

    command = typer.main.get_command(one)
    plain_coercion(command)
    kinds = {p.name: type(p._runtime_param).__name__ for p in command.params}
    assert kinds == {"n": "NoneType", "k": "NoneType", "s": "Plain"}


def test_every_robocal_option_reads_without_pydantic_or_says_why():
    """The whole app: every parameter is plain (robocal's reader) or left to typer on purpose."""
    command = typer.main.get_command(app)
    plain_coercion(command)
    left = []

    def walk(cmd):
        for p in cmd.params:
            if getattr(p, "_runtime_param", "x") is None:
                left.append((cmd.name, p.name))
        for sub in getattr(cmd, "commands", {}).values():
            walk(sub)

    walk(command)
    assert left == []


def test_narrowed_app_holds_the_named_command_alone():
    full = typer.main.get_command(app)
    for name in ("calibrate", "filter", "evaluate", "robots"):
        one = typer.main.get_command(_narrowed([name, "--help"]))
        assert list(one.commands) == [name]
        assert [p.name for p in one.commands[name].params] == [p.name for p in full.commands[name].params]
        assert [p.name for p in one.params] == [p.name for p in full.params]  # --version
    for argv in ([], ["--help"], ["--version"], ["calibrat"], ["pkm", "ik"], ["iso9283", "plan"]):
        assert _narrowed(argv) is app, argv


def test_misspelled_command_and_option_still_get_suggestions(run_cli):
    code, _, err = run_cli("calibrat", "x")
    assert code == 2 and "Did you mean 'calibrate'?" in err
    code, _, err = run_cli("calibrate", "er10l-c10", "x.csv", "--metod", "ipso")
    assert code == 2 and "--method" in err and err.count("\n") == 1
    code, _, err = run_cli("calibrate", "er10l-c10", "x.csv", "--seed", "1.5")
    assert code == 2 and "'--seed'" in err and "valid integer" in err


def _robocal_process(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(code))
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)


def test_program_ends_at_once_with_its_code_its_output_and_exit_handlers(tmp_path):
    """``run``: the exit handlers run, stdout is complete (a large document, piped), the exit
    code is the command's; with another thread alive, that thread finishes first."""
    marker, late = tmp_path / "atexit.txt", tmp_path / "thread.txt"
    proc = _robocal_process(f"""
        import atexit, sys, threading, time
        from pathlib import Path
        atexit.register(lambda: Path({str(marker)!r}).write_text("ran"))
        sys.argv = ["robocal", "robots", "--json"]
        from robocal.cli import run
        run()
    """, tmp_path)
    assert proc.returncode == 0 and marker.read_text() == "ran"
    assert len(json.loads(proc.stdout)) > 5
    proc = _robocal_process("""
        import sys
        sys.argv = ["robocal", "simulate", "no-such-robot", "--out", "x.csv"]
        from robocal.cli import run
        run()
    """, tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "no-such-robot" in proc.stderr
    proc = _robocal_process(f"""
        import sys, threading, time
        from pathlib import Path
        def late():
            time.sleep(0.5)
            Path({str(late)!r}).write_text("done")
        threading.Thread(target=late).start()
        sys.argv = ["robocal", "simulate", "no-such-robot", "--out", "x.csv"]
        from robocal.cli import run
        run()
    """, tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and late.read_text() == "done"


def test_without_typer_s_internal_reader_nothing_is_changed(monkeypatch):
    """An older typer (click's parsing) or a newer one without ``typer._coercion``: every option
    keeps typer's own reader."""
    monkeypatch.setitem(sys.modules, "typer._coercion", None)  # its import now fails
    command = _command(int, 0)
    plain_coercion(command)
    assert next(p for p in command.params if p.name == "value")._runtime_param is None
