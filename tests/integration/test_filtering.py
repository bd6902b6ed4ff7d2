"""Program filtering against a planted accurate robot, checked by an independent controller.

Programs are written by tests/controller.py from joints the targets were taught at, in each
language's documented form, with configuration data computed from those joints as the manuals
define them.  After filtering, the controller reads the new numbers back with its own patterns,
inverts its nominal model started from the taught joints (tests/independent.py), and the
planted accurate robot at those joints must land on the original target within 0.01 mm and
0.001°; the configuration data written must be those of the joints the controller went to.
The public programs of tests/data/programs are run too: nothing but target numbers changes.
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import controller as ctl
import independent as ind
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.filtering import Frames, filter_program, load_program
from robocal.math.se3 import frame_from_values

PROGRAMS = Path(__file__).parents[1] / "data" / "programs"
PLANTED = {"a2": 0.4, "d4": -0.3, "theta2": 0.002, "alpha3": -0.0015, "theta5": 0.001, "a3": 0.25, "theta1": 0.001}
CHECK_MM, CHECK_DEG = 0.01, 0.001
#: a pedestal: the robot stands 750 mm up, turned by 30° about the vertical, 2 m from the world's origin
PEDESTAL = ctl.frame([2000.0, -500.0, 750.0], [0.0, 0.0, 30.0])


def _angle_deg(A, B) -> float:
    return float(np.degrees(np.linalg.norm(Rotation.from_matrix(A @ B.T).as_rotvec())))


def _lands(reached, intent):
    assert np.linalg.norm(reached[:3, 3] - intent[:3, 3]) < CHECK_MM
    assert _angle_deg(reached[:3, :3], intent[:3, :3]) < CHECK_DEG


def _robots(folder: Path, name: str, base, coupling: str = "", planted=None):
    nominal, accurate = folder / f"{name}-nominal.toml", folder / f"{name}-accurate.toml"
    nominal.write_text(ind.robot_toml(name, {}, base=base, coupling=coupling))
    accurate.write_text(ind.robot_toml(name, PLANTED if planted is None else planted, base=base, coupling=coupling))
    return nominal, accurate


def _taught(rng, box_deg, n):
    box = np.radians(box_deg)
    return rng.uniform(box[:, 0], box[:, 1], (n, 6))


def _non_numbers(text: str) -> str:
    return re.sub(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", "#", text)


# --- KUKA: its axis conventions, on a pedestal, frames from $config.dat and FDAT ---------------

KUKA_BOX = [(-120, 120), (-140, -40), (20, 140), (-300, 300), (25, 110), (-300, 300)]


def test_krl_on_a_kuka_convention_robot_on_a_pedestal(tmp_path, run_cli):
    rng = np.random.default_rng(7)
    B = PEDESTAL @ ind.base_of("kr5-kuka")
    nominal, accurate = _robots(tmp_path, "kr5-kuka", B)
    g_nom, g_acc = ind.geometry("kr5-kuka"), ind.geometry("kr5-kuka", PLANTED)
    tool, user = ctl.frame([12.0, -5.0, 180.0], [0.0, 35.0, 10.0]), ctl.frame([2900.0, -300.0, 760.0], [0, 0, -15.0])
    q = _taught(rng, KUKA_BOX, 14)
    q[::3, 4] *= -1.0  # wrists flipped too
    q[1::4, 2] = np.radians(rng.uniform(-14.0, 5.0, len(q[1::4])))  # elbows down (A3 below the stretched 10.9°)
    world = [ind.pose(g_nom, qi, base=B, tool=tool) for qi in q]
    st = [ctl.kuka_status("kr5-kuka", g_nom, qi, PEDESTAL) for qi in q]
    assert {s for s, _ in st} >= {0, 1, 2, 5, 6} and len({t for _, t in st}) > 3  # several configurations
    joints = _taught(rng, KUKA_BOX, 3)
    src, dat = ctl.krl_program([np.linalg.inv(user) @ T for T in world], joints, st)
    folder = tmp_path / "KRC" / "R1"
    (folder / "Program").mkdir(parents=True)
    (folder / "System").mkdir()
    (folder / "Program" / "cell.src").write_bytes(src.encode())
    (folder / "Program" / "cell.dat").write_bytes(dat.encode())
    (folder / "System" / "$config.dat").write_text(ctl.krl_config({2: tool}, {1: user}))
    out = tmp_path / "out" / "cell.src"
    out.parent.mkdir()
    code, _, err = run_cli("filter", accurate, folder / "Program" / "cell.src", "--nominal", nominal, "--out", out,
                           "--summary", tmp_path / "s.json")
    summary = json.loads((tmp_path / "s.json").read_text())
    assert code == 0, err
    assert summary["status"] == {"ok": 17}
    # the .src has no numbers: it changes by the stamp alone, three comment lines after its DEF
    written = out.read_bytes().decode().replace("\r\n", "\n")
    lines = written.split("\n")
    at = next(i for i, x in enumerate(lines) if x.startswith("DEF"))
    stamp = lines[at + 1:at + 4]
    assert stamp[0].lstrip().startswith("; Filtered by robocal")
    assert "sha256" in stamp[1] and "taught points" in stamp[2]
    assert "\n".join(x for x in written.split("\n") if x not in stamp) == src.replace("\r\n", "\n")
    new = ctl.read_krl(out.with_suffix(".dat").read_text())
    for i, (qi, T) in enumerate(zip(q, world)):
        v = new[f"XP{i + 1}"]
        T_new = B_user = user @ ctl.frame([v["X"], v["Y"], v["Z"]], [v["C"], v["B"], v["A"]])
        q_ctrl = ind.inverse(g_nom, B_user, qi, tool=tool, base=B)
        assert (int(v["S"]), int(v["T"])) == ctl.kuka_status("kr5-kuka", g_nom, q_ctrl, PEDESTAL)
        _lands(ind.pose(g_acc, q_ctrl, base=B, tool=tool), T)
        assert np.linalg.norm(T_new[:3, 3] - T[:3, 3]) > 0.05  # it was corrected
    for i, qi in enumerate(joints):
        v = new[f"XJ{i + 1}"]
        _lands(ind.pose(g_acc, np.radians([v[f"A{k}"] for k in range(1, 7)]), base=B, tool=tool),
               ind.pose(g_nom, qi, base=B, tool=tool))
    # the same program with the nominal model of the same robot for its calibration: byte for byte unchanged
    code, _, err = run_cli("filter", nominal, folder / "Program" / "cell.src", "--nominal", nominal, "--out",
                           tmp_path / "out" / "same.src")
    assert code == 0, err
    assert (tmp_path / "out" / "same.dat").read_bytes() == dat.encode()


def test_krl_without_its_config_dat_flags_the_targets_and_exits_3(tmp_path, run_cli):
    rng = np.random.default_rng(8)
    B = ind.base_of("kr5-kuka")
    nominal, accurate = _robots(tmp_path, "kr5-kuka", B)
    g = ind.geometry("kr5-kuka")
    q = _taught(rng, KUKA_BOX, 3)
    src, dat = ctl.krl_program([ind.pose(g, qi, base=B) for qi in q], [], [ctl.kuka_status("kr5-kuka", g, qi)
                                                                          for qi in q])
    (tmp_path / "p.src").write_text(src)
    (tmp_path / "p.dat").write_text(dat)
    code, _, err = run_cli("filter", accurate, tmp_path / "p.src", "--nominal", nominal, "--out", tmp_path / "o.src",
                           "--summary", tmp_path / "s.json")
    rows = json.loads((tmp_path / "s.json").read_text())["targets"]
    assert code == 3 and (tmp_path / "o.dat").read_bytes() == (tmp_path / "p.dat").read_bytes()  # all flagged
    assert [r["status"] for r in rows] == ["frame"] * 3
    assert "$config.dat, which was not found" in rows[0]["reason"] and "3 frame" in err
    # given on the command line instead: corrected (the world is the robot's base here)
    code, _, err = run_cli("filter", accurate, tmp_path / "p.src", "--nominal", nominal, "--out", tmp_path / "o.src",
                           "--tool", "2=0,0,0,0,0,0", "--user-frame", "1=0,0,0,0,0,0")
    assert code == 0, err


# --- ABB: a pedestal, a work object and a tool of the module ----------------------------------

def _abb_cell(tmp_path):
    """An IRB 120 on the pedestal, its nominal and planted robot files and geometries, a gun tool and a
    table work object (world frames, mm)."""
    nominal, accurate = _robots(tmp_path, "irb120", PEDESTAL)
    tool = ctl.frame([0.0, 25.0, 140.0], [0.0, -30.0, 0.0])
    wobj = PEDESTAL @ ctl.frame([450.0, -100.0, 120.0], [0.0, 0.0, 90.0])
    return nominal, accurate, ind.geometry("irb120"), ind.geometry("irb120", PLANTED), tool, wobj


def test_rapid_on_a_pedestal_with_work_object_and_tool(tmp_path):
    rng = np.random.default_rng(11)
    nominal, accurate, g_nom, g_acc, tool, wobj = _abb_cell(tmp_path)
    box = [(-150, 150), (-60, 70), (-80, 50), (-150, 150), (20, 110), (-350, 350)]
    q = _taught(rng, box, 16)
    q[1::2, 4] *= -1.0
    world = [ind.pose(g_nom, qi, base=PEDESTAL, tool=tool) for qi in q]
    cfs = [ctl.abb_config("irb120", g_nom, qi, PEDESTAL) for qi in q]
    joints = _taught(rng, box, 2)
    text = ctl.rapid_program([np.linalg.inv(wobj) @ T for T in world], cfs, joints, tool, wobj)
    (tmp_path / "cell.mod").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(accurate, tmp_path / "cell.mod", nominal)
    assert result.counts() == {"ok": 18}, [(c.target.name, c.status, c.reason) for c in result.flagged]
    new = ctl.read_rapid(result.text)
    for i, (qi, T) in enumerate(zip(q, world)):
        v = new[f"p{i + 1}"]
        T_new = wobj @ ctl.frame(v[:3], [0, 0, 0])
        T_new[:3, :3] = wobj[:3, :3] @ Rotation.from_quat([v[4], v[5], v[6], v[3]]).as_matrix()
        q_ctrl = ind.inverse(g_nom, T_new, qi, tool=tool, base=PEDESTAL)
        assert [int(x) for x in v[7:11]] == ctl.abb_config("irb120", g_nom, q_ctrl, PEDESTAL)
        _lands(ind.pose(g_acc, q_ctrl, base=PEDESTAL, tool=tool), T)
    for i, qi in enumerate(joints):
        v = new[f"j{i + 1}"]
        _lands(ind.pose(g_acc, np.radians(v[:6]), base=PEDESTAL, tool=tool), ind.pose(g_nom, qi, base=PEDESTAL,
                                                                                        tool=tool))
    assert _non_numbers(result.text) == _non_numbers(text)


# --- UR: qnear inline and as a variable, NAME_q for movel, set_tcp, a feature -----------------

def test_urscript_takes_the_branch_of_qnear_and_never_corrects_it(tmp_path):
    rng = np.random.default_rng(5)
    nominal, accurate = _robots(tmp_path, "ur10", np.eye(4))
    g_nom, g_acc = ind.geometry("ur10"), ind.geometry("ur10", PLANTED)
    tcp = ctl.frame([0.0, 0.0, 120.0], [0.0, 0.0, 0.0])
    plane = ctl.frame([300.0, -400.0, 50.0], [0.0, 0.0, 40.0])
    box = [(-170, 170), (-150, -30), (30, 150), (-170, -10), (-150, -30), (-170, 170)]
    q = _taught(rng, box, 4)
    q[1, 4] *= -1.0  # the wrist on its other branch
    q[3] = q[2] + np.radians([5.0, -4.0, 6.0, 3.0, -5.0, 8.0])  # movel with no qnear: near where the robot is

    def p(T):
        r = Rotation.from_matrix(T[:3, :3]).as_rotvec()
        return "p[" + ", ".join(f"{v:.9f}" for v in (*(T[:3, 3] / 1000.0), *r)) + "]"

    def qs(x):
        return "[" + ", ".join(f"{v:.9f}" for v in x) + "]"

    world = [ind.pose(g_nom, qi, tool=tcp) for qi in q]
    text = "\n".join([
        "def cell():", f"  set_tcp({p(tcp)})", f"  global Plane_1={p(plane)}",
        f"  global Wp_1_p={p(world[0])}", f"  global Wp_1_q={qs(q[0])}",
        f"  global Wp_2_p={p(world[1])}", f"  global Wp_2_q={qs(q[1])}",
        "  movej(get_inverse_kin(Wp_1_p, qnear=Wp_1_q), a=1.4, v=1.05)",
        "  movel(Wp_2_p, a=1.2, v=0.25)",
        f"  movej(get_inverse_kin({p(world[2])}, qnear={qs(q[2])}), a=1.4, v=1.05)",
        f"  movel(pose_trans(Plane_1, {p(np.linalg.inv(plane) @ world[3])}), a=1.2, v=0.25)", "end", ""])
    (tmp_path / "cell.script").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(accurate, tmp_path / "cell.script", nominal)
    assert result.counts() == {"ok": 4}
    out = result.text
    # the hints are not targets: both joint lists stay as they were
    assert qs(q[0]) in out and qs(q[1]) in out and qs(q[2]) in out
    poses = [[float(v) for v in m.split(",")] for m in re.findall(r"p\[([^\]]*)\]", out)]
    new = [poses[2], poses[3], poses[4], poses[5]]  # after set_tcp and Plane_1
    for i, (qi, T, v) in enumerate(zip(q, world, new)):
        T_new = ctl.frame(np.array(v[:3]) * 1000.0, [0, 0, 0])
        T_new[:3, :3] = Rotation.from_rotvec(v[3:]).as_matrix()
        if i == 3:
            T_new = plane @ T_new
        # UR's controller: the solution nearest qnear, or, for movel without one, nearest where the robot is
        q_ctrl = ind.inverse(g_nom, T_new, qi if i < 3 else q[2], tool=tcp)
        assert np.abs(q_ctrl - qi).max() < np.radians(5.0)
        _lands(ind.pose(g_acc, q_ctrl, tool=tcp), T)


# --- FANUC: UF/UT given, CONFIG strings, the J2/J3 coupling, PR[] and Offset flagged ------------

COUPLING = "[controller]\ncoupling = [{joint = 3, plus = 2, factor = 1.0}]"


def test_fanuc_positions_in_user_frame_and_tool_with_coupled_joints(tmp_path, run_cli):
    rng = np.random.default_rng(21)
    nominal, accurate = _robots(tmp_path, "irb120", np.eye(4), COUPLING)
    g_nom, g_acc = ind.geometry("irb120"), ind.geometry("irb120", PLANTED)
    tool, uf = ctl.frame([0.0, 0.0, 210.0], [0.0, 0.0, 0.0]), ctl.frame([500.0, 200.0, 100.0], [0.0, 0.0, 20.0])
    box = [(-150, 150), (-60, 70), (-80, 50), (-150, 150), (20, 110), (-350, 350)]
    q = _taught(rng, box, 10)  # the model's joints
    q[::2, 4] *= -1.0
    world = [ind.pose(g_nom, qi, tool=tool) for qi in q]
    configs = [ctl.fanuc_config("irb120", g_nom, qi) for qi in q]
    controller = lambda m: np.array([m[0], m[1], m[2] - m[1], m[3], m[4], m[5]])  # noqa: E731  J3 = q3 − J2
    joints = [controller(qi) for qi in _taught(rng, box, 2)]
    text = ctl.fanuc_program([np.linalg.inv(uf) @ T for T in world], configs, joints)
    (tmp_path / "CELL.LS").write_bytes(text.encode())
    out = tmp_path / "OUT.LS"
    args = ("filter", accurate, tmp_path / "CELL.LS", "--nominal", nominal, "--out", out,
            "--summary", tmp_path / "s.json")
    code, _, err = run_cli(*args)
    rows = json.loads((tmp_path / "s.json").read_text())["targets"]
    status = {r["target"]: r["status"] for r in rows}
    assert code == 3 and status.pop("P[1]") == "unsupported" and status.pop("PR[3]") == "unsupported"
    reason = {r["target"]: r["reason"] for r in rows}
    assert set(status.values()) == {"frame"} and "give --tool 2=" in reason["P[2]"]
    code, _, err = run_cli(*args, "--tool", "2=0,0,210,0,0,0", "--user-frame", "1=500,200,100,0,0,20")
    rows = json.loads((tmp_path / "s.json").read_text())["targets"]
    assert code == 3, err  # PR[3] and the offset motion's P[1]
    status = {r["target"]: r["status"] for r in rows}
    assert status.pop("PR[3]") == "unsupported" and status.pop("P[1]") == "unsupported"
    assert set(status.values()) == {"ok"} and len(status) == 11
    new = ctl.read_fanuc(out.read_text())
    assert new[1]["X"] == ctl.read_fanuc(text)[1]["X"]  # P[1] left as it was
    for i in range(1, len(q)):
        v = new[i + 1]
        T_new = uf @ ctl.frame([v["X"], v["Y"], v["Z"]], [v["W"], v["P"], v["R"]])
        q_ctrl = ind.inverse(g_nom, T_new, q[i], tool=tool)
        assert v["config"] == ctl.fanuc_config("irb120", g_nom, q_ctrl)
        _lands(ind.pose(g_acc, q_ctrl, tool=tool), world[i])
    for i, J in enumerate(joints):
        v = new[len(q) + i + 1]
        J_new = np.radians([v[f"J{k}"] for k in range(1, 7)])
        model = lambda c: np.array([c[0], c[1], c[2] + c[1], c[3], c[4], c[5]])  # noqa: E731
        _lands(ind.pose(g_acc, model(J_new), tool=tool), ind.pose(g_nom, model(J), tool=tool))
    assert _non_numbers(out.read_bytes().decode()) == _non_numbers(text)


# --- the public programs ---------------------------------------------------------------------

TOOL = frame_from_values([0.0, 0.0, 150.0])
BASE2 = frame_from_values([400.0, 0.0, 0.0])
PUBLIC = [("krl/demo_screenshot.src", "kr5-arc", Frames(tools={"1": TOOL}, users={"2": BASE2})),
          ("krl/Program.src", "kr5-arc", Frames()),
          ("rapid/Module1.mod", "irb120", Frames(tools={"smc_gripper": TOOL})),
          ("rapid/Program.mod", "irb120", Frames()), ("urscript/timing_debug.script", "ur10", Frames()),
          ("urscript/PickAndPlace_App_Final.script", "ur10", Frames()), ("urscript/Prog1.script", "ur10", Frames())]


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("planted")
    out = {}
    for robot in ("kr5-arc", "irb120", "ur10"):
        out[robot] = folder / f"{robot}.toml"
        out[robot].write_text(ind.robot_toml(robot, PLANTED))
    return out


@pytest.mark.parametrize("program,robot,frames", PUBLIC)
def test_public_programs_change_target_numbers_only(program, robot, frames, planted):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(planted[robot], PROGRAMS / program, robot, frames=frames)
        same = filter_program(robot, PROGRAMS / program, robot, frames=frames)
    files = [PROGRAMS / program] + ([(PROGRAMS / program).with_suffix(".dat")] if len(result.texts) > 1 else [])
    for path, new, identical in zip(files, result.texts, same.texts):
        original = path.read_bytes().decode("utf-8")
        assert _non_numbers(new) == _non_numbers(original)
        assert new.count("\r\n") == original.count("\r\n")
        assert identical == original  # the nominal model for the calibrated one: nothing changes
    assert sum(c.corrected for c in result.corrections) >= 1
    for c in result.corrections:  # the numbers of other targets and of everything else stay
        if not c.corrected:
            continue
        assert c.check_mm < CHECK_MM and c.check_deg < CHECK_DEG
    for c in result.flagged:
        assert c.reason and c.status != "ok"


def test_bad_programs_are_input_errors_naming_the_file(tmp_path, planted, run_cli):
    src = tmp_path / "empty.mod"
    src.write_text("MODULE M\nENDMODULE\n")
    code, _, err = run_cli("filter", planted["irb120"], src, "--nominal", "irb120", "--out", tmp_path / "o.mod")
    assert code == 2 and "no targets found" in err and "empty.mod" in err and not (tmp_path / "o.mod").exists()
    code, _, err = run_cli("filter", planted["irb120"], tmp_path / "x.txt", "--nominal", "irb120",
                           "--out", tmp_path / "o.txt")
    assert code == 2 and "give --format" in err
    bad = tmp_path / "bad.mod"
    bad.write_text("MODULE M\n  CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
                   "  CONST robtarget p2:=[[1,2,x],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n")
    code, _, err = run_cli("filter", planted["irb120"], bad, "--nominal", "irb120", "--out", tmp_path / "o.mod")
    assert code == 2 and "bad.mod: line 3: robtarget p2" in err
    src = tmp_path / "bad.src"
    src.write_text("DEF bad()\nDECL E6POS P1={X 1.0,Y 2.0,Z ,A 0,B 0,C 0}\nPTP P1\nEND\n")
    code, _, err = run_cli("filter", planted["kr5-arc"], src, "--nominal", "kr5-arc", "--out", tmp_path / "o.src")
    assert code == 2 and "line 2" in err and "no number for Z" in err
    fanuc = tmp_path / "bad.ls"
    fanuc.write_text("/PROG B\n/MN\n   1:J P[2] 100% FINE ;\n/POS\nP[1]{\n   GP1:\n\tUF : 0, UT : 0,\n"
                     "\tX = 1 mm, Y = 2 mm, Z = 3 mm,\n\tW = 0 deg, P = 0 deg, R = 0 deg\n};\n/END\n")
    code, _, err = run_cli("filter", planted["irb120"], fanuc, "--nominal", "irb120", "--out", tmp_path / "o.ls")
    assert code == 2 and "P[2] is used by a motion but has no position" in err


def test_an_unreachable_target_is_flagged_with_its_numbers_and_the_run_exits_3(tmp_path, planted, run_cli):
    text = (PROGRAMS / "urscript/Prog1.script").read_text()
    far = re.sub(r"movel\(p\[[^\]]*\]", "movel(p[9.000000, 0.000000, 0.500000, 0.000000, 3.141593, 0.000000]", text,
                 count=1)
    src = tmp_path / "far.script"
    src.write_text(far)
    code, out, err = run_cli("filter", planted["ur10"], src, "--nominal", "ur10", "--out", tmp_path / "f.script",
                             "--summary", tmp_path / "s.json")
    assert code == 3, err
    summary = json.loads((tmp_path / "s.json").read_text())
    flagged = [t for t in summary["targets"] if t["status"] != "ok"]
    assert [t["status"] for t in flagged] == ["unreachable (nominal)"] and flagged[0]["reason"]
    assert "not corrected: line" in err and "unreachable (nominal)" in err
    assert "9.000000, 0.000000, 0.500000" in (tmp_path / "f.script").read_text()
    assert all(t["check"]["mm"] is not None for t in summary["targets"] if t["status"] == "ok")


def test_a_calibrated_model_of_another_robot_is_said(tmp_path, planted):
    # an IRB 120's model against a KR5's program and nominal reaches none of it; a KR5 whose upper arm
    # is 30 mm longer than the controller's model corrects by centimetres: both said
    far = tmp_path / "long.toml"
    far.write_text(ind.robot_toml("kr5-arc", {"a2": 30.0}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        other = filter_program(planted["irb120"], PROGRAMS / "krl/Program.src", "kr5-arc")
        long = filter_program(far, PROGRAMS / "krl/Program.src", "kr5-arc")
        fine = filter_program(planted["kr5-arc"], PROGRAMS / "krl/Program.src", "kr5-arc")
    assert any(n.startswith("no target could be corrected: check that --nominal") for n in other.notes)
    assert any("mm: a calibration corrects by a few millimetres; check that --nominal" in n for n in long.notes)
    assert not any("check that --nominal" in n for n in fine.notes)


def test_load_program_reads_every_language():
    for program, _, _ in PUBLIC:
        assert load_program(PROGRAMS / program).targets


def test_filter_and_compensate_give_the_same_joints_for_the_same_goal_and_tool(tmp_path):
    """A RAPID target and the same pose as a goal of compensate, with the same tool: one frame
    algebra, one inverse: the same joints."""
    from robocal.compensation import compensate
    from robocal.io.goals import Goals
    from robocal.io.robotfile import load_robot

    rng = np.random.default_rng(3)
    nominal, accurate = _robots(tmp_path, "irb120", PEDESTAL)
    g = ind.geometry("irb120")
    tool = ctl.frame([10.0, 0.0, 120.0], [0.0, 20.0, 0.0])
    q = _taught(rng, [(-150, 150), (-60, 70), (-80, 50), (-150, 150), (20, 110), (-350, 350)], 5)
    world = [ind.pose(g, qi, base=PEDESTAL, tool=tool) for qi in q]
    (tmp_path / "m.mod").write_text(ctl.rapid_program(world, [ctl.abb_config("irb120", g, qi, PEDESTAL)
                                                              for qi in q], [], tool, np.eye(4)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        filtered = filter_program(accurate, tmp_path / "m.mod", nominal)
        T = np.stack([ctl.frame(t.position, [0, 0, 0]) for t in filtered.program.targets])  # as written
        T[:, :3, :3] = np.stack([t.rotation for t in filtered.program.targets])
        res = compensate(load_robot(nominal), load_robot(accurate),
                         Goals(q=q, position=T[:, :3, 3], rotation=T[:, :3, :3], ids=list("abcde")), tool=tool)
    assert res.status == ["ok"] * 5 and filtered.counts() == {"ok": 5}
    np.testing.assert_allclose(np.stack([c.q for c in filtered.corrections]), res.q, atol=1e-9)


def test_an_unnamed_tool_for_a_program_of_several_tools_is_refused(tmp_path, run_cli):
    nominal, accurate = _robots(tmp_path, "irb120", np.eye(4), COUPLING)
    g = ind.geometry("irb120")
    q = np.radians([[10.0, 20.0, -10.0, 30.0, 50.0, 20.0], [-20.0, 10.0, 5.0, -30.0, -40.0, 10.0],
                    [30.0, 0.0, -20.0, 10.0, 60.0, 0.0]])  # P[1] is also reached with an offset: not counted
    text = ctl.fanuc_program([ind.pose(g, qi) for qi in q], [ctl.fanuc_config("irb120", g, qi) for qi in q], [])
    head, _, tail = text.rpartition("UF : 1, UT : 2")
    text = head + "UF : 0, UT : 1" + tail  # the last position in another tool and frame
    (tmp_path / "two.ls").write_text(text)
    code, _, err = run_cli("filter", accurate, tmp_path / "two.ls", "--nominal", nominal, "--out", tmp_path / "o.ls",
                           "--tool", "0,0,100,0,0,0")
    assert code == 2 and "taught in 2 tools (1, 2)" in err and "--tool NAME=" in err
    assert not (tmp_path / "o.ls").exists()


# --- configuration bits on their boundaries: an identity filter changes nothing ----------------

#: joints on the boundaries of the configuration data: 0 for KUKA's T bits and ABB's cf, ±90°
#: and 180° quadrant and turn boundaries, taught as the pendant shows them
BOUNDARY_DEG = {"kr5-kuka": [[0.0, -90.0, 90.0, 0.0, 45.0, 0.0], [90.0, -60.0, 60.0, -90.0, 30.0, 180.0],
                             [-90.0, -100.0, 110.0, 180.0, 60.0, -90.0], [0.0, -45.0, 45.0, 90.0, -50.0, -180.0]],
                "irb120": [[0.0, -30.0, 20.0, 0.0, 45.0, 0.0], [90.0, -20.0, 10.0, -90.0, 30.0, 180.0],
                           [-90.0, 10.0, -40.0, 90.0, 60.0, -90.0], [45.0, 20.0, 30.0, 0.0, -50.0, -180.0]]}


def test_configuration_bits_on_their_boundaries_stay_as_taught(tmp_path):
    """Joints exactly on a boundary come back from IK a hair either side (−2e−14°): without a
    tolerance the bit flips and an identity filter would rewrite the program."""
    for robot, writer in (("kr5-kuka", "krl"), ("irb120", "rapid"), ("irb120", "fanuc")):
        q = np.radians(BOUNDARY_DEG[robot])
        B = ind.base_of(robot) if robot == "kr5-kuka" else np.eye(4)
        nominal, _ = _robots(tmp_path, robot, B)
        g = ind.geometry(robot)
        poses = [ind.pose(g, qi, base=B) for qi in q]
        if writer == "krl":
            src, dat = ctl.krl_program(poses, [], [ctl.kuka_status(robot, g, qi) for qi in q])
            (tmp_path / "b.src").write_bytes(src.encode())
            (tmp_path / "b.dat").write_bytes(dat.encode())
            program, texts = tmp_path / "b.src", [src, dat]
        elif writer == "rapid":
            text = ctl.rapid_program(poses, [ctl.abb_config(robot, g, qi) for qi in q], [], np.eye(4), np.eye(4))
            (tmp_path / "b.mod").write_bytes(text.encode())
            program, texts = tmp_path / "b.mod", [text]
        else:
            text = ctl.fanuc_program(poses, [ctl.fanuc_config(robot, g, qi) for qi in q], [])
            (tmp_path / "B.LS").write_bytes(text.encode())
            program, texts = tmp_path / "B.LS", [text]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = filter_program(nominal, program, nominal,
                                    frames=Frames(tools={"2": np.eye(4)}, users={"1": np.eye(4)}))
        # (the FANUC program's position register and offset motion are its controller's, by design)
        assert {c.status for c in result.flagged} <= {"unsupported"}, [(c.target.name, c.reason)
                                                                       for c in result.flagged]
        assert result.counts()["ok"] >= len(q) - 1 and result.texts == texts, writer


# --- the TCP rule: the program's tool data, the calibrated tool only where the user says so ---

def _rapid_cell(tmp_path, reflector, program_tool, true_tool, n=10, seed=21):
    """An IRB 120 on a pedestal whose calibrated model carries ``reflector`` (the point the tracker
    measured, mm in the flange frame) and a RAPID program taught with ``program_tool`` (mm): the
    taught poses, the program, the true geometry and the true tool."""
    rng = np.random.default_rng(seed)
    nominal = tmp_path / "nominal.toml"
    nominal.write_text(ind.robot_toml("irb120", {}, base=PEDESTAL))
    accurate = tmp_path / "accurate.toml"
    accurate.write_text(ind.robot_toml("irb120", PLANTED, base=PEDESTAL, tool=reflector))
    g_nom = ind.geometry("irb120")
    tool = ctl.frame(program_tool, [0.0, 0.0, 0.0])
    q = _taught(rng, [(-150, 150), (-60, 70), (-80, 50), (-150, 150), (20, 110), (-350, 350)], n)
    world = [ind.pose(g_nom, qi, base=PEDESTAL, tool=tool) for qi in q]
    text = ctl.rapid_program(world, [ctl.abb_config("irb120", g_nom, qi, PEDESTAL) for qi in q], [], tool, np.eye(4))
    (tmp_path / "cell.mod").write_text(text)
    return nominal, accurate, q, world, tool, ctl.frame(true_tool, [0.0, 0.0, 0.0])


def _landing_mm(result, q, world, tool):
    """How far the true robot's TCP lands from each target, driven by the filtered program as the
    independent controller takes it (its nominal inverse from the taught joints)."""
    g_nom, g_acc = ind.geometry("irb120"), ind.geometry("irb120", PLANTED)
    new = ctl.read_rapid(result.text)
    out = []
    for i, (qi, T) in enumerate(zip(q, world)):
        v = new[f"p{i + 1}"]
        T_new = ctl.frame(v[:3], [0, 0, 0])
        T_new[:3, :3] = Rotation.from_quat([v[4], v[5], v[6], v[3]]).as_matrix()
        q_ctrl = ind.inverse(g_nom, T_new, qi, tool=tool[0], base=PEDESTAL)
        out.append(np.linalg.norm(ind.pose(g_acc, q_ctrl, base=PEDESTAL, tool=tool[1])[:3, 3] - T[:3, 3]))
    return np.array(out)


def test_a_reflector_near_the_flange_never_replaces_the_programs_tcp(tmp_path):
    """Calibrated with a reflector 4 mm from the flange, the program taught with the flange (tool0's
    data): every target lands for the flange, as taught, and the JSON says which TCP each used."""
    nominal, accurate, q, world, tool, _ = _rapid_cell(tmp_path, (3.0, -2.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(accurate, tmp_path / "cell.mod", nominal)
    assert result.counts() == {"ok": 10}
    assert np.max(_landing_mm(result, q, world, (tool, tool))) < CHECK_MM
    assert any("if the calibration measured that tool, say so" in n for n in result.notes)
    rows = json.loads(result.json())["targets"]
    assert {r["tcp"] for r in rows} == {"the program's tool gun"}


def test_the_calibrated_tool_stands_in_only_where_the_user_says_it_is_the_programs(tmp_path, run_cli):
    """The calibration measured the program's tool itself (0.8 mm off its data): with --tool
    gun=calibrated the true robot with the true tool lands on every target; without, the program's
    data are taken as they are, and the true tool misses by what the data miss."""
    nominal, accurate, q, world, tool, true_tool = _rapid_cell(tmp_path, (0.8, 24.4, 140.5), (0.0, 25.0, 140.0),
                                                               (0.8, 24.4, 140.5))
    out = tmp_path / "out.mod"
    code, _, err = run_cli("filter", accurate, tmp_path / "cell.mod", "--nominal", nominal, "--out", out,
                           "--tool", "gun=calibrated", "--summary", tmp_path / "s.json")
    assert code == 0, err
    result = type("R", (), {"text": out.read_text()})
    assert np.max(_landing_mm(result, q, world, (tool, true_tool))) < CHECK_MM
    rows = json.loads((tmp_path / "s.json").read_text())["targets"]
    assert {r["tcp"] for r in rows} == {"the program's tool gun (the calibrated model's tool standing in)"}
    code, _, err = run_cli("filter", accurate, tmp_path / "cell.mod", "--nominal", nominal, "--out", out)
    assert code == 0, err
    result = type("R", (), {"text": out.read_text()})
    assert np.min(_landing_mm(result, q, world, (tool, true_tool))) > 0.5  # the data's own miss, 0.86 mm
    code, _, err = run_cli("filter", accurate, tmp_path / "cell.mod", "--nominal", nominal, "--out", out,
                           "--tool", "gun=calibrated", "--tool", "gun=calibrated")
    assert code == 2 and "said calibrated twice" in err


# --- FANUC production programs: options in any order, wrapped lines, untaught and odd positions ---

def _production_ls(tmp_path):
    """A FANUC program as production backups write them: harmless options (ACC, TB … P-SPS, Skip)
    beside run-time offsets after them, an instruction wrapped onto a continuation line, an untaught
    position, one holding group 2 alone, one in the frames active at run time, a joint position in a
    user frame robocal is not given, an option it does not know."""
    rng = np.random.default_rng(31)
    g = ind.geometry("irb120")
    tool = ctl.frame([0.0, 0.0, 210.0], [0.0, 0.0, 0.0])
    box = [(-150, 150), (-60, 70), (-80, 50), (-150, 150), (20, 110), (-350, 350)]
    q = _taught(rng, box, 8)
    world = [ind.pose(g, qi, tool=tool) for qi in q]
    text = ctl.fanuc_program(world, [ctl.fanuc_config("irb120", g, qi) for qi in q], [], uf=0, ut=2)
    main, pos = text.split("/POS")
    motions = ["   1:J P[1] 100% CNT0 ACC100 TB .10sec,P-SPS Tool_Offset,PR[11] Offset,PR[12]    ;",
               "   2:L P[2] 2000mm/sec CNT100 ACC50 TB .10sec,P-SPS Tool_Offset,PR[11]\r\n    :  Offset,PR[12]    ;",
               "   3:L P[3] 500mm/sec FINE ACC80 TB .05sec,P-SPS Skip,LBL[3]    ;",
               "   4:L P[4] 500mm/sec CNT50 Wjnt    ;",
               "   5:J P[5] 100% FINE INC    ;",
               "   6:L P[6] 500mm/sec FINE MAGIC_OPTION    ;",
               "   7:J P[7:Home] 100% FINE    ;", "   8:J P[8] 100% FINE    ;",
               "   9:J P[9] 100% FINE    ;", "  10:J P[10] 100% FINE    ;", "  11:J P[11] 100% FINE    ;",
               "  12:J P[12] 100% FINE    ;"]
    main = main[:main.index("/MN") + 3] + "\r\n" + "\r\n".join(motions) + "\r\n"
    odd = ["P[9]{", "   GP1:", "\tUF : 0, UT : 2,\t\tCONFIG : 'N U T, 0, 0, 0',",
           "\tX = ******** mm,\tY = ******** mm,\tZ = ******** mm,",
           "\tW = ******** deg,\tP = ******** deg,\tR = ******** deg", "};",
           "P[10]{", "   GP2:", "\tUF : 0, UT : 2,", "\tJ1 =     0.000  mm", "};",
           "P[11]{", "   GP1:", "\tUF : F, UT : F,\t\tCONFIG : 'N U T, 0, 0, 0',",
           "\tX = 400.000  mm,\tY = 0.000  mm,\tZ = 500.000  mm,", "\tW = 180.000 deg,\tP = 0.000 deg,\tR = 0.000 deg",
           "};", "P[12]{", "   GP1:", "\tUF : 7, UT : 2,",
           "\tJ1=    10.000 deg,\tJ2=    20.000 deg,\tJ3=   -10.000 deg,",
           "\tJ4=     5.000 deg,\tJ5=    40.000 deg,\tJ6=    30.000 deg", "};"]
    pos = pos.replace("/END", "\r\n".join(odd) + "\r\n/END")
    # CONFIG as controllers and editors also write it: letters run together (P[4]), turns of 0 left out
    configs = dict(re.findall(r"P\[(\d+)\]\{[^}]*?CONFIG : '([^']*)'", pos))
    bare = next(k for k in ("8", "7", "3") if configs[k].endswith(", 0, 0, 0"))
    for k, spelled in (("4", configs["4"].replace(" ", "")), (bare, configs[bare][:-len(", 0, 0, 0")])):
        pos = re.sub(rf"(P\[{k}\]\{{[^}}]*?CONFIG : ')[^']*'", lambda m, c=spelled: m.group(1) + c + "'", pos)
    (tmp_path / "PROD.LS").write_bytes((main + "/POS" + pos).encode())
    return tmp_path / "PROD.LS", q, world, tool


def test_fanuc_production_options_and_odd_positions(tmp_path, run_cli):
    program, q, world, tool = _production_ls(tmp_path)
    nominal, accurate = _robots(tmp_path, "irb120", np.eye(4), COUPLING)
    out = tmp_path / "OUT.LS"
    code, _, err = run_cli("filter", accurate, program, "--nominal", nominal, "--out", out, "--tool",
                           "2=0,0,210,0,0,0", "--summary", tmp_path / "s.json")
    assert code == 3, err  # written, with targets left
    rows = {r["target"].split()[0]: r for r in json.loads((tmp_path / "s.json").read_text())["targets"]}
    left = {k: (r["status"], r["reason"]) for k, r in rows.items() if r["status"] != "ok"}
    assert "Tool_Offset" in left["P[1]"][1] and "Tool_Offset" in left["P[2]"][1]  # after TB … P-SPS, and wrapped
    assert "INC" in left["P[5]"][1] and "'MAGIC_OPTION'" in left["P[6]"][1]
    assert "untaught" in left["P[9]"][1] and "group 2" in left["P[10]"][1]
    assert "active at run time" in left["P[11]"][1]
    assert {"P[3]", "P[4]", "P[7]", "P[8]", "P[12]"} <= {k for k, r in rows.items() if r["status"] == "ok"}
    assert set(left) == {"P[1]", "P[2]", "P[5]", "P[6]", "P[9]", "P[10]", "P[11]"}  # the offsets' PRs are no targets
    new = ctl.read_fanuc(out.read_text())
    g_nom, g_acc = ind.geometry("irb120"), ind.geometry("irb120", PLANTED)
    for k in (3, 4, 7, 8):  # corrected as the independent controller takes them
        v = new[k]
        T_new = ctl.frame([v["X"], v["Y"], v["Z"]], [v["W"], v["P"], v["R"]])
        _lands(ind.pose(g_acc, ind.inverse(g_nom, T_new, q[k - 1], tool=tool), tool=tool), world[k - 1])
    old = ctl.read_fanuc(program.read_text())
    for k in (1, 2, 5, 6, 11):
        assert new[k] == old[k]
    assert "******** mm" in out.read_text()
    spelled = [dict(re.findall(r"P\[(\d+)\]\{[^}]*?CONFIG : '([^']*)'", f.read_text())) for f in (program, out)]
    assert [k for k, c in spelled[0].items() if "," not in c] == [k for k, c in spelled[1].items() if "," not in c]
    assert " " not in spelled[1]["4"] and len(spelled[1]) == len(spelled[0])  # each kept its spelling
    # the calibrated model of the nominal itself: the program comes back byte for byte
    code, _, err = run_cli("filter", nominal, program, "--nominal", nominal, "--out", tmp_path / "SAME.LS", "--tool",
                           "2=0,0,210,0,0,0")
    assert (tmp_path / "SAME.LS").read_bytes() == program.read_bytes()


# --- KRL: S and T in binary and hex, FRAME data, spline motions' frames, unknown modifiers ----

def _status_of(text: str) -> int:
    text = text.strip()
    return int(text[2:-1], 2 if text[1] in "Bb" else 16) if text.startswith("'") else int(text)


def test_krl_status_in_every_spelling_frames_untouched_spline_frames_read(tmp_path, run_cli):
    rng = np.random.default_rng(17)
    B = ind.base_of("kr5-kuka")
    nominal, accurate = _robots(tmp_path, "kr5-kuka", B)
    g_nom, g_acc = ind.geometry("kr5-kuka"), ind.geometry("kr5-kuka", PLANTED)
    tool, other, user = (ctl.frame([12.0, -5.0, 180.0], [0.0, 35.0, 10.0]), ctl.frame([0.0, 40.0, 95.0], [20, 0, 0]),
                         ctl.frame([900.0, -300.0, 60.0], [0, 0, -15.0]))
    q = _taught(rng, KUKA_BOX, 6)
    q[::2, 4] *= -1.0
    tools = [tool] * 5 + [other]  # the last reached by a spline motion whose FDAT names tool 3
    world = [ind.pose(g_nom, qi, base=B, tool=tcp) for qi, tcp in zip(q, tools)]
    st = [ctl.kuka_status("kr5-kuka", g_nom, qi) for qi in q]
    src, dat = ctl.krl_program([np.linalg.inv(user) @ T for T in world[:5]], [], st[:5])
    c, b, a = ctl.fixed_angles((np.linalg.inv(user) @ world[5])[:3, :3])
    T6 = np.linalg.inv(user) @ world[5]
    dat = dat.replace("ENDDAT", "\r\n".join([
        "  DECL FDAT FP1={TOOL_NO 3,BASE_NO 1,IPO_FRAME #BASE,POINT2[] \" \"}",
        f"  DECL E6POS XP6={{X {T6[0, 3]:.3f},Y {T6[1, 3]:.3f},Z {T6[2, 3]:.3f},A {a:.4f},B {b:.4f},C {c:.4f},"
        f"S 'B{st[5][0]:03b}',T 'H{st[5][1]:02X}',E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}",
        "  DECL FRAME BASE_MEAS[3]", "  BASE_MEAS[1]={X 101.5,Y 202.25,Z 3.0,A 0.0,B 0.0,C 0.0}",
        "  BASE_MEAS[2]={X 501.5,Y 202.25,Z 3.0,A 0.0,B 0.0,C 0.0}", "ENDDAT"]))
    # XP1 in binary, XP2 in hex: spelled as KUKA's editors write them
    for i, style in ((1, "B"), (2, "H")):
        s, t = st[i - 1]
        spelled = f"S 'B{s:03b}',T 'B{t:06b}'" if style == "B" else f"S 'H{s:X}',T 'H{t:02X}'"
        dat = re.sub(rf"(DECL E6POS XP{i}=\{{[^}}]*?)S {s},T {t}", lambda m, w=spelled: m.group(1) + w, dat)
    src = src.replace("END\r\n", "  SPLINE WITH $VEL = SVEL_CP(2.0, , LCPDAT1)\r\n"
                      "    SPL XP6 WITH $TOOL = STOOL2(FP1), $BASE = SBASE(FP1.BASE_NO), $IPO_MODE = "
                      "SIPO_MODE(FP1.IPO_FRAME), $LOAD = SLOAD(FP1.TOOL_NO)\r\n  ENDSPLINE\r\n"
                      "  LIN XP3:{X 0,Y 0,Z 5,A 0,B 0,C 0}\r\nEND\r\n")
    folder = tmp_path / "R1"
    folder.mkdir()
    (folder / "cell.src").write_bytes(src.encode())
    (folder / "cell.dat").write_bytes(dat.encode())
    (folder / "$config.dat").write_text(ctl.krl_config({2: tool, 3: other}, {1: user}))
    out = tmp_path / "out.src"
    code, _, err = run_cli("filter", accurate, folder / "cell.src", "--nominal", nominal, "--out", out, "--summary",
                           tmp_path / "s.json")
    rows = {r["target"]: r for r in json.loads((tmp_path / "s.json").read_text())["targets"]}
    assert code == 3 and rows["XP3"]["status"] == "unsupported" and "':{X'" in rows["XP3"]["reason"], err
    assert not any("BASE_MEAS" in name for name in rows)  # a FRAME: no target
    new_dat = out.with_suffix(".dat").read_text()
    for line in ("BASE_MEAS[1]={X 101.5,Y 202.25,Z 3.0,A 0.0,B 0.0,C 0.0}", "DECL FRAME BASE_MEAS[3]"):
        assert line in new_dat
    for i in (1, 2, 4, 5, 6):
        assert rows[f"XP{i}"]["status"] == "ok", rows[f"XP{i}"]
        m = re.search(rf"DECL E6POS XP{i}=\{{([^}}]*)\}}", new_dat)
        v = {k.upper(): x for k, x in re.findall(r"(\w+) ('[^']*'|" + ctl.NUM + r")", m.group(1))}
        T_new = user @ ctl.frame([float(v["X"]), float(v["Y"]), float(v["Z"])],
                                 [float(v["C"]), float(v["B"]), float(v["A"])])
        q_ctrl = ind.inverse(g_nom, T_new, q[i - 1], tool=tools[i - 1], base=B)
        _lands(ind.pose(g_acc, q_ctrl, base=B, tool=tools[i - 1]), world[i - 1])
        assert (_status_of(v["S"]), _status_of(v["T"])) == ctl.kuka_status("kr5-kuka", g_nom, q_ctrl)
        if i in (1, 6):  # written back in the spelling it had
            assert v["S"].startswith("'B")
        if i == 2:
            assert v["S"].startswith("'H") and v["T"].startswith("'H")
    same = tmp_path / "same.src"
    code, _, err = run_cli("filter", nominal, folder / "cell.src", "--nominal", nominal, "--out", same)
    assert same.with_suffix(".dat").read_bytes() == dat.encode()


def test_targets_reached_through_a_function_or_a_path_correction_are_left_and_named(tmp_path, planted):
    """RAPID's Offs() and RelTool() of values the program computes, the \\Corr switch, URScript's pose_add()
    of a variable: the motion's target changes as the program runs, so the target is left as written and
    the function named (of literal values, they take the target's correction: the tests above)."""
    g = ind.geometry("irb120")
    rng = np.random.default_rng(4)
    q = _taught(rng, [(-150, 150), (-60, 70), (-80, 50), (-150, 150), (20, 110), (-350, 350)], 4)
    world = [ind.pose(g, qi) for qi in q]
    text = ctl.rapid_program(world, [ctl.abb_config("irb120", g, qi) for qi in q], [], np.eye(4), np.eye(4))
    text = text.replace("MoveJ p2,", "MoveL Offs(p2,0,0,dz),").replace("MoveJ p3,v500,fine,gun\\WObj:=table;",
                                                                       "MoveJ p3,v500,fine,gun\\WObj:=table;\n    "
                                                                       "MoveL RelTool(p3,0,0,-2*dz),v500,fine,gun"
                                                                       "\\WObj:=table;")
    text = text.replace("MoveJ p4,v500,fine,gun", "MoveL p4,v500\\Corr,fine,gun")
    (tmp_path / "m.mod").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(planted["irb120"], tmp_path / "m.mod", "irb120")
    status = {c.target.name: (c.status, c.reason) for c in result.corrections}
    assert status["p1"][0] == "ok"
    assert status["p2"][0] == "unsupported" and "Offs()" in status["p2"][1]
    assert status["p3"][0] == "unsupported" and "RelTool()" in status["p3"][1]
    assert status["p4"][0] == "unsupported" and "\\Corr" in status["p4"][1]
    script = "def prog():\n  X = p[0.4, -0.2, 0.3, 3.14, 0.0, 0.0]\n  Y = p[0.4, 0.2, 0.3, 3.14, 0.0, 0.0]\n" \
             "  movel(X)\n  movel(pose_add(X, d))\n  movel(Y)\nend\n"
    (tmp_path / "p.script").write_text(script)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(planted["ur10"], tmp_path / "p.script", "ur10")
    status = {c.target.name: (c.status, c.reason) for c in result.corrections}
    assert status["X"][0] == "unsupported" and "pose_add()" in status["X"][1]
    assert status["Y"][0] == "ok"


def test_a_joint_target_at_a_wrist_singularity_is_flagged_not_moved_by_degrees(tmp_path, planted):
    """A jointtarget taught with the wrist nearly straight (A5 = −0.14°): reaching its pose exactly
    on the calibrated robot would swing axes 4 and 6 by degrees; it is left as taught and said."""
    joints = np.radians([[10.0, 20.0, -15.0, 30.0, -0.14, -40.0], [15.0, 10.0, -10.0, 20.0, 45.0, 10.0]])
    text = ctl.rapid_program([], [], joints, np.eye(4), np.eye(4))
    (tmp_path / "j.mod").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(planted["irb120"], tmp_path / "j.mod", "irb120")
    status = {c.target.name: c for c in result.corrections}
    assert status["j2"].status == "ok" and status["j2"].joints_deg < 1.0
    assert status["j1"].status == "singular" and "left as taught" in status["j1"].reason
    assert "joint 4" in status["j1"].reason or "joint 6" in status["j1"].reason
    assert ctl.read_rapid(result.text)["j1"] == ctl.read_rapid(text)["j1"]


def test_a_written_program_is_stamped_its_configuration_changes_said_and_its_angles_keep_their_decimals(
        tmp_path, planted, run_cli):
    """RAPID: the written module carries robocal's stamp after its MODULE line (version, the calibrated
    model's file and SHA-256, what a corrected motion is), reads back with every target, and --no-stamp
    leaves it out; each changed configuration datum names the joint that moved it.  FANUC: a rewritten
    angle keeps the file's three decimals wherever they turn the tool to within 0.0005° of the correction."""
    import hashlib

    from robocal.cli.filter import config_change
    from robocal.filtering.language import ANGLE_KEEP_DEG
    from robocal.math.so3 import rpy_to_matrix

    program = PROGRAMS / "rapid" / "Module1.mod"
    out = tmp_path / "Module1.mod"
    code, _, err = run_cli("filter", planted["irb120"], program, "--nominal", "irb120", "--tool",
                           "smc_gripper=0,0,150,0,0,0", "--out", out, "--summary", tmp_path / "s.json")
    assert code == 0, err
    lines = out.read_bytes().decode().split("\r\n")
    assert lines[0].startswith("MODULE") and lines[1].strip().startswith("! Filtered by robocal")
    assert hashlib.sha256(planted["irb120"].read_bytes()).hexdigest() in lines[2]
    assert "taught points" in lines[3] and "taught points" in err
    assert len(load_program(out).targets) == len(load_program(program).targets)
    code, _, err = run_cli("filter", planted["irb120"], program, "--nominal", "irb120", "--tool",
                           "smc_gripper=0,0,150,0,0,0", "--out", tmp_path / "plain.mod", "--no-stamp")
    assert "robocal" not in (tmp_path / "plain.mod").read_text()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(planted["irb120"], program, "irb120", frames=Frames(tools={"smc_gripper": TOOL}))
    changed = [c for c in result.corrections if c.corrected and config_change(c)]
    for c in changed:
        for part in config_change(c).split("; "):
            key = part.split()[0]
            joint = {"cf1": 0, "cf4": 3, "cf6": 5}.get(key)
            if joint is not None:  # the quadrant written is the one the corrected joint lies in
                value = float(re.search(r"j\d at ([-+][\d.]+)°", part).group(1))
                assert f"j{joint + 1} at" in part and int(part.split("→")[1].split(":")[0]) == \
                    math.floor(np.radians(value) / (math.pi / 2) + 1e-12)
    # FANUC: a rewritten angle keeps the file's decimals unless they would turn the tool too far
    fanuc, _, _, _ = _production_ls(tmp_path)
    nominal, accurate = _robots(tmp_path, "irb120", np.eye(4), COUPLING)
    code, _, err = run_cli("filter", accurate, fanuc, "--nominal", nominal, "--out", tmp_path / "OUT.LS", "--tool",
                           "2=0,0,210,0,0,0", "--no-stamp")
    pattern = r"W =\s*(\S+) deg,\s*P =\s*(\S+) deg,\s*R =\s*(\S+) deg"
    before = re.findall(pattern, fanuc.read_text())
    after = re.findall(pattern, (tmp_path / "OUT.LS").read_text())
    rewritten = [(a, b) for a, b in zip(before, after) if a != b]
    assert rewritten
    for a, b in rewritten:
        own = min(len(v.split(".")[1]) if "." in v else 0 for v in a)
        places = {len(v.split(".")[1]) for v in b}
        if places != {max(own, 3)}:  # more decimals: the file's would have turned the tool too far
            assert places == {4}
            written = np.radians([float(v) for v in b])
            R, Q = rpy_to_matrix(written), rpy_to_matrix(np.radians(np.round(np.degrees(written), own)))
            assert np.degrees(np.arccos(np.clip((np.trace(R @ Q.T) - 1) / 2, -1, 1))) > ANGLE_KEEP_DEG - 1e-4


# --- offset motions: a taught point reached directly and through a literal offset ----------------

def _reached_error(g_nom, g_acc, sent, want, start, base, tool):
    """mm: where the calibrated robot lands when the controller (its nominal inverse from ``start``) goes
    to ``sent``, from ``want`` (world poses)."""
    q = ind.inverse(g_nom, sent, start, tool=tool, base=base)
    return float(np.linalg.norm(ind.pose(g_acc, q, base=base, tool=tool)[:3, 3] - want[:3, 3]))


def test_rapid_offs_and_reltool_motions_take_their_targets_correction_and_say_what_it_leaves(tmp_path, run_cli):
    """p1 is reached directly and through Offs(p1, 0, 0, 50), p2 through RelTool(p2, 0, 0, -40 \\Rz:=20) and
    directly, p3 through Offs(p3, d, 0, 0) with d a variable: p1 and p2 are corrected; where each offset
    motion lands on the planted robot (the independent controller's inverse of the written offset, the
    manual's Offs: + d in the work object, RelTool: T · Trans(d) · Rz) is the remaining error robocal
    says, and it is far below the uncorrected one; p3 is left, its offset in the controller."""
    rng = np.random.default_rng(4)
    nominal, accurate, g_nom, g_acc, tool, wobj = _abb_cell(tmp_path)
    box = [(-100, 100), (-40, 50), (-60, 30), (-100, 100), (30, 100), (-150, 150)]
    q = _taught(rng, box, 3)
    world = [ind.pose(g_nom, qi, base=PEDESTAL, tool=tool) for qi in q]
    cfs = [ctl.abb_config("irb120", g_nom, qi, PEDESTAL) for qi in q]
    text = ctl.rapid_program([np.linalg.inv(wobj) @ T for T in world], cfs, [], tool, wobj)
    motions = ["    MoveL Offs(p1, 0, 0, 50), v100, fine, gun\\WObj:=table;",
               "    MoveL RelTool(p2, 0, 0, -40 \\Rz:=20), v100, fine, gun\\WObj:=table;",
               "    MoveL Offs(p3, d, 0, 0), v100, fine, gun\\WObj:=table;"]
    text = text.replace("  ENDPROC", "\n".join(motions) + "\n  ENDPROC").replace(
        "  PROC main()", "  VAR num d := 20;\n  PROC main()")
    (tmp_path / "cell.mod").write_text(text)
    code, _, err = run_cli("filter", accurate, tmp_path / "cell.mod", "--nominal", nominal, "--out",
                           tmp_path / "out.mod", "--summary", tmp_path / "s.json")
    assert code == 3, err  # p3 left
    rows = {r["target"]: r for r in json.loads((tmp_path / "s.json").read_text())["targets"]}
    assert rows["p1"]["status"] == rows["p2"]["status"] == "ok"
    assert rows["p3"]["status"] == "unsupported" and "Offs()" in rows["p3"]["reason"]
    new = ctl.read_rapid((tmp_path / "out.mod").read_text())

    def in_world(v):
        T = ctl.frame(v[:3], [0, 0, 0])
        T[:3, :3] = Rotation.from_quat([v[4], v[5], v[6], v[3]]).as_matrix()
        return wobj @ T

    rel = ctl.frame([0, 0, -40.0], [0, 0, 20.0])
    cases = {"p1": (lambda T: _shifted(wobj, T, [0, 0, 50.0]), 0), "p2": (lambda T: T @ rel, 1)}
    for name, (moved, k) in cases.items():
        (motion,) = rows[name]["offset_motions"]
        want, sent = moved(world[k]), moved(in_world(new[name]))
        remaining = _reached_error(g_nom, g_acc, sent, want, q[k], PEDESTAL, tool)
        uncorrected = _reached_error(g_nom, g_acc, want, want, q[k], PEDESTAL, tool)
        # (robocal's from the corrected pose, this from its numbers as written: 3 decimals of mm, 8 of a quaternion)
        assert motion["remaining_mm"] == pytest.approx(remaining, abs=2e-3)
        assert motion["uncorrected_mm"] == pytest.approx(uncorrected, abs=2e-4)
        # the target's correction carries most of the way; what it leaves grows with the offset (the planted
        # 0.1° of joint 2 over 50 mm is 0.1 mm), and is said where it passes 0.01 mm
        assert remaining < 0.5 * uncorrected and uncorrected > 0.3
        assert (f"{name}: its offset motion" in err) == (remaining > 0.01)


def _shifted(wobj: np.ndarray, T: np.ndarray, d) -> np.ndarray:
    """Offs: the pose moved by d in the work object's axes, its orientation kept (world poses)."""
    out = np.array(T, float)
    out[:3, 3] = T[:3, 3] + wobj[:3, :3] @ np.asarray(d, float)
    return out


def test_urscript_pose_trans_and_pose_add_of_literals_take_their_targets_correction(tmp_path, planted):
    """A waypoint reached directly, through pose_trans(wp, p[…]) (wp · D) and through pose_add(wp, p[…])
    (position + d, rotation R_wp · R_d, the URScript manual's): the waypoint is corrected, and where each
    offset motion lands (the independent controller's inverse, from the taught joints) is the remaining
    error robocal says."""
    rng = np.random.default_rng(8)
    g_nom, g_acc = ind.geometry("ur10"), ind.geometry("ur10", PLANTED)
    qi = _taught(rng, [(-90, 90), (-120, -60), (60, 120), (-120, -60), (60, 120), (-90, 90)], 1)[0]
    T = ind.pose(g_nom, qi)
    rv = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    pose = ", ".join(f"{v:.7f}" for v in (*(T[:3, 3] / 1000.0), *rv))
    joints = ", ".join(f"{v:.7f}" for v in qi)
    text = "\n".join(["def prog():", f"  global wp_p = p[{pose}]", f"  global wp_q = [{joints}]",
                      "  movej(get_inverse_kin(wp_p, qnear=wp_q))",
                      "  movel(pose_trans(wp_p, p[0, 0, -0.05, 0, 0, 0.2]))",
                      "  movel(pose_add(wp_p, p[0.03, 0, 0.01, 0, 0, 0.1]))", "end", ""])
    (tmp_path / "prog.script").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program(planted["ur10"], tmp_path / "prog.script", "ur10")
    (c,) = [c for c in result.corrections if c.target.name == "wp_p"]
    assert c.corrected and [o["text"].split("(")[0] for o in c.offsets] == ["pose_trans", "pose_add"]
    m = re.search(r"wp_p = p\[([^\]]*)\]", result.text)
    v = [float(x) for x in m.group(1).split(",")]
    written = ctl.frame([1000 * x for x in v[:3]], [0, 0, 0])
    written[:3, :3] = Rotation.from_rotvec(v[3:]).as_matrix()
    D_trans = ctl.frame([0, 0, -50.0], [0, 0, 0])
    D_trans[:3, :3] = Rotation.from_rotvec([0, 0, 0.2]).as_matrix()

    def add(P):
        out = np.array(P)
        out[:3, 3] = P[:3, 3] + [30.0, 0.0, 10.0]
        out[:3, :3] = P[:3, :3] @ Rotation.from_rotvec([0, 0, 0.1]).as_matrix()
        return out

    for motion, moved in zip(c.offsets, (lambda P: P @ D_trans, add)):
        remaining = _reached_error(g_nom, g_acc, moved(written), moved(T), qi, np.eye(4), np.eye(4))
        assert motion["remaining_mm"] == pytest.approx(remaining, abs=2e-3)
        assert motion["remaining_mm"] < 0.5 * motion["uncorrected_mm"]


@pytest.mark.parametrize("motion", [
    "J P[4] 100% CNT0 ACC100 TB .10sec,P-SPS Tool_Offset,PR[11] Offset,PR[12] ;",
    "J P[4] 100% CNT0 ACC100 Offset,PR[12] TB .10sec,P-SPS Tool_Offset,PR[11] ;",
    "J P[4:approach]  100%  CNT0   Tool_Offset , PR[ 11 ]   Offset , PR[12:shift] ;",
    "L P[4] 500mm/sec FINE TB 0.10sec , P-SPS\n   :  Offset,PR[12] ;",
    "J P[4] 100% CNT0 ACC100 Skip,LBL[3] Tool_Offset,PR[11] ;",
])
def test_a_fanuc_point_a_motion_offsets_by_a_register_is_left_however_the_line_is_spaced(tmp_path, motion):
    """The offsets live in the controller's PR[11] and PR[12]: P[4] is left as written, with why, whatever
    the options' order and spacing, wrapped or not."""
    rng = np.random.default_rng(3)
    g_nom = ind.geometry("irb120")
    q = _taught(rng, [(-90, 90), (-40, 50), (-60, 30), (-90, 90), (30, 100), (-150, 150)], 4)
    poses = [ind.pose(g_nom, qi) for qi in q]
    text = ctl.fanuc_program(poses, ["N U T, 0, 0, 0"] * 4, [], uf=0, ut=0)
    lines = text.split("\r\n")
    at = lines.index("/POS")
    body = [f"{k + 1:4d}:{line}" for k, line in enumerate(motion.replace("\n", "\r\n").split("\r\n"))]
    body = [b if not b.split(":", 1)[1].lstrip().startswith(":") else "    " + b.split(":", 1)[1].lstrip()
            for b in body]
    lines[at:at] = body
    program = tmp_path / "OFF.LS"
    program.write_bytes("\r\n".join(lines).encode())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = filter_program("irb120", program, "irb120")
    (c,) = [c for c in result.corrections if c.target.name.startswith("P[4]")]
    assert c.status == "unsupported" and ("Offset" in c.reason or "Tool_Offset" in c.reason), c.reason
    assert "changes it as the program runs" in c.reason
