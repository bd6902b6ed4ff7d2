"""2TPR&2TPS parallel mechanism: kinematics, error model, identification, compensation."""

import json
import math

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.pkm import (
    PARAM_NAMES,
    chen2023,
    fk,
    forward,
    ik,
    jacobian,
    leg_vectors,
    load_pkm,
    reduced_to_pose,
    rod_lengths,
    save_pkm,
    workspace_violations,
)
from robocal.pkm_study import (
    compensate_iterated,
    compensate_model,
    compensate_paper,
    identify,
    improvement,
    planted,
    pose_error,
    sensitivity,
    uncompensated,
    workspace_targets,
)

G = chen2023()


def test_inverse_kinematics_against_a_hand_computed_pose():
    # platform level at z = 400: u_1 = (140 − 294.2, −40 + 192.35, 400) → |u_1| = √(154.2² + 152.35² + 400²)
    L = ik(G, [0.0, 400.0, 0.0, 0.0])
    assert L[0] == pytest.approx(math.sqrt(154.2**2 + 152.35**2 + 400**2), abs=1e-12)
    assert L[2] == pytest.approx(math.sqrt(39.25**2 + 400**2), abs=1e-12)
    assert L[0] == pytest.approx(L[1]) and L[2] == pytest.approx(L[3])


def test_jacobian_matches_finite_differences():
    q = workspace_targets(G, 25, seed=1, angle=0.25)
    J = jacobian(G, q)
    h = 1e-6
    for k in range(4):
        e = np.zeros(4)
        e[k] = h
        fd = (ik(G, q + e) - ik(G, q - e)) / (2 * h)
        np.testing.assert_allclose(J[..., k], fd, rtol=1e-6, atol=1e-6)


def test_fk_inverts_ik_across_the_workspace_and_constraints_hold():
    q = workspace_targets(G, 500, seed=2, angle=0.25)
    pose = fk(G, ik(G, q))
    np.testing.assert_allclose(pose, reduced_to_pose(q), atol=1e-9)
    assert np.abs(pose[:, 5]).max() < 1e-12  # γ = 0
    np.testing.assert_allclose(pose[:, 0], pose[:, 2] * np.tan(pose[:, 4]), atol=1e-9)  # x = z tan β
    # the TPR limbs are perpendicular to the platform's x1 axis
    u = leg_vectors(G, pose)
    from robocal.pkm import rotation

    x1 = rotation(pose)[:, :, 0]
    assert np.abs(np.einsum("ma,mia->mi", x1, u[:, 2:])).max() < 1e-9


def test_fk_with_errors_satisfies_its_own_equations():
    real = G.with_errors(planted(3))
    q = workspace_targets(G, 50, seed=4)
    L = ik(G, q)
    r = forward(real, L, reduced_to_pose(q))
    assert r.converged.all()
    np.testing.assert_allclose(rod_lengths(real, r.pose), L, atol=1e-9)


def test_out_of_workspace_and_no_assembly_are_clear_errors(run_cli):
    assert workspace_violations(G, reduced_to_pose([0.0, 700.0, 0.0, 0.0]))[0]
    assert workspace_violations(G, reduced_to_pose([0.0, 400.0, 0.0, 0.0])) == [[]]
    with pytest.raises(InputError, match="no assembly"):
        fk(G, [[100.0, 100.0, 100.0, 100.0]])
    code, _, err = run_cli("pkm", "ik", "--pose", "0,700,0,0")
    assert code == 2 and "outside the workspace" in err and err.count("\n") == 1
    code, _, err = run_cli("pkm", "fk", "--lengths", "100,100,100,100")
    assert code == 2 and "no assembly" in err


def test_geometry_file_round_trip(tmp_path):
    g = G.with_errors(planted(5))
    save_pkm(g, tmp_path / "m.toml")
    back = load_pkm(tmp_path / "m.toml")
    np.testing.assert_array_equal(back.vector(), g.vector())
    (tmp_path / "bad.toml").write_text("[fixed]\nT1 = [1, 2]\n")
    with pytest.raises(InputError, match="T1"):
        load_pkm(tmp_path / "bad.toml")


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


def test_pose_error_is_zero_for_the_nominal_machine():
    q = workspace_targets(G, 10, seed=1, angle=0.2)
    assert np.abs(pose_error(G, G, q)).max() < 1e-9


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
