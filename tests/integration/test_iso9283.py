"""ISO 9283: the test cube's poses, and the characteristics against a computation written here
from the standard's formulas, one pose and one cycle at a time."""

from __future__ import annotations

import csv
import json
import math

import independent as ind
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.io.robotfile import load_robot
from robocal.iso9283.characteristics import characteristics
from robocal.iso9283.cube import FROM_CORNER, plan_cube
from robocal.iso9283.files import load_campaign


def test_the_cube_poses_lie_where_the_standard_puts_them_and_the_joints_reach_them():
    plan = plan_cube(load_robot("kr5-arc"), edge=300.0)
    c, a = plan.centre, 300.0
    corners = c + 0.5 * a * np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]])
    assert plan.position[0] == pytest.approx(c)
    diagonal = a * math.sqrt(3)
    for k in range(4):
        assert np.linalg.norm(plan.position[k + 1] - corners[k]) == pytest.approx(FROM_CORNER * diagonal)
    # the five lie in the plane through C1, C2, C7, C8
    normal = np.cross(corners[1] - corners[0], corners[3] - corners[0])
    assert np.abs((plan.position - corners[0]) @ normal).max() < 1e-6 * np.linalg.norm(normal)
    # the independent simulator's forward kinematics of the planned joints lands on them, one orientation
    g = ind.geometry("kr5-arc")
    for k in range(5):
        T = ind.pose(g, plan.q[k])
        assert T[:3, 3] == pytest.approx(plan.position[k], abs=1e-4)
        assert np.allclose(T[:3, :3], plan.rotation, atol=1e-8)


def _campaign_file(path, rng, cycles=30, orientation=True, bias=(0.2, -0.1, 0.05), spread=0.02):
    """Measured cycles of five commanded poses: a bias, Gaussian scatter, small turns."""
    commanded = np.array([[600.0, 0, 500], [480, -120, 380], [720, -120, 380], [720, 120, 620], [480, 120, 620]])
    rpy_c = np.array([180.0, 44.0, 0.0])
    rows = []
    for c in range(1, cycles + 1):
        for k in range(5):
            p = commanded[k] + np.array(bias) * (k + 1) + rng.normal(0, spread, 3)
            R = Rotation.from_euler("ZYX", rpy_c[::-1], degrees=True) * Rotation.from_rotvec(rng.normal(0, 2e-4, 3))
            rpy = R.as_euler("ZYX", degrees=True)[::-1]
            rows.append([f"P{k + 1}", c, *p, *(rpy if orientation else ()), *commanded[k],
                         *(rpy_c if orientation else ())])
    head = ["pose", "cycle", "x", "y", "z"] + (["rx", "ry", "rz"] if orientation else []) + ["cx", "cy", "cz"] + \
        (["crx", "cry", "crz"] if orientation else [])
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        w.writerows(rows)
    return rows


def _by_hand(rows):
    """ISO 9283 §7.2–7.3 with plain loops: per pose AP, RP; per pair AD, RD."""
    poses = sorted({r[0] for r in rows})
    out, pts, cmd, ang, cang = {}, {}, {}, {}, {}
    for p in poses:
        mine = [r for r in rows if r[0] == p]
        pts[p] = [np.array(r[2:5], float) for r in mine]
        cmd[p] = np.array(mine[0][8:11], float)
        ang[p] = [np.array(r[5:8], float) for r in mine]
        cang[p] = np.array(mine[0][11:14], float)
        n = len(mine)
        xb = sum(pts[p]) / n
        ap = math.sqrt(sum((xb[i] - cmd[p][i]) ** 2 for i in range(3)))
        ls = [math.sqrt(sum((q[i] - xb[i]) ** 2 for i in range(3))) for q in pts[p]]
        lb = sum(ls) / n
        sl = math.sqrt(sum((v - lb) ** 2 for v in ls) / (n - 1))
        ab = [sum(((a[i] - cang[p][i] + 180) % 360 - 180) for a in ang[p]) / n for i in range(3)]
        sa = [math.sqrt(sum((((a[i] - cang[p][i] + 180) % 360 - 180) - ab[i]) ** 2 for a in ang[p]) / (n - 1))
              for i in range(3)]
        out[p] = {"AP_p": ap, "RP_l": lb + 3 * sl, "AP_a": ab[0], "AP_b": ab[1], "AP_c": ab[2], "RP_a": 3 * sa[0],
                  "RP_b": 3 * sa[1], "RP_c": 3 * sa[2]}
    pairs = {}
    for i, p in enumerate(poses):
        for q in poses[i + 1:]:
            n = len(pts[p])
            D = [math.sqrt(sum((pts[p][k][j] - pts[q][k][j]) ** 2 for j in range(3))) for k in range(n)]
            Dc = math.sqrt(sum((cmd[p][j] - cmd[q][j]) ** 2 for j in range(3)))
            Db = sum(D) / n
            pairs[(p, q)] = {"AD_p": Db - Dc, "RD": 3 * math.sqrt(sum((d - Db) ** 2 for d in D) / (n - 1))}
    return out, pairs


def test_characteristics_agree_with_the_standards_formulas(tmp_path):
    rows = _campaign_file(tmp_path / "m.csv", np.random.default_rng(3))
    result = characteristics(load_campaign(tmp_path / "m.csv"))
    poses, pairs = _by_hand(rows)
    for p in result.poses:
        for key, value in poses[p.pose].items():
            assert getattr(p, key) == pytest.approx(value, abs=1e-9), (p.pose, key)
    assert len(result.distances) == 10
    for d in result.distances:
        for key, value in pairs[d.poses].items():
            assert getattr(d, key) == pytest.approx(value, abs=1e-9), (d.poses, key)


def test_the_command_line_plans_evaluates_and_puts_campaigns_side_by_side(tmp_path, run_cli):
    code, out, err = run_cli("iso9283", "plan", "kr5-arc", "--cube-size", "250", "--cycles", "5",
                             "--out", tmp_path / "plan.csv")
    assert code == 0, err
    lines = (tmp_path / "plan.csv").read_text().splitlines()
    assert len(lines) == 1 + 25 and lines[0].startswith("pose,cycle,q1")
    _campaign_file(tmp_path / "before.csv", np.random.default_rng(1), bias=(0.5, 0.3, -0.2))
    _campaign_file(tmp_path / "after.csv", np.random.default_rng(2), bias=(0.02, 0.01, 0.0), orientation=False)
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "before.csv", tmp_path / "after.csv", "--json",
                             "--report", tmp_path / "r.html")
    assert code == 0, err
    before, after = json.loads(out)
    assert before["campaign"] == "before" and after["campaign"] == "after"
    assert after["poses"][0]["AP_p"] < before["poses"][0]["AP_p"]
    assert "AP_a" in before["poses"][0] and "AP_a" not in after["poses"][0]
    assert "ISO 9283" in (tmp_path / "r.html").read_text()
    code, out, err = run_cli("iso9283", "plan", "kr5-arc", "--cube-size", "5000", "--out", tmp_path / "x.csv")
    assert code == 2 and "is not reached" in err and not (tmp_path / "x.csv").exists()


def test_a_campaign_missing_a_cycle_is_refused_with_the_pose_named(tmp_path, run_cli):
    rows = _campaign_file(tmp_path / "m.csv", np.random.default_rng(0), cycles=3)
    text = (tmp_path / "m.csv").read_text().splitlines()
    (tmp_path / "m.csv").write_text("\n".join(text[:-1]) + "\n")  # P5 of cycle 3 lost
    code, _, err = run_cli("iso9283", "evaluate", tmp_path / "m.csv")
    assert code == 2 and "pose P5 has no row for cycle 3" in err
    assert rows


def test_an_honest_campaign_is_not_called_two_frames(tmp_path, run_cli):
    _campaign_file(tmp_path / "m.csv", np.random.default_rng(5))
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "m.csv", "--json")
    assert code == 0 and "two frames" not in err and json.loads(out)[0]["notes"] == []


def test_measured_and_commanded_poses_in_two_frames_are_said(tmp_path, run_cli):
    rows = _campaign_file(tmp_path / "m.csv", np.random.default_rng(5))
    text = (tmp_path / "m.csv").read_text().splitlines()
    # the measured points as a tracker 3 m away gives them, the commands in the base frame
    moved = [text[0]] + [",".join([*line.split(",")[:2], str(float(line.split(",")[2]) + 3000.0),
                                   *line.split(",")[3:]]) for line in text[1:]]
    (tmp_path / "m.csv").write_text("\n".join(moved) + "\n")
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "m.csv", "--json")
    assert code == 0 and rows
    assert "look like two frames" in err and json.loads(out)[0]["notes"]


@pytest.mark.parametrize("dropped", ["rz", "crx"])
def test_an_orientation_without_one_of_its_angles_is_refused(tmp_path, run_cli, dropped):
    """Measured rx, ry without rz (or a commanded angle missing) would leave the orientation
    figures meaningless: refused like calibrate refuses it, the missing column named, nothing written."""
    _campaign_file(tmp_path / "m.csv", np.random.default_rng(3))
    header, *rows = (tmp_path / "m.csv").read_text().splitlines()
    names = header.split(",")
    if dropped not in names:  # a commanded orientation: add crx, cry, crz and drop one of them
        header, rows = header + ",crx,cry,crz", [r + ",0,0,0" for r in rows]
        names = header.split(",")
    keep = [i for i, n in enumerate(names) if n != dropped]
    text = "\n".join(",".join(line.split(",")[i] for i in keep) for line in [header, *rows]) + "\n"
    (tmp_path / "m.csv").write_text(text)
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "m.csv", "--report", tmp_path / "r.html")
    assert code == 2 and f"'{dropped}' is missing" in err and err.count("\n") == 1, err
    assert "m.csv" in err and not (tmp_path / "r.html").exists()


def test_a_specification_is_a_verdict_in_the_report_and_the_exit_status(tmp_path, run_cli):
    """--require AP<=…,RP<=… holds the last campaign to a specification: the report heads with the
    run (version, command, each file's SHA-256) and the verdict, and the exit status is 4 when not met."""
    import hashlib

    _campaign_file(tmp_path / "before.csv", np.random.default_rng(1), bias=(0.5, 0.3, -0.2))
    _campaign_file(tmp_path / "after.csv", np.random.default_rng(2), bias=(0.02, 0.01, 0.0))
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "before.csv", tmp_path / "after.csv", "--json")
    figures = json.loads(out)[-1]["figures"]
    loose = f"AP<={figures['AP'] * 1.1:.6f},RP<={figures['RP'] * 1.1:.6f}"
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "before.csv", tmp_path / "after.csv", "--require",
                             loose, "--report", tmp_path / "ok.html", "--quiet")
    assert code == 0, err
    text = (tmp_path / "ok.html").read_text()
    assert "Specification met" in text and hashlib.sha256((tmp_path / "after.csv").read_bytes()).hexdigest() in text
    tight = f"AP<={figures['AP'] * 0.9:.6f}"
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "before.csv", tmp_path / "after.csv", "--require",
                             tight, "--report", tmp_path / "no.html", "--quiet")
    assert code == 4 and f"AP = {figures['AP']:.4g} mm" in err
    assert "Specification not met" in (tmp_path / "no.html").read_text()  # the report is written all the same
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "after.csv", "--require", "XY<=1")
    assert code == 2 and "unknown figure 'XY'" in err


def test_the_documented_chain_plans_compensates_simulates_and_evaluates_without_hand_editing(tmp_path, run_cli):
    """plan → compensate → measure (simulated on the true robot) → evaluate: the plan is a goals file,
    the compensated commands keep each row's pose, cycle and commanded pose, and a simulated ISO
    campaign of the true robot is read as measured; the compensated campaign's AP is the smaller."""
    truth_args = ("--errors", "uniform:0.3,0.003", "--seed", "3")
    code, _, err = run_cli("simulate", "kr5-arc", *truth_args, "--poses", "60", "--noise", "0.02",
                           "--out", tmp_path / "cal.csv", "-q")
    assert code == 0, err
    code, _, err = run_cli("calibrate", "kr5-arc", tmp_path / "cal.csv", "--export", tmp_path / "cal.toml", "-q")
    assert code == 0, err
    code, _, err = run_cli("iso9283", "plan", "kr5-arc", "--cycles", "4", "--out", tmp_path / "plan.csv", "-q")
    assert code == 0, err
    plan = list(csv.DictReader((tmp_path / "plan.csv").open()))
    assert all(len(v.split(".")[-1]) <= 9 for r in plan for k, v in r.items() if k.startswith(("q", "c")))
    code, _, err = run_cli("compensate", "kr5-arc", tmp_path / "cal.toml", tmp_path / "plan.csv",
                           "--out", tmp_path / "commands.csv", "-q")
    assert code == 0, err
    commands = list(csv.DictReader((tmp_path / "commands.csv").open()))
    assert [(r["pose"], r["cycle"]) for r in commands] == [(r["pose"], r["cycle"]) for r in plan]
    assert all(float(a["cx"]) == float(b["cx"]) and float(a["crz"]) == float(b["crz"]) for a, b in zip(commands, plan))
    assert any(abs(float(a["q2"]) - float(b["q2"])) > 1e-3 for a, b in zip(commands, plan))  # corrected
    for name, file in (("before", "plan.csv"), ("after", "commands.csv")):
        code, _, err = run_cli("simulate", "kr5-arc", *truth_args, "--noise", "0.005", "--joint-noise", "0.001",
                               "--iso", tmp_path / file, "--out", tmp_path / f"{name}.csv", "-q")
        assert code == 0, err
    code, out, err = run_cli("iso9283", "evaluate", tmp_path / "before.csv", tmp_path / "after.csv", "--json",
                             "--conditions", "payload=2 kg,speed=100 %", "--report", tmp_path / "iso.html")
    assert code == 0, err
    before, after = json.loads(out)
    ap = [max(p["AP_p"] for p in c["poses"]) for c in (before, after)]
    assert ap[1] < 0.3 * ap[0], ap
    assert before["conditions"] == {"payload": "2 kg", "speed": "100 %"}
    page = (tmp_path / "iso.html").read_text()
    assert "Test conditions" in page and "2 kg" in page and "Not stated: warmup, temperature" in page
