"""A single self-contained HTML report of a calibration (figures embedded, no network)."""

from __future__ import annotations

import base64
import html
from pathlib import Path

from ..calibration.result import CalibrationResult
from ..cli.calibrate import noise_line
from ..io.atomic import atomic_write
from ..model.metrics import Metrics, pose_errors
from . import figures
from .tables import FRAME_COLUMNS, PARAMETER_COLUMNS, frame_rows, parameter_rows

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1000px;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td:first-child,th:first-child{text-align:left}img{max-width:100%}
td.l{text-align:left}.warn{background:#fff4e0;border-left:4px solid #e90;padding:.4em .8em}code{background:#f4f4f4}
"""


def _img(fig) -> str:
    data = base64.b64encode(figures.png_bytes(fig)).decode("ascii")
    return f'<img alt="figure" src="data:image/png;base64,{data}">'


def _metrics_table(columns: dict[str, Metrics]) -> str:
    rows = [m.rows() for m in columns.values()]
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(
        f"<tr><td>{html.escape(label)}</td>" + "".join(f"<td>{r[i][1]:.4f}</td>" for r in rows) + "</tr>"
        for i, (label, _) in enumerate(rows[0])
    )
    return f"<table><tr><th>error</th>{head}</tr>{body}</table>"


def _summary(result: CalibrationResult, d: dict) -> str:
    return (f"<p>Method <b>{html.escape(result.method)}</b> (objective {html.escape(d['objective'])}, seed "
            f"{result.seed}), frames <code>{html.escape(result.config.frames)}</code>, {result.n_poses} poses "
            f"({'full pose' if result.full_pose else 'position only'}) from <code>{html.escape(result.data)}</code>. "
            f"Status: {html.escape(d['status'])} after {d['iterations']} iterations, {d['evaluations']} evaluations, "
            f"{d['time_s']:.2f} s.</p>")


def _error_figures(result: CalibrationResult) -> list[str]:
    parts = []
    if result.measurements is not None:
        dp0, dr0 = pose_errors(result.initial, result.measurements)
        dp1, dr1 = pose_errors(result.robot, result.measurements)
        parts.append("<h2>Per-pose errors (calibration data)</h2>")
        parts.append(_img(figures.position_errors(dp0, {result.method: dp1}, "calibration poses")))
        parts.append(_img(figures.axis_errors(dp1, f"after {result.method}")))
        if dr0 is not None:
            parts.append(_img(figures.orientation_errors(dr0, dr1, "calibration poses")))
    if result.validation is not None:
        dp0, _ = pose_errors(result.initial, result.validation)
        dp1, _ = pose_errors(result.robot, result.validation)
        parts.append("<h2>Validation poses (not used to identify)</h2>")
        parts.append(_img(figures.position_errors(dp0, {result.method: dp1}, "validation poses")))
    return parts


def _table(columns, rows, left: int = 1) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td{' class=l' if i < left or i == len(r) - 1 else ''}>{html.escape(v)}</td>"
                                    for i, v in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _parameter_tables(result: CalibrationResult, d: dict) -> list[str]:
    parts = ["<h2>Identified parameters</h2><p>Lengths in mm, angles in degrees; ± σ is the standard "
             "uncertainty. A regrouped parameter estimates the combination shown.</p>",
             _table(PARAMETER_COLUMNS, parameter_rows(result)), "<h2>Parameters not identified</h2>"]
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


def calibration_html(result: CalibrationResult) -> str:
    """The report of one calibration as a self-contained HTML page."""
    d = result.to_dict()
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>robocal calibration</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>Calibration of {html.escape(result.nominal.name)}</h1>",
             _summary(result, d)]
    parts += [f"<p class='warn'>{html.escape(w)}</p>" for w in result.warnings]
    cols = {"before": result.metrics["before"], "after": result.metrics["after"]}
    if "validation_before" in result.metrics:
        cols["validation before"] = result.metrics["validation_before"]
        cols["validation after"] = result.metrics["validation_after"]
    parts.append("<h2>Accuracy</h2><p>“Before” is the nominal geometry with the registered frames.</p>")
    parts.append(_metrics_table(cols))
    parts += _error_figures(result)
    parts.append("<h2>Convergence</h2>")
    parts.append(_img(figures.convergence({result.method: result.optimisation.history}, "best objective")))
    parts += _parameter_tables(result, d)
    parts.append("<p>Generated by robocal.</p></body></html>")
    return "\n".join(parts)


def write_report(result: CalibrationResult, path: str | Path) -> None:
    """Write :func:`calibration_html` of ``result`` to ``path``."""
    atomic_write(path, calibration_html(result))
