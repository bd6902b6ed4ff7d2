"""``robocal reproduce wen2019``: IPSO on the ER10L-C10 beside PSO, LM and hybrid."""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

from ...calibration import CalibrationResult, calibrate
from ...io.atomic import atomic_write
from ...io.robotfile import load_robot
from ...model.metrics import pose_errors
from ...model.parameters import is_angle
from ...presets.wen2019 import IPSO, JOINT_NOISE_UNIFORM, PARAMETERS, POSES, PUBLISHED, TABLE2_DEVIATIONS
from ...report import figures
from ...simulation import simulate
from ..common import Say, fmt, machine, quiet, write_json


def recovery(res: CalibrationResult, truth: dict[str, float]) -> dict[str, float]:
    """Largest |identified − planted| over identified lengths (mm) and angles (rad)."""
    lengths = [abs(res.parameter(n) - truth.get(n, 0.0)) for n in res.names if not is_angle(n)]
    angles = [abs(res.parameter(n) - truth.get(n, 0.0)) for n in res.names if is_angle(n)]
    return {"length_mm": max(lengths, default=0.0), "angle_rad": max(angles, default=0.0)}


def entry(res: CalibrationResult) -> dict:
    """What a summary needs of one calibration."""
    d = res.to_dict()
    keep = ("metrics", "iterations", "evaluations", "objective_value", "status", "dropped", "parameters", "history")
    return {**{k: d[k] for k in keep}, "optimizer_time_s": res.optimization.time_s, "total_time_s": res.time_s}


CASES = {
    "a": {"label": "(a) joint noise U(±0.1 rad) as the paper writes", "joint_noise_uniform": JOINT_NOISE_UNIFORM},
    "b": {"label": "(b) tracker noise 0.02 mm, 0.001°, exact joints", "noise": 0.02,
          "angle_noise": math.radians(0.001)},
}


def _methods(quick: bool) -> dict[str, dict]:
    return {
        "ipso": {"iterations": 60 if quick else IPSO["iterations"]},
        "pso": {"objective": "sum_squares", **({"particles": 40, "iterations": 40} if quick else {})},
        "lm": {},
        "hybrid": {"iterations": 30} if quick else {},
    }


def _figures(out: Path, key: str, label: str, robot, meas, runs: dict[str, CalibrationResult]) -> None:
    before_dp, before_dr = pose_errors(robot, meas)
    after = {m: pose_errors(runs[m].robot, meas)[0] for m in ("ipso", "lm")}
    # LM starts whitened by σp = 1 mm and σr = 0.01 rad: its χ² is this objective in mm² (k = 1e4)
    figures.save_png(figures.convergence({m: r.optimization.history for m, r in runs.items()},
                                         f"Wen 2019 ER10L-C10 {label}", "best Σ k|δ|² + |δp|² (mm², k = 1e4 mm²/rad²)",
                                         figures.iteration_label(runs)), out / f"convergence_{key}.png")
    figures.save_png(figures.position_errors(before_dp, after, f"ER10L-C10 {label}"),
                     out / f"position_errors_{key}.png")
    figures.save_png(figures.orientation_errors(before_dr, pose_errors(runs["ipso"].robot, meas)[1], f"IPSO {key}"),
                     out / f"orientation_errors_{key}.png")


def wen2019(out: Path, *, quick: bool = False, seed: int = 0, say: Say = quiet) -> dict:
    """Paper 000: ER10L-C10, Table 2 deviations, 32 joint sets in [−π, π], full pose, IPSO.

    Case (a) adds U(−0.1, 0.1) rad to the actual joints as the paper writes; case (b) uses
    a tracker-like noise (0.02 mm, 0.001°) and exact joints.  Beside IPSO: PSO, LM and
    hybrid on the same data; every method validated on 200 fresh poses measured the same way.
    """
    robot = load_robot("er10l-c10")
    results: dict = {"scenario": "wen2019", "quick": quick, "seed": seed, "machine": machine(), "cases": {}}
    warm = time.perf_counter()  # one-off kernel compilation or loading, measured apart from the timed runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for method in ("ipso", "pso"):
            sim = simulate(robot, POSES, deviations="paper", seed=seed)
            calibrate(robot, sim.measurements, method, params=PARAMETERS, iterations=2, particles=10)
    results["warm_up_s"] = time.perf_counter() - warm
    for key, case in CASES.items():
        opts = {k: v for k, v in case.items() if k != "label"}
        sim = simulate(robot, POSES, deviations="paper", seed=seed, **opts)
        val = simulate(sim.truth, 200, seed=seed + 1000, **opts).measurements
        runs: dict[str, CalibrationResult] = {}
        for method, kw in _methods(quick).items():
            say(f"wen2019 {case['label']}: {method}")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                # the paper's least squares, without a prior (its planted errors are its own)
                runs[method] = calibrate(robot, sim.measurements, method, params=PARAMETERS, validate=val, seed=seed,
                                         prior="all=free", **kw)
        results["cases"][key] = {"label": case["label"], "methods": {
            m: {**entry(r), "recovery": recovery(r, TABLE2_DEVIATIONS)} for m, r in runs.items()}}
        _figures(out, key, case["label"], robot, sim.measurements, runs)
    write_json(out / "results.json", results)
    atomic_write(out / "summary.md", summary(results))
    return results


def _metric_row(name: str, e: dict) -> str:
    m = e["metrics"]
    b, a = m["before"]["position"], m["after"]["position"]
    cells = [name, fmt(b["mean"]), fmt(a["mean"]), fmt(a["std"]), fmt(a["max"])]
    cells += [fmt(m["after"]["orientation"][ax]["mean"]) for ax in "xyz"]
    cells += [fmt(m["validation_before"]["position"]["rms"]), fmt(m["validation_after"]["position"]["rms"]),
              fmt(e["recovery"]["length_mm"]), fmt(e["recovery"]["angle_rad"]), fmt(e["optimizer_time_s"], 3),
              str(e["evaluations"])]
    return "| " + " | ".join(cells) + " |"


def _published_rows(b: dict) -> list[str]:
    P = PUBLISHED
    ipso_t = b["ipso"]["optimizer_time_s"]
    gens = len(b["ipso"]["history"]) - 1
    full = gens >= IPSO["iterations"]
    ob, oa = P["real_orientation_before"]["z"][0], P["real_orientation_after"]["z"][0]
    rb, ra = P["real_before"], P["real_after"]
    return [
        f"| time of {IPSO['iterations']} IPSO generations | {P['time_s']:g} s (MATLAB, i5-4570) | {fmt(ipso_t, 3)} s "
        f"for {gens} generations | {'beats it' if ipso_t < P['time_s'] and full else 'shortened run: not comparable'} "
        f"({fmt(P['time_s'] / max(ipso_t, 1e-9), 3)}× faster{'' if full else ', fewer generations'}) |",
        "| simulated accuracy after IPSO (Fig. 3–5) | figures only, no numbers | "
        f"mean {fmt(b['ipso']['metrics']['after']['position']['mean'])} mm (case b) | reproduces the claim "
        "(error far below before); the paper's numbers cannot be compared, none were printed |",
        f"| real robot position mean/std/max before → after (Table 3) | {rb['mean']}/{rb['std']}/{rb['max']} → "
        f"{ra['mean']}/{ra['std']}/{ra['max']} mm | — | cannot reproduce: needs the real robot and tracker data |",
        f"| real robot orientation Z mean before → after | {ob}° → {oa}° | — | cannot reproduce (real robot) |",
    ]


def summary(r: dict) -> str:
    """summary.md: what the paper published beside what robocal measured."""
    b, a = r["cases"]["b"]["methods"], r["cases"]["a"]["methods"]
    gens = len(b["ipso"]["history"]) - 1
    lines = [
        "# Wen et al. (2019): IPSO calibration of the ER10L-C10 — reproduction", "",
        f"Measured by robocal on {r['machine']}{' (quick run: shortened settings)' if r['quick'] else ''}.",
        f"Setup as in the paper: Hayati model of Table 1, true errors of Table 2, {POSES} joint sets uniform in",
        "[−π, π], full pose measured, objective eq. 7 (the paper does not give k: the swarms use k = 1e4",
        "mm²/rad², LM and hybrid whiten by the noise they estimate per residual block), the",
        f"paper's 24 parameters, IPSO with {IPSO['particles']} particles, c1 = c2 = {IPSO['c1']}, constriction "
        f"K = 0.7298, {gens} generations, start in ±0.5 mm / ±0.01 rad by (scrambled) Halton points. Validation:",
        "200 fresh poses of the same true robot, measured the same way. Times are the optimizers' own, after a",
        f"warm-up that compiled or loaded the kernels ({fmt(r['warm_up_s'], 3)} s, not counted).", "",
        "## Published against measured", "",
        "| published figure | paper | robocal | verdict |", "|---|---|---|---|",
        *_published_rows(b), "",
    ]
    for key in ("a", "b"):
        case = r["cases"][key]
        lines += [f"## {case['label']}", "",
                  "| method | before mean (mm) | after mean | after std | after max | orient. X after mean (deg) "
                  "| orient. Y | orient. Z | validation before rms | validation after rms | max param. error (mm) "
                  "| max param. error (rad) | optimizer time (s) | evaluations |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        lines += [_metric_row(m, e) for m, e in case["methods"].items()] + [""]
    va = {m: e["metrics"]["validation_after"]["position"]["rms"] for m, e in a.items()}
    vb = a["lm"]["metrics"]["validation_before"]["position"]["rms"]
    lines += [
        "## What the paper's joint noise does", "",
        "Case (a) follows the paper's text: the robot's actual joints differ from the commanded ones by",
        f"U(−{JOINT_NOISE_UNIFORM}, {JOINT_NOISE_UNIFORM}) rad, a fresh random error at every pose, i.e. up to "
        f"{math.degrees(JOINT_NOISE_UNIFORM):.1f}° per joint and tens of",
        "millimetres at the flange. No geometric parameter can explain an error that changes randomly from",
        "pose to pose, so every method fits noise: on fresh poses measured the same way the error stays",
        f"at validation RMS {fmt(min(va.values()))}–{fmt(max(va.values()))} mm against {fmt(vb)} mm before, and the",
        f"identified parameters are off by up to {fmt(max(e['recovery']['length_mm'] for e in a.values()))} mm and",
        f"{fmt(max(e['recovery']['angle_rad'] for e in a.values()))} rad. With realistic noise (case b) the same",
        f"methods recover Table 2 to {fmt(b['lm']['recovery']['length_mm'])} mm / "
        f"{fmt(b['lm']['recovery']['angle_rad'])} rad (LM) and validate at "
        f"{fmt(b['lm']['metrics']['validation_after']['position']['rms'])} mm RMS.", "",
        "Figures: `convergence_a.png`, `convergence_b.png` (best objective per iteration, all methods),",
        "`position_errors_a.png`, `position_errors_b.png` (Fig. 3: |δp| per pose before and after),",
        "`orientation_errors_a.png`, `orientation_errors_b.png` (Fig. 4–5: orientation error about X, Y, Z).", "",
    ]
    return "\n".join(lines)
