"""``robocal reproduce chen2023``: the 2TPR&2TPS study of Chen et al. beside robocal's methods."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from . import figures
from .errors import atomic_write
from .pkm import PARAM_NAMES
from .pkm import chen2023 as chen_geometry
from .pkm_study import compare_methods, identify_simulated, improvement, planted, sensitivity, workspace_targets

PUBLISHED = {"simulation_pct": 98.148, "real_pct": 87.457}


def _f(x: float, d: int = 4) -> str:
    return "—" if x is None or not math.isfinite(x) else (f"{x:.{d}g}" if abs(x) < 1e-3 else f"{x:.{d}f}")


def chen2023(out: Path, *, quick: bool = False, seed: int = 0, say: Callable[[str], None] = lambda s: None) -> dict:
    """Sensitivity study, the paper's compensation, its iteration, and model-based compensation
    on a simulated machine with planted errors; targets with orientation 0 as in the paper."""
    nominal = chen_geometry()
    errors = planted(seed + 2023)
    real = nominal.with_errors(errors)
    say("chen2023: sensitivity")
    sens_q = workspace_targets(nominal, 30, seed + 1, angle=0.2)
    sens = sensitivity(nominal, sens_q)
    table = sens.mean_table()
    targets = workspace_targets(nominal, 30, seed + 2)  # orientation 0, as the paper's 30 poses
    fresh = workspace_targets(nominal, 10 if quick else 200, seed + 3)
    calib_q = workspace_targets(nominal, 40, seed + 4, angle=0.2)
    pso = {"iterations": 20} if quick else None
    results: dict = {
        "scenario": "chen2023",
        "quick": quick,
        "seed": seed,
        "planted_errors_mm": dict(zip(PARAM_NAMES, map(float, errors))),
        "sensitivity_mean_abs_error": table,
        "cases": {},
    }
    for noise in (0.0, 0.01):
        say(f"chen2023: compensation, tracker noise {noise} mm")
        cal = identify_simulated(nominal, real, calib_q, noise=noise, seed=seed)
        case = {"identification": cal.to_dict(), "targets": {}, "fresh": {}}
        for label, q in (("targets", targets), ("fresh", fresh)):
            runs = compare_methods(nominal, real, q, cal.geometry, noise=noise, seed=seed, pso=pso)
            base = runs[0]
            case[label] = {
                r.method: {
                    "mean_mm": r.mean_error,
                    "max_mm": float(np.linalg.norm(r.error, axis=1).max()),
                    "improvement_pct": improvement(base, r) if r is not base else 0.0,
                    "time_s": r.time_s,
                }
                for r in runs
            }
            if label == "targets":
                key = "noisefree" if noise == 0 else "noisy"
                figures.save_png(
                    figures.per_pose_errors(
                        {r.method: r.error for r in runs}, f"2TPR&2TPS: 30 targets, tracker noise {noise} mm"
                    ),
                    out / f"compensation_{key}.png",
                )
                paper_run = runs[1]
                figures.save_png(
                    figures.convergence(
                        {"mean over the 30 targets": paper_run.history.mean(axis=1)},
                        "eq. 18 PSO: best fitness per iteration",
                        "fitness (mm)",
                    ),
                    out / f"pso_convergence_{key}.png",
                )
        results["cases"]["noise_free" if noise == 0 else "noise_0.01mm"] = case
    for group, fname in (
        ("limb 1", "sensitivity_limb1.png"),
        ("rod zero lengths", "sensitivity_rods.png"),
        ("all four limbs", "sensitivity_all_limbs.png"),
    ):
        figures.save_png(
            figures.sensitivity_bars(table[group], f"1 mm error: {group} (mean over 30 poses)"), out / fname
        )
    figures.save_png(
        figures.per_pose_errors(
            {k: v[:, :3] for k, v in sens.cases["limb 1"].items()},
            "1 mm error on one parameter of limb 1: position error per pose",
        ),
        out / "sensitivity_limb1_per_pose.png",
    )
    atomic_write(out / "results.json", json.dumps(results, indent=1, default=float) + "\n")
    atomic_write(out / "summary.md", _summary(results, quick))
    return results


def _summary(r: dict, quick: bool) -> str:
    nf, noisy = r["cases"]["noise_free"], r["cases"]["noise_0.01mm"]
    paper = "paper (eq. 18, PSO)"
    pct_nf, pct_noisy = nf["targets"][paper]["improvement_pct"], noisy["targets"][paper]["improvement_pct"]
    s = r["sensitivity_mean_abs_error"]
    lines = [
        "# Chen et al. (2023): 2TPR&2TPS parallel mechanism — reproduction",
        "",
        f"Measured by robocal{' (quick run: shortened settings)' if quick else ''}. Geometry of Table 2",
        "(d = 294.2 mm; Table 1's 292.4 read as a transposition). Planted errors, which the paper",
        "does not give: uniform ±0.5 mm on the 24 joint-point coordinates and ±0.5 mm on the 4 rod zero",
        "lengths (seeded; listed in `results.json`). Targets: 30 poses with orientation 0 (y in ±60 mm,",
        "z in 330–430 mm), as the paper's; fresh targets drawn the same way for validation. The tracker",
        "reads the platform origin's position only. Model-based calibration uses 40 other poses with",
        "α, β in ±0.2 rad.",
        "",
        "## Published against measured",
        "",
        "| figure | paper | robocal, paper's method | verdict |",
        "|---|---|---|---|",
        f"| mean position accuracy improvement, simulation | 98.148 % | {_f(pct_nf)} % "
        f"(noise-free), {_f(pct_noisy)} % (tracker noise 0.01 mm) | "
        f"{'reproduces it' if pct_nf >= 95 else 'does not reproduce it'}: one "
        "rod-space correction removes the first-order error; what is left is second order in the planted errors "
        "(and the tracker noise) |",
        "| same, real machine | 87.457 % | — | cannot reproduce: needs the machine and its tracker data |",
        "",
        "## Compensation methods on the same simulated machine",
        "",
        "| method | 30 targets: mean error (mm) | improvement | fresh targets: mean (mm) | improvement |",
        "|---|---|---|---|---|",
    ]
    for label, case in (("noise-free", nf), ("tracker noise 0.01 mm", noisy)):
        for m, v in case["targets"].items():
            fv = case["fresh"][m]
            lines.append(
                f"| {m} ({label}) | {_f(v['mean_mm'])} | {_f(v['improvement_pct'])} % | "
                f"{_f(fv['mean_mm'])} | {_f(fv['improvement_pct'])} % |"
            )
    ident = nf["identification"]
    dropped = ", ".join(d["name"] for d in ident["dropped"]) or "none"
    lines += [
        "",
        "- The paper's PSO finds ΔL = L* − L, the exact minimiser of eq. 18, to its accuracy; it needs no",
        "  search. Repeating the correction (closed form) converges to the target on the real machine.",
        "- Model-based: identified from 40 measured positions; not identifiable from positions of the",
        f"  platform origin: {dropped}. Fit RMS {_f(ident['rms_before_mm'])} → {_f(ident['rms_after_mm'])} mm "
        "(noise-free). It compensates any target through the identified inverse kinematics, with no measurement "
        "at the target.",
        "",
        "## Sensitivity (Fig. 4–9): mean |E| over 30 poses for 1 mm of error",
        "",
        "| case | parameter | dx (mm) | dy | dz | dα (deg) | dβ | dγ |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for group, table in s.items():
        for name, v in table.items():
            lines.append(
                f"| {group} | {name} | "
                + " | ".join(_f(x, 3) for x in v[:3])
                + " | "
                + " | ".join(_f(math.degrees(x), 3) for x in v[3:])
                + " |"
            )
    l1 = s["limb 1"]
    biggest = max(l1, key=lambda k: sum(l1[k][:3]))
    smallest = min(l1, key=lambda k: sum(l1[k][:3]))
    lines += [
        "",
        f"Limb 1: {biggest} has the largest effect and {smallest} the smallest (paper: dL1 largest, dB1x "
        "smallest); y > x > z for limb 1 as in the paper; limb 3 and 4 rod errors give about "
        f"{_f(np.mean(s['rod zero lengths']['dL3'][:3]), 2)} mm per axis (paper: about 0.6 mm). A common shift of "
        "the fixed points moves the platform by the same amount; γ stays 0 because the TPR constraints hold.",
        "",
        "Figures: `sensitivity_limb1.png`, `sensitivity_rods.png`, `sensitivity_all_limbs.png`,",
        "`sensitivity_limb1_per_pose.png`, `compensation_noisefree.png`, `compensation_noisy.png`,",
        "`pso_convergence_noisefree.png`, `pso_convergence_noisy.png`.",
        "",
    ]
    return "\n".join(lines)
