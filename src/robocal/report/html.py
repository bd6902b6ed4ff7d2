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
from . import figures
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
    rows = f"{result.n_poses} camera rows" if result.unit == "px" else \
        f"{result.n_poses} poses ({'full pose' if result.full_pose else 'position only'})"
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


def _in_base(robot, points: np.ndarray) -> np.ndarray:
    """Points (m, 3) mm of the measuring frame in the robot's base frame."""
    B = np.linalg.inv(robot.base)
    return points @ B[:3, :3].T + B[:3, 3]


def _uncertainty_map(result: CalibrationResult) -> list[str]:
    m = result.tcp_uncertainty
    if m is None:
        return []
    s = m.summary()
    return ["<h2>How well the model knows the TCP</h2><p>The predicted position's standard uncertainty (1σ, rms "
            "radius) from the parameter covariance" + (" and the residual process's variance" if
                                                        result.robot.residual is not None else "")
            + f", at {s['points']} joint sets drawn over the joint ranges the "
            f"model was calibrated on, in any combination: median {s['median_mm']:.4f} mm, 95 % below "
            f"{s['p95_mm']:.4f} mm, largest {s['max_mm']:.4f} mm"
            + (f"; at the calibration poses themselves median {s['at_calibration_poses']['median_mm']:.4f} mm, "
               f"largest {s['at_calibration_poses']['max_mm']:.4f} mm" if "at_calibration_poses" in s else "")
            + ". Combinations of joint angles the poses never took lie among them: there the model "
            "extrapolates, and the map shows it. It is the calibration's own uncertainty (how well these poses "
            "determine the parameters), not the robot's error; where it is large, more poses there would pin the "
            "model down. <code>robocal evaluate --uncertainty</code> gives it per pose, outside these ranges too: "
            "the model is used whole everywhere, and its uncertainty says where it is less known.</p>",
            _img(figures.workspace_errors(_in_base(result.robot, m.position), m.sigma,
                                          "predicted TCP position uncertainty (base frame)",
                                          "σ of the predicted position (mm)"))]


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
    in_base = _in_base(result.robot, points)
    parts.append(f"<h2>Where the error is</h2><p>Measured points of the {label} poses in the robot's base frame "
                 + ("(where a row touched a point or plane, the calibrated model's tool point), " if
                    where.constraints is not None else "")
                 + "coloured by the calibrated model's position error (the colour scale runs to the "
                 f"{figures.ROBUST_PERCENTILE:g}th percentile, so that a few large errors do not darken the rest; the "
                 "points above it are ringed in red, and the largest are drawn on top).</p>")
    parts.append(_img(figures.workspace_errors(in_base, after, f"{label} poses after calibration (base frame)")))
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
    if e.geometric:
        return [f"<h2>What the exports hold</h2><p>The model is geometry and frames alone: a robot TOML, a URDF and "
                f"a kinematics YAML carry all of it ({e.whole_rms_mm:.4f} {e.unit} RMS{html.escape(e.at_tool)} "
                f"{html.escape(e.where)}).{cameras}</p>"]
    own = e.geometry_of == "the model's own"
    return ["<h2>What the exports hold</h2><p>A robot TOML holds the whole model; a URDF or a kinematics YAML only "
            "geometry and frames" + ("" if own else ": the geometric calibration's, since the model's own geometry was "
                                     "fitted beside its joint terms, which took their share") +
            f". What the receiver then gets, {html.escape(e.where)}:</p>",
            _table(("export", "holds", f"{'reprojection' if e.unit == 'px' else 'position'} RMS ({e.unit})",
                    f"max ({e.unit})"),
                   [("robot TOML (robocal filter, compensate, evaluate)", "the whole model", f"{e.whole_rms_mm:.4f}",
                     f"{e.whole_max_mm:.4f}"),
                    ("URDF, kinematics YAML (a controller, ROS)",
                     f"{'' if own else 'the geometric calibration: '}geometry and frames", f"{e.geometry_rms_mm:.4f}",
                     f"{e.geometry_max_mm:.4f}")], left=2),
            "<p>The joint terms and the learned correction reach the robot only through <code>robocal filter</code> "
            "(its programs) and <code>robocal compensate</code> (its commands).</p>"]


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
    files = [("data", part) for part in result.data.split(" + ")] + \
        ([("validation", result.validation.source)] if result.validation else [])
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
    """The poses with the largest errors (validation poses when there are, else calibration ones)."""
    rows = result.per_pose()
    if not rows:
        return []
    which = "validation" if any(r["set"] == "validation" for r in rows) else "calibration"
    pixels = result.unit == "px"
    error, parts = ("error_px", ("du_px", "dv_px")) if pixels else ("error_mm", ("dx_mm", "dy_mm", "dz_mm"))
    rows = sorted((r for r in rows if r["set"] == which and r[error] != ""), key=lambda r: -r[error])[:count]
    head = ("pose", "row", *(("camera", "marker", "error (px)", "δu", "δv") if pixels else
                             ("error (mm)", "δx", "δy", "δz")), "flags")
    body = []
    for r in rows:
        flags = ", ".join(f for f, on in (("outlier", r["outlier"]),
                                          (f"{r['outside_region_deg']:.1f}° outside the region",
                                           r["outside_region_deg"] > 0)) if on)
        body.append((r["pose_id"] or "—", str(r["row"]), *((r["camera"], r["reflector"]) if pixels else ()),
                     f"{r[error]:.4f}", *(f"{r[k]:.4f}" for k in parts), flags))
    return [f"<h2>The worst {which} {'rows' if pixels else 'poses'}</h2><p>By "
            f"{'reprojection' if pixels else 'position'} error of the calibrated model; "
            "<code>--poses-out</code> writes every pose.</p>", _table(head, body)]


#: a figure this many times the instrument's floor is the model's, not the instrument's
FLOOR_GAP = 3.0
#: the predicted TCP uncertainty over the joint ranges this many times that at the measured poses
#: asks for poses where it is large
SPREAD_GAP = 2.0
#: at most this many suggestions, the most pressing first
MOST = 3


def _headline(result: CalibrationResult) -> tuple[str, float] | None:
    """The figure the advice weighs: the validation poses' position RMS, else the cross-validated
    one (what the model does on poses it was not fitted to)."""
    for key, what in (("validation_after", "on the validation poses"), ("predicted", "cross-validated")):
        if key in result.metrics:
            return what, float(result.metrics[key].position["rms"])
    return None


def _floor(result: CalibrationResult) -> float | None:
    """The instrument's own noise as a position RMS (mm): the figure no model goes below."""
    row = next((b for b in result.error_budget if b.model.startswith("the instrument's own noise")), None)
    if row is not None:
        return row.validation_rms_mm
    sigma = None if result.measurements is None else result.measurements.sigma_position
    if sigma is None:
        return None
    from ..calibration.select.learned import instrument_noise

    return float(np.sqrt(instrument_noise(sigma)))


def _tied_to_cameras(result: CalibrationResult) -> list[str]:
    """The parameters held by their prior that no pose can tell from where the cameras, the base
    and the markers are: for a camera on link k, joint k+1's zero and offset along its axis (a turn
    or a shift along an axis commutes with the joint's own turn, so the camera may take it: MODEL
    §10), and for Craig's convention the twist and length before that axis; and what the estimate's
    dependences tie to those or to a frame (the lengths' common scale among them)."""
    robot = result.robot
    if not robot.cameras:
        return []
    tied = set()
    for mount in robot.cameras.values():
        if mount.link and mount.link < robot.n_joints and robot.convention in ("dh", "hayati", "craig"):
            j = mount.link + 1
            tied |= {f"theta{j}", f"d{j}"} | ({f"a{j}", f"alpha{j}"} if robot.convention == "craig" else set())
    at = result.at_estimate
    groups = [] if at is None else [{name, *related} for name, related in at.dependent.items()]
    for group in groups * 2:  # twice: a dependence may tie to another that ties to a frame
        if any(is_frame(n) or n in tied for n in group):  # a camera, the base, a marker: they take it exactly
            tied |= {n for n in group if not is_frame(n)}
    return [n for n in result.held if n in tied]


def next_steps(result: CalibrationResult) -> list[str]:
    """At most :data:`MOST` concrete suggestions from the figures the report shows, the most
    pressing first: physicality, the gap between the model's figure and the instrument's floor,
    the predicted TCP uncertainty over the calibrated joint ranges, parameters the poses do not
    pin, outliers, validation poses beyond the data, too few poses.  "Nothing calls for more"
    only where the figure is near the floor and the uncertainty even over the ranges."""
    out = []
    meas = result.measurements
    if not result.physical.physical:
        out.append(f"The calibrated model is not physical: {html.escape(result.physical.listed())} (likely cause: "
                   f"{html.escape(result.physical.cause)}). Do not load it into a controller: check the nominal model, "
                   "and measure poses that move the joints these parameters belong to.")
    headline, floor = _headline(result), _floor(result)
    if headline is not None and floor is not None and headline[1] > FLOOR_GAP * floor:
        what, figure = headline
        if result.model == "geometric":
            act = ("calibrate with <code>--model auto</code> to try joint terms (compliance, harmonics, backlash, "
                   "drift) and learned corrections")
        else:
            act = ("the model chosen already holds what cross-validation could find; what remains is repeatable "
                   "error robocal does not model (temperature, a loaded tool, the tracker's own setup) or poses "
                   "too sparse for it: measure more poses over the working range")
        out.append(f"The model predicts {figure:.3g} mm RMS {what}, {figure / floor:.0f}× the instrument's own "
                   f"{floor:.3g} mm: the difference is the model's, not the instrument's. To take more of it, {act}.")
    m = result.tcp_uncertainty
    if m is not None and m.at_poses is not None and len(m.at_poses):
        summary, at = m.summary(), float(np.median(m.at_poses))
        if summary["median_mm"] > SPREAD_GAP * at:
            out.append(f"Over the calibrated joint ranges the predicted TCP uncertainty is {summary['median_mm']:.3g} "
                       f"mm (median; 95 % below {summary['p95_mm']:.3g} mm), {summary['median_mm'] / at:.1f}× that "
                       "at the measured poses: the model is sure of itself only near them. Measure poses where the "
                       "uncertainty map is bright before relying on it across the workspace.")
    tied = _tied_to_cameras(result)
    if tied:
        out.append(f"{html.escape(', '.join(tied))} cannot be told from where the cameras, the base and the markers "
                   "are, nor from the lengths' common scale: the pixels see the same whichever takes the difference, "
                   "so the prior holds it (MODEL §10). No pose separates them; a camera's pose known by other means "
                   "(--camera-pose), markers of known offsets or sizes (--markers), or tracker rows would.")
    held = [n for n in result.held if n not in tied]
    if held:
        many = len(held) > 1
        out.append(f"The poses do not pin {html.escape(', '.join(held))}: {'they are' if many else 'it is'} "
                   f"held by {'their' if many else 'its'} prior (the nominal value within its width, MODEL §3.1), not "
                   f"measured. Poses that move {'their' if many else 'its'} joints more widely would measure "
                   f"{'them' if many else 'it'}.")
    g, inst = result.goodness_of_fit, result.instrument
    if result.model == "geometric" and floor is None and ((g is not None and g.misfit()) or (
            inst is not None and inst.reduced_chi2 and inst.reduced_chi2 > 4)):
        beyond = "" if inst is None else f" ({inst.reduced_chi2:.3g}× the instrument's noise in χ²)"
        out.append(f"The geometric model leaves systematic error{beyond}: calibrate with <code>--model auto</code> "
                   "to try joint terms (compliance, harmonics, backlash, drift) and a residual process.")
    if result.outliers:
        ids = ", ".join(str(o.get("pose_id") or f"row {o['row']}") for o in result.outliers[:5])
        out.append(f"{len(result.outliers)} pose(s) were left out as outliers ({html.escape(ids)}): re-check or "
                   "re-measure them; <code>--exclude</code> leaves a pose out on purpose.")
    region = result.robot.region
    if result.validation is not None and region is not None:
        far = region.outside(result.validation.q)
        if result.robot.uncertainty is not None and region.sigma_mm:  # where the model knows less, by its σ
            from ..model.region import SIGMA_FACTOR
            from ..model.uncertainty import known_targets, predicted_sigma

            v = result.validation
            loose = predicted_sigma(result.robot, v.q, known_targets(result.robot, v), v.inputs, v.chain) > \
                SIGMA_FACTOR * region.sigma_mm
            far = np.where(loose[:, None], far, 0.0)
        if np.any(far > 0):
            j = int(np.argmax(far.max(axis=0)))
            out.append(f"{int(np.sum(far.max(axis=1) > 0))} validation pose(s) lie outside the joint ranges calibrated "
                       f"on where the model knows its TCP less well, joint {j + 1} most: measure calibration poses "
                       "that cover its range.")
    if meas is not None and meas.n_poses < 5 * len(result.names):
        out.append(f"{meas.n_poses} poses for {len(result.names)} parameters: about {5 * len(result.names)} would "
                   "pin them down better.")
    if out:
        return out[:MOST]
    if headline is None or floor is None:
        return ["No diagnostic calls for more. The instrument's noise is not stated (sx, sy, sz columns, or "
                "<code>--instrument</code>), so how far the model's figure lies above it is not known."]
    return [f"Nothing calls for more: the model predicts {headline[1]:.3g} mm RMS {headline[0]}, within "
            f"{FLOOR_GAP:g}× the instrument's own {floor:.3g} mm, and its predicted TCP uncertainty over the "
            f"calibrated joint ranges is near that at the measured poses."]


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
    parts += ["<h2>What to do next</h2>"] + [f"<p class='next'>{s}</p>" for s in next_steps(result)]
    parts += _exports(result)
    cols = result.accuracy_columns()
    contact = _contact(result)
    parts.append("<h2>Accuracy</h2><p>“Before” is the nominal geometry with the registered frames; “after (fit)” "
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
    drawn, phases, marks = len(opt.history), opt.extra.get("history_phases"), None
    if result.config.spec.swarm is not None:  # a point per generation, each evaluating every particle
        said = [f"one point per generation of the swarm and per residual evaluation of the LM after it "
                f"({drawn} points; {opt.nfev} objective evaluations in all, a generation evaluating every particle)"]
        drawn = opt.nfev
    else:
        said = [f"{drawn} of the {opt.nfev} residual evaluations are drawn" if drawn < opt.nfev else
                f"all {drawn} residual evaluations are drawn"]
    if phases and len(phases) == 2 and phases[1] and sum(phases) <= drawn:
        marks = {phases[0] - 0.5: "with the prior"}
        said.append(f"the first {phases[0]} fit the data alone, for the scale of their noise, the next {phases[1]} fit "
                    "with the prior weighed by that noise (its χ² is on those weights: the curve steps there)")
    if drawn < opt.nfev:
        said.append(f"the other {opt.nfev - drawn}, refits after reweighting by the estimated or the instrument's "
                    "noise, are not (χ² under other weights is another scale), so the last point is not the final "
                    "χ²")
    parts.append(f"<p>{'; '.join(said).capitalize()}.</p>")
    parts.append(_img(figures.convergence({result.method: opt.history}, f"{result.method}: best objective",
                                          objective_label(result), figures.iteration_label([result.method]),
                                          marks)))
    parts += _parameter_tables(result, d)
    parts.append("<p>Generated by robocal.</p></body></html>")
    return "\n".join(parts)


def write_report(result: CalibrationResult, path: str | Path, command: str | None = None) -> None:
    """Write :func:`calibration_html` of ``result`` to ``path``; command: the command line, for its header."""
    atomic_write(path, calibration_html(result, command))
