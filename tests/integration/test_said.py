"""What robocal says: notes inform (choices made, frames registered, files written), warnings
ask the user to act or doubt a figure, and --quiet hides the notes, never the warnings."""

import warnings

from robocal import calibrate
from robocal.exceptions import RobocalWarning
from robocal.io.measurements import save_measurements
from robocal.io.robotfile import load_robot
from robocal.math.se3 import xyz_rpy_to_transform
from robocal.simulation import simulate


def _tracker_file(tmp_path, poses=40, frame=True):
    """A campaign in a tracker frame away from the robot's (frames auto registers it)."""
    robot = load_robot("kr5-arc")
    if frame:
        robot = robot.replace(base=xyz_rpy_to_transform([1500.0, -300.0, 200.0], [0.0, 0.0, 0.7]))
    sim = simulate(robot, poses, deviations="uniform:0.2,0.002", seed=3, noise=0.01)
    path = tmp_path / "arm.csv"
    save_measurements(sim.measurements, path)
    return path


def test_a_choice_made_is_a_note_never_a_python_warning(tmp_path):
    path = _tracker_file(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = calibrate("kr5-arc", path, "lm")
    raised = [str(w.message) for w in caught if issubclass(w.category, RobocalWarning)]
    assert any(n.startswith("frames auto:") for n in res.notes)
    assert not any(m.startswith("frames auto:") for m in raised + res.warnings)
    assert res.to_dict()["notes"] == res.notes


def test_the_command_line_prints_notes_as_notes_and_quiet_hides_them_only(tmp_path, run_cli):
    path = _tracker_file(tmp_path)
    code, out, err = run_cli("calibrate", "kr5-arc", path, "--out", tmp_path / "r.json")
    assert code == 0
    assert "robocal: note: frames auto:" in err and "robocal: warning: frames auto" not in err
    code, out, err = run_cli("calibrate", "kr5-arc", path, "--quiet", "--out", tmp_path / "q.json")
    assert code == 0 and "note:" not in err and out == ""
    # a warning is something to act on: it is said even with --quiet (too few poses for the parameters)
    few = _tracker_file(tmp_path, poses=6, frame=False)
    code, out, err = run_cli("calibrate", "kr5-arc", few, "--frames", "none", "--quiet")
    assert "robocal: warning:" in err and "note:" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert all(line.startswith(("robocal: warning:", "robocal: error:")) for line in lines), lines


def test_export_is_repeatable_and_each_file_says_what_its_receiver_gets(tmp_path, run_cli):
    path = _tracker_file(tmp_path)
    out = [tmp_path / "arm.toml", tmp_path / "arm.urdf", tmp_path / "arm.yaml"]
    code, _, err = run_cli("calibrate", "kr5-arc", path, "--export", out[0], "--export", out[1], "--export", out[2])
    assert code == 0, err
    assert all(p.is_file() and p.stat().st_size > 0 for p in out)
    for p in out:
        assert f"robocal: note: wrote {p}" in err
    code, _, err = run_cli("calibrate", "kr5-arc", path, "--export", out[0], "--export", out[0])
    assert code == 2 and "--export" in err and err.count("\n") == 1


def test_auto_under_quiet_says_what_matters_in_three_lines_at_most(tmp_path, run_cli):
    """The IRB 120 under --model auto: a term that gravity never loads (joint 1 turns about the
    vertical) is one choice, said once, and --quiet leaves the notes out; the headline's "next" is
    the report's own advice."""
    sim = simulate(load_robot("irb120"), 100, deviations="uniform:0.3,0.003", seed=2, noise=0.02, measure="position")
    path = tmp_path / "irb.csv"
    save_measurements(sim.measurements, path)
    code, out, err = run_cli("calibrate", "irb120", path, "--model", "auto", "--quiet")
    assert code == 0, err
    said = [line for line in (out + err).splitlines() if line.strip()]
    assert len(said) <= 3, said
    assert sum("gravity1_" in line for line in said) <= 1
    code, out, err = run_cli("calibrate", "irb120", path, "--report", tmp_path / "r.html")
    nexts = [line[len("next: "):] for line in out.splitlines() if line.startswith("next: ")]
    assert 1 <= len(nexts) <= 3
    import html

    page = html.unescape(" ".join((tmp_path / "r.html").read_text().split()))
    assert all(" ".join(n.split())[:60].replace("`", "") in page.replace("<code>", "").replace("</code>", "")
               for n in nexts)
