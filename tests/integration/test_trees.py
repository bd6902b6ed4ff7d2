"""Kinematic trees against an independent cell (tests.tree_world: its own URDF text, its own reader
and forward kinematics, OpenCV's projection): a turntable carrying two arms and a pan-tilt neck with a
camera.  robocal reads the tree from the URDF's tips, calibrates both arms as one robot (the
turntable's joint one set of parameters), and must find the planted truth within its σ, predict new
poses as the true model does, and write a URDF another reader agrees with."""

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import robocal
from tests import tree_world as tw

TIPS = "left_tool,right_tool,head_camera"


def _nominal(tmp_path, neck=True):
    path = tmp_path / "dual.urdf"
    path.write_text(tw.urdf(neck=neck))
    return path, robocal.load_robot(path, tip_link=TIPS if neck else "left_tool,right_tool")


def test_the_tree_is_read_from_the_tips_and_moves_as_an_independent_reader_says(tmp_path):
    path, robot = _nominal(tmp_path)
    assert robot.tree is not None and robot.tree.names == ("left_tool", "right_tool", "head_camera")
    assert robot.joint_names == tuple(tw.movable())
    # the turntable is the trunk all three chains share: one joint, one set of parameters
    assert robot.tree.shared() == (0,)
    truth = tw.Truth(tw.Urdf(tw.urdf()), {}, np.eye(4))
    q = tw.joint_sets(np.random.default_rng(0), 20)
    for tip in robot.tree.names:
        mine = robot.fk(q, chains=[tip] * len(q))
        assert np.abs(mine - truth.pose(tip, q)).max() < 1e-9


def _kept(robot, data):
    """The joint parameters the rows identify (robocal's own choice on the nominal model)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = robocal.calibrate(robot, data, frames="base+tool", model="geometric")
    return [n for n in result.identifiability.kept if not n.startswith(("base", "tool"))]


def _planted(robot, kept, rng, length=0.3, angle=0.5e-3):
    """A truth moved in the parameters the rows identify: URDF origins (mm → m, a rotation vector
    after the file's rpy → new rpy) and joint zeros, in the independent cell's own terms."""
    names = robot.joint_names
    moves, zeros, values = {}, {}, {}
    nominal = {j[0]: j for j in tw.joints()}
    for name in kept:
        kind = name.rstrip("0123456789")
        values[name] = rng.normal(0, angle if kind in ("rx", "ry", "rz", "theta") else length)
    for i, joint in enumerate(names):
        d = [values.get(f"{k}{i + 1}", 0.0) for k in ("x", "y", "z")]
        r = np.array([values.get(f"{k}{i + 1}", 0.0) for k in ("rx", "ry", "rz")])
        rpy = np.array(nominal[joint][5])
        R = Rotation.from_euler("xyz", rpy).as_matrix() @ Rotation.from_rotvec(r).as_matrix()
        moves[joint] = (np.array(d) / 1000.0, Rotation.from_matrix(R).as_euler("xyz") - rpy)
        zeros[joint] = values.get(f"theta{i + 1}", 0.0)
    return values, moves, zeros


def _measurements(truth, q, rng, noise):
    rows = tw.tracker_rows(truth, q, rng, noise)
    return robocal.Measurements(q=np.array([r["q"] for r in rows]), position=np.array([r["xyz"] for r in rows]),
                                chain=tuple(r["chain"] for r in rows), pose_ids=tuple(r["pose_id"] for r in rows))


def test_both_arms_calibrated_as_one_tree_find_the_planted_truth(tmp_path):
    _, robot = _nominal(tmp_path, neck=False)
    rng = np.random.default_rng(11)
    q, q_new = tw.joint_sets(rng, 60, neck=False), tw.joint_sets(rng, 60, neck=False)
    nominal_cell = tw.Truth(tw.Urdf(tw.urdf(neck=False)), {}, np.eye(4), neck=False)
    kept = _kept(robot, _measurements(nominal_cell, q, rng, 0.02))
    values, moves, zeros = _planted(robot, kept, rng)
    truth = tw.Truth(tw.Urdf(tw.urdf(moves, neck=False)), zeros, tw.tracker(rng), neck=False)
    data, new = _measurements(truth, q, rng, 0.02), _measurements(truth, q_new, rng, 0.02)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = robocal.calibrate(robot, data, frames="base+tool", validate=new)
    assert result.physical.physical
    # every parameter it moved within 3σ of the truth; the turntable's one set of parameters
    sigma = dict(zip(result.names, result.uncertainty))
    x = dict(zip(result.names, result.x))
    z = [(x[n] - values.get(n, 0.0)) / sigma[n] for n in result.names if n in sigma and n[0] in "xyzrt"
         and not n.startswith(("base", "tool"))]
    assert np.max(np.abs(z)) < 3.5, max(z, key=abs)
    # new poses of both arms within 1.2× of what the true model gives there (the noise, 0.02 mm per axis)
    floor = 0.02 * np.sqrt(3)
    assert result.metrics["validation_after"].position["rms"] < 1.2 * floor


def _calibrated_dual_arm(tmp_path, seed=11, n=60):
    _, robot = _nominal(tmp_path, neck=False)
    rng = np.random.default_rng(seed)
    q = tw.joint_sets(rng, n, neck=False)
    truth = tw.plant(rng, neck=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return robocal.calibrate(robot, _measurements(truth, q, rng, 0.02), frames="base+tool"), truth


def test_the_exported_urdf_and_per_arm_files_move_every_branch_as_the_calibrated_tree(tmp_path):
    from pytransform3d.urdf import UrdfTransformManager

    result, _ = _calibrated_dual_arm(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    written = result.export(out / "dual.urdf")
    assert {p.name for p in written} >= {"dual.urdf", "dual.left_tool.toml", "dual.right_tool.toml"}
    text = (out / "dual.urdf").read_text()
    ours = tw.Urdf(text)
    theirs = UrdfTransformManager()
    theirs.load_urdf(text)
    q = tw.joint_sets(np.random.default_rng(5), 6, neck=False)
    names = tw.movable(neck=False)
    calibrated = result.robot
    for chain in calibrated.tree.names:
        mine = calibrated.fk(q, chains=[chain] * len(q))
        arm = robocal.load_robot(out / f"dual.{chain}.toml")
        path = list(calibrated.tree.chains[chain])
        assert arm.tree is None and arm.joint_names == tuple(names[j] for j in path)
        assert np.abs(arm.fk(q[:, path]) - mine).max() < 1e-9
        for row, T in zip(q, mine):
            values = dict(zip(names, row))
            independent = ours.transform("measuring_frame", f"target_{chain}", values)
            for name, v in values.items():
                theirs.set_joint(name, v)
            other = theirs.get_transform(f"target_{chain}", "measuring_frame")
            for M in (independent, other):
                M = M.copy()
                M[:3, 3] *= 1000.0
                assert np.abs(M - T).max() < 1e-9
    # read back by robocal from its tips, the tree is the calibrated one
    again = robocal.load_robot(out / "dual.urdf", tip_link="left_tool,right_tool")
    for chain in calibrated.tree.names:
        assert np.abs(again.fk(q, chains=[chain] * len(q)) - calibrated.fk(q, chains=[chain] * len(q))).max() < 1e-9


def test_a_camera_on_a_pan_tilt_neck_calibrates_both_arms_through_the_trunk_they_share(tmp_path):
    """The head's camera rides turntable, pan and tilt; the markers it sees ride turntable and an arm:
    the residual follows the tree from the camera down to the turntable and up the arm."""
    cw = pytest.importorskip("tests.camera_world")
    path, robot = _nominal(tmp_path)
    rng = np.random.default_rng(3)
    truth = tw.plant(rng)
    camera = cw.camera("head", np.eye(4), f=800.0, size=(1280, 960))
    camera.write(tmp_path / "head.yaml")
    markers = {f"m{i + 1}": np.array([x, y, z], float) for i, (x, y, z) in
               enumerate((x, y, z) for x in (-25, 25) for y in (-25, 25) for z in (75, 125))}
    cw.write_markers({k: (p, None) for k, p in markers.items()}, tmp_path / "markers.csv")
    for name, m in (("data.csv", 300), ("held.csv", 150)):
        q = tw.facing_the_hands(truth, tw.joint_sets(rng, m))
        tw.write_rows(tw.camera_rows(truth, camera, markers, q, rng, 0.5), tmp_path / name, tw.movable())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = robocal.calibrate(robot, str(tmp_path / "data.csv"), markers=str(tmp_path / "markers.csv"),
                                   cameras=[f"head={tmp_path / 'head.yaml'},link=head_camera"],
                                   validate=str(tmp_path / "held.csv"))
    assert result.physical.physical
    # the camera found on the head's last link, the neck's joints in the tree's rows
    assert result.robot.cameras["head"].link == tw.movable().index("neck_tilt") + 1
    # new poses within 1.2× of what the true model gives there (0.5 px per axis)
    assert result.metrics["validation_after"].position["rms"] < 1.2 * 0.5 * np.sqrt(2)
    after = result.metrics["validation_after"].position["rms"]
    assert result.metrics["validation_before"].position["rms"] > 1.5 * after


@pytest.mark.parametrize("change, message", [
    (lambda text: text.replace(",left_tool,", ",left_arm,", 1), "row 2, column 'chain': chain 'left_arm' is not "
                                                                 "one of left_tool, right_tool"),
    (lambda text: "\n".join(",".join(c for i, c in enumerate(line.split(",")) if i != 1)
                            for line in text.splitlines()) + "\n", "each row names its chain (a chain column)"),
])
def test_rows_that_do_not_name_a_chain_of_the_tree_are_refused_on_one_line(tmp_path, run_cli, change, message):
    path, robot = _nominal(tmp_path, neck=False)
    rng = np.random.default_rng(2)
    rows = tw.tracker_rows(tw.plant(rng, neck=False), tw.joint_sets(rng, 12, neck=False), rng, 0.02)
    data = tmp_path / "data.csv"
    tw.write_rows(rows, data, tw.movable(neck=False))
    data.write_text(change(data.read_text()))
    code, _, err = run_cli("calibrate", path, data, "--tip-link", "left_tool,right_tool", "--out", tmp_path / "r.json")
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "r.json").exists()


def test_a_chain_column_for_a_serial_robot_is_refused(tmp_path, run_cli):
    path, _ = _nominal(tmp_path, neck=False)
    rng = np.random.default_rng(2)
    rows = tw.tracker_rows(tw.plant(rng, neck=False), tw.joint_sets(rng, 12, neck=False), rng, 0.02)
    data = tmp_path / "data.csv"
    left = [{**r, "q": r["q"][:7]} for r in rows if r["chain"] == "left_tool"]  # the left arm's own joints
    tw.write_rows(left, data, tw.movable(neck=False)[:7])
    code, _, err = run_cli("calibrate", path, data, "--tip-link", "left_tool")
    assert code == 2 and "has a chain column" in err and len(err.strip().splitlines()) == 1, err


def test_the_tree_s_standard_errors_match_the_spread_over_40_draws(tmp_path):
    """FIGAROH's check on a tree: over 40 campaigns (new noise, new planted truth) every identified
    parameter's error in units of its reported σ spreads as a standard normal does."""
    _, robot = _nominal(tmp_path, neck=False)
    rng = np.random.default_rng(21)
    q = tw.joint_sets(rng, 30, neck=False)
    nominal_cell = tw.Truth(tw.Urdf(tw.urdf(neck=False)), {}, np.eye(4), neck=False)
    kept = _kept(robot, _measurements(nominal_cell, q, rng, 0.02))
    z = []
    for _ in range(40):
        values, moves, zeros = _planted(robot, kept, rng)
        truth = tw.Truth(tw.Urdf(tw.urdf(moves, neck=False)), zeros, tw.tracker(rng), neck=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = robocal.calibrate(robot, _measurements(truth, q, rng, 0.02), frames="base+tool",
                                       model="geometric", noise=0.02)
        sigma = dict(zip(result.names, result.uncertainty))
        z += [(x - values.get(n, 0.0)) / sigma[n] for n, x in zip(result.names, result.x)
              if not n.startswith(("base", "tool")) and n not in result.held]
    z = np.array(z)
    assert 0.8 <= z.std() <= 1.25, z.std()
    assert np.abs(z).max() < 5.0
