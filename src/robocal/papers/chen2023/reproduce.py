"""``robocal reproduce chen2023``: the 2TPR&2TPS study of Chen et al. beside robocal's methods."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ...io.atomic import atomic_write
from ...pkm.compensation import compare_methods, improvement, planted
from ...pkm.geometry import PARAM_NAMES, chen2023
from ...pkm.identify import identify_simulated
from ...pkm.kinematics import workspace_targets
from ...pkm.sensitivity import sensitivity
from ...presets.chen2023 import PUBLISHED
from ...report import figures
from ..common import Say, fmt, quiet

PAPER_METHOD = "paper (eq. 18, PSO)"
NOISES = (0.0, 0.01)


def _case_figures(out: Path, key: str, noise: float, runs) -> None:
    figures.save_png(figures.per_pose_errors({r.method: r.error for r in runs},
                                             f"2TPR&2TPS: 30 targets, tracker noise {noise} mm"),
                     out / f"compensation_{key}.png")
    figures.save_png(figures.convergence({"mean over the 30 targets": runs[1].history.mean(axis=1)},
                                         "eq. 18 PSO: best fitness per iteration", "fitness (mm)", "iteration"),
                     out / f"pso_convergence_{key}.png")


def _sensitivity_figures(out: Path, table: dict, sens) -> None:
    for group, fname in (("limb 1", "sensitivity_limb1.png"), ("rod zero lengths", "sensitivity_rods.png"),
                         ("all four limbs", "sensitivity_all_limbs.png")):
        figures.save_png(figures.sensitivity_bars(table[group], f"1 mm error: {group} (mean over 30 poses)"),
                         out / fname)
    figures.save_png(figures.per_pose_errors({k: v[:, :3] for k, v in sens.cases["limb 1"].items()},
                                             "1 mm error on one parameter of limb 1: position error per pose"),
                     out / "sensitivity_limb1_per_pose.png")


def chen2023_study(out: Path, *, quick: bool = False, seed: int = 0, say: Say = quiet) -> dict:
    """Sensitivity study, the paper's compensation, its iteration, and model-based compensation
    on a simulated machine with planted errors; targets with orientation 0 as in the paper."""
    nominal = chen2023()
    errors = planted(seed + 2023)
    real = nominal.with_errors(errors)
    say("chen2023: sensitivity")
    sens = sensitivity(nominal, workspace_targets(nominal, 30, seed + 1, angle=0.2))
    table = sens.mean_table()
    targets = workspace_targets(nominal, 30, seed + 2)  # orientation 0, as the paper's 30 poses
    fresh = workspace_targets(nominal, 10 if quick else 200, seed + 3)
    calib_q = workspace_targets(nominal, 40, seed + 4, angle=0.2)
    pso = {"iterations": 20} if quick else None
    results: dict = {"scenario": "chen2023", "quick": quick, "seed": seed,
                     "planted_errors_mm": dict(zip(PARAM_NAMES, map(float, errors))),
                     "sensitivity_mean_abs_error": table, "cases": {}}
    for noise in NOISES:
        say(f"chen2023: compensation, tracker noise {noise} mm")
        cal = identify_simulated(nominal, real, calib_q, noise=noise, seed=seed)
        case = {"identification": cal.to_dict()}
        for label, q in (("targets", targets), ("fresh", fresh)):
            runs = compare_methods(nominal, real, q, cal.geometry, noise=noise, seed=seed, pso=pso)
            case[label] = {r.method: {"mean_mm": r.mean_error, "max_mm": r.max_error,
                                      "improvement_pct": improvement(runs[0], r), "time_s": r.time_s}
                           for r in runs}
            if label == "targets":
                _case_figures(out, "noisefree" if noise == 0 else "noisy", noise, runs)
        results["cases"]["noise_free" if noise == 0 else "noise_0.01mm"] = case
    _sensitivity_figures(out, table, sens)
    atomic_write(out / "results.json", json.dumps(results, indent=1, default=float) + "\n")
    atomic_write(out / "summary.md", summary(results, quick))
    return results


def summary(r: dict, quick: bool) -> str:
    """summary.md: what the paper published beside what robocal measured."""
    nf, noisy = r["cases"]["noise_free"], r["cases"]["noise_0.01mm"]
    pct_nf = nf["targets"][PAPER_METHOD]["improvement_pct"]
    pct_noisy = noisy["targets"][PAPER_METHOD]["improvement_pct"]
    s = r["sensitivity_mean_abs_error"]
    lines = [
        "# Chen et al. (2023): 2TPR&2TPS parallel mechanism — reproduction", "",
        f"Measured by robocal{' (quick run: shortened settings)' if quick else ''}. Geometry of Table 2",
        "(d = 294.2 mm; Table 1's 292.4 read as a transposition). Planted errors, which the paper",
        "does not give: uniform ±0.5 mm on the 24 joint-point coordinates and ±0.5 mm on the 4 rod zero",
        "lengths (seeded; listed in `results.json`). Targets: 30 poses with orientation 0 (y in ±60 mm,",
        "z in 330–430 mm), as the paper's; fresh targets drawn the same way for validation. The tracker",
        "reads the platform origin's position only. Model-based calibration uses 40 other poses with",
        "α, β in ±0.2 rad.", "",
        "## Published against measured", "",
        "| figure | paper | robocal, paper's method | verdict |", "|---|---|---|---|",
        f"| mean position accuracy improvement, simulation | {PUBLISHED['simulation_pct']} % | {fmt(pct_nf)} % "
        f"(noise-free), {fmt(pct_noisy)} % (tracker noise 0.01 mm) | "
        f"{'reproduces it' if pct_nf >= 95 else 'does not reproduce it'}: one rod-space correction removes the "
        "first-order error; what is left is second order in the planted errors (and the tracker noise) |",
        f"| same, real machine | {PUBLISHED['real_pct']} % | — | cannot reproduce: needs the machine and its tracker "
        "data |", "",
        "## Compensation methods on the same simulated machine", "",
        "| method | 30 targets: mean error (mm) | improvement | fresh targets: mean (mm) | improvement |",
        "|---|---|---|---|---|",
    ]
    for label, case in (("noise-free", nf), ("tracker noise 0.01 mm", noisy)):
        for m, v in case["targets"].items():
            fv = case["fresh"][m]
            lines.append(f"| {m} ({label}) | {fmt(v['mean_mm'])} | {fmt(v['improvement_pct'])} % | "
                         f"{fmt(fv['mean_mm'])} | {fmt(fv['improvement_pct'])} % |")
    ident = nf["identification"]
    dropped = ", ".join(d["name"] for d in ident["dropped"]) or "none"
    lines += [
        "", "- The paper's PSO finds ΔL = L* − L, the exact minimiser of eq. 18, to its accuracy; it needs no",
        "  search. Repeating the correction (closed form) converges to the target on the real machine.",
        "- Model-based: identified from 40 measured positions; not identifiable from positions of the",
        f"  platform origin: {dropped}. Fit RMS {fmt(ident['rms_before_mm'])} → {fmt(ident['rms_after_mm'])} mm "
        "(noise-free). It compensates any target through the identified inverse kinematics, with no measurement "
        "at the target.", "",
        "## Sensitivity (Fig. 4–9): mean |E| over 30 poses for 1 mm of error", "",
        "| case | parameter | dx (mm) | dy | dz | dα (deg) | dβ | dγ |", "|---|---|---|---|---|---|---|---|",
    ]
    for group, table in s.items():
        for name, v in table.items():
            lines.append(f"| {group} | {name} | " + " | ".join(fmt(x, 3) for x in v[:3]) + " | "
                         + " | ".join(fmt(math.degrees(x), 3) for x in v[3:]) + " |")
    l1 = s["limb 1"]
    lines += [
        "", f"Limb 1: {max(l1, key=lambda k: sum(l1[k][:3]))} has the largest effect and "
        f"{min(l1, key=lambda k: sum(l1[k][:3]))} the smallest (paper: dL1 largest, dB1x smallest); y > x > z for "
        "limb 1 as in the paper; limb 3 and 4 rod errors give about "
        f"{fmt(np.mean(s['rod zero lengths']['dL3'][:3]), 2)} mm per axis (paper: about 0.6 mm). A common shift of "
        "the fixed points moves the platform by the same amount; γ stays 0 because the TPR constraints hold.", "",
        "Figures: `sensitivity_limb1.png`, `sensitivity_rods.png`, `sensitivity_all_limbs.png`,",
        "`sensitivity_limb1_per_pose.png`, `compensation_noisefree.png`, `compensation_noisy.png`,",
        "`pso_convergence_noisefree.png`, `pso_convergence_noisy.png`.", "",
    ]
    return "\n".join(lines)
