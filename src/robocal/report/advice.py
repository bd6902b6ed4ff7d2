"""What to do next after a calibration: at most three concrete suggestions from the figures the
report shows, the most pressing first (the report's "What to do next", and the terminal's "next"
lines under the headline: one text for both, code in backticks)."""

from __future__ import annotations

import html
import re

import numpy as np

from ..calibration.result import CalibrationResult
from ..model.parameters import is_frame
from ..model.uncertainty import in_base

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
        out.append(f"The calibrated model is not physical: {(result.physical.listed())} (likely cause: "
                   f"{(result.physical.cause)}). Do not load it into a controller: check the nominal model, "
                   "and measure poses that move the joints these parameters belong to.")
    headline, floor = _headline(result), _floor(result)
    if headline is not None and floor is not None and headline[1] > FLOOR_GAP * floor:
        what, figure = headline
        if result.model == "geometric":
            act = ("calibrate with `--model auto` to try joint terms (compliance, harmonics, backlash, "
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
            where = "Over the measured poses' workspace" if m.over == "workspace" else \
                "Over the calibrated joint ranges"
            x, y, z = in_base(result.robot, m.brightest())
            out.append(f"{where} the predicted TCP uncertainty is {summary['median_mm']:.3g} mm (median; 95 % "
                       f"below {summary['p95_mm']:.3g} mm), {summary['median_mm'] / at:.1f}× that at the measured "
                       "poses: the model is sure of itself only near them. Its largest tenth lies around x "
                       f"{x:.0f}, y {y:.0f}, z {z:.0f} mm (base frame): measure poses there before relying on the "
                       "model across the workspace.")
    tied = _tied_to_cameras(result)
    if tied:
        out.append(f"{(', '.join(tied))} cannot be told from where the cameras, the base and the markers "
                   "are, nor from the lengths' common scale: the pixels see the same whichever takes the difference, "
                   "so the prior holds it (MODEL §10). No pose separates them; a camera's pose known by other means "
                   "(--camera-pose), markers of known offsets or sizes (--markers), or tracker rows would.")
    held = [n for n in result.held if n not in tied]
    if held:
        many = len(held) > 1
        out.append(f"The poses do not pin {(', '.join(held))}: {'they are' if many else 'it is'} "
                   f"held by {'their' if many else 'its'} prior (the nominal value within its width, MODEL §3.1), not "
                   f"measured. Poses that move {'their' if many else 'its'} joints more widely would measure "
                   f"{'them' if many else 'it'}.")
    g, inst = result.goodness_of_fit, result.instrument
    if result.model == "geometric" and floor is None and ((g is not None and g.misfit()) or (
            inst is not None and inst.reduced_chi2 and inst.reduced_chi2 > 4)):
        beyond = "" if inst is None else f" ({inst.reduced_chi2:.3g}× the instrument's noise in χ²)"
        out.append(f"The geometric model leaves systematic error{beyond}: calibrate with `--model auto` "
                   "to try joint terms (compliance, harmonics, backlash, drift) and a residual process.")
    if result.outliers:
        ids = ", ".join(str(o.get("pose_id") or f"row {o['row']}") for o in result.outliers[:5])
        out.append(f"{len(result.outliers)} pose(s) were left out as outliers ({(ids)}): re-check or "
                   "re-measure them; `--exclude` leaves a pose out on purpose.")
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
                "`--instrument`), so how far the model's figure lies above it is not known."]
    return [f"Nothing calls for more: the model predicts {headline[1]:.3g} mm RMS {headline[0]}, within "
            f"{FLOOR_GAP:g}× the instrument's own {floor:.3g} mm, and its predicted TCP uncertainty over the "
            f"calibrated joint ranges is near that at the measured poses."]


def as_html(text: str) -> str:
    """A suggestion as HTML: escaped, its `code` in <code>."""
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", html.escape(text))
