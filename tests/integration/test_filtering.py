"""Program filtering on real public programs (tests/data/programs) against a planted accurate
robot: every corrected target, sent through the nominal inverse and the accurate forward model
(both the independent simulator's, tests/independent.py), lands on the original target; joint
targets likewise; everything but target numbers stays byte for byte."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import independent as ind
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.filtering import filter_program, load_program

PROGRAMS = Path(__file__).parents[1] / "data" / "programs"
PLANTED = {"a2": 0.4, "d4": -0.3, "theta2": 0.002, "alpha3": -0.0015, "theta5": 0.001, "a3": 0.25}
CASES = [("krl/demo_screenshot.src", "kr5-arc"), ("krl/Program.src", "kr5-arc"), ("rapid/Module1.mod", "irb120"),
         ("rapid/Program.mod", "irb120"), ("urscript/timing_debug.script", "ur10"),
         ("urscript/PickAndPlace_App_Final.script", "ur10"), ("urscript/Prog1.script", "ur10")]


def _frame(T_pos, R):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, T_pos
    return T


def _angle_deg(A, B) -> float:
    return float(np.degrees(np.linalg.norm(Rotation.from_matrix(A @ B.T).as_rotvec())))


@pytest.fixture(scope="module")
def accurate_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("planted")
    out = {}
    for robot in ("kr5-arc", "irb120", "ur10"):
        path = folder / f"{robot}.toml"
        path.write_text(ind.robot_toml(robot, PLANTED))
        out[robot] = path
    return out


def _non_numbers(text: str) -> str:
    return re.sub(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", "#", text)


@pytest.mark.parametrize("program,robot", CASES)
def test_filtered_targets_land_where_the_programmer_meant(program, robot, accurate_files):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(accurate_files[robot], PROGRAMS / program, robot)
    original = (PROGRAMS / program).read_bytes().decode("utf-8")
    # nothing but numbers changed, and only numbers of targets
    assert _non_numbers(result.text) == _non_numbers(original)
    assert result.text.count("\r\n") == original.count("\r\n")
    filtered, _ = _reload(result, program)
    g_nom, g_acc = ind.geometry(robot), ind.geometry(robot, PLANTED)
    tool = result.program.tool if result.program.tool is not None else np.eye(4)
    base = result.program.base if result.program.base is not None else np.eye(4)
    corrected = 0
    for c, t_new in zip(result.corrections, filtered.targets):
        t = c.target
        if not c.corrected:
            assert _same_numbers(t, t_new), t.name  # left as it was
            continue
        corrected += 1
        if t.kind == "pose":
            new_goal = base @ _frame(t_new.position, t_new.rotation)
            # the controller: its nominal inverse on the solution's branch (started from robocal's joints)
            q = ind.inverse(g_nom, new_goal, c.q, tool)
            intent = base @ _frame(t.position, t.rotation)
        else:
            q = t_new.q
            intent = ind.pose(g_nom, t.q, tool=tool)
        reached = ind.pose(g_acc, q, tool=tool)
        assert np.linalg.norm(reached[:3, 3] - intent[:3, 3]) < 0.01, t.name
        assert _angle_deg(reached[:3, :3], intent[:3, :3]) < 0.001, t.name
    assert corrected >= 2


def _reload(result, program):
    """The filtered files read back as programs (what a controller would get)."""
    folder = Path(re.sub(r"[^/]+$", "", str(PROGRAMS / program)))
    return load_program_text(result, folder, program)


def load_program_text(result, folder, program):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / Path(program).name
        path.write_bytes(result.text.encode("utf-8"))
        if result.dat is not None:
            path.with_suffix(".dat").write_bytes(result.dat.encode("utf-8"))
        return load_program(path)


def _same_numbers(a, b) -> bool:
    return all(a.fields[k].text == b.fields[k].text for k in a.fields)


def test_an_unreachable_target_is_flagged_and_left_as_it_was(tmp_path, accurate_files, run_cli):
    text = (PROGRAMS / "urscript/Prog1.script").read_text()
    # a target 9 m away: no UR10 reaches it
    far = re.sub(r"movel\(p\[[^\]]*\]", "movel(p[9.000000, 0.000000, 0.500000, 0.000000, 3.141593, 0.000000]", text,
                 count=1)
    src = tmp_path / "far.script"
    src.write_text(far)
    code, out, err = run_cli("filter", accurate_files["ur10"], src, "--nominal", "ur10", "--out", tmp_path / "f.script",
                             "--json", tmp_path / "s.json")
    assert code == 0, err
    summary = json.loads((tmp_path / "s.json").read_text())
    flagged = [t for t in summary["targets"] if t["status"] != "ok"]
    assert flagged and flagged[0]["status"].startswith("unreachable") and "left unchanged and flagged" in err
    assert "9.000000, 0.000000, 0.500000" in (tmp_path / "f.script").read_text()


def test_numbers_outside_the_corrected_targets_are_untouched(accurate_files):
    from robocal.filtering.program import fields_in

    for program, robot in CASES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = filter_program(accurate_files[robot], PROGRAMS / program, robot)
        for text, new, first, last in ((result.program.text, result.text, 0, result.program.split),
                                       (result.program.dat, result.dat, result.program.split, None)):
            if text is None:
                continue
            spans = {f.start for c in result.corrections[first:last] if c.corrected for f in c.target.fields.values()}
            before, after = fields_in(text), fields_in(new)
            assert len(before) == len(after)
            assert all(a.text == b.text for a, b in zip(before, after) if a.start not in spans), program


def test_bad_programs_are_input_errors_naming_the_file(tmp_path, accurate_files, run_cli):
    src = tmp_path / "empty.mod"
    src.write_text("MODULE M\nENDMODULE\n")
    code, _, err = run_cli("filter", accurate_files["irb120"], src, "--nominal", "irb120", "--out", tmp_path / "o.mod")
    assert code == 2 and "no targets found" in err and "empty.mod" in err and not (tmp_path / "o.mod").exists()
    code, _, err = run_cli("filter", accurate_files["irb120"], tmp_path / "x.txt", "--nominal", "irb120",
                           "--out", tmp_path / "o.txt")
    assert code == 2 and "give --format" in err
    bad = tmp_path / "bad.mod"
    bad.write_text("MODULE M\n  CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
                   "  CONST robtarget p2:=[[1,2,x],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n")
    code, _, err = run_cli("filter", accurate_files["irb120"], bad, "--nominal", "irb120", "--out", tmp_path / "o.mod")
    assert code == 2 and "bad.mod: line 3: robtarget p2" in err
    src = tmp_path / "bad.src"
    src.write_text("DEF bad()\nDECL E6POS P1={X 1.0,Y 2.0,Z ,A 0,B 0,C 0}\nPTP P1\nEND\n")
    code, _, err = run_cli("filter", accurate_files["kr5-arc"], src, "--nominal", "kr5-arc",
                           "--out", tmp_path / "o.src")
    assert code == 2 and "line 2" in err and "no number for Z" in err


def test_a_calibrated_model_of_another_robot_is_said(tmp_path, accurate_files):
    # an IRB 120's model against a KR5's program and nominal reaches none of it; a KR5 whose upper arm
    # is 30 mm longer than the controller's model corrects by centimetres: both said
    far = tmp_path / "long.toml"
    far.write_text(ind.robot_toml("kr5-arc", {"a2": 30.0}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        other = filter_program(accurate_files["irb120"], PROGRAMS / "krl/Program.src", "kr5-arc")
        long = filter_program(far, PROGRAMS / "krl/Program.src", "kr5-arc")
        fine = filter_program(accurate_files["kr5-arc"], PROGRAMS / "krl/Program.src", "kr5-arc")
    assert any(n.startswith("no target could be corrected: check that --nominal") for n in other.notes)
    assert any("mm: a calibration corrects by a few millimetres; check that --nominal" in n for n in long.notes)
    assert not any("check that --nominal" in n for n in fine.notes)

