"""Every command's --help, rendered at 80 columns as a terminal shows it: no Python type
placeholders, every option described, a robot file's [tables] shown as written, the long commands'
options in panels by what they are about."""

import re

import pytest

from tests.integration.test_grammar import COMMANDS


def _help(run_cli, monkeypatch, path):
    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setenv("TERM", "dumb")
    code, out, err = run_cli(*path.split(), "--help")
    assert code == 0, err
    return out


@pytest.mark.parametrize("path,cmd", COMMANDS, ids=[p for p, _ in COMMANDS])
def test_every_command_s_help_reads_at_80_columns(run_cli, monkeypatch, path, cmd):
    out = _help(run_cli, monkeypatch, path)
    assert max(len(line) for line in out.splitlines()) <= 80
    assert not re.search(r"<(str|bool|int|float|path|list\[[^\]]*\])>", out), out
    for param in cmd.params:
        opts = [o for o in getattr(param, "opts", ()) if o.startswith("--")]
        assert param.help, f"{path}: {opts or param.name} has no description"
        for opt in opts:
            assert opt in out, f"{path}: {opt} not shown"


def test_calibrate_s_help_keeps_brackets_and_groups_its_options(run_cli, monkeypatch):
    out = _help(run_cli, monkeypatch, "calibrate")
    assert "[gravity] payload_com" in out and "robot file's [prior]" in out
    panels = re.findall(r"╭─ ([^─]+) ─", out)
    assert [p.strip() for p in panels] == ["Arguments", "Data", "Model and fit", "Swarm", "Output"], panels
    assert "RIGHT@LEFT" in out and "--seed" in out
    seed = out[out.index("--seed"):].splitlines()[0]
    assert "seeds" in seed and re.search(r"--seed\s+N\s", seed)


@pytest.mark.parametrize("path", ["", "iso9283", "pkm"])
def test_the_groups_help_shows_no_type_placeholder_either(run_cli, monkeypatch, path):
    out = _help(run_cli, monkeypatch, path)
    assert not re.search(r"<(str|bool|int|float|path|list\[[^\]]*\])>", out), out
    assert "--help" in out
