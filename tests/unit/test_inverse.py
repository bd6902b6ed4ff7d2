"""The one inverse kinematics: the DH equivalent of every convention, the closed forms against the
independent simulator's forward model, every solution found, configuration facts against the
manuals' definitions (tests/controller.py), whole turns, and the controller's joint coupling."""

from __future__ import annotations

import controller as ctl
import independent as ind
import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.inverse.closed_form import form_of
from robocal.inverse.configuration import arm_configuration
from robocal.inverse.equivalent import dh_equivalent, wrap
from robocal.inverse.solve import Request, all_solutions, choose, controller_joints
from robocal.io.robotfile import load_robot, parse_robot, robot_to_toml
from robocal.model.robot import Robot


def _random_chain(convention: str, rng) -> Robot:
    n = 6
    if convention == "urdf":
        from robocal.model import urdf

        g = np.zeros((n, urdf.WIDTH))
        g[:, urdf.X:urdf.Z + 1] = rng.uniform(-300, 300, (n, 3))
        g[:, urdf.ROLL:urdf.YAW + 1] = rng.uniform(-np.pi, np.pi, (n, 3))
        axes = rng.normal(size=(n, 3))
        g[:, urdf.AX:urdf.AZ + 1] = axes / np.linalg.norm(axes, axis=1)[:, None]
        g[:, urdf.OFFSET] = rng.uniform(-1, 1, n)
        return Robot("urdf", g, base=ctl.frame([10, 20, 30], [5, -10, 20]), tool=ctl.frame([0, 5, 90], [0, 30, 0]))
    a, d = rng.uniform(-400, 400, n), rng.uniform(-400, 400, n)
    alpha, theta = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    beta = rng.uniform(-0.1, 0.1, n) if convention == "hayati" else None
    return Robot.from_dh(convention, a, alpha, theta, d, beta, base=ctl.frame([100, 0, 50], [0, 0, 30]),
                         tool=ctl.frame([0, 0, 100], [10, 0, 0]))


@pytest.mark.parametrize("convention", ["dh", "hayati", "craig", "urdf"])
def test_the_dh_equivalent_reproduces_every_convention(convention, rng):
    for _ in range(5):
        robot = _random_chain(convention, rng)
        eq = dh_equivalent(robot)
        assert eq is not None
        q = rng.uniform(-3, 3, (20, 6))
        np.testing.assert_allclose(eq.pose(eq.phi(q)), robot.fk(q), atol=1e-8)


@pytest.mark.parametrize("name", ["kr5-arc", "irb120", "ur10", "kr5-kuka", "er10l-c10"])
def test_every_closed_form_solution_reaches_the_goal_in_the_independent_model(name, rng):
    g = ind.geometry(name)
    B = ind.base_of(name)
    robot = load_robot(name if name != "kr5-kuka" else "kr5-arc-kuka").replace(tool=np.eye(4))
    lim = np.radians(ind.LIMITS_DEG[name])
    q = rng.uniform(np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi), (60, 6))
    T = np.array([ind.pose(g, qi, base=B) for qi in q])
    sols = all_solutions(robot, T)
    assert sols.method.startswith("closed form") and (sols.count >= 2).all() and sols.count.max() == 8
    for i in range(len(q)):
        found = sols.q[i][sols.valid[i]]
        assert np.abs(wrap(found - q[i])).max(axis=1).min() < 1e-7  # the taught joints are among them
        for qs in found:
            reached = ind.pose(g, qs, base=B)
            np.testing.assert_allclose(reached, T[i], atol=1e-7)


def test_closed_form_finds_what_many_random_starts_find(rng):
    robot = load_robot("irb120").replace(limits=None)
    q = rng.uniform(-2.5, 2.5, (1, 6))
    T = robot.fk(q)
    closed = all_solutions(robot, T)
    from robocal.inverse.solve import _polish

    starts = rng.uniform(-np.pi, np.pi, (1, 400, 6))
    found, ok = _polish(robot, T, starts)
    distinct = []
    for s in found[0][ok[0]]:
        if all(np.abs(wrap(s - d)).max() > 1e-4 for d in distinct):
            distinct.append(s)
    assert len(distinct) == closed.count[0] == 8
    for d in distinct:
        assert np.abs(wrap(closed.q[0] - d)).max(axis=1).min() < 1e-6


def test_a_calibrated_model_near_the_form_is_solved_and_polished(rng):
    deviations = ind.uniform_deviations("kr5-arc", 0.5, 0.005, rng)
    robot = parse_robot(ind.robot_toml("kr5-arc", deviations))
    eq = dh_equivalent(robot)
    assert form_of(eq) == ("spherical", False)
    g = ind.geometry("kr5-arc", deviations)
    q = rng.uniform(-1.2, 1.2, (20, 6))
    T = np.array([ind.pose(g, qi) for qi in q])
    sols = all_solutions(robot, T)
    assert "polished" in sols.method
    for i in range(len(q)):
        found = sols.q[i][sols.valid[i]]
        assert np.abs(wrap(found - q[i])).max(axis=1).min() < 1e-7
        for qs in found:
            np.testing.assert_allclose(ind.pose(g, qs)[:3, 3], T[i, :3, 3], atol=1e-5)


def test_a_chain_with_no_closed_form_is_searched(rng):
    robot = load_robot("tests/data/irb120_ros_industrial.urdf", tip_link="tool0")
    five = robot.replace(geometry=robot.geometry[:5], limits=robot.limits[:5], joint_names=None, urdf=None)  # 5 axes
    q = rng.uniform(-1.5, 1.5, (4, 5))
    T = five.fk(q)
    sols = all_solutions(five, T, hint=q + 0.05)
    assert sols.method == "multi-start"
    pick = choose(five, sols, hint=q)
    np.testing.assert_allclose(five.fk(pick.q), T, atol=1e-6)


KUKA_BOX = np.radians([(-150, 150), (-170, 50), (-14, 150), (-340, 340), (-125, 125), (-340, 340)])


def test_kuka_status_and_turn_name_the_taught_solution(rng):
    """S and T written from the manual's definitions (controller.py) pick the taught joints among
    all solutions; every other solution has other S or T."""
    robot = load_robot("kr5-arc-kuka").replace(tool=np.eye(4))
    g, B = ind.geometry("kr5-kuka"), ind.base_of("kr5-kuka")
    q = rng.uniform(KUKA_BOX[:, 0], KUKA_BOX[:, 1], (80, 6))
    from robocal.filtering import krl

    T = np.array([ind.pose(g, qi, base=B) for qi in q])
    st = [ctl.kuka_status("kr5-kuka", g, qi) for qi in q]
    requests = [krl.request(type("T", (), {"config": {"S": s, "T": t}})()) for s, t in st]
    sols = all_solutions(robot, T)
    pick = choose(robot, sols, requests)
    assert (pick.mismatch == 0).all()
    np.testing.assert_allclose(pick.q, q, atol=1e-7)
    arm = arm_configuration(robot, q)
    for i, (s, t) in enumerate(st):
        facts = {k: int(getattr(arm, k)[i]) for k in ("front", "elbow", "lower")}
        assert krl.encode(q[i], facts, {"S": 0, "T": 0}) == {"S": s, "T": t}


@pytest.mark.parametrize("offset", [0.0, -70.0], ids=["irb120", "no wrist offset"])
def test_abb_and_fanuc_configuration_data_follow_their_manuals(rng, offset):
    from robocal.filtering import fanuc, rapid

    robot = load_robot("irb120")  # and the same arm with axis 4 in line with axis 3 (a3 = 0)
    geometry = robot.geometry.copy()
    geometry[2, 0] += offset
    robot = robot.replace(geometry=geometry)
    g = ind.geometry("irb120", {"a3": offset})
    lim = np.radians(ind.LIMITS_DEG["irb120"])
    q = rng.uniform(lim[:, 0], lim[:, 1], (200, 6))
    arm = arm_configuration(robot, q)
    for i in range(len(q)):
        facts = {k: int(getattr(arm, k)[i]) for k in ("front", "elbow", "lower")}
        cf = rapid.encode(q[i], facts, {"cf1": 0, "cf4": 0, "cf6": 0, "cfx": 0})
        assert [cf[k] for k in ("cf1", "cf4", "cf6", "cfx")] == ctl.abb_config("irb120", g, q[i])
        c = fanuc.encode(q[i], facts, {"flip": "N", "elbow": "U", "side": "T", "t1": 0, "t4": 0, "t6": 0})
        assert f"{c['flip']} {c['elbow']} {c['side']}, {c['t1']}, {c['t4']}, {c['t6']}" == \
            ctl.fanuc_config("irb120", g, q[i])


def test_a_joint_on_a_flags_boundary_keeps_the_targets_flag():
    from robocal.filtering import krl, rapid

    q = np.radians([0.0, -90.0, 90.0, 0.0, 30.0, 0.0]) + np.array([-2e-16, 0, 0, 1e-15, 0, -3e-14])
    facts = {"front": 1, "elbow": 1, "lower": 1}
    for t in (0b000010, 0b101011):  # A2 < 0; A1, A4, A6 at zero: each of their bits as the target has it
        assert krl.encode(q, facts, {"S": 2, "T": t})["T"] == t
    assert rapid.encode(q, facts, {"cf1": -1, "cf4": 0, "cf6": -1, "cfx": 0})["cf1"] == -1
    assert rapid.encode(q, facts, {"cf1": 0, "cf4": -1, "cf6": 0, "cfx": 0})["cf4"] == -1


def test_whole_turns_follow_kuka_t_and_fanuc_turn_numbers(rng):
    robot = load_robot("kr5-arc-kuka")
    q = np.radians([[20.0, -80.0, 100.0, 200.0, 40.0, -300.0]])
    T = robot.fk(q)
    sols = all_solutions(robot, T)
    # A4 = 200° and A6 = −300°: the base solutions hold −160° and 60°; T names the turns
    bits = sum(1 << i for i in range(6) if q[0, i] < 0)
    front = int(arm_configuration(robot, q).front[0])
    elbow = int(arm_configuration(robot, q).elbow[0])
    joints = tuple((-np.inf, 0.0) if bits >> i & 1 else (0.0, np.inf) for i in range(6))
    pick = choose(robot, sols, [Request(front=front, elbow=elbow, joints=joints)])
    np.testing.assert_allclose(pick.q, q, atol=1e-7)
    near = choose(robot, sols, hint=q + 0.1)  # or the turn nearest the taught joints
    np.testing.assert_allclose(near.q, q, atol=1e-7)


def test_each_joints_turn_is_chosen_by_the_rule_read_one_joint_at_a_time(rng):
    """The batched choice of whole turns against the rule applied to each joint of each solution in plain
    Python: inside the limits, then inside the target's interval, then nearest the hint (where it has one),
    else the fewest turns; the first of equal costs.  Joints on their limits, on an interval's ends, a
    sliding joint, hints NaN in part and half-open intervals are all drawn."""
    import types

    from robocal.inverse.configuration import TOLERANCE_RAD
    from robocal.inverse.solve import TURNS, _turned

    base = load_robot("kr5-arc")
    m, k, n = 40, 8, base.n_joints
    for trial in range(12):
        slide = np.zeros(n, bool)
        slide[2] = trial % 4 == 3
        robot = types.SimpleNamespace(prismatic=slide, limits=base.limits)
        q = rng.uniform(-7.0, 7.0, (m, k, n))
        on_limit = rng.random((m, k, n)) < 0.05
        q[on_limit] = np.broadcast_to(base.limits[:, 1], (m, k, n))[on_limit]
        lo = np.where(rng.random((m, n)) < 0.5, -np.inf, rng.uniform(-4.0, 2.0, (m, n)))
        hi = np.where(rng.random((m, n)) < 0.5, np.inf, np.where(np.isinf(lo), 1.0, lo) + rng.uniform(0, 3, (m, n)))
        ends = np.isfinite(lo[:, 1])
        q[ends, 0, 1] = lo[ends, 1]  # on an interval's end
        hint = None if trial % 3 == 0 else np.where(rng.random((m, n)) < 0.2, np.nan, rng.uniform(-4, 4, (m, n)))
        chosen, missed, limits_ok, choice = _turned(robot, q, lo - TOLERANCE_RAD, hi + TOLERANCE_RAD, hint)
        lim = base.limits + np.array([-TOLERANCE_RAD, TOLERANCE_RAD])
        for i in range(m):
            for s in range(k):
                misses, fits, several = 0, True, False
                for j in range(n):
                    best = None
                    allowed = 0
                    for turn in ([0] * len(TURNS) if slide[j] else TURNS):
                        v = float(q[i, s, j]) + 2.0 * np.pi * int(turn)
                        inside = bool(lim[j, 0] <= v <= lim[j, 1])
                        wanted = bool(lo[i, j] - TOLERANCE_RAD <= v <= hi[i, j] + TOLERANCE_RAD)
                        allowed += inside and wanted
                        near = abs(int(turn)) if hint is None or np.isnan(hint[i, j]) else abs(v - hint[i, j])
                        cost = (0.0 if inside else np.inf) + (0.0 if wanted else 1e6) + near
                        if best is None or cost < best[0]:
                            best = (cost, v)
                    assert chosen[i, s, j] == best[1], (trial, i, s, j)
                    fits &= bool(np.isfinite(best[0]))
                    misses += bool(np.isfinite(best[0]) and best[0] >= 1e6)
                    several |= allowed > 1
                assert (missed[i, s], limits_ok[i, s], choice[i, s]) == (misses, fits, several), (trial, i, s)


def test_controller_joints_say_what_went_wrong():
    robot = load_robot("irb120")
    far = np.eye(4)
    far[:3, 3] = (3000.0, 0.0, 0.0)
    q, status, reasons, _ = controller_joints(robot, far[None])
    assert status == ["unreachable"] and "no solution" in reasons[0] and np.isnan(q).all()


def test_the_controllers_joint_coupling_travels_in_the_robot_file():
    robot = load_robot("lrmate200id")
    assert robot.coupling == ((2, 1, 1.0),)
    J = np.radians([[10.0, 20.0, -30.0, 40.0, -50.0, 60.0]])
    q = robot.from_controller(J)
    np.testing.assert_allclose(np.degrees(q[0, 2]), -10.0)
    np.testing.assert_allclose(robot.to_controller(q), J)
    again = parse_robot(robot_to_toml(robot))
    assert again.coupling == robot.coupling
    text = robot_to_toml(robot).replace("plus = 2", "plus = 3")
    with pytest.raises(InputError, match="two different joints"):
        parse_robot(text)


@pytest.mark.parametrize("name,form", [("ur10", "offset"), ("irb120", "spherical")])
@pytest.mark.parametrize("as_urdf", [False, True])
def test_the_taught_joints_are_always_among_the_solutions_of_a_near_closed_form_model(name, form, as_urdf,
                                                                                     tmp_path):
    """Models near a closed form (±1 mm, ±0.1°, as a calibration leaves them; DH tables and their
    URDFs): over many random joint sets, the taught joints are always among the solutions of their
    pose, and chosen given them as the hint or given their configuration facts.  (Keeping only the
    ideal form's 'possible' seeds lost a solution its polish had reached, and a goal came back on
    another branch.)"""
    from robocal.io.urdf import urdf_text

    rng = np.random.default_rng({"ur10": 1, "irb120": 2}[name] + 10 * as_urdf)
    for draw in range(4):
        deviations = ind.uniform_deviations(name, 1.0, np.radians(0.1), rng)
        robot = parse_robot(ind.robot_toml(name, deviations))
        if as_urdf:
            path = tmp_path / f"{name}{draw}.urdf"
            path.write_text(urdf_text(robot))
            robot = load_robot(path, tip_link="target")
        assert form_of(dh_equivalent(robot))[0] == form
        lim = np.radians(ind.LIMITS_DEG[name])
        q = rng.uniform(np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi), (60, 6))
        T = robot.fk(q)
        sols = all_solutions(robot, T, hint=q)
        # (1e-4 rad: near a singularity the polish stops a few microradians from the taught joints)
        for i in range(len(q)):
            found = sols.q[i][sols.valid[i]]
            assert np.abs(wrap(found - q[i])).max(axis=1).min() < 1e-4, (draw, i)
        pick = choose(robot, sols, hint=q)
        assert np.abs(wrap(pick.q - q)).max() < 1e-4
        # configuration data that name the taught solution (its facts, its joints within 0.02 rad),
        # without the taught joints themselves: the same solution is chosen
        arm = arm_configuration(robot, q)
        requests = [Request(front=int(arm.front[i]), elbow=int(arm.elbow[i]),
                            joints=tuple((v - 0.02, v + 0.02) for v in q[i])) for i in range(len(q))]
        pick = choose(robot, all_solutions(robot, T), requests)
        # (at a singularity two solutions meet within the data's 0.02 rad: either is the one they name)
        off = np.abs(wrap(pick.q - q)).max(axis=1)
        assert (pick.mismatch == 0).all() and off.max() <= 0.02 and np.mean(off < 1e-4) >= 0.95
