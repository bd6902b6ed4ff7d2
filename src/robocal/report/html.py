"""A single self-contained HTML report of a calibration (figures embedded, no network)."""

from __future__ import annotations

import base64
import html
from pathlib import Path

import numpy as np

from ..calibration.result import CalibrationResult
from ..io.atomic import atomic_write
from ..model.metrics import Metrics, pose_errors, table_rows
from ..model.parameters import is_angle, is_frame
from ..model.uncertainty import in_base
from . import figures
from .advice import as_html, next_steps
from .header import run_header
from .tables import (
    FRAME_COLUMNS,
    LEARNED_COLUMNS,
    PARAMETER_COLUMNS,
    budget_rows,
    chain_table,
    frame_rows,
    ladder_columns,
    ladder_rows,
    learned_rows,
    noise_line,
    parameter_rows,
)

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1000px;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td:first-child,th:first-child{text-align:left}img{max-width:100%}
td.l,th.l{text-align:left}.warn{background:#fff4e0;border-left:4px solid #e90;padding:.4em .8em}code{background:#f4f4f4}
.info{background:#eef3f8;border-left:4px solid #7a9cc6;padding:.4em .8em}
.next{background:#eef8ee;border-left:4px solid #4a4;padding:.4em .8em}
.head{font-size:90%;color:#444;table-layout:fixed;width:100%}.head td{overflow-wrap:anywhere;word-break:break-word}
.head td:first-child{width:9em}.lead{font-size:120%;font-weight:600}
"""


def _img(fig) -> str:
    data = base64.b64encode(figures.png_bytes(fig)).decode("ascii")
    return f'<img alt="figure" src="data:image/png;base64,{data}">'


def _metrics_table(columns: dict[str, Metrics]) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(f"<tr><td>{html.escape(label)}</td>" + "".join(f"<td>{v}</td>" for v in values) + "</tr>"
                   for label, values in table_rows(columns))
    return f"<table><tr><th>error</th>{head}</tr>{body}</table>"


def _camera_table(result: CalibrationResult) -> list[str]:
    """The camera rows' reprojection RMS (px), over all and per camera, before and after: beside
    tracker rows, or of several cameras (one camera's alone are the accuracy table's)."""
    if not result.cameras or (result.unit == "px" and len(result.robot.cameras) < 2):
        return []
    keys = list(dict.fromkeys(k for figures in result.cameras.values() for k in figures))
    rows = [(k.replace("reprojection_rms_px", "reprojection RMS (px)").replace("[", " camera ").rstrip("]"),
             *(f"{figures[k]:.4f}" if k in figures else "—" for figures in result.cameras.values())) for k in keys]
    return ["<p>Camera rows:</p>", _table(("", *(k.replace("_", " ") for k in result.cameras)), rows)]


def _contact(result: CalibrationResult) -> list[str]:
    """Data whose rows touched points or planes: what they are judged by, before and after."""
    if not result.contact:
        return []
    keys = list(dict.fromkeys(k for figures in result.contact.values() for k in figures))
    head = "".join(f"<th>{html.escape(k.replace('_', ' '))} (mm)</th>" for k in keys)
    rows = "".join(f"<tr><td>{html.escape(name.replace('_', ' '))}</td>"
                   + "".join(f"<td>{figures[k]:.4f}</td>" if k in figures else "<td>—</td>" for k in keys) + "</tr>"
                   for name, figures in result.contact.items())
    return ["<p>The rows touched points or planes whose place is unknown: the position errors above are each "
            "row's offset from its point's (plane's) best fit, its <b>point spread</b>; the distance error is how "
            "far the two points of a setup miss their stated distance.  The frame the robot stands in is not "
            "observable from them (the parameters table says what else is not).</p>",
            f"<table><tr><th>set</th>{head}</tr>{rows}</table>"]


def _lead(result: CalibrationResult) -> str:
    """The honest figure first: validation, else the cross-validated prediction; the fit labelled."""
    return f"<p class='lead'>{html.escape(result.headline_text()[0].upper() + result.headline_text()[1:])}.</p>"


def _summary(result: CalibrationResult, d: dict) -> str:
    meas = result.measurements
    tracker = meas is None or (meas.camera is None and meas.constraints is None)
    described = meas.describe() if meas is not None else f"{result.n_poses} poses"
    rows = f"{described} ({'full pose' if result.full_pose else 'position only'})" if tracker else described
    return (f"<p>Method <b>{html.escape(result.method)}</b> (objective {html.escape(d['objective'])}, seed "
            f"{result.seed}), frames <code>{html.escape(result.frames)}</code>, {rows} "
            f"from <code>{html.escape(result.data)}</code>. "
            f"Status: {html.escape(d['status'])} after {d['iterations']} iterations, {d['evaluations']} evaluations, "
            f"{d['time_s']:.2f} s.</p>")


#: above this many poses, per-pose figures give way to distributions
PER_POSE_LIMIT = 60


def objective_label(result: CalibrationResult) -> str:
    """What the convergence history measures, with its unit."""
    if result.config.least_squares:
        return "χ² (whitened sum of squares, dimensionless)"
    if result.objective == "sum_norms":
        return "best Σ|δp| (mm)"
    return "best Σ k|δ|² + |δp|² (mm²)"


def _norms(robot, meas) -> np.ndarray:
    dp, _ = pose_errors(robot, meas)
    return np.linalg.norm(dp, axis=1)


def _uncertainty_map(result: CalibrationResult) -> list[str]:
    m = result.tcp_uncertainty
    if m is None:
        return []
    s = m.summary()
    if m.over == "workspace":
        box = np.asarray(m.box)
        where = (f"at {s['points']} joint sets drawn over the calibrated joint ranges whose TCP lies in the box the "
                 "measured poses span (x {:.0f} to {:.0f}, y {:.0f} to {:.0f}, z {:.0f} to {:.0f} mm, base "
                 "frame, with a tenth of its size around it)".format(*box.T.ravel()))
    else:
        where = (f"at {s['points']} joint sets drawn over the joint ranges the model was calibrated on, in any "
                 "combination (<code>--map-over joints</code>)")
    bright = in_base(result.robot, m.brightest())
    return ["<h2>How well the model knows the TCP</h2><p>The predicted position's standard uncertainty (1σ, rms "
            "radius) from the parameter covariance" + (" and the residual process's variance" if
                                                        result.robot.residual is not None else "")
            + f", {where}: median {s['median_mm']:.4f} mm, 95 % below {s['p95_mm']:.4f} mm, largest "
            f"{s['max_mm']:.4f} mm"
            + (f"; at the calibration poses themselves median {s['at_calibration_poses']['median_mm']:.4f} mm, "
               f"largest {s['at_calibration_poses']['max_mm']:.4f} mm" if "at_calibration_poses" in s else "")
            + ". The colours run from the 2nd to the 98th percentile, so that the map tells its values apart; the "
            f"largest tenth lies around x {bright[0]:.0f}, y {bright[1]:.0f}, z {bright[2]:.0f} mm (base frame), "
            "where more poses would pin the model down most. Combinations of joint angles the poses never took lie "
            "among the joint sets: there the model extrapolates, and the map shows it. It is the calibration's own "
            "uncertainty (how well these poses determine the parameters), not the robot's error. <code>robocal "
            "evaluate --uncertainty</code> gives it per pose, anywhere: the model is used whole everywhere, and its "
            "uncertainty says where it is less known.</p>",
            _img(figures.workspace_errors(in_base(result.robot, m.position), m.sigma,
                                          "predicted TCP position uncertainty (base frame)",
                                          "σ of the predicted position (mm)", from_zero=False))]


def _error_figures(result: CalibrationResult) -> list[str]:
    meas, val = result.measurements, result.validation
    if meas is None:
        return []
    pixels = result.unit == "px"
    parts = ["<h2>Error distribution</h2><p>" + ("Reprojection error |δuv| (px) of every camera row" if pixels else
                                                 "Position error |δp| of every pose")
             + "; the curves show the fraction of poses with a smaller error (log scale).</p>"]
    series = {"before (calibration poses)": _norms(result.initial, meas),
              "after (calibration poses)": _norms(result.robot, meas)}
    if val is not None:
        series["before (validation poses)"] = _norms(result.initial, val)
        series["after (validation poses)"] = _norms(result.robot, val)
    parts.append(_img(figures.error_distribution(series, f"{result.nominal.name}: model {result.model}",
                                                 result.unit)))
    where = val if val is not None else meas
    label = "validation" if val is not None else "calibration"
    after = _norms(result.robot, where)
    if pixels:
        return parts + _camera_figures(result, where, label, after)
    points = where.position
    if where.constraints is not None:  # a contact row measured no point: the calibrated model's is drawn
        points = np.where(where.constraints.rows[:, None],
                          result.robot.positions(where.q, where.targets, where.inputs, where.chain), points)
    placed = in_base(result.robot, points)
    parts.append(f"<h2>Where the error is</h2><p>Measured points of the {label} poses in the robot's base frame "
                 + ("(where a row touched a point or plane, the calibrated model's tool point), " if
                    where.constraints is not None else "")
                 + "coloured by the calibrated model's position error (the colour scale runs to the "
                 f"{figures.ROBUST_PERCENTILE:g}th percentile, so that a few large errors do not darken the rest; the "
                 "points above it are ringed in red, and the largest are drawn on top).</p>")
    parts.append(_img(figures.workspace_errors(placed, after, f"{label} poses after calibration (base frame)")))
    parts += _uncertainty_map(result)
    geometric = result.geometric or (result.robot if result.robot.geometric else None)
    others = {}
    what = "the geometric calibration"
    if geometric is None:  # no geometric fit beside the model: its parametric part
        geometric = result.robot.replace(residual=None)
        if not geometric.geometric:
            what = "the parametric part of the model (without its residual correction)"
    if geometric is not result.robot:
        others[f"model {result.model}"] = after
    parts.append(f"<h2>Error against each joint angle</h2><p>What {what} left, against each joint: a trend or a "
                 "wave here is a joint effect geometry cannot take (compliance, gear errors)"
                 + (f"; the medians of the chosen model ({html.escape(result.model)}) beside it" if others else "")
                 + ".</p>")
    parts.append(_img(figures.residual_vs_joints(where.q, _norms(geometric, where),
                                                 f"{label} poses, {what.replace('the ', '', 1)}", others=others)))
    if meas.n_poses <= PER_POSE_LIMIT:
        dp0, dr0 = pose_errors(result.initial, meas)
        dp1, dr1 = pose_errors(result.robot, meas)
        parts.append("<h2>Per-pose errors (calibration data)</h2>")
        parts.append(_img(figures.position_errors(dp0, {result.method: dp1}, "calibration poses")))
        parts.append(_img(figures.axis_errors(dp1, f"after {result.method}")))
        if dr0 is not None:
            parts.append(_img(figures.orientation_errors(dr0, dr1, "calibration poses")))
    return parts


def _exports(result: CalibrationResult) -> list[str]:
    """What each kind of export hands its receiver, and how accurate that is."""
    e = result.exports
    if e is None:
        return []
    cameras = (" The cameras' poses are in the robot TOML (<code>[cameras.NAME]</code>; beside a URDF, in the TOML "
               "written with it), which <code>robocal evaluate --camera</code> reads." if result.robot.cameras else "")
    if result.robot.tree is not None:
        cameras += (" A tree: the URDF holds every branch (each chain's tool on <code>target_CHAIN</code>, each "
                    "camera's optical frame on <code>camera_NAME_optical</code>), and each chain is written beside "
                    "any export as its own robot TOML (<code>NAME.CHAIN.toml</code>) for <code>robocal filter</code> "
                    "and <code>compensate</code>; a kinematics YAML holds one arm, and a tree is not written as one.")
    from ..inverse.closed_form import form_of
    from ..inverse.equivalent import dh_equivalent
    from ..io.ur import holds

    # a UR kinematics YAML is for a UR-type arm (axes 2, 3 and 4 parallel: the "offset" closed form) it can hold
    yaml = holds(result.robot) and form_of(dh_equivalent(result.nominal))[0] == "offset"
    kinematics = (" A UR kinematics YAML holds the joints' geometry alone: the measuring frame and the tool are in "
                  "the robot TOML written beside it." if yaml else "")
    if e.geometric:
        return [f"<h2>What the exports hold</h2><p>The model is geometry and frames alone: a robot TOML and a URDF "
                f"carry all of it, {e.whole_rms_mm:.4f} {e.unit} RMS{html.escape(e.at_tool)} "
                f"{html.escape(e.where)}.{kinematics}{cameras}</p>"]
    own = e.geometry_of == "the model's own"
    return ["<h2>What the exports hold</h2><p>A robot TOML holds the whole model; a URDF only geometry and frames"
            + (", a UR kinematics YAML the joints' geometry" if yaml else "")
            + ("" if own else ": the geometric calibration's, since the model's own geometry was fitted beside its "
                              "joint terms, which took their share") +
            f". What the receiver then gets, {html.escape(e.where)}:</p>",
            _table(("export", "holds", f"{'reprojection' if e.unit == 'px' else 'position'} RMS ({e.unit})",
                    f"max ({e.unit})"),
                   [("robot TOML (robocal filter, compensate, evaluate)", "the whole model", f"{e.whole_rms_mm:.4f}",
                     f"{e.whole_max_mm:.4f}"),
                    ("URDF, kinematics YAML (a controller, ROS)" if yaml else "URDF (a controller, ROS)",
                     f"{'' if own else 'the geometric calibration: '}geometry and frames", f"{e.geometry_rms_mm:.4f}",
                     f"{e.geometry_max_mm:.4f}")], left=2),
            "<p>The joint terms and the learned correction reach the robot only through <code>robocal filter</code> "
            "(its programs) and <code>robocal compensate</code> (its commands)."
            + (" Each chain's own robot TOML holds the geometric calibration: the tree's joint terms load its trunk "
               "with every arm, which one chain cannot hold." if result.robot.tree is not None else "")
            + f"{kinematics}{cameras}</p>"]


def _model_tables(result: CalibrationResult) -> list[str]:
    """The ladder of ``--model auto`` and the error budget on the validation poses."""
    parts = []
    if result.model_selection:
        rows = ladder_rows(result)
        how = result.cross_validation.phrase if result.cross_validation else "5-fold cross-validation"
        what = "reprojection" if result.unit == "px" else "position"
        parts += [f"<h2>Model selection</h2><p>Model {html.escape(result.model)}, chosen by {html.escape(how)}: "
                  "each model refitted without a fold predicts it. A richer model is kept only if it predicts the "
                  "held-out data better than a simpler one.</p>",
                  _table(tuple({"cv RMS": f"cross-validated {what} RMS ({result.unit})",
                                "validation RMS": f"validation {what} RMS ({result.unit})"}.get(c, c)
                               for c in ladder_columns(result)), rows)]
    if result.error_budget:
        rows = budget_rows(result)
        parts += ["<h2>Error budget</h2><p>Position RMS on the validation poses as each part of the model is "
                  "added: what each removes, and the RMS of each axis of the measuring frame.</p>",
                  _table(("model", "validation RMS (mm)", "removed (mm)", "x (mm)", "y (mm)", "z (mm)"), rows)]
    if learned_rows(result):
        parts += ["<h2>What the trees take</h2><p>The RMS of the tree correction over the calibration poses, per "
                  "output, and the joints its splits used most (share of the split gain). Outside the joint "
                  "configurations of its data the correction fades out and the model's uncertainty grows.</p>",
                  _table(LEARNED_COLUMNS, learned_rows(result))]
    return parts


def _per_target(result: CalibrationResult) -> list[str]:
    per_target = result.per_target_metrics()
    if not per_target:
        return []
    keys = [k for k in ("before", "after", "validation_before", "validation_after")
            if all(k in m for m in per_target.values())]
    rows = [(t, str(m["after"].n), *(f"{m[k].position['rms']:.4f}" for k in keys)) for t, m in per_target.items()]
    what = "marker" if result.unit == "px" else "reflector"
    return [f"<h2>Per {what}</h2>",
            _table((what, "points" if result.unit == "mm" else "rows",
                    *(f"{k.replace('_', ' ')} RMS ({result.unit})" for k in keys)), rows)]


def _per_chain(result: CalibrationResult) -> list[str]:
    title, columns, rows = chain_table(result)
    if not rows:
        return []
    what = title[len("per chain: "):]
    return ["<h2>Per chain</h2>", f"<p>{html.escape(what[0].upper() + what[1:])} of each chain of the "
            "tree on its own rows; the trunk they share was calibrated once, from all of them.</p>",
            _table(columns, rows)]


def _table(columns, rows, left: int = 1) -> str:
    head = "".join(f"<th{' class=l' if i < left or i == len(columns) - 1 else ''}>{html.escape(c)}</th>"
                   for i, c in enumerate(columns))
    body = "".join("<tr>" + "".join(f"<td{' class=l' if i < left or i == len(r) - 1 else ''}>{html.escape(v)}</td>"
                                    for i, v in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _parameter_tables(result: CalibrationResult, d: dict) -> list[str]:
    parts = ["<h2>Identified parameters</h2><p>Lengths in mm, angles in degrees, compliances in rad/(N·m); ± σ is "
             "the standard uncertainty. A regrouped parameter estimates the combination shown.</p>",
             _table(PARAMETER_COLUMNS, parameter_rows(result))]
    joints = [i for i, n in enumerate(result.names) if not is_frame(n)]
    if joints:
        names = [result.names[i] for i in joints]
        sig = None if result.uncertainty is None else result.uncertainty[joints]
        parts.append(_img(figures.parameter_bars(names, result.x[joints], sig, np.array([is_angle(n) for n in names]),
                                                 "identified deviations")))
    parts.append("<h2>Parameters not identified</h2>")
    if d["dropped"]:
        parts.append(_table(("name", "reason"), [(x["name"], x["reason"]) for x in d["dropped"]]))
    else:
        parts.append("<p>None: every candidate parameter is identifiable from these data.</p>")
    ident = d["identifiability"]
    obs = ", ".join(f"{k} = {v:.4g}" for k, v in ident["observability"].items())
    parts.append(f"<p>Condition number {ident['condition_number']:.4g}; observability {obs} "
                 f"(angle columns scaled by {ident['length_scale_mm_per_rad']:.0f} mm/rad).</p>")
    parts.append("<h2>Frames</h2>" + _table(FRAME_COLUMNS, frame_rows(result)))
    if result.noise is not None:
        parts.append(f"<h2>Noise and goodness of fit</h2><p>{html.escape(noise_line(result))}.</p>")
    return parts


def _run_header(result: CalibrationResult, command: str | None) -> str:
    """Who made the report, when, from what: version, date, command, input files with SHA-256,
    robot, poses and the campaign's temperature range."""
    from pathlib import Path

    source = result.nominal.source or ""
    robot_file = [("robot", source)] if source and not source.startswith("built-in") and Path(source).is_file() \
        else []
    files = robot_file + [("data", part) for part in result.data.split(" + ")] + \
        ([("validation", result.validation.source)] if result.validation else []) + \
        [(f"camera {c.name}", c.path) for c in result.config.cameras] + \
        ([("markers", result.config.markers)] if result.config.markers else [])
    rows = [("robot", f"{result.nominal.name} ({result.nominal.source or 'given as a Robot'})"),
            ("poses", result.measurements.describe() if result.measurements else str(result.n_poses))]
    meas = result.all_rows or result.measurements
    if meas is not None and meas.temperature is not None:
        rows.append(("temperature", f"{np.min(meas.temperature):.2f} to {np.max(meas.temperature):.2f} °C"))
    return run_header(command, "robocal.calibrate", files, rows)


def _said(result: CalibrationResult) -> list[str]:
    return [f"<p class='warn'>{html.escape(w)}</p>" for w in result.warnings] + \
        [f"<p class='info'>{html.escape(n)}</p>" for n in result.notes]


def _worst(result: CalibrationResult, count: int = 10) -> list[str]:
    """The poses with the largest errors (validation poses when there are, else calibration ones): for
    contact rows with their setup and point or plane, a setup or point most of them share named; the
    joint a pose lies outside the calibrated region by."""
    rows = result.per_pose()
    if not rows:
        return []
    which = "validation" if any(r["set"] == "validation" for r in rows) else "calibration"
    pixels = result.unit == "px"
    contact = any(r.get("contact") for r in rows)
    error, parts = ("error_px", ("du_px", "dv_px")) if pixels else ("error_mm", ("dx_mm", "dy_mm", "dz_mm"))
    rows = [r for r in rows if r["set"] == which and r[error] != ""]
    worst = sorted(rows, key=lambda r: -r[error])[:count]
    named = any(r["pose_id"] != f"row {r['row']}" for r in worst)  # else "pose" only repeats "row"
    head = (*(("pose",) if named else ()), "row", *(("setup", "touched") if contact else ()),
            *(("camera", "marker", "error (px)", "δu", "δv") if pixels else ("error (mm)", "δx", "δy", "δz")), "flags")
    body = []
    for r in worst:
        far = r["outside_region_deg"]
        flags = ", ".join(f for f, on in (("outlier", r["outlier"]),
                                          (f"{far:.1f}° outside the region (joint {r.get('outside_joint', '?')})",
                                           far > 0)) if on)
        body.append((*((r["pose_id"] or "—",) if named else ()), str(r["row"]),
                     *((str(r["setup"]), r["contact"]) if contact else ()),
                     *((r["camera"], r["reflector"]) if pixels else ()),
                     f"{r[error]:.4f}", *(f"{r[k]:.4f}" for k in parts), flags))
    said = _worst_said(worst, rows, contact, error, parts)
    return [f"<h2>The worst {which} {'rows' if pixels else 'poses'}</h2><p>By "
            f"{'reprojection' if pixels else 'position'} error of the calibrated model; "
            "<code>--poses-out</code> writes every pose.</p>", _table(head, body)] + \
        [f"<p class='warn'>{html.escape(s)}</p>" for s in said]


def _worst_said(worst: list[dict], rows: list[dict], contact: bool, error: str, parts) -> list[str]:
    """What the worst rows have in common: most in one setup or at one point (a badly seated artefact
    is one placement's rows), or the worst one beyond the calibrated region."""
    out = []
    if contact and len(worst) >= 4:
        for key, what in (("setup", "setup"), ("contact", "")):
            values = [r[key] for r in worst if r[key] != ""]
            if not values:
                continue
            top = max(set(values), key=values.count)
            share = sum(r[key] == top for r in rows) / len(rows)
            if values.count(top) >= max(3, 0.5 * len(worst)) and values.count(top) > 2 * share * len(worst):
                axis = max(parts, key=lambda k: np.mean([abs(r[k]) for r in worst if r[key] == top]))
                spread = [r[axis] for r in worst if r[key] == top]
                place = f"{what} {top}".strip()
                out.append(f"{values.count(top)} of the {len(worst)} worst rows are in {place} ({share:.0%} of the "
                           f"rows), δ{axis[1]} {min(spread):+.2f} to {max(spread):+.2f} mm: something of that "
                           f"{'placement' if key == 'setup' else 'point or plane'} (a badly seated artefact, a worn "
                           "socket) that the rest do not share")
                break
    first = worst[0] if worst else None
    if first is not None and first["outside_region_deg"] > 0:
        out.append(f"The largest error, {first[error]:.4f} {'px' if error == 'error_px' else 'mm'}, is "
                   f"{first['pose_id']}, {first['outside_region_deg']:.1f}° outside the joint ranges the "
                   f"model was calibrated on (joint {first.get('outside_joint', '?')}): there the model extrapolates.")
    return out


def _camera_figures(result: CalibrationResult, where, label: str, after: np.ndarray) -> list[str]:
    """Camera rows: what each camera saw on its image, and the reprojection error against the joints."""
    views = where.views
    before, _ = pose_errors(result.initial, where)
    now, _ = pose_errors(result.robot, where)
    covered = views.coverage()
    drawn = [{"name": name, "width": camera.width, "height": camera.height, "uv": where.pixels[views.index == c],
              "before": before[views.index == c, :2], "after": now[views.index == c, :2],
              "cells": covered.get(name, (None, None))[1]}
             for c, (name, camera) in enumerate(zip(views.names, views.cameras)) if np.any(views.index == c)]
    shares = ", ".join(f"camera {html.escape(c)} {100 * share:.0f} %" for c, (share, _) in covered.items())
    parts = [f"<h2>What each camera saw</h2><p>Every {label} row on its camera's image: the measured pixel, coloured "
             "by the calibrated model's reprojection error, and that error as an arrow, magnified so that it can be "
             "seen (the arrow above each image says how long an error it draws, and by how much). Arrows that line up "
             "over a region are what the model leaves there (a lens the intrinsics do not describe, a marker off its "
             "place); scattered arrows are the detection's noise."
             + (f" The markers fell in {shares} of the image: the grey cells saw none, and there the lens is "
                "untested — the model knows it only from its calibration file." if covered else "") + "</p>",
             _img(figures.image_planes(drawn, f"{label} rows after calibration"))]
    parts.append("<h2>Error against each joint angle</h2><p>The calibrated model's reprojection error against each "
                 "joint: a trend or a wave here is a joint effect geometry cannot take.</p>")
    parts.append(_img(figures.residual_vs_joints(where.q, after, f"{label} rows", ylabel="|δuv| (px)")))
    return parts


def calibration_html(result: CalibrationResult, command: str | None = None) -> str:
    """The report of one calibration as a self-contained HTML page: how accurate it is now and
    where, what changed and whether it is significant, which model and why, what limits it, and
    what to do next."""
    d = result.to_dict()
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>robocal calibration</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>Calibration of {html.escape(result.nominal.name)}</h1>",
             _run_header(result, command), _lead(result), _summary(result, d)]
    parts += _said(result)
    parts += ["<h2>What to do next</h2>"] + [f"<p class='next'>{as_html(s)}</p>" for s in next_steps(result)]
    parts += _exports(result)
    cols = result.accuracy_columns()
    contact = _contact(result)
    nominal = result.initial.source or result.initial.name
    ur = nominal.startswith("built-in ur")
    parts.append(f"<h2>Accuracy</h2><p>“Before” is the nominal geometry ({html.escape(nominal)}"
                 + (": the drawing's DH, not the factory calibration a UR controller runs, which <code>robocal robots "
                    "--from-ur</code> reads" if ur else "") + ") with the registered frames; “after (fit)” "
                 "the calibrated model on the poses it was fitted to, which flatters it; "
                 + ("“validation” the poses kept out of the fit. " if result.validation else
                    f"“predicted” what the model does on {html.escape(result.held_out)}, each held out of a refit. ")
                 + "Measured: "
                 f"{html.escape(result.measurements.describe() if result.measurements else str(result.n_poses))}"
                 + (f"; validation: {html.escape(result.validation.describe())}" if result.validation else "")
                 + ".</p>")
    parts.append(_metrics_table(cols))
    parts += contact
    parts += _camera_table(result)
    parts += _per_chain(result)
    parts += _per_target(result)
    parts += _error_figures(result)
    parts += _worst(result)
    parts += _model_tables(result)
    parts.append("<h2>Convergence</h2>")
    opt = result.optimization
    drawn, phases = len(opt.history), opt.extra.get("history_phases")
    if result.config.spec.swarm is not None:  # a point per generation, each evaluating every particle
        said = [f"one point per generation of the swarm and per residual evaluation of the LM after it "
                f"({drawn} points; {opt.nfev} objective evaluations in all, a generation evaluating every particle)"]
        drawn = opt.nfev
    else:
        said = [f"{drawn} of the {opt.nfev} residual evaluations are drawn" if drawn < opt.nfev else
                f"all {drawn} residual evaluations are drawn"]
    history = np.asarray(opt.history, float)
    segments = [(f"{result.method}", history)]
    if phases and len(phases) == 2 and phases[1] and sum(phases) <= drawn:
        segments = [(f"the data alone ({phases[0]})", history[:phases[0]]),
                    (f"with the prior ({phases[1]})", history[phases[0]:phases[0] + phases[1]])]
        said.append(f"the first {phases[0]} fit the data alone, for the scale of their noise, the next {phases[1]} fit "
                    "with the prior weighed by that noise: each phase on its own panel and scale, since their χ² "
                    "are weighed differently")
    if drawn < opt.nfev:
        said.append(f"the other {opt.nfev - drawn}, refits after reweighting by the estimated or the instrument's "
                    "noise, are not (χ² under other weights is another scale), so the last point is not the final "
                    "χ²")
    parts.append(f"<p>{'; '.join(said).capitalize()}.</p>")
    what = "best objective per generation" if result.config.spec.swarm is not None else "objective per evaluation"
    parts.append(_img(figures.convergence_phases(segments, f"{result.method}: {what}", objective_label(result),
                                                 figures.iteration_label([result.method]))))
    parts += _parameter_tables(result, d)
    parts.append("<p>Generated by robocal.</p></body></html>")
    return "\n".join(parts)


def write_report(result: CalibrationResult, path: str | Path, command: str | None = None) -> None:
    """Write :func:`calibration_html` of ``result`` to ``path``; command: the command line, for its header."""
    atomic_write(path, calibration_html(result, command))
