"""2TPR&2TPS: the paper's sensitivity pattern, identification, compensation, command line."""

import json

import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.pkm.compensation import (
    compensate_iterated,
    compensate_model,
    compensate_paper,
    improvement,
    planted,
    simulate_compensation,
    uncompensated,
)
from robocal.pkm.files import load_pkm
from robocal.pkm.geometry import PARAM_NAMES, chen2023, reduced_to_pose
from robocal.pkm.identify import identify
from robocal.pkm.kinematics import fk, forward, ik, workspace_targets, workspace_violations
from robocal.pkm.sensitivity import sensitivity

G = chen2023()


def test_out_of_workspace_and_no_assembly_are_clear_errors(run_cli):
    assert workspace_violations(G, reduced_to_pose([0.0, 700.0, 0.0, 0.0]))[0]
    assert workspace_violations(G, reduced_to_pose([0.0, 400.0, 0.0, 0.0])) == [[]]
    with pytest.raises(InputError, match="no assembly"):
        fk(G, [[100.0, 100.0, 100.0, 100.0]])
    code, _, err = run_cli("pkm", "ik", "--pose", "0,700,0,0")
    assert code == 2 and "outside the workspace" in err and err.count("\n") == 1
    code, _, err = run_cli("pkm", "fk", "--lengths", "100,100,100,100")
    assert code == 2 and "no assembly" in err


def test_sensitivity_shows_the_papers_pattern():
    s = sensitivity(G, workspace_targets(G, 30, seed=1, angle=0.2)).mean_table()
    limb1 = s["limb 1"]
    # dL1 dominates limb 1; its y error exceeds x, which exceeds z (paper §3.2)
    assert max(limb1, key=lambda k: sum(limb1[k][:3])) == "dL1"
    dx, dy, dz = limb1["dL1"][:3]
    assert dy > dx > dz
    # limb 3 rod: about 0.6 mm on every axis (paper)
    assert all(0.4 < v < 0.8 for v in s["rod zero lengths"]["dL3"][:3])
    # the same error on all four fixed points shifts the platform rigidly
    np.testing.assert_allclose(s["all four limbs"]["dTx"][:3], [1.0, 0.0, 0.0], atol=1e-9)
    assert s["all four limbs"]["dL"][2] == pytest.approx(1.0, abs=0.02)


def test_identification_recovers_planted_errors_on_the_identifiable_subset():
    errors = planted(7)
    real = G.with_errors(errors)
    q = workspace_targets(G, 40, seed=8, angle=0.2)
    L = ik(G, q)
    P = forward(real, L, reduced_to_pose(q)).pose[:, :3]
    cal = identify(G, L, P)
    assert cal.rms_before > 0.5 and cal.rms_after < 1e-9
    # every identified combination predicts the real machine: fresh poses agree to 1e-6 mm
    qv = workspace_targets(G, 50, seed=9, angle=0.2)
    Lv = ik(G, qv)
    Pr = forward(real, Lv, reduced_to_pose(qv)).pose
    Pm = forward(cal.geometry, Lv, reduced_to_pose(qv)).pose
    assert np.abs(Pr[:, :3] - Pm[:, :3]).max() < 1e-6
    assert set(cal.names) | set(cal.identifiability.dropped) == set(PARAM_NAMES)
    assert len(cal.names) >= 20


def test_compensation_methods():
    real = G.with_errors(planted(11))
    q = workspace_targets(G, 30, seed=12)
    base = uncompensated(G, real, q)
    assert base.mean_error > 0.3
    paper = compensate_paper(G, real, q, seed=1)
    assert improvement(base, paper) > 95.0
    iterated = compensate_iterated(G, real, q, rounds=4)
    assert iterated.mean_error < paper.mean_error
    qc = workspace_targets(G, 40, seed=13, angle=0.2)
    Lc = ik(G, qc)
    cal = identify(G, Lc, forward(real, Lc, reduced_to_pose(qc)).pose[:, :3])
    fresh = workspace_targets(G, 100, seed=14)
    model = compensate_model(cal.geometry, real, fresh)
    paper_fresh = compensate_paper(G, real, fresh, seed=2)
    assert model.mean_error <= paper_fresh.mean_error
    assert improvement(uncompensated(G, real, fresh), model) > 99.9


def test_cli_pkm_commands(tmp_path, run_cli):
    code, out, _ = run_cli("pkm", "ik", "--pose", "0,400,0,0")
    assert code == 0 and "454.9595" in out
    code, out, _ = run_cli("pkm", "sensitivity", "--out", tmp_path / "s.json", "--poses", 10)
    assert code == 0 and "dL1" in json.loads((tmp_path / "s.json").read_text())["limb 1"]
    real = G.with_errors(planted(2))
    q = workspace_targets(G, 30, seed=3, angle=0.2)
    L = ik(G, q)
    P = forward(real, L, reduced_to_pose(q)).pose[:, :3]
    data = tmp_path / "d.csv"
    data.write_text(
        "L1,L2,L3,L4,x,y,z\n" + "\n".join(",".join(str(float(v)) for v in [*L[i], *P[i]]) for i in range(30)) + "\n"
    )
    code, out, err = run_cli("pkm", "calibrate", data, "--out", tmp_path / "r.json", "--export", tmp_path / "m.toml")
    assert code == 0, err
    assert load_pkm(tmp_path / "m.toml").vector().shape == (28,)
    assert json.loads((tmp_path / "r.json").read_text())["rms_after_mm"] < 1e-6


def test_simulated_compensation_api_and_its_checks():
    study = simulate_compensation(errors=0.5, targets=10, seed=3)
    rows = {r["method"]: r for r in study.table()}
    assert rows["none (nominal IK)"]["improvement_pct"] == 0.0
    assert rows["identified model"]["improvement_pct"] > 99.9
    with pytest.raises(InputError, match="≥ 0"):
        simulate_compensation(errors=-1)
