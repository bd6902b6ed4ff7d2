"""The corpus of bad inputs in tests/data/bad: one line, exit code 2, no traceback, no output touched."""

import json
from pathlib import Path

import pytest

BAD = Path(__file__).parent / "data" / "bad"
CASES = json.loads((BAD / "manifest.json").read_text(encoding="utf-8"))
SENTINEL = "previous content that must survive\n"


def test_corpus_is_large_enough():
    assert len([c for c in CASES.values() if c["kind"] != "cli"]) >= 40
    assert len([c for c in CASES.values() if c["kind"] == "cli"]) >= 30


@pytest.fixture(scope="module")
def good_data(tmp_path_factory):
    from robocal.cli import main

    path = tmp_path_factory.mktemp("good") / "good.csv"
    assert main(["simulate", "kr5-arc", "--poses", "20", "--measure", "position", "--out", str(path)]) == 0
    return path


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input(name, good_data, tmp_path, run_cli):
    case = CASES[name]
    out = tmp_path / "out.file"
    out.write_text(SENTINEL)  # an existing output must not be overwritten
    fresh = tmp_path / "fresh.file"  # and a new one must not be created
    if case["kind"] == "robot":
        args = ["calibrate", BAD / name, good_data, "--out", out, "--export", fresh]
    elif case["kind"] == "data":
        args = ["calibrate", "kr5-arc", BAD / name, "--out", out, "--export", fresh]
    else:
        args = [a.replace("{good}", str(good_data)).replace("{tmp}", str(tmp_path)).replace("{bad}", str(BAD))
                for a in case["args"]]
        if "--out" not in args and args[0] in ("calibrate", "simulate", "reproduce"):
            args += ["--out", fresh if args[0] != "calibrate" else out]
    code, stdout, err = run_cli(*args)
    assert code == 2, (name, code, err)
    assert err.count("\n") == 1 and err.startswith("robocal: "), (name, err)
    assert "Traceback" not in err and "Traceback" not in stdout
    assert case["expect"] in err, (name, err)
    if case["kind"] in ("robot", "data"):
        assert name in err  # the message names the file
    assert out.read_text() == SENTINEL and not fresh.exists()
