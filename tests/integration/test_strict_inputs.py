"""Strict reading of the newest inputs: each case a user could make, with what robocal must do:
refuse it in one line naming the file or option (exit 2, no output), read it as meant, or say
what it could not do (exit 3).  Cases of the team's own, beside the corpora of tests/integration/data."""

from __future__ import annotations

import json

import pytest

PROGRAM = """MODULE Cell
  PERS tooldata gun:=[TRUE,[[0,0,100],[1,0,0,0]],[2,[0,0,50],[1,0,0,0],0,0,0]];
  CONST robtarget p1:=[[400,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveJ p1,v500,fine,gun;
  ENDPROC
ENDMODULE
"""


@pytest.fixture
def data(tmp_path, run_cli):
    path = tmp_path / "d.csv"
    code, _, err = run_cli("simulate", "kr5-arc", "--poses", "30", "--errors", "uniform:0.5,0.002", "--noise", "0.02",
                           "--seed", "2", "--out", path, "--quiet")
    assert code == 0, err
    return path


def _refused(result, *words):
    code, out, err = result
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)


def test_a_trailing_delimiter_on_every_line_is_read(tmp_path, data, run_cli):
    trailing = tmp_path / "t.csv"
    trailing.write_text("".join(line + ",\n" for line in data.read_text().splitlines()))
    code, plain, _ = run_cli("evaluate", "kr5-arc", data, "--json")
    code2, other, err = run_cli("evaluate", "kr5-arc", trailing, "--json")
    assert code == code2 == 0, err
    assert json.loads(plain) == json.loads(other)
    # but an empty last column with a value in one row is a broken row, named
    lines = trailing.read_text().splitlines()
    lines[3] += "7"
    trailing.write_text("\n".join(lines) + "\n")
    _refused(run_cli("evaluate", "kr5-arc", trailing), "t.csv", "row 1", "column 13 has an empty name")


def test_column_names_are_checked_against_robocals(data, run_cli):
    _refused(run_cli("calibrate", "kr5-arc", data, "--column", "x=xx"), "--column", "'xx' is not a column robocal")
    _refused(run_cli("evaluate", "kr5-arc", data, "--column", "q1=joint_1"), "--column", "'joint_1'")


def test_orientation_needs_all_three_axes(tmp_path, data, run_cli):
    two = tmp_path / "two.csv"
    rows = [line.split(",") for line in data.read_text().splitlines()]
    two.write_text("\n".join(",".join(r[:-1]) for r in rows) + "\n")  # rz dropped: rx, ry left
    _refused(run_cli("calibrate", "kr5-arc", two), "two.csv", "'rz' is missing")


@pytest.mark.parametrize("statement", ["1e999+0/m", "0.01+1e999/m", "0.01+0.006/m k=1e999", "nan"])
def test_a_non_finite_instrument_is_refused(data, run_cli, statement):
    _refused(run_cli("calibrate", "kr5-arc", data, "--instrument", statement), "--instrument")


def test_empty_selections_are_refused_by_name(tmp_path, data, run_cli):
    every = ",".join(f"row {i}" for i in range(2, 32))
    _refused(run_cli("calibrate", "kr5-arc", data, "--exclude", every), "--exclude", "none of the 30 poses")
    _refused(run_cli("calibrate", "kr5-arc", data, "--exclude", " , "), "--exclude", "names no pose")
    listed = tmp_path / "none.txt"
    listed.write_text("# nothing this time\n\n")
    _refused(run_cli("calibrate", "kr5-arc", data, "--exclude-file", listed), "none.txt", "lists no pose id")
    _refused(run_cli("calibrate", "kr5-arc", data, "--params", ","), "--params")


def test_uncertainty_names_are_checked_against_the_model(tmp_path, data, run_cli):
    cal = tmp_path / "cal.toml"
    code, _, err = run_cli("calibrate", "kr5-arc", data, "--export", cal, "--quiet")
    assert code == 0, err
    text = cal.read_text()
    assert '"alpha2"' in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('"alpha2"', '"alpha9"', 1))
    _refused(run_cli("evaluate", bad, data, "--uncertainty"), "bad.toml", "[uncertainty]", "alpha9")


def _filter(run_cli, tmp_path, name, body: bytes, *extra):
    path = tmp_path / name
    path.write_bytes(body)
    out = tmp_path / ("out_" + name)
    return run_cli("filter", "irb120", path, "--nominal", "irb120", "--out", out, "--summary", tmp_path / "s.json",
                   *extra), out


@pytest.mark.parametrize("value,words", [("[1e999,0,500]", ("line 3", "not a finite number")),
                                         ("[1" + "0" * 400 + ",0,500]", ("line 3", "not a finite number")),
                                         ("[400x,0,500]", ("line 3", "robtarget p1")),
                                         ("[4.0.0,0,500]", ("line 3", "robtarget p1"))])
def test_program_numbers_are_read_whole_and_finite(tmp_path, run_cli, value, words):
    result, out = _filter(run_cli, tmp_path, "c.mod", PROGRAM.replace("[400,0,500]", value).encode())
    _refused(result, "c.mod", *words)
    assert not out.exists()


@pytest.mark.parametrize("quaternion", ["[0,0,0,0]", "[0,0,1.001,0]"])
def test_quaternions_off_unit_norm_are_refused(tmp_path, run_cli, quaternion):
    result, _ = _filter(run_cli, tmp_path, "c.mod", PROGRAM.replace("[0,0,1,0]", quaternion).encode())
    _refused(result, "c.mod", "line 3", "quaternion")


@pytest.mark.parametrize("codec", ["utf-16-le", "utf-16-be", "utf-32-le", "utf-16"])
def test_wide_encodings_are_read_with_or_without_their_mark(tmp_path, run_cli, codec):
    (code, _, err), out = _filter(run_cli, tmp_path, "c.mod", PROGRAM.encode(codec))
    assert code == 0, err
    assert out.read_bytes() == PROGRAM.encode(codec)  # an identity filter: the same bytes, the same encoding


def test_a_motion_to_a_target_the_files_do_not_hold_is_said(tmp_path, run_cli):
    move = "    MoveJ p1,v500,fine,gun;\n"
    text = PROGRAM.replace(move, move + "    MoveL p9,v500,fine,gun;\n")
    (code, _, err), out = _filter(run_cli, tmp_path, "c.mod", text.encode())
    rows = {r["target"]: r for r in json.loads((tmp_path / "s.json").read_text())["targets"]}
    assert code == 3 and rows["p9"]["status"] == "unsupported" and "not declared in this module" in rows["p9"]["reason"]
    assert rows["p1"]["status"] == "ok" and "p9" in err


def test_krl_targets_declared_nowhere_are_said(tmp_path, run_cli):
    src = "DEF cell()\n  PTP XP1\n  PTP XHOME\n  LIN $POS_ACT\nEND\n"
    dat = ("DEFDAT cell\n  DECL E6POS XP1={X 500.0,Y 0.0,Z 600.0,A 0.0,B 90.0,C 0.0,S 2,T 2,E1 0.0,E2 0.0,E3 0.0,"
           "E4 0.0,E5 0.0,E6 0.0}\nENDDAT\n")
    (tmp_path / "cell.src").write_text(src)
    (tmp_path / "cell.dat").write_text(dat)
    code, _, err = run_cli("filter", "kr5-arc-kuka", tmp_path / "cell.src", "--nominal", "kr5-arc-kuka", "--out",
                           tmp_path / "o.src", "--tool", "0,0,0,0,0,0", "--user-frame", "0,0,0,0,0,0", "--summary",
                           tmp_path / "s.json")
    rows = {r["target"]: r for r in json.loads((tmp_path / "s.json").read_text())["targets"]}
    assert code == 3, err
    assert "$config.dat" in rows["XHOME"]["reason"] and "system variable" in rows["$POS_ACT"]["reason"]
    assert rows["XP1"]["status"] == "ok"
