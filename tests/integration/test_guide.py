"""The user guide (docs/, built with MkDocs) and the README: the guide builds without a warning,
and every command they show runs as written.

Each page's ```bash blocks run in order in one working folder of their own, in which the
project's ``examples/`` and ``tests/data/`` are where the guide's relative paths expect them.
``robocal`` commands run in-process (the ``run_cli`` fixture); ``python examples/…`` scripts in a
subprocess; ``mkdir -p`` makes its folders; a ```toml block whose first line is ``# NAME.toml``
is written to NAME (a study file the next block runs).  A page's ```python blocks run too (the
README's are run by test_readme.py).

An HTML comment on the line before a block says what the test cannot see in it:

- ``<!-- exit N -->``: its commands exit with N (3: written, but some targets left; 4: a
  requirement not met), not 0;
- ``<!-- guide-test: parse-only -->``: its commands take too long for the suite (a calibration
  on thousands of poses, a paper's whole experiment, a study on a Dask scheduler) or need what
  only a real cell has: their command lines are parsed by robocal's own parser without running,
  so option names and the types of their values cannot drift, and the files they read from
  ``examples/`` must exist;
- ``<!-- guide-test: figures A B … -->``: the figures the page quotes from the block's run (its
  prose after it): each must appear in what the block's commands printed, and on the page after
  the block, so that a changed number fails here instead of drifting;
- ``<!-- guide-test: output -->`` before a ```text block: what the bash block before it prints;
  each of its lines must appear in that output (whitespace aside: the terminal wraps).

Any other line of a bash block is shell setup the guide shows for a user (a venv, pip, a Dask
scheduler) and is named here, so that a misspelt command cannot pass unseen.  The command
tables of the README and the guide's home page name only options the commands have.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
PAGES = [*sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md"]

#: the fenced blocks of a page, each with the HTML comments on the lines right before it
BLOCK = re.compile(r"^((?:<!--[^\n]*-->\n)*)```(\w*)\n(.*?)^```", re.S | re.M)
#: shell the guide shows that is not robocal's to run: environments, installs, a Dask cluster
SETUP = ("python -m venv", ". .venv/bin/activate", "pip install", "python -m pip install", "python -m pytest",
         "dask scheduler", "dask worker")
#: read-only inputs of the source tree the guide's commands name by relative path
INPUTS = ("examples", "tests/data")


def blocks(page: Path) -> list[tuple[str, str, str]]:
    """(language, text, comments before it) of every fenced block of a page, in order."""
    text = page.read_text(encoding="utf-8")
    return [(lang, body, notes) for notes, lang, body in BLOCK.findall(text)]


def commands(body: str) -> list[str]:
    """The commands of a bash block: backslash continuations joined, comments and blank lines
    dropped, ``a && b`` split into its commands."""
    lines = re.sub(r"\\\n\s*", " ", body).splitlines()
    out = []
    for line in lines:
        line = line.strip()
        if line and not line.startswith("#"):
            out.extend(part.strip() for part in line.split(" && "))
    return out


def expected_exit(notes: str) -> int:
    found = re.search(r"<!--\s*exit\s+(\d+)\s*-->", notes)
    return int(found.group(1)) if found else 0


def parse_only(notes: str) -> bool:
    return "guide-test: parse-only" in notes


def runnable(page: Path) -> bool:
    return any(lang in ("bash", "python") for lang, _, _ in blocks(page))


def parse(args: list[str]) -> None:
    """Parse a command line as ``robocal`` would, without running the command: raises the
    parser's UsageError for an unknown command or option, a missing argument or a value of the
    wrong type."""
    import typer
    import typer.main

    from robocal.cli import app

    command = typer.main.get_command(app)
    context = command.make_context("robocal", list(args), resilient_parsing=False)
    while hasattr(command, "resolve_command"):  # a group (robocal, pkm, iso9283): on to its command
        rest = [*(getattr(context, "_protected_args", None) or getattr(context, "protected_args", [])),
                *context.args]
        name, command, rest = command.resolve_command(context, rest)
        context = command.make_context(name, rest, parent=context)


def usage_error() -> type[Exception]:
    """The parser's UsageError, whether typer vendors click or uses it."""
    import typer

    return next(c for c in typer.BadParameter.__mro__ if c.__name__ == "UsageError")


def read_inputs(args: list[str]) -> list[str]:
    """The paths in examples/ a command line names (as a value, or after ``=``)."""
    values = [a.split("=", 1)[-1] for a in args]
    return [v for v in values if v.startswith("examples/")]


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A working folder in which the source tree's inputs are where the guide names them."""
    for name in INPUTS:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    return tmp_path


def test_the_guide_builds_without_a_warning(tmp_path):
    pytest.importorskip("mkdocs")
    # (the theme's banner about its own future is no warning of the build: it is silenced)
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr
    assert "WARNING" not in done.stderr, done.stderr


def test_the_api_reference_documents_every_public_name():
    """Every name ``import robocal`` offers has its entry in the API reference, from its own module."""
    import robocal

    page = (ROOT / "docs" / "api-reference.md").read_text(encoding="utf-8")
    entries = set(re.findall(r"^::: ([\w.]+)$", page, re.M))
    for name in robocal.__all__:
        module = robocal._EXPORTS[name]
        assert f"{module}.{name}" in entries, f"{name} ({module}) is not in docs/api-reference.md"


def test_every_page_is_in_the_guide():
    """Every page of docs/ is in mkdocs.yml's nav (the build says so too, as a warning)."""
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in (ROOT / "docs").glob("*.md"):
        assert re.search(rf"\b{re.escape(page.name)}\b", nav), f"{page.name} is not in mkdocs.yml's nav"


def quoted_figures(notes: str) -> list[str]:
    found = re.search(r"<!--\s*guide-test:\s*figures\s+([^>]*?)\s*-->", notes)
    return found.group(1).split() if found else []


def _flat(text: str) -> str:
    """Text with its whitespace runs made one space and table rules dropped (the terminal wraps
    and frames what the guide quotes on one line)."""
    text = re.sub(r"[│┃┏┓┗┛┡┩┣┫━─┳┻╇╈╋┼┬┴├┤╭╮╰╯║═╔╗╚╝]", " ", text)
    return " ".join(text.split())


def parts(page: Path) -> list[tuple[str, str]]:
    """A page cut at its ``##`` and ``###`` sections, each run in a folder of its own: (title, text) in
    order, the text before the first section with the first.  A section that builds on the files of
    the one before says ``<!-- guide-test: continues -->`` under its heading and runs with it; one that
    builds on another's says ``<!-- guide-test: after TITLE -->`` and runs that section's blocks first."""
    text = page.read_text(encoding="utf-8")
    cut = [m.start() for m in re.finditer(r"^###? ", text, re.M)]
    pieces = [text[a:b] for a, b in zip([0, *cut], [*cut, len(text)])]
    out: list[list[str]] = []
    for piece in pieces:
        head = piece.split("\n```", 1)[0]
        if out and ("guide-test: continues" in head or not out[-1][1].strip()):
            out[-1][1] += piece
            continue
        title = piece.splitlines()[0].lstrip("# ").strip() if piece.startswith("#") else "top"
        after = re.search(r"<!--\s*guide-test:\s*after\s+(.+?)\s*-->", head)
        if after:
            earlier = next((t for t in out if t[0] == after.group(1)), None)
            assert earlier is not None, f"{page.name}: section {title!r} is after {after.group(1)!r}, which it is not"
            piece = earlier[1] + piece
        out.append([title, piece])
    kinds = ("bash",) if page.name == "README.md" else ("bash", "python")  # the README's Python: test_readme.py
    return [(title, piece) for title, piece in out if any(lang in kinds for _, lang, _ in BLOCK.findall(piece))]


GUIDE_PARTS = [(p, title) for p in PAGES if runnable(p) for title, _ in parts(p)]


@pytest.mark.parametrize("page,part", GUIDE_PARTS, ids=lambda x: x.name if isinstance(x, Path) else
                         re.sub(r"\W+", "-", x.lower()).strip("-")[:40])
def test_every_guide_command_runs(page, part, workdir, run_cli):
    ran = 0
    printed = ""  # what the last bash block run printed
    text = dict(parts(page))[part]
    for notes, lang, body in BLOCK.findall(text):
        if lang == "text" and "guide-test: output" in notes:
            for line in body.splitlines():
                if line.strip() and line.strip() != "…":
                    assert _flat(line) in _flat(printed), f"{page.name}: the quoted output {line!r} is not what " \
                                                          "the commands before it printed"
            continue
        if lang == "toml":
            first = body.splitlines()[0] if body else ""
            name = re.fullmatch(r"#\s*([\w.-]+\.toml)\s*", first)
            if name:  # a file the commands after it read
                (workdir / name.group(1)).write_text(body, encoding="utf-8")
            continue
        if lang == "python" and page.name != "README.md":
            exec(compile(body, page.name, "exec"), {})
            ran += 1
            continue
        if lang != "bash":
            continue
        printed = ""
        for line in commands(body):
            done, said = run(line, parse_only(notes), expected_exit(notes), page, run_cli)
            ran += done
            printed += said
        figures = quoted_figures(notes)
        assert not (figures and parse_only(notes)), f"{page.name}: figures quoted from a block that does not run"
        after = text[text.index(body) + len(body):]
        for figure in figures:
            assert figure in printed, f"{page.name}: {figure} is quoted, the commands print otherwise"
            assert figure in after, f"{page.name}: {figure} is listed for checking but not quoted after its block"
    assert ran, f"{page.name} ({part}): no command to run"


def run(line: str, parse_only_: bool, code: int, page: Path, run_cli) -> tuple[int, str]:
    """Run (or parse) one command of the guide: (1 if it was robocal's or an example's, else 0;
    what it printed, stdout and stderr)."""
    where = f"{page.name}: `{line}`"
    args = shlex.split(line)
    if args[0] == "robocal":
        args = args[1:]
        out = None
        if ">" in args:  # robocal … > FILE
            at = args.index(">")
            args, out = args[:at], args[at + 1]
        if parse_only_:
            try:
                parse(args)
            except usage_error() as exc:
                pytest.fail(f"{where}: {exc.format_message()}")
            for path in read_inputs(args):
                assert Path(path).exists(), f"{where}: {path} does not exist"
            return 1, ""
        got, stdout, stderr = run_cli(*args)
        assert got == code, f"{where}: exit {got}, expected {code}\n{stderr[-2000:]}"
        if out is not None:
            Path(out).write_text(stdout, encoding="utf-8")
        return 1, stdout + stderr
    if line.startswith("python examples/"):
        script = args[1]
        assert Path(script).exists(), f"{where}: {script} does not exist"
        if not parse_only_:
            done = subprocess.run([sys.executable, *args[1:]], capture_output=True, text=True)
            assert done.returncode == code, f"{where}: exit {done.returncode}\n{done.stderr[-2000:]}"
            return 1, done.stdout + done.stderr
        return 1, ""
    if args[:2] == ["mkdir", "-p"]:
        for folder in args[2:]:
            os.makedirs(folder, exist_ok=True)
        return 0, ""
    assert line.startswith(SETUP), f"{where}: a command the guide's test does not know (add it to SETUP?)"
    return 0, ""


def command_of(words: list[str]) -> list:
    """The commands a table cell names: ``calibrate ROBOT DATA``, ``iso9283 plan``, ``pkm ik|fk``
    (each named subcommand, or every one of a group named alone), ``robocal --version`` (the root)."""
    import typer.main

    from robocal.cli import app

    root = typer.main.get_command(app)
    words = words[1:] if words[:1] == ["robocal"] else words
    if not words or words[0].startswith("-"):
        return [root]
    command = root.commands.get(words[0])
    if command is None:
        return []
    if hasattr(command, "commands"):
        named = [w for w in re.split(r"\\?\|", words[1]) if w in command.commands] if len(words) > 1 else []
        return [command.commands[n] for n in named] or list(command.commands.values())
    return [command]


@pytest.mark.parametrize("page", [ROOT / "README.md", ROOT / "docs" / "index.md"], ids=lambda p: p.name)
def test_the_command_tables_name_options_that_exist(page):
    """Every option a row of a command table names exists on the command(s) of its first cell, and
    a ✓ in the grammar table's --quiet column is a --quiet on each of them."""
    rows = 0
    for line in page.read_text(encoding="utf-8").splitlines():
        if not line.startswith("| `"):
            continue
        cells = line.split(" | ")
        commands = [c for name in re.findall(r"`([^`]+)`", cells[0]) for c in command_of(name.split())]
        assert commands, f"{page.name}: no command in {cells[0]}"
        options = {o for c in commands for p in c.params for o in (*p.opts, *p.secondary_opts)}
        named = set(re.findall(r"(?<![\w-])--[a-z][a-z-]*", line))
        assert named <= options, f"{page.name}: {cells[0]}: no {sorted(named - options)}"
        if "✓" in line:
            for c in commands:
                assert "--quiet" in {o for p in c.params for o in p.opts}, f"{page.name}: {c.name} has no --quiet"
        rows += 1
    assert rows
