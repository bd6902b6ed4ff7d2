"""Robot files: round trips, validation, one-line errors with exit code 2."""

import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.io.builtins import builtin_names, builtin_summaries
from robocal.io.robotfile import load_robot, parse_robot, robot_to_toml, save_robot
from robocal.math.se3 import xyz_rpy_to_transform

GOOD = """
name = "test arm"
convention = "hayati"
[[joint]]
a = 170.0
alpha = -90.0
d = 0.0
theta = 0.0
limits = [-170.0, 170.0]
[[joint]]
a = 780.0
alpha = 0.0
d = 0.0
theta = -90.0
beta = 0.1
[base]
xyz = [1000.0, -2000.0, 50.0]
rpy = [10.0, -20.0, 130.0]
[tool]
xyz = [0.0, 0.0, 125.0]
"""


def test_builtins_load():
    names = builtin_names()
    for required in ("er10l-c10", "kr5-arc", "irb120", "ur10", "puma560"):
        assert required in names
    for name, summary in zip(names, builtin_summaries()):
        r = load_robot(name)
        assert r.n_joints == 6 == summary["joints"]
        assert (summary["name"], summary["robot"], summary["convention"]) == (name, r.name, r.convention)
        assert summary["source"]


def test_robot_file_round_trip_is_exact(tmp_path, rng):
    r = parse_robot(GOOD)
    # random, not representable-in-few-digits values exercise the degree conversion
    g = r.geometry.copy()
    g[:, 1:3] += rng.normal(size=(2, 2)) * 0.01
    r = r.replace(geometry=g, targets={"B": xyz_rpy_to_transform([1, 2, 3], [0.1, 0.2, 0.3])})
    path = tmp_path / "r.toml"
    save_robot(r, path)
    back = load_robot(path)
    assert back.convention == r.convention and back.name == r.name
    np.testing.assert_array_equal(back.geometry, r.geometry)
    np.testing.assert_array_equal(back.limits, r.limits)
    np.testing.assert_allclose(back.base, r.base, atol=1e-12)
    np.testing.assert_allclose(back.tool, r.tool, atol=1e-12)
    np.testing.assert_allclose(back.targets["B"], r.targets["B"], atol=1e-12)
    # saving the reloaded robot gives the same text again
    assert robot_to_toml(back) == robot_to_toml(r)


BAD_ROBOTS = [
    ("convention = 'dh'\n", "needs at least one [[joint]]"),
    ("[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n", "missing key 'convention'"),
    ("convention = 'dhh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n", "unknown convention"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\n", "joint 1: missing key 'theta'"),
    ("convention = 'dh'\n[[joint]]\na='x'\nalpha=0\nd=0\ntheta=0\n", "joint 1, key 'a': expected a number"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nbeta=0\n", "only allowed with convention 'hayati'"),
    ("convention = 'dh'\n[[joint]]\na=0\nalhpa=0\nalpha=0\nd=0\ntheta=0\n", "joint 1: unknown key 'alhpa'"),
    ("convention = 'dh'\n[[joint]]\na=nan\nalpha=0\nd=0\ntheta=0\n", "must be finite"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=-1.5708\nd=0\ntheta=0\n", "looks like radians"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nlimits=[5, -5]\n", "low < high"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n[base]\nxyz=[1,2]\n", "[base] xyz"),
    ("convention = 'dh'\nreach = 3\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n", "unknown key 'reach'"),
    ("convention = 'dh'\n[[joint]\na=0\n", "not valid TOML"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\ncompliance='soft'\n",
     "joint 1, key 'compliance': expected a number"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nharmonics=[[0.01]]\n",
     "joint 1, key 'harmonics': expected a list of 2 numbers"),
    ("convention = 'dh'\n" + "[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n" * 2
     + "gravity_deflection=[[0, 0, 0], [0, 0, 0]]\n",
     "joint 2, key 'gravity_deflection': expected 1 [x, y, z] triples"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n[gravity]\ndirection=[0, 0, 0]\n",
     "gravity direction must not be zero"),
    ("convention = 'dh'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n[gravity]\ncom=[0, 0, 0]\n",
     "[gravity]: unknown key 'com'"),
    ("convention = 'dh'\nresidual = 'nowhere.residual.json'\n[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\n",
     "key 'residual': no such residual-model file"),
]


@pytest.mark.parametrize("text,message", BAD_ROBOTS)
def test_malformed_robot_files_give_one_line_and_exit_2(tmp_path, run_cli, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=None) as info:
        load_robot(path)
    assert message in str(info.value)
    assert str(path) in str(info.value)
    code, out, err = run_cli("evaluate", path, "whatever.csv")
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err and message in err


def test_radian_limits_are_rejected():
    text = "convention='dh'\n" + "[[joint]]\na=0\nalpha=0\nd=0\ntheta=0\nlimits=[-3.14, 3.14]\n" * 3
    with pytest.raises(InputError, match="look like radians"):
        parse_robot(text)


def test_joint_terms_and_the_residual_file_round_trip(tmp_path, rng):
    from robocal.model.residual import Block, ResidualModel
    from robocal.model.terms import JointInputs, JointTerms

    r = load_robot("kr5-arc")
    gravity = np.zeros((6, 6, 3))
    for i in range(6):
        gravity[i, i:] = rng.normal(0, 1e-4, (6 - i, 3))
    terms = JointTerms({"compliance": rng.normal(0, 1e-6, 6), "gravity": gravity,
                        "harmonics": rng.normal(0, 1e-4, (6, 2, 2))},
                       gravity_direction=np.array([0.0, 0.6, -0.8]), payload_com=np.array([1.0, -2.0, 80.0]))
    X = rng.uniform(-2, 2, (30, 6))
    blocks = (Block(rng.normal(size=(30, 3)), rng.uniform(0.3, 3, 6), 1.7, rng.normal(size=3), rng.uniform(0.1, 1, 3)),)
    residual = ResidualModel(X, blocks, np.linalg.qr(rng.normal(size=(3, 3)))[0])
    robot = r.replace(terms=terms, residual=residual)
    written = save_robot(robot, tmp_path / "arm.toml")
    assert [p.name for p in written] == ["arm.toml", "arm.residual.json"]
    back = load_robot(tmp_path / "arm.toml")
    assert set(back.terms.arrays) == {"compliance", "gravity", "harmonics"}
    for key in ("compliance", "gravity", "harmonics"):
        np.testing.assert_allclose(back.terms.get(key), terms.get(key), rtol=1e-15, atol=0)
    for key in ("gravity_direction", "payload_com"):
        np.testing.assert_allclose(getattr(back.terms, key), getattr(terms, key), rtol=1e-15, atol=0)
    q = rng.uniform(-2, 2, (40, 6))
    torques = rng.normal(0, 50, (40, 6))
    payload = rng.uniform(0, 5, 40)
    inputs = JointInputs(torques, payload)
    np.testing.assert_allclose(back.fk(q, None, inputs), robot.fk(q, None, inputs), atol=1e-12)
    assert not np.allclose(robot.fk(q, None, inputs), r.fk(q), atol=1e-3)  # the terms do act


def test_a_gravity_table_alone_sets_the_direction():
    text = GOOD + "[gravity]\ndirection = [0.0, 0.0, 1.0]  # a ceiling-mounted arm\n"
    r = parse_robot(text)
    np.testing.assert_array_equal(r.terms.gravity_direction, [0.0, 0.0, 1.0])
    assert r.terms.empty and r.geometric
    assert "[gravity]" in robot_to_toml(r)


def test_a_folder_named_like_a_built_in_robot_does_not_hide_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ur10").mkdir()  # e.g. the README's output folder
    assert load_robot("ur10").source == "built-in ur10"
