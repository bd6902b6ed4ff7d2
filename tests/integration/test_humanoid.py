"""A humanoid upper body against an independent simulator (tests.humanoid_world: its own URDF text,
reader, forward kinematics and gravity moments): a torso whose last joint is coupled to the one before
it (a URDF <mimic>), two 7-axis arms, an external camera system on a marker of each hand, and every
joint elastic, the torso's loaded by both arms.  robocal reads the coupling, takes rows that give the
free joints only (or every joint), and the compliance of the tree must bring held-out poses down to
the camera system's noise where geometry alone cannot."""

import warnings

import numpy as np
import pytest

import robocal
from robocal.model import coupled
from tests import humanoid_world as hw

TIPS = "left_hand,right_hand"


def _nominal(tmp_path):
    path = tmp_path / "upper_body.urdf"
    path.write_text(hw.urdf())
    return path, robocal.load_robot(path, tip_link=TIPS)


def test_the_coupled_torso_joint_is_read_from_its_mimic_and_moves_as_the_independent_reader_says(tmp_path):
    path, robot = _nominal(tmp_path)
    assert robot.n_joints == 18 and robot.n_free == 17
    (c,) = robot.coupled
    assert (c.joint, c.sources, c.factors) == (3, (2,), (-1.0,))
    rng = np.random.default_rng(0)
    q = hw.joint_sets(rng, 20)
    truth = hw.Truth(hw.Urdf(hw.urdf()), {})  # the nominal body, rigid, in its own frame
    full = coupled.expand(robot.coupled, q, robot.n_joints)
    for side in ("left", "right"):
        T = robot.fk(full, chains=[f"{side}_hand"] * len(q))
        assert np.abs(T[:, :3, 3] - truth.marker(side, q)).max() < 1e-9


def test_rows_give_the_free_joints_or_every_joint_and_a_coupled_column_that_strays_is_said(tmp_path):
    path, robot = _nominal(tmp_path)
    rng = np.random.default_rng(1)
    truth = hw.plant(rng)
    q = hw.joint_sets(rng, 8)
    short, every = tmp_path / "free.csv", tmp_path / "every.csv"
    hw.write_rows(truth, q, np.random.default_rng(2), 0.1, short)
    hw.write_rows(truth, q, np.random.default_rng(2), 0.1, every, every=True)
    options = dict(n_joints=18, chains=("left_hand", "right_hand"),
                   coupled=tuple((c.joint, c.sources, c.factors, c.offset) for c in robot.coupled))
    a = robocal.load_measurements(short, **options)
    b = robocal.load_measurements(every, **options)
    assert a.q.shape == (16, 18)
    np.testing.assert_allclose(a.q, b.q, atol=1e-12)
    np.testing.assert_allclose(a.q[:, 3], -a.q[:, 2], atol=1e-15)
    lines = every.read_text().splitlines()
    for k in (3, 11):  # pose p2 of both hands: q4 half a degree off its coupling
        cells = lines[k].split(",")
        cells[2 + 3] = f"{float(cells[2 + 3]) + 0.5:.12f}"
        lines[k] = ",".join(cells)
    every.write_text("\n".join(lines) + "\n")
    with pytest.warns(robocal.RobocalWarning, match=r"q4 strays from its coupling \(q4 = −q3\) by up to 0\.5° "
                                                    r"\(row 4\): the file's values are used"):
        strayed = robocal.load_measurements(every, **options)
    assert strayed.q[2, 3] == pytest.approx(b.q[2, 3] + np.radians(0.5))


def test_the_torso_loaded_by_both_arms_is_found_by_the_tree_s_compliance(tmp_path):
    path, robot = _nominal(tmp_path)
    rng = np.random.default_rng(5)
    truth = hw.plant(rng)
    noise = 0.3
    cal, val = tmp_path / "cal.csv", tmp_path / "val.csv"
    hw.write_rows(truth, hw.joint_sets(rng, 150), rng, noise, cal)
    hw.write_rows(truth, hw.joint_sets(rng, 60), rng, noise, val)
    floor = noise * np.sqrt(3)  # the true model's held-out RMS: the noise itself
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geometric = robocal.calibrate(robot, cal, validate=val)
        elastic = robocal.calibrate(robot, cal, validate=val, model="compliance")
    held = {r.model: r.metrics["validation_after"].position["rms"] for r in (geometric, elastic)}
    assert held["geometric"] > 10 * floor  # the arms' weight bends the torso: no geometry takes it
    assert held["compliance"] < 1.25 * floor, held
    names = set(elastic.names) | set(elastic.identifiability.dropped)
    # joint 5 (the left shoulder) carries the left arm, never the right one's links 12–18
    assert "gravity5_11y" in names and not any(n.startswith("gravity5_12") for n in names)
    assert any(n.startswith("gravity2_1") for n in elastic.names)  # the torso pitch, loaded by both arms
    said = " ".join(elastic.warnings)
    assert "gravity has no moment about joint 1's axis" in said and said.count("gravity1_") <= 2
    for side in ("left", "right"):
        per = elastic.per_chain_metrics()[f"{side}_hand"]["validation_after"].position["rms"]
        assert per < 1.3 * floor
    out = tmp_path / "body.toml"
    written = elastic.export(out)
    again = robocal.load_robot(out)
    assert again.coupled == robot.coupled and again.terms is not None
    qv = coupled.expand(robot.coupled, hw.joint_sets(rng, 5), 18)
    for side in ("left", "right"):
        np.testing.assert_allclose(again.fk(qv, chains=[f"{side}_hand"] * 5),
                                   elastic.robot.fk(qv, chains=[f"{side}_hand"] * 5), atol=1e-9)
    arms = [p for p in written if p.name.startswith("body.") and p.name.endswith("_hand.toml")]
    assert len(arms) == 2 and "Geometry only" in arms[0].read_text()


def test_a_robot_file_states_a_joint_that_follows_several_and_refuses_what_cannot_be(tmp_path, run_cli):
    text = """name = "torso"
convention = "urdf"
[[joint]]
xyz = [0, 0, 300]
axis = [0, 1, 0]
[[joint]]
xyz = [0, 0, 350]
axis = [0, 1, 0]
[[joint]]
xyz = [0, 0, 350]
axis = [0, 1, 0]
follows = [{joint = 1, factor = -1}, {joint = 2, factor = -1}]
follows_offset = 2.5
"""
    path = tmp_path / "torso.toml"
    path.write_text(text)
    robot = robocal.load_robot(path)
    (c,) = robot.coupled
    assert c.describe() == "q3 = −q1 − q2 + 2.5°"
    q = robot.couple(np.array([[0.1, 0.2, 9.9]]))
    assert q[0, 2] == pytest.approx(-0.3 + np.radians(2.5))
    out = tmp_path / "again.toml"
    robocal.save_robot(robot, out)
    assert robocal.load_robot(out).coupled == robot.coupled
    # the chest stays level: the last link's orientation does not change with the free joints
    R = robot.fk(robot.couple(np.array([[0.3, -0.1, 0.0], [-0.2, 0.4, 0.0]])))[:, :3, :3]
    np.testing.assert_allclose(R[0], R[1], atol=1e-12)
    for bad, message in [("follows = [{joint = 3, factor = -1}]", "each joint followed is another joint 1…3"),
                         ("follows = [{joint = 1}]", "expected a list of tables {joint = K, factor = F}")]:
        path.write_text(text.replace("follows = [{joint = 1, factor = -1}, {joint = 2, factor = -1}]", bad))
        code, _, err = run_cli("evaluate", path, tmp_path / "x.csv")
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    data = tmp_path / "q.csv"
    data.write_text("q1,x,y,z\n1,0,0,0\n2,0,0,0\n3,0,0,0\n")
    path.write_text(text)
    code, _, err = run_cli("evaluate", path, data)
    assert code == 2 and "has 3 joints (2 free, the 1 coupled ones computed)" in err, err


def test_goals_for_a_robot_with_a_coupled_joint_are_refused_not_solved_freely(tmp_path, run_cli):
    """Inverse kinematics would move the coupled torso joint off its coupling (a pose the robot cannot
    take): compensate refuses on one line and writes nothing; a learned correction of a tree is refused."""
    path, robot = _nominal(tmp_path)
    goals = tmp_path / "goals.csv"
    goals.write_text("x,y,z\n500,100,800\n")
    code, _, err = run_cli("compensate", path, path, goals, "--tip-link", "left_hand", "--out", tmp_path / "c.csv")
    assert code == 2 and "follows others" in err and "inverse kinematics" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c.csv").exists()
    rng = np.random.default_rng(3)
    data = tmp_path / "d.csv"
    hw.write_rows(hw.plant(rng), hw.joint_sets(rng, 20), rng, 0.3, data)
    code, _, err = run_cli("calibrate", path, data, "--tip-link", TIPS, "--model", "trees")
    assert code == 2 and "learned corrections run along one chain" in err
