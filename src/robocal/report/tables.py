"""Tables of a calibration as users read them: the units of the files (mm, degrees),
uncertainties beside every value, what is not significant, what a value stands for.

Rows are plain strings, shared by the terminal and the HTML report.
"""

from __future__ import annotations

import math

import numpy as np

from ..calibration.result import SIGNIFICANCE_SIGMAS, CalibrationResult, nominal_values
from ..math.se3 import transform_to_xyz_rpy
from ..math.so3 import orientation_error
from ..model.metrics import Metrics
from ..model.parameters import is_angle, is_frame
from ..model.terms import reported_unit

PARAMETER_COLUMNS = ("parameter", "unit", "nominal", "identified", "deviation", "± σ", "prior ± σ", "note")
#: what the table says of a parameter its prior holds (MODEL §3.1)
HELD_NOTE = "held by its prior: the poses do not pin it"
FRAME_COLUMNS = ("frame", "in", "identified xyz (mm)", "identified rpy (deg)", "σ xyz (mm); rpy (deg)",
                 "change from registration", "note")


def _number(value: float, angle: bool | None) -> str:
    """mm (angle False), degrees (True), or a compliance in rad/(N·m) (None)."""
    if angle is None:
        return f"{value:.4g}"
    text = f"{math.degrees(value):.5f}" if angle else f"{value:.4f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # no "-0.0000"


def _uncertainty(u: float | None, angle: bool | None) -> str:
    if u is None or not math.isfinite(u):
        return "—"
    return f"{math.degrees(u) if angle else u:.2g}"


def _kind(name: str, terms=None) -> tuple[bool | None, str]:
    """How a parameter is shown: (angle flag for :func:`_number`, unit)."""
    shown = reported_unit(name, terms)
    if shown is not None and shown[0] != "rad":
        # a joint term's own unit: degrees of an angle (per its clock), else as identified
        return (True if shown[0].startswith("deg") else None), shown[0]
    return (True, "deg") if is_angle(name) else (False, "mm")


def shown_sigma(name: str, sigma: float, terms=None) -> str:
    """A parameter's σ as every table shows it: "± 0.000519 deg", "± 0.012 mm" (3 significant digits)."""
    angle, unit = _kind(name, terms)
    return f"± {math.degrees(sigma) if angle else sigma:.3g} {unit}"


def _absorbs(result: CalibrationResult, name: str) -> str:
    terms = result.identifiability.absorbed_by(name)
    if not terms:
        return ""
    parts = " ".join(f"{'+' if c >= 0 else '−'} {abs(c):.3g}·{d}" for d, c in terms)
    return f"estimates {name} {parts} (regrouped)"


def parameter_rows(result: CalibrationResult) -> list[tuple[str, ...]]:
    """One row per identified joint parameter (joint terms included): nominal, identified value,
    deviation and its standard uncertainty (mm, degrees for angles, rad/(N·m) for
    compliances), and a note."""
    nominal = nominal_values(result.initial)
    rows = []
    for i, name in enumerate(result.names):
        if is_frame(name):
            continue
        angle, unit = _kind(name, result.robot.terms)
        x = float(result.x[i])
        u = None if result.uncertainty is None else float(result.uncertainty[i])
        notes = [n for n in (_absorbs(result, name),) if n]
        held = name in result.held
        if held:
            notes.append(HELD_NOTE)
        elif result.significant(i) is False:
            notes.append(f"not significant (< {SIGNIFICANCE_SIGMAS:g} σ)")
        prior = "—" if result.prior_sigma is None else _uncertainty(float(result.prior_sigma[i]), angle) \
            if math.isfinite(result.prior_sigma[i]) else "free"
        rows.append((name, unit, _number(nominal.get(name, 0.0), angle),
                     _number(nominal.get(name, 0.0) + x, angle), _number(x, angle), _uncertainty(u, angle),
                     prior, "; ".join(notes)))
    return rows


def _frame_change(before: np.ndarray, after: np.ndarray, rotation: bool) -> str:
    moved = float(np.linalg.norm(after[:3, 3] - before[:3, 3]))
    if not rotation:
        return f"{moved:.4f} mm"
    turned = math.degrees(float(np.linalg.norm(orientation_error(after[:3, :3], before[:3, :3]))))
    return f"{moved:.4f} mm, {turned:.5f}°"


def frame_rows(result: CalibrationResult) -> list[tuple[str, ...]]:
    """Base and tool frames as identified, and their change from the closed-form registration."""
    frames = {"base": (result.initial.base, result.robot.base)}
    if result.robot.tree is None:  # a tree's chains carry their own tools, its targets
        frames["tool"] = (result.initial.tool, result.robot.tool)
    for name, T in result.robot.targets.items():
        frames[f"tool[{name}]"] = (result.initial.targets.get(name, T), T)
    cameras = {}
    for name, mount in result.robot.cameras.items():
        before = result.initial.cameras.get(name, mount).pose
        frames[f"camera[{name}]"] = (before, mount.pose)
        where = "in the measuring frame" if mount.link == 0 else f"on link {mount.link}"
        cameras[f"camera[{name}]"] = "given" if mount.known else where
    estimated = set(n.rsplit("_", 1)[0] for n in result.names if is_frame(n))
    inside = {"base": "measuring frame", "tool": "flange"}
    for name, mount in result.robot.cameras.items():
        inside[f"camera[{name}]"] = f"camera {mount.of}" if mount.of else \
            "measuring frame" if mount.link == 0 else f"link {mount.link}"
    rows = []
    for frame, (before, after) in frames.items():
        xyz, rpy = transform_to_xyz_rpy(after)
        rotation_identified = any(f"{frame}_r{a}" in result.names for a in "xyz")
        if frame in cameras and frame not in estimated:
            gauge = cameras[frame] == "in the measuring frame"
            note = "the measuring frame (not estimated)" if gauge else "as given (not estimated)"
            change = "—"
        elif frame not in estimated:
            note = "as given (not estimated)" if result.frames == "none" or frame != "base" else ""
            change = "—"
        else:
            change = _frame_change(before, after, rotation_identified)
            note = "" if rotation_identified or frame == "base" else "rotation not identified (position data)"
            if frame in cameras:
                note = f"camera {cameras[frame]}"
        rpy_text = ", ".join(_number(v, True) for v in rpy)
        if frame in estimated and not rotation_identified and frame != "base":
            rpy_text = "not identified"
        where = inside.get(frame, "flange" if frame.startswith("tool[") else "")
        rows.append((frame, where, ", ".join(_number(v, False) for v in xyz), rpy_text, _frame_sigma(result, frame),
                     change, note))
    return rows


def _frame_sigma(result: CalibrationResult, frame: str) -> str:
    """A frame's standard uncertainties as estimated: x, y, z (mm); rx, ry, rz (deg), "—" where not."""
    if result.covariance is None:
        return "—"
    index = {n: i for i, n in enumerate(result.names)}

    def sigma(axis: str) -> str:
        i = index.get(f"{frame}_{axis}")
        if i is None or not np.isfinite(result.covariance[i, i]):
            return "—"
        value = float(np.sqrt(max(result.covariance[i, i], 0.0)))
        return f"{math.degrees(value) if axis.startswith('r') else value:.2g}"

    xyz, rpy = [sigma(a) for a in ("x", "y", "z")], [sigma(a) for a in ("rx", "ry", "rz")]
    if set(xyz + rpy) == {"—"}:
        return "—"
    return ", ".join(xyz) + "; " + ", ".join(rpy)


def chain_table(result: CalibrationResult) -> tuple[str, tuple[str, ...], list[tuple[str, ...]]]:
    """Each chain of a tree: its rows and RMS before, after and on the validation poses, in the
    data's unit, and in mm at the markers where its rows are pixels (title, columns, rows); no rows
    for a serial robot."""
    chains = result.per_chain_metrics()
    keys = [k for k in ("before", "after", "validation_before", "validation_after")
            if all(k in m for m in chains.values())]
    mm = result.unit == "px" and all(m["after"].at_marker is not None for m in chains.values())

    def cell(m: Metrics) -> str:
        text = f"{m.position['rms']:.4f}"
        return f"{text} ({m.at_marker['rms']:.3f} mm)" if mm and m.at_marker is not None else text

    title = "per chain: " + ("reprojection RMS, px (mm at the markers)" if mm else
                             "reprojection RMS (px)" if result.unit == "px" else "position RMS (mm)")
    columns = ("chain", "rows", *(k.replace("_", " ") for k in keys))
    return title, columns, [(name, str(m["after"].n), *(cell(m[k]) for k in keys)) for name, m in chains.items()]


def noise_line(result) -> str:
    """σ used and the goodness of fit, in one line."""
    import math

    n, g = result.noise, result.goodness_of_fit
    unit = getattr(result, "unit", "mm")
    kinds = getattr(result, "kind_sigma", {})
    if kinds:  # each kind of rows its own σ (and unit)
        units = {"tracker": "mm", "contact": "mm", "camera": "px"}
        text = f"{n.label} by kind: " + ", ".join(f"{k} rows {v:.3g} {units[k]}" for k, v in kinds.items())
    else:
        text = f"{n.label} {n.position:.3g} {unit}"
    text += "" if n.orientation is None else f", {math.degrees(n.orientation):.3g}°"
    text += " (stated)" if n.source == "stated" else " (estimated from the fit: the instrument's noise plus what the " \
        "model leaves out)"
    if g is not None and g.dof > 0 and n.source == "stated":  # a test of the model against the stated noise
        text += f"; χ² {g.chi2:.4g} on {g.dof:.0f} degrees of freedom (reduced {g.reduced_chi2:.3g}, p {g.p_value:.3g})"
    if result.robot.residual is not None:
        text += " — of the parametric fit; its residual correction is judged by cross-validation"
    if result.instrument is not None:
        text += f"\n{result.instrument.sentence()}"
    return text


def ladder_rows(result: CalibrationResult) -> list[tuple[str, ...]]:
    """The rungs of ``--model auto`` as table rows: model, cv RMS (mm), parameters, chosen; with
    validation data, the validation RMS (mm) before the last column, or why a rung has none
    ("folds only": a learned correction is fitted on all the poses, and so predicts the
    validation poses, only when chosen)."""
    with_validation = any(r.validation_rms_mm is not None for r in result.model_selection)
    rows = []
    for r in result.model_selection:
        if not with_validation:
            val = ()
        elif r.validation_rms_mm is not None:
            val = (f"{r.validation_rms_mm:.4f}",)
        else:
            val = ("— (folds only)",)
        last = "chosen" if r.model == result.model else "screened: not tuned in full" if r.screened else ""
        learned = [t for t in ("residual", "trees") if t in r.model.split("+")]
        # a learned correction's own fit is no count of parameters: say it rides on the parametric ones
        count = f"{r.n_params} + {' + '.join(learned)}" if learned else str(r.n_params)
        rows.append((r.model, f"{r.cv_rms_mm:.4f}", count, *val, last))
    return rows


def ladder_columns(result: CalibrationResult) -> tuple[str, ...]:
    with_validation = any(r.validation_rms_mm is not None for r in result.model_selection)
    return ("model", "cv RMS", "parameters", *(("validation RMS",) if with_validation else ()), "choice")


#: the columns of :func:`budget_rows`
BUDGET_COLUMNS = ("model", "RMS", "removed", "x", "y", "z")


def budget_rows(result: CalibrationResult) -> list[tuple[str, ...]]:
    """The error budget as table rows: stage, validation RMS (mm), removed (mm), and the RMS of
    each axis (mm)."""
    return [(r.model, f"{r.validation_rms_mm:.4f}", "" if r.removed_mm is None else f"{r.removed_mm:.4f}",
             *(("", "", "") if r.axes_mm is None else (f"{v:.4f}" for v in r.axes_mm))) for r in result.error_budget]


#: the columns of :func:`learned_rows`
LEARNED_COLUMNS = ("output", "taken (RMS)", "joints used most")


def learned_rows(result: CalibrationResult) -> list[tuple[str, ...]]:
    """What a tree correction takes on the calibration poses, per output (RMS: mm for x, y, z;
    mdeg for rx, ry, rz), and the joints its splits used most (share of the split gain); none
    for a model without trees."""
    residual = result.robot.residual
    trees = getattr(residual, "trees", residual)
    if getattr(trees, "kind", "") != "trees" or trees.taken is None or trees.importance is None:
        return []
    rows = []
    for k, (taken, share) in enumerate(zip(trees.taken, trees.importance)):
        top = [j for j in np.argsort(-share)[:3] if share[j] >= 0.05]
        value = f"{taken:.4f} mm" if k < 3 else f"{np.degrees(taken) * 1000:.3g} mdeg"
        rows.append((("x", "y", "z", "rx", "ry", "rz")[k], value,
                     ", ".join(f"J{j + 1} {100 * share[j]:.0f}%" for j in top)))
    return rows
