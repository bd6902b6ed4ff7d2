"""Calibration without a tracker, against planted robots of the independent simulator: a ball on
the flange touches sockets or planes whose place is unknown, and only the joints are recorded.

The joints are found here by the independent simulator's own forward kinematics and scipy's
least squares (random starts inside the limits), never by robocal.  A calibrated model cannot
know where the robot stands (the points are unknowns in any frame), so it is judged on fresh
joint sets after the one rigid motion that best lays its predicted points on the true ones.
"""

from __future__ import annotations

import json
import warnings

import independent as ind
import numpy as np
import pytest
from independent_urdf import Urdf

from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.model.measurements import Measurements

NAME = "kr5-arc"
PLAY = 0.02  # mm per axis: where the ball really sits in its socket
TOOL_NOMINAL = (0.0, 0.0, 150.0)
TOOL_TRUE = np.array([4.0, -3.0, 153.0])


def _ball(x):
    T = np.eye(4)
    T[:3, 3] = x
    return T


def _reach(g, goal, rng, lim):
    """Joints (rad) that put the true ball on ``goal`` (mm), or None: scipy from a random start."""
    def ball(Q):
        return ind.poses(g, Q, tool=_ball(TOOL_TRUE))[:, :3, 3]

    for _ in range(20):  # the least-norm Gauss–Newton step on finite differences, from a random start
        q = ind.reach(ball, rng.uniform(lim[:, 0], lim[:, 1]), goal)
        if np.max(np.abs(ball(q) - goal)) < 1e-7 and np.all((q >= lim[:, 0]) & (q <= lim[:, 1])):
            return q
    return None


def _campaign(g, rng, setups, per, kind="points", spacing=50.0):
    """Rows of a contact campaign: joints, labels, setups; each setup's points (or plane)
    placed where the true robot reaches, the ball seated with PLAY."""
    lim = np.radians(ind.LIMITS_DEG[NAME]) * 0.95
    middle = lim.mean(axis=1)[:, None] + 0.5 * (lim - lim.mean(axis=1)[:, None])
    q, label, setup = [], [], []
    for s in range(setups):
        centre = ind.pose(g, rng.uniform(middle[:, 0], middle[:, 1]), tool=_ball(TOOL_TRUE))[:3, 3]
        if kind == "points":
            u = np.array([np.cos(s), np.sin(s), 0.1])
            goals = {"A": [centre] * per, "B": [centre + spacing * u / np.linalg.norm(u)] * per}
        else:
            n = rng.normal(size=3)
            n /= np.linalg.norm(n)
            a = np.cross(n, [1.0, 0.0, 0.0])
            a /= np.linalg.norm(a)
            b = np.cross(n, a)
            goals = {"P": [centre + rng.uniform(-100, 100) * a + rng.uniform(-100, 100) * b for _ in range(per)]}
        for name, points in goals.items():
            for p in points:
                qi = _reach(g, p + rng.normal(0.0, PLAY, 3), rng, lim)
                if qi is not None:
                    q.append(qi)
                    label.append(name)
                    setup.append(f"S{s}")
    return np.array(q), tuple(label), tuple(setup)


def _measurements(q, label, setup, kind="points", distances=()):
    labels = {"point": label} if kind == "points" else {"plane": label}
    return Measurements(q=q, position=np.full((len(q), 3), np.nan), setup=setup, source="<contacts>",
                        **labels).with_distances(distances)


def _rigid_rms(P, Q, scaled=False):
    """RMS (mm) of P after the rigid motion (``scaled``: and the scale) that best lays it on Q
    (Kabsch; Umeyama)."""
    Pc, Qc = P - P.mean(0), Q - Q.mean(0)
    U, S, Vt = np.linalg.svd(Pc.T @ Qc)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    s = np.trace(np.diag(S) @ D) / np.sum(Pc * Pc) if scaled else 1.0
    return float(np.sqrt(np.mean(np.sum((s * Pc @ R.T - Qc) ** 2, axis=1))))


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    rng = np.random.default_rng(31)
    deviations = ind.uniform_deviations(NAME, 0.3, 0.002, rng)
    g = ind.geometry(NAME, deviations)
    folder = tmp_path_factory.mktemp("contacts")
    nominal = folder / "kr5.toml"
    nominal.write_text(ind.robot_toml(NAME, {}, tool=TOOL_NOMINAL))
    q, label, setup = _campaign(g, rng, setups=6, per=12)
    lim = np.radians(ind.LIMITS_DEG[NAME]) * 0.8
    fresh = rng.uniform(lim[:, 0], lim[:, 1], (200, 6))
    truth = ind.poses(g, fresh, tool=_ball(TOOL_TRUE))[:, :3, 3]
    return {"g": g, "nominal": nominal, "q": q, "label": label, "setup": setup, "fresh": fresh, "truth": truth,
            "rng": rng, "folder": folder}


def _fit(nominal, meas, **kw):
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        res = calibrate(nominal, meas, "lm", **kw)
    return res, [str(w.message) for w in said] + res.notes  # what it said: warnings and notes


def test_fixed_points_with_a_known_distance_recover_the_robot_to_the_play(planted):
    meas = _measurements(planted["q"], planted["label"], planted["setup"], distances=[("A", "B", 50.0)])
    res, said = _fit(planted["nominal"], meas)
    assert res.frames == "tcp" and any("base frame is not observable" in s for s in said)
    per = np.bincount(meas.constraints.group).mean()
    floor = PLAY * np.sqrt(3 * (per - 1) / per)
    assert res.contact["after"]["point_spread_rms"] < 1.3 * floor
    assert res.contact["before"]["point_spread_rms"] > 20 * floor
    assert res.contact["after"]["distance_error_rms"] < 3 * PLAY
    # the calibrated robot predicts fresh joint sets as the true one does, up to where it stands
    nominal = load_robot(planted["nominal"])
    before = _rigid_rms(nominal.positions(planted["fresh"]), planted["truth"])
    after = _rigid_rms(res.robot.positions(planted["fresh"]), planted["truth"])
    assert before > 1.0 and after < 0.1, (before, after)
    # what such data cannot see, said by name: the frame the robot stands in, its first joint's zero
    ident = res.identifiability
    for name in ("theta1", "d1"):
        assert name in ident.dropped
    assert "base" in ident.reasons["theta1"].text() or "dependent" in ident.reasons["theta1"].text()
    assert not any(n.startswith("base_") for n in res.names)


def test_without_a_distance_the_scale_is_said_unobservable_not_fitted(planted):
    meas = _measurements(planted["q"], planted["label"], planted["setup"])
    res, said = _fit(planted["nominal"], meas)
    held = [n for n in res.identifiability.dropped if "length scale" in res.identifiability.reasons[n].text()]
    assert len(held) == 1 and any("length scale is not observable" in s for s in said)
    assert res.identifiability.reasons[held[0]].kind == "unobservable"
    # the robot did not shrink to fit: it keeps the nominal size within what the lengths' errors allow
    pts = res.robot.positions(planted["fresh"])
    size = np.linalg.norm(pts - pts.mean(0), axis=1).mean()
    true_size = np.linalg.norm(planted["truth"] - planted["truth"].mean(0), axis=1).mean()
    assert size == pytest.approx(true_size, rel=2e-3)


def test_planes_recover_what_planes_can_see(planted):
    rng = np.random.default_rng(32)
    q, label, setup = _campaign(planted["g"], rng, setups=5, per=20, kind="planes")
    meas = _measurements(q, label, setup, kind="planes")
    res, _ = _fit(planted["nominal"], meas)
    assert res.contact["after"]["plane_rms"] < 1.5 * PLAY
    assert res.contact["before"]["plane_rms"] > 10 * PLAY
    nominal = load_robot(planted["nominal"])
    before = _rigid_rms(nominal.positions(planted["fresh"]), planted["truth"])
    after = _rigid_rms(res.robot.positions(planted["fresh"]), planted["truth"])
    assert after < 0.5 * before, (before, after)


def test_tracker_rows_and_contact_rows_give_one_fit(planted):
    """Tracker rows in the tracker's frame beside socket rows: the base is registered from the
    tracker rows, the scale and the shape from both, and fresh poses are predicted in the
    tracker's frame."""
    rng = np.random.default_rng(33)
    B = ind._trans(1500.0, -300.0, 200.0) @ ind._rz(0.4)
    lim = np.radians(ind.LIMITS_DEG[NAME]) * 0.9
    qt = rng.uniform(lim[:, 0], lim[:, 1], (40, 6))
    pt = np.array([ind.pose(planted["g"], qi, base=B, tool=_ball(TOOL_TRUE))[:3, 3] for qi in qt])
    pt += rng.normal(0.0, 0.01, pt.shape)
    n = len(planted["q"])
    meas = Measurements(q=np.vstack([planted["q"], qt]), position=np.vstack([np.full((n, 3), np.nan), pt]),
                        point=planted["label"] + ("",) * len(qt), setup=planted["setup"] + ("",) * len(qt),
                        source="<mixed>")
    res, said = _fit(planted["nominal"], meas)
    assert res.frames == "base+tool"
    truth = np.array([ind.pose(planted["g"], qi, base=B, tool=_ball(TOOL_TRUE))[:3, 3] for qi in planted["fresh"]])
    rms = float(np.sqrt(np.mean(np.sum((res.robot.positions(planted["fresh"]) - truth) ** 2, axis=1))))
    tracker_only, _ = _fit(planted["nominal"], meas.subset(np.arange(n, n + len(qt))))
    alone = float(np.sqrt(np.mean(np.sum((tracker_only.robot.positions(planted["fresh"]) - truth) ** 2, axis=1))))
    assert rms < 0.03 and rms < alone, (rms, alone)
    assert res.contact["after"]["point_spread_rms"] < 1.5 * PLAY * np.sqrt(3)


def test_the_exported_urdf_gives_evaluates_figures_independently(planted, run_cli):
    """From the recorded file to a calibrated URDF in one command; evaluate's figures on it equal
    those computed here from the URDF file itself (an independent reader, the tip link kept)."""
    folder = planted["folder"]
    code, text, err = run_cli("robots", "--urdf", planted["nominal"])
    assert code == 0, err
    urdf_in = folder / "kr5.urdf"
    urdf_in.write_text(text)
    rows = ["q1,q2,q3,q4,q5,q6,point,setup"] + [",".join(repr(float(v)) for v in np.degrees(qi)) + f",{lab},{s}"
                                                 for qi, lab, s in zip(planted["q"], planted["label"],
                                                                       planted["setup"])]
    (folder / "sockets.csv").write_text("\n".join(rows) + "\n")
    out = folder / "cal.urdf"
    code, _, err = run_cli("calibrate", urdf_in, folder / "sockets.csv", "--point-distance", "A,B=50", "--export",
                           out, "--quiet")
    assert code == 0, err
    tip = Urdf(out.read_text())
    leaf = [c for c in tip.joints if c not in {j["parent"] for j in tip.joints.values()}]
    tip_link = next(c for c in leaf if c != "measuring_frame")
    code, js, err = run_cli("evaluate", out, folder / "sockets.csv", "--tip-link", tip_link, "--point-distance",
                            "A,B=50", "--json")
    assert code == 0, err
    figures = json.loads(js)
    # independently: the tool point of each row through the exported file, grouped by setup and socket
    root = next(j["parent"] for j in tip.joints.values() if j["parent"] not in tip.joints)
    names = tip.movable(root, tip_link)
    p = np.array([1000 * tip.transform(root, tip_link, dict(zip(names, qi)))[:3, 3] for qi in planted["q"]])
    keys = list(zip(planted["setup"], planted["label"]))
    means = {k: p[[i for i, x in enumerate(keys) if x == k]].mean(0) for k in dict.fromkeys(keys)}
    spread = np.sqrt(np.mean([np.sum((p[i] - means[k]) ** 2) for i, k in enumerate(keys)]))
    miss = [np.linalg.norm(means[(s, "A")] - means[(s, "B")]) - 50.0 for s in dict.fromkeys(planted["setup"])]
    assert figures["point_spread_rms"] == pytest.approx(spread, rel=1e-6)
    assert figures["distance_error_rms"] == pytest.approx(np.sqrt(np.mean(np.square(miss))), rel=1e-6, abs=1e-9)
    assert figures["point_spread_rms"] < 1.3 * PLAY * np.sqrt(3)


@pytest.mark.parametrize("body,words", [
    ("q1,q2,q3,q4,q5,q6,x,y,z,point\n1,2,3,4,5,6,1,2,3,A\n", ("row 2", "a row is a contact")),
    ("q1,q2,q3,q4,q5,q6,point,plane\n1,2,3,4,5,6,A,P\n", ("row 2", "touches point 'A' and plane 'P'")),
    ("q1,q2,q3,q4,q5,q6,setup\n1,2,3,4,5,6,S1\n", ("setup column",)),
])
def test_contact_files_that_say_two_things_are_refused(tmp_path, run_cli, body, words):
    path = tmp_path / "c.csv"
    path.write_text(body)
    code, out, err = run_cli("calibrate", "kr5-arc", path)
    assert code == 2 and out == "" and err.count("\n") == 1
    for w in words:
        assert w in err, err


def test_contact_options_are_checked(tmp_path, run_cli):
    path = tmp_path / "c.csv"
    code, _, err = run_cli("simulate", "kr5-arc", "--contact", "points", "--poses", "6", "--setups", "2", "--out",
                           path, "--quiet")
    assert code == 0, err
    for args, words in ((("--point-distance", "A,C=50"), ("--point-distance", "'C'")),
                        (("--point-distance", "A,B"), ("--point-distance", "A,B=MM")),
                        (("--point-distance", "A,B=-5"), ("--point-distance",)),
                        (("--frames", "base"), ("--frames", "not observable"))):
        code, out, err = run_cli("calibrate", "kr5-arc", path, *args)
        assert code == 2 and err.count("\n") == 1 and all(w in err for w in words), (args, err)


def test_planned_socket_configurations_beat_random_ones(planted, run_cli, tmp_path):
    """Configurations planned on the nominal model for four sockets, reached by the true robot from
    them (the ball pushed home), calibrate the robot better than as many random reaching ones."""
    from robocal.plan.contacts import plan_contacts

    nominal = load_robot(planted["nominal"])
    g, rng = planted["g"], np.random.default_rng(41)
    lim = np.radians(ind.LIMITS_DEG[NAME]) * 0.95
    sockets = [ind.pose(g, qi, tool=_ball(TOOL_TRUE))[:3, 3] for qi in
               rng.uniform(lim[:, 0] * 0.4, lim[:, 1] * 0.4, (4, 6))]
    plan = plan_contacts(nominal, sockets, 8, candidates=200, seed=1)
    assert plan.value > np.median(plan.random_values)

    def seated(q0, goal):  # the true robot from a configuration, its ball pushed into the socket
        return ind.reach(lambda Q: ind.poses(g, Q, tool=_ball(TOOL_TRUE))[:, :3, 3], q0, goal, iterations=30)

    def rigid_error(q_rows, sockets_of, seed):
        noise = np.random.default_rng(seed)
        q = np.array([seated(qi, sockets[k] + noise.normal(0, PLAY, 3)) for qi, k in zip(q_rows, sockets_of)])
        meas = Measurements(q=q, position=np.full((len(q), 3), np.nan), point=tuple(f"P{k}" for k in sockets_of),
                            source="<planned>")
        res, _ = _fit(planted["nominal"], meas)
        # without a distance the size is not observable: the shape is compared
        return _rigid_rms(res.robot.positions(planted["fresh"]), planted["truth"], scaled=True)

    planned = np.mean([rigid_error(plan.q, plan.socket, s) for s in range(2)])
    randoms = []
    for s in range(4):
        r = np.random.default_rng(100 + s)
        q = [_reach(g, sockets[k], r, lim) for k in plan.socket]
        randoms.append(rigid_error(np.array(q), plan.socket, s))
    assert planned < 0.8 * np.median(randoms), (planned, randoms)  # measured: 0.036 against 0.071 mm


@pytest.mark.slow
def test_plane_rows_count_one_value_each_so_their_sigma_is_the_play(planted):
    """A plane row says only its offset along the plane's normal: its degrees of freedom, the noise
    estimate and the outlier test count one value, and planted planes with play p estimate σ = p
    (counted as three values, σ came out √3 too low and good rows were called outliers)."""
    sigmas = []
    for seed in range(4):
        rng = np.random.default_rng(40 + seed)
        q, label, setup = _campaign(planted["g"], rng, setups=6, per=30, kind="planes")
        res, said = _fit(planted["nominal"], _measurements(q, label, setup, kind="planes"))
        sigmas.append(res.noise.position)
        assert not any("look like outliers" in s for s in said)
        g = res.goodness_of_fit  # one value a row, three unknowns a plane, less the parameters' effective number
        assert g.dof == pytest.approx(len(q) - 3 * 6 - len(res.names) + float(np.sum(res.prior_share)))
    assert np.mean(sigmas) == pytest.approx(PLAY, rel=0.1), sigmas
