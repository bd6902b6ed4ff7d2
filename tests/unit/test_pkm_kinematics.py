"""2TPR&2TPS kinematics: IK by hand, Jacobian by finite differences, FK inverts IK, files."""

import math

import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.pkm.compensation import planted
from robocal.pkm.files import load_pkm, save_pkm
from robocal.pkm.geometry import chen2023, leg_vectors, reduced_to_pose, rotation
from robocal.pkm.kinematics import fk, forward, ik, jacobian, rod_lengths, workspace_targets
from robocal.pkm.sensitivity import pose_error

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
    x1 = rotation(pose)[:, :, 0]
    assert np.abs(np.einsum("ma,mia->mi", x1, u[:, 2:])).max() < 1e-9


def test_fk_with_errors_satisfies_its_own_equations():
    real = G.with_errors(planted(3))
    q = workspace_targets(G, 50, seed=4)
    L = ik(G, q)
    r = forward(real, L, reduced_to_pose(q))
    assert r.converged.all()
    np.testing.assert_allclose(rod_lengths(real, r.pose), L, atol=1e-9)


def test_geometry_file_round_trip(tmp_path):
    g = G.with_errors(planted(5))
    save_pkm(g, tmp_path / "m.toml")
    back = load_pkm(tmp_path / "m.toml")
    np.testing.assert_array_equal(back.vector(), g.vector())
    (tmp_path / "bad.toml").write_text("[fixed]\nT1 = [1, 2]\n")
    with pytest.raises(InputError, match="T1"):
        load_pkm(tmp_path / "bad.toml")


def test_pose_error_is_zero_for_the_nominal_machine():
    q = workspace_targets(G, 10, seed=1, angle=0.2)
    assert np.abs(pose_error(G, G, q)).max() < 1e-9
