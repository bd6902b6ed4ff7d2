"""Re-runs of the papers' experiments: what they published beside what robocal measures.

``wen2019`` — Wen et al. (2019), IPSO on the ER10L-C10 (Hayati model, full pose).
``kou2022`` — Kou, Guo, Ren (2022), PSO against LDPSO-BT on the KUKA KR5 arc (DH,
position only).  Each writes ``summary.md``, ``results.json`` and PNG figures to a folder.
"""

from __future__ import annotations

import json
import math
import platform
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from . import figures
from .calibration import WEN2019_PARAMS, CalibrationResult, calibrate
from .errors import InputError, atomic_write
from .metrics import Metrics, pose_errors
from .parameters import is_angle
from .robotfile import load_robot
from .simulate import WEN2019_ERRORS, planted_errors, simulate

Say = Callable[[str], None]
SCENARIOS = ("wen2019", "kou2022", "chen2023")

WEN_PUBLISHED = {
    "time_s": 220.0,
    "real_before": {"mean": 9.6794, "std": 5.2230, "max": 12.0781},
    "real_after": {"mean": 1.7785, "std": 0.4820, "max": 4.6433},
    "real_orientation_before": {"x": (0.5543, 0.0932, 0.7376), "y": (0.2381, 0.0960, 0.3904),
                                "z": (1.5737, 0.0579, 1.6989)},
    "real_orientation_after": {"x": (0.3885, 0.0974, 0.5810), "y": (0.2148, 0.0951, 0.4103),
                               "z": (0.0578, 0.0471, 0.1785)},
}  # fmt: skip
KOU_PUBLISHED = {
    "before": (47.1, 51.8, 52.8),
    "pso": (0.14, 0.13, 0.10),
    "ldpso-bt": (0.18, 0.18, 0.15),
    "time_reduction_pct": 41.85,
}


def _quiet(_: str) -> None:
    pass


def _f(x: float, digits: int = 4) -> str:
    if x is None or not math.isfinite(x):
        return "—"
    return f"{x:.{digits}g}" if abs(x) < 1e-3 or abs(x) >= 1e4 else f"{x:.{digits}f}"


def _recovery(res: CalibrationResult, truth: dict[str, float]) -> dict[str, float]:
    """Largest |identified − planted| over identified lengths (mm) and angles (rad)."""
    lengths = [abs(res.parameter(n) - truth.get(n, 0.0)) for n in res.names if not is_angle(n)]
    angles = [abs(res.parameter(n) - truth.get(n, 0.0)) for n in res.names if is_angle(n)]
    return {"length_mm": max(lengths, default=0.0), "angle_rad": max(angles, default=0.0)}


def _entry(res: CalibrationResult) -> dict:
    d = res.to_dict()
    return {
        "metrics": d["metrics"],
        "optimiser_time_s": res.optimisation.time_s,
        "total_time_s": res.time_s,
        "iterations": d["iterations"],
        "evaluations": d["evaluations"],
        "objective_value": d["objective_value"],
        "status": d["status"],
        "dropped": d["dropped"],
        "parameters": d["parameters"],
        "history": d["history"],
    }


def _write_json(path: Path, data: dict) -> None:
    atomic_write(path, json.dumps(data, indent=1, allow_nan=False, default=float) + "\n")


def _machine() -> str:
    return f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}"


# --------------------------------------------------------------------------------------------
# Wen et al. 2019
# --------------------------------------------------------------------------------------------


def wen2019(out: Path, *, quick: bool = False, seed: int = 0, say: Say = _quiet) -> dict:
    """Paper 000: ER10L-C10, Table 2 errors, 32 joint sets in [−π, π], full pose, IPSO.

    Case (a) adds U(−0.1, 0.1) rad to the actual joints as the paper writes; case (b)
    uses a tracker-like noise (0.02 mm, 0.001°) and exact joints.  Beside IPSO: PSO,
    LM and hybrid on the same data; every method validated on 200 fresh poses
    measured the same way.
    """
    robot = load_robot("er10l-c10")
    cases = {
        "a": {"label": "(a) joint noise U(±0.1 rad) as the paper writes", "joint_noise_uniform": 0.1},
        "b": {"label": "(b) tracker noise 0.02 mm, 0.001°, exact joints", "noise": 0.02,
              "angle_noise": math.radians(0.001)},
    }  # fmt: skip
    gens = 60 if quick else 2000
    methods = {
        "ipso": {"iterations": gens},
        "pso": {"objective": "sum_squares", **({"particles": 40, "iterations": 40} if quick else {})},
        "lm": {},
        "hybrid": {"iterations": 30} if quick else {},
    }
    results: dict = {"scenario": "wen2019", "quick": quick, "seed": seed, "machine": _machine(), "cases": {}}
    for key, case in cases.items():
        opts = {k: v for k, v in case.items() if k != "label"}
        sim = simulate(robot, 32, errors="paper", seed=seed, **opts)
        val = simulate(sim.truth, 200, errors="none", seed=seed + 1000, **opts).measurements
        runs: dict[str, CalibrationResult] = {}
        for method, kw in methods.items():
            say(f"wen2019 {case['label']}: {method}")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runs[method] = calibrate(
                    robot, sim.measurements, method, params=WEN2019_PARAMS, validate=val, seed=seed, **kw
                )
        entry = {"label": case["label"], "methods": {}}
        for method, res in runs.items():
            e = _entry(res)
            e["recovery"] = _recovery(res, WEN2019_ERRORS)
            entry["methods"][method] = e
        results["cases"][key] = entry
        before_dp, before_dr = pose_errors(robot, sim.measurements)
        after = {m: pose_errors(runs[m].robot, sim.measurements)[0] for m in ("ipso", "lm")}
        figures.save_png(
            figures.convergence(
                {m: r.optimisation.history for m, r in runs.items()},
                f"Wen 2019 ER10L-C10 {case['label']}",
                "best Σ k|δ|² + |δp|² (mm²)",
            ),
            out / f"convergence_{key}.png",
        )
        figures.save_png(
            figures.position_errors(before_dp, after, f"ER10L-C10 {case['label']}"), out / f"position_errors_{key}.png"
        )
        figures.save_png(
            figures.orientation_errors(before_dr, pose_errors(runs["ipso"].robot, sim.measurements)[1], f"IPSO {key}"),
            out / f"orientation_errors_{key}.png",
        )
    _write_json(out / "results.json", results)
    atomic_write(out / "summary.md", _wen_summary(results))
    return results


def _metric_row(name: str, m: dict, e: dict, orientation: bool) -> str:
    b, a = m["before"]["position"], m["after"]["position"]
    vb, va = m["validation_before"]["position"], m["validation_after"]["position"]
    cells = [name, _f(b["mean"]), _f(a["mean"]), _f(a["std"]), _f(a["max"])]
    if orientation:
        cells += [_f(m["after"]["orientation"][ax]["mean"]) for ax in "xyz"]
    cells += [
        _f(vb["rms"]),
        _f(va["rms"]),
        _f(e["recovery"]["length_mm"]),
        _f(e["recovery"]["angle_rad"]),
        _f(e["optimiser_time_s"], 3),
        str(e["evaluations"]),
    ]
    return "| " + " | ".join(cells) + " |"


def _wen_summary(r: dict) -> str:
    b = r["cases"]["b"]["methods"]
    a = r["cases"]["a"]["methods"]
    ipso_t = b["ipso"]["optimiser_time_s"]
    gens = len(b["ipso"]["history"]) - 1
    lines = [
        "# Wen et al. (2019): IPSO calibration of the ER10L-C10 — reproduction",
        "",
        f"Measured by robocal on {r['machine']}{' (quick run: shortened settings)' if r['quick'] else ''}.",
        "Setup as in the paper: Hayati model of Table 1, true errors of Table 2, 32 joint sets uniform in",
        "[−π, π], full pose measured, objective eq. 7 (k = 1e4 mm²/rad²: the paper does not give k), the",
        "paper's 24 parameters, IPSO with 20 particles, c1 = c2 = 2.05, constriction K = 0.7298,",
        f"{gens} generations, start in ±0.5 mm / ±0.01 rad by (scrambled) Halton points. Validation:",
        "200 fresh poses of the same true robot, measured the same way.",
        "",
        "## Published against measured",
        "",
        "| published figure | paper | robocal | verdict |",
        "|---|---|---|---|",
        f"| time of 2000 IPSO generations | 220 s (MATLAB, i5-4570) | {_f(ipso_t, 3)} s for {gens} generations "
        f"| {'beats it' if ipso_t < 220 and gens >= 2000 else 'shortened run: not comparable'} "
        f"({_f(220 / max(ipso_t, 1e-9), 3)}× faster{'' if gens >= 2000 else ', fewer generations'}) |",
        "| simulated accuracy after IPSO (Fig. 3–5) | figures only, no numbers | "
        f"mean {_f(b['ipso']['metrics']['after']['position']['mean'])} mm (case b) | reproduces the claim "
        "(error far below before); the paper's numbers cannot be compared, none were printed |",
        "| real robot position mean/std/max before → after (Table 3) | 9.6794/5.2230/12.0781 → "
        "1.7785/0.4820/4.6433 mm | — | cannot reproduce: needs the real robot and tracker data |",
        "| real robot orientation Z mean before → after | 1.5737° → 0.0578° | — | cannot reproduce (real robot) |",
        "",
    ]
    for key in ("a", "b"):
        case = r["cases"][key]
        lines += [
            f"## {case['label']}",
            "",
            "| method | before mean (mm) | after mean | after std | after max | orient. X after mean (deg) "
            "| orient. Y | orient. Z | validation before rms | validation after rms | max param. error (mm) "
            "| max param. error (rad) "
            "| optimiser time (s) | evaluations |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        lines += [_metric_row(m, e["metrics"], e, True) for m, e in case["methods"].items()]
        lines.append("")
    va = {m: e["metrics"]["validation_after"]["position"]["rms"] for m, e in a.items()}
    vb = a["lm"]["metrics"]["validation_before"]["position"]["rms"]
    lines += [
        "## What the paper's joint noise does",
        "",
        "Case (a) follows the paper's text: the robot's actual joints differ from the commanded ones by",
        "U(−0.1, 0.1) rad, a fresh random error at every pose, i.e. up to 5.7° per joint and tens of",
        "millimetres at the flange. No geometric parameter can explain an error that changes randomly from",
        "pose to pose, so every method fits noise: on fresh poses measured the same way the error stays",
        f"at validation RMS {_f(min(va.values()))}–{_f(max(va.values()))} mm against {_f(vb)} mm before, and the",
        f"identified parameters are off by up to {_f(max(e['recovery']['length_mm'] for e in a.values()))} mm and",
        f"{_f(max(e['recovery']['angle_rad'] for e in a.values()))} rad. With realistic noise (case b) the same",
        f"methods recover Table 2 to {_f(b['lm']['recovery']['length_mm'])} mm / "
        f"{_f(b['lm']['recovery']['angle_rad'])} rad (LM) and validate at "
        f"{_f(b['lm']['metrics']['validation_after']['position']['rms'])} mm RMS.",
        "",
        "Figures: `convergence_a.png`, `convergence_b.png` (best objective per iteration, all methods),",
        "`position_errors_a.png`, `position_errors_b.png` (Fig. 3: |δp| per pose before and after),",
        "`orientation_errors_a.png`, `orientation_errors_b.png` (Fig. 4–5: orientation error about X, Y, Z).",
        "",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# Kou, Guo, Ren 2022
# --------------------------------------------------------------------------------------------


def kou2022(out: Path, *, quick: bool = False, runs: int = 10, seed: int = 0, say: Say = _quiet) -> dict:
    """Paper 001: KR5 arc (DH), errors uniform ±0.25 mm / ±0.05 rad, 30 joint sets inside the
    limits, position only, objective Σ|δp|; ``runs`` runs each of PSO (240 × 500, w 0.8,
    c 1.49) and LDPSO-BT (240 → 40 × 500); LM and hybrid beside; validation on 200 fresh poses."""
    robot = load_robot("kr5-arc")
    errors = planted_errors(robot, "uniform:0.25,0.05", np.random.default_rng(seed + 2022))
    sim = simulate(robot, 30, errors=errors, seed=seed, measure="position")
    val = simulate(sim.truth, 200, errors="none", seed=seed + 1000, measure="position").measurements
    swarm_kw = {"particles": 60, "iterations": 60} if quick else {}
    swarm_runs: dict[str, list[CalibrationResult]] = {"pso": [], "ldpso-bt": []}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in range(runs):
            for method in swarm_runs:  # interleaved, so drifting machine load hits both alike
                say(f"kou2022 run {i + 1}/{runs}: {method}")
                swarm_runs[method].append(
                    calibrate(
                        robot, sim.measurements, method, params="kou2022", validate=val, seed=seed + i, **swarm_kw
                    )
                )
        say("kou2022: lm and hybrid")
        lm = calibrate(robot, sim.measurements, "lm", params="kou2022", validate=val)
        hybrid = calibrate(
            robot,
            sim.measurements,
            "hybrid",
            params="kou2022",
            validate=val,
            seed=seed,
            **({"iterations": 30} if quick else {}),
        )
    stats = {}
    for method, rs in swarm_runs.items():
        fit = np.array([r.optimisation.fun for r in rs])
        times = np.array([r.optimisation.time_s for r in rs])
        best = rs[int(np.argmin(fit))]
        stats[method] = {
            "fitness_mean": float(fit.mean()),
            "fitness_best": float(fit.min()),
            "fitness_all": fit.tolist(),
            "time_mean_s": float(times.mean()),
            "time_all_s": times.tolist(),
            "evaluations": rs[0].optimisation.nfev,
            "best_run": _entry(best),
            "axis_max_after_best": best.metrics["after"].axis_max,
            "axis_max_after_mean": {ax: float(np.mean([r.metrics["after"].axis_max[ax] for r in rs])) for ax in "xyz"},
            "validation_rms_mean": float(np.mean([r.metrics["validation_after"].position["rms"] for r in rs])),
        }
    reduction = 100.0 * (1.0 - stats["ldpso-bt"]["time_mean_s"] / stats["pso"]["time_mean_s"])
    before = lm.metrics["before"]
    results = {
        "scenario": "kou2022", "quick": quick, "seed": seed, "runs": runs, "machine": _machine(),
        "planted_errors": errors, "before": before.to_dict(),
        "validation_before": lm.metrics["validation_before"].to_dict(),
        "swarms": stats, "time_reduction_pct": reduction,
        "lm": _entry(lm), "hybrid": _entry(hybrid),
    }  # fmt: skip
    dp0, _ = pose_errors(robot, sim.measurements)
    figures.save_png(figures.axis_errors(dp0, "KR5 arc before calibration (Fig. 2)"), out / "errors_before.png")
    for method, label, name in (
        ("pso", "after PSO (Fig. 3)", "errors_after_pso.png"),
        ("ldpso-bt", "after LDPSO-BT (Fig. 4)", "errors_after_ldpso_bt.png"),
    ):
        rs = swarm_runs[method]
        best = rs[int(np.argmin([r.optimisation.fun for r in rs]))]
        figures.save_png(figures.axis_errors(pose_errors(best.robot, sim.measurements)[0], label), out / name)
    median = {m: sorted(rs, key=lambda r: r.optimisation.fun)[len(rs) // 2] for m, rs in swarm_runs.items()}
    figures.save_png(
        figures.convergence(
            {f"{m} (median run)": r.optimisation.history for m, r in median.items()},
            "Kou 2022 KR5 arc: best Σ|δp| per iteration",
            "best Σ|δp| (mm)",
        ),
        out / "convergence.png",
    )
    figures.save_png(
        figures.convergence(
            {"lm": lm.optimisation.history, "hybrid": hybrid.optimisation.history},
            "KR5 arc: LM and hybrid",
            "best Σ|δp|² (mm²)",
        ),
        out / "convergence_lm.png",
    )
    _write_json(out / "results.json", results)
    atomic_write(out / "summary.md", _kou_summary(results, Metrics.from_errors(dp0)))
    return results


def _verdict_axes(ours: dict, published: tuple[float, float, float]) -> str:
    worst = max(ours[ax] / p for ax, p in zip("xyz", published))
    if worst <= 1.0:
        return "beats it"
    if worst <= 3.0:
        return "reproduces it (same order)"
    return "does not reproduce it"


def _kou_summary(r: dict, before: Metrics) -> str:
    s = r["swarms"]
    axes = lambda d: "/".join(_f(d[a], 3) for a in "xyz")  # noqa: E731
    red = r["time_reduction_pct"]
    red_verdict = "reproduces it" if abs(red - 41.85) <= 10 else "beats it" if red > 41.85 else "does not reproduce it"
    ratio = s["ldpso-bt"]["fitness_mean"] / s["pso"]["fitness_mean"]
    fitness_verdict = (
        "reproduces it" if 0.5 <= ratio <= 2 else f"does not reproduce it: LDPSO-BT ends at {_f(ratio, 3)}× PSO's"
    )
    b = r["before"]["axis_max"]
    lines = [
        "# Kou, Guo, Ren (2022): PSO against LDPSO-BT on the KUKA KR5 arc — reproduction",
        "",
        f"Measured by robocal on {r['machine']}{' (quick run: shortened settings)' if r['quick'] else ''}.",
        "Setup: the paper's DH table and error table did not survive, so the KR5 arc is ARTE's standard-DH",
        "table and the 24 errors are drawn uniform in ±0.25 mm / ±0.05 rad (seeded; listed in",
        "`results.json`); 30 joint sets uniform inside the joint limits; position only, no noise; objective",
        f"eq. 4, Σ|δp|. {r['runs']} runs each (seeds {r['seed']}…{r['seed'] + r['runs'] - 1}), PSO and LDPSO-BT",
        "interleaved so that machine load affects both alike. Time is the optimiser's own wall time.",
        "",
        "## Published against measured",
        "",
        "| published figure | paper | robocal | verdict |",
        "|---|---|---|---|",
        f"| max error X/Y/Z before (mm) | 47.1/51.8/52.8 | {axes(b)} | reproduces the regime (tens of mm); "
        "exact values depend on the lost tables |",
        f"| after PSO, best run (mm) | 0.14/0.13/0.10 | {axes(s['pso']['axis_max_after_best'])} | "
        f"{_verdict_axes(s['pso']['axis_max_after_best'], KOU_PUBLISHED['pso'])} |",
        f"| after LDPSO-BT, best run (mm) | 0.18/0.18/0.15 | {axes(s['ldpso-bt']['axis_max_after_best'])} | "
        f"{_verdict_axes(s['ldpso-bt']['axis_max_after_best'], KOU_PUBLISHED['ldpso-bt'])} |",
        f"| LDPSO-BT time saving over PSO | 41.85 % | {_f(red, 4)} % | {red_verdict} (expected from particle "
        "counts alone: 1 − 140/240 = 41.7 %) |",
        f"| mean fitness LDPSO-BT vs PSO | “about the same” | ratio {_f(ratio, 3)} | {fitness_verdict} |",
        "",
        "## Swarms over the runs",
        "",
        "| method | mean fitness Σ‖δp‖ (mm) | best fitness | mean time (s) | evaluations per run "
        "| mean max X/Y/Z after (mm) | mean validation RMS (mm) |",
        "|---|---|---|---|---|---|---|",
    ]
    for m in ("pso", "ldpso-bt"):
        x = s[m]
        lines.append(
            f"| {m} | {_f(x['fitness_mean'])} | {_f(x['fitness_best'])} | {_f(x['time_mean_s'], 3)} | "
            f"{x['evaluations']} | {axes(x['axis_max_after_mean'])} | {_f(x['validation_rms_mean'])} |"
        )
    lines += [
        "",
        "## Beside the swarms",
        "",
        "| method | max X/Y/Z after (mm) | validation RMS before → after (mm) | time (s) | evaluations |",
        "|---|---|---|---|---|",
    ]
    for m in ("lm", "hybrid"):
        e = r[m]
        lines.append(
            f"| {m} | {axes(e['metrics']['after']['axis_max'])} | "
            f"{_f(e['metrics']['validation_before']['position']['rms'])} → "
            f"{_f(e['metrics']['validation_after']['position']['rms'])} | "
            f"{_f(e['optimiser_time_s'], 3)} | {e['evaluations']} |"
        )
    dropped = ", ".join(d["name"] for d in r["lm"]["dropped"]) or "none"
    lines += [
        "",
        f"Not identifiable from position-only data, so not reported by any method: {dropped}. Swarms search all",
        "24 parameters as the paper does, and their solution is then re-expressed in the identifiable ones.",
        "",
        "Figures: `errors_before.png` (Fig. 2), `errors_after_pso.png` (Fig. 3), `errors_after_ldpso_bt.png`",
        "(Fig. 4), `convergence.png` (median runs), `convergence_lm.png`.",
        "",
    ]
    return "\n".join(lines)


def reproduce(
    name: str, out: str | Path, *, quick: bool = False, runs: int = 10, seed: int = 0, say: Say = _quiet
) -> dict:
    """Run one scenario (or ``all``) into folder ``out`` (subfolders per scenario for ``all``)."""
    out = Path(out)
    names = SCENARIOS if name == "all" else (name,)
    for n in names:
        if n not in SCENARIOS:
            raise InputError(f"unknown scenario {n!r} (expected {' | '.join(SCENARIOS)} | all)", source="reproduce")
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", source=out)
    done = {}
    for n in names:
        folder = out / n if name == "all" else out
        folder.mkdir(parents=True, exist_ok=True)
        if n == "wen2019":
            done[n] = wen2019(folder, quick=quick, seed=seed, say=say)
        elif n == "kou2022":
            done[n] = kou2022(folder, quick=quick, runs=runs, seed=seed, say=say)
        else:
            from .pkm_reproduce import chen2023

            done[n] = chen2023(folder, quick=quick, seed=seed, say=say)
    return done
