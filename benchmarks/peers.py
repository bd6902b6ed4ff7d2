"""Peer benchmarks: the same workloads in pyswarms, pybotics and Robotics Toolbox, side by side.

Not part of the installed package.  ``robocal bench`` loads this file from the source tree
(``--peers benchmarks``) and runs it when the peers are installed:
``pip install ".[bench]"`` and ``pip install --no-deps pybotics`` (its metadata pins
numpy < 2, but it runs on numpy 2).  Each peer is timed interleaved with robocal's own
run of the same job, and the row states the ratio.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np

from robocal.bench.timing import Row, median_time
from robocal.bench.workloads import wen2019_problem
from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.optimize.swarm import constriction, ipso
from robocal.presets import wen2019
from robocal.simulation import planted_deviations, simulate


def _missing(label: str, unit: str) -> list[Row]:
    return [Row(label, float("nan"), unit, "", None, note="not installed (bench extra)")]


def pyswarms_gbest(repeats: int) -> list[Row]:
    """pyswarms GlobalBestPSO on robocal's W1 objective, with constriction-equivalent settings."""
    try:
        import pyswarms as ps
    except ImportError:
        return _missing("  peer pyswarms GlobalBestPSO", "s")
    logging.getLogger("pyswarms").setLevel(logging.ERROR)
    prob, box = wen2019_problem()
    K = constriction(wen2019.IPSO["c1"] + wen2019.IPSO["c2"])  # as inertia weight: w = K, c = K·2.05
    options = {"c1": K * wen2019.IPSO["c1"], "c2": K * wen2019.IPSO["c2"], "w": K}
    result = {}

    def peer():
        opt = ps.single.GlobalBestPSO(n_particles=wen2019.IPSO["particles"], dimensions=len(box), options=options,
                                      bounds=(-box, box), velocity_clamp=(-box, box))
        np.random.seed(0)
        result["cost"], _ = opt.optimize(lambda X: prob.objective(X), iters=wen2019.IPSO["iterations"], verbose=False)

    def ours():
        result["ours"] = ipso(lambda X: prob.objective(X), -box, box, **wen2019.IPSO, seed=0).fun

    ours()
    t_peer, t_ours = median_time(peer, max(1, repeats // 2)), median_time(ours, max(1, repeats // 2))
    return [Row("  peer pyswarms GlobalBestPSO, same objective", t_peer, "s", "", None,
                peer=f"robocal ipso {t_peer / t_ours:.1f}× faster",
                note=f"final objective pyswarms {result['cost']:.4g} vs robocal ipso {result['ours']:.4g}")]


def pybotics_calibration(repeats: int) -> list[Row]:
    """pybotics' calibration example: its kinematic chain (Craig MDH) in scipy least_squares."""
    try:
        from pybotics.robot import Robot as PRobot
    except ImportError:
        return _missing("  peer pybotics + least_squares", "s")
    from scipy.optimize import least_squares

    robot = load_robot("kr5-arc")
    deviations = planted_deviations(robot, "uniform:0.1,0.002", np.random.default_rng(1))
    deviations.update(a6=0.0, alpha6=0.0)  # Craig form keeps a6, α6 in the fixed tool: plant none there
    sim = simulate(robot, 32, deviations=deviations, seed=1, measure="position", noise=0.02)
    g = robot.geometry
    # the same arm in Craig's modified DH (pybotics' convention): row i = (α_{i-1}, a_{i-1}, θ_i, d_i)
    mdh = np.zeros((6, 4))
    mdh[1:, 0], mdh[1:, 1] = g[:-1, 1], g[:-1, 0]
    mdh[:, 2], mdh[:, 3] = g[:, 2], g[:, 3]
    tool = np.eye(4)
    c, s = np.cos(g[-1, 1]), np.sin(g[-1, 1])
    tool[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    tool[0, 3] = g[-1, 0]
    q, p = sim.measurements.q, sim.measurements.position
    mask = np.ones(24, bool)
    mask[[1 * 4 + 3, 5 * 4 + 2, 5 * 4 + 0]] = False  # d2 (∥ axes), θ6, α6: unidentifiable here
    result = {}

    def peer():
        def fun(x):
            m = mdh.ravel().copy()
            m[mask] += x
            r = PRobot.from_parameters(m.reshape(6, 4))
            r.tool.matrix = tool
            return np.concatenate([r.fk(qi)[:3, 3] for qi in q]) - p.ravel()

        res = least_squares(fun, np.zeros(mask.sum()), method="lm")
        result["rms"] = float(np.sqrt(np.mean(np.sum(res.fun.reshape(-1, 3) ** 2, 1))))

    def ours():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result["ours"] = calibrate(robot, sim.measurements, "lm").metrics["after"].position["rms"]

    try:
        t_peer = median_time(peer, max(1, repeats // 2))
    except Exception as exc:  # a peer's API drift must not break the bench
        return [Row("  peer pybotics + least_squares", float("nan"), "s", "", None, note=f"failed: {exc}")]
    ours()
    t_ours = median_time(ours, repeats)
    return [Row("  peer pybotics + least_squares (KR5, 32 poses)", t_peer, "s", "", None,
                peer=f"robocal lm {t_peer / t_ours:.0f}× faster",
                note=f"after RMS pybotics {result['rms']:.4f} mm vs robocal {result['ours']:.4f} mm")]


def rtb_fkine(repeats: int) -> list[Row]:
    """Robotics Toolbox DHRobot.fkine and ETS.fkine against robocal's batched numpy FK."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return _missing("  peer Robotics Toolbox fkine", "M/s")
    robot = load_robot("kr5-arc")
    g = robot.geometry
    bot = rtb.DHRobot([rtb.RevoluteDH(a=g[i, 0], alpha=g[i, 1], offset=g[i, 2], d=g[i, 3]) for i in range(6)])
    q = np.random.default_rng(0).uniform(-2, 2, (20_000, 6))
    rate_ours = len(q) / median_time(lambda: robot.positions(q), repeats) / 1e6
    rate = len(q) / median_time(lambda: bot.fkine(q), 3) / 1e6
    err = max(float(np.abs(np.array(bot.fkine(q[i]).t) - robot.positions(q[i : i + 1])[0]).max()) for i in range(5))
    rows = [Row("  peer Robotics Toolbox DHRobot.fkine", rate, "M/s", "", None,
                peer=f"robocal numpy {rate_ours / rate:.0f}× faster", note=f"agrees to {err:.1e} mm")]
    try:
        ets = bot.ets()
        rate_ets = 2000 / median_time(lambda: [ets.fkine(qi) for qi in q[:2000]], 3) / 1e6
        rows.append(Row("  peer Robotics Toolbox ETS.fkine (per pose)", rate_ets, "M/s", "", None,
                        peer=f"robocal numpy {rate_ours / rate_ets:.0f}× faster"))
    except Exception as exc:  # pragma: no cover - peer API drift
        rows.append(Row("  peer Robotics Toolbox ETS.fkine", float("nan"), "M/s", "", None, note=f"failed: {exc}"))
    return rows


def run_all(quick: bool = False, say=lambda s: None) -> list[Row]:
    reps = 3 if quick else 5
    rows: list[Row] = []
    for name, fn in (("pyswarms", pyswarms_gbest), ("pybotics", pybotics_calibration), ("rtb", rtb_fkine)):
        say(f"running peer {name}")
        rows += fn(reps)
    return rows


if __name__ == "__main__":
    from robocal.bench.timing import print_rows

    print_rows(run_all())
