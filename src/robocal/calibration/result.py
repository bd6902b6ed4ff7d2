"""The result of a calibration, and its JSON (MODEL §5)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write
from ..math.se3 import transform_to_xyz_rpy
from ..model.kinematics import joint_parameter_names
from ..model.measurements import Measurements
from ..model.metrics import Metrics
from ..model.parameters import is_frame, unit
from ..model.prior import HELD
from ..model.robot import Robot
from ..model.terms import reported_unit
from ..model.uncertainty import UncertaintyMap, tcp_map
from ..optimize.result import OptimizeResult
from .config import CalibrationConfig
from .exports import ExportFigures, export
from .fit.instrument import InstrumentFit
from .fit.noise import NoiseEstimate
from .judge.diagnostics import GoodnessOfFit, Physicality
from .judge.identifiability import Identifiability
from .judge.judgement import AtEstimate
from .select.crossval import Scheme

#: version of the result JSON; 2 added ``schema_version``, the structured ``dropped`` reasons
#: (kind, related), ``optimizer.method`` naming the solver that ran, status ``completed``,
#: ``noise``, ``goodness_of_fit``, and per parameter ``absorbs`` and ``significant``; 3 added
#: ``model``, ``model_selection``, ``error_budget``, ``residual_model`` and joint-term
#: parameters (``compliance1``, ``gravity2_3x``, ``harmonic1_cos1``, …, with their units); 4
#: (migration: ``time_s`` was the whole call and is now the optimizers' wall time, the whole call
#: is ``timings.total_s``) added ``timings`` {load_s, compile_s, optimize_s, statistics_s,
#: model_s, evaluate_s, total_s}, ``region`` and ``fallback``; 5 added ``instrument`` (the
#: misfit against the instrument's own σ per point), ``noise.meaning`` and the joint terms
#: ``backlash1..N`` (deg) and ``drift1..N`` (deg/h or deg/1000 rows), ``tcp_uncertainty`` (the
#: predicted position's σ over the calibrated region: points, median_mm, p95_mm, max_mm); 6 dropped
#: ``fallback`` (the whole model is used everywhere), ``region`` gained ``sigma_mm`` and
#: ``tcp_uncertainty`` counts the residual process's own variance; 7 added the prior (per parameter
#: ``prior_sigma``, ``prior_share``, ``pinned_by``; ``held_by_prior``), ``physical`` (the verdict),
#: ``exports`` (what a TOML, a URDF and a YAML hand their receivers) and ``identifiability.at_estimate``;
#: ``goodness_of_fit.dof`` counts the parameters' effective number and a plane row as one value;
#: 8 split ``notes`` (information: choices made, frames registered, sources read) from ``warnings``
#: (something to act on, or a reason to doubt a figure), and marks screened ladder rows; 9 added
#: camera rows: ``metrics.*.unit`` (``px`` where every row is a camera's), the headline's ``unit``,
#: ``rms`` and ``max`` (``position_rms_mm``/``position_max_mm`` only where it is a length) and the
#: cameras' frames (``camera[NAME]`` with ``link``, ``known`` and, for a rig's camera, ``of``: its pose
#: is in that camera's frame) in ``frames_*``
SCHEMA_VERSION = 9
#: a deviation smaller than this many standard uncertainties is "not significant"
SIGNIFICANCE_SIGMAS = 2.0


@dataclass(frozen=True)
class LadderRow:
    """One rung of ``--model auto``: its cross-validated position RMS (mm), its parameter count,
    for a residual process the points it is conditioned on, and with validation data its
    position RMS there (mm; a residual process's only for the one chosen, the one fitted).
    ``screened``: a residual process judged by its screen alone (a kernel tuned on fewer poses,
    not re-tuned per fold), which lost clearly and was not tuned in full."""

    model: str
    cv_rms_mm: float
    n_params: int
    residual_points: int | None = None
    validation_rms_mm: float | None = None
    screened: bool = False

    def to_dict(self) -> dict:
        out = {"model": self.model, "cv_rms_mm": self.cv_rms_mm, "n_params": self.n_params}
        if self.validation_rms_mm is not None:
            out["validation_rms_mm"] = self.validation_rms_mm
        if self.screened:
            out["screened"] = True
        return out if self.residual_points is None else {**out, "residual_points": self.residual_points}


@dataclass(frozen=True)
class BudgetRow:
    """One stage of the error budget: the validation position RMS (mm) with it, and what it
    removed from the stage before (None for the first); axes_mm: the RMS of each axis (x, y, z
    of the measuring frame, mm), where the stage is a model."""

    model: str
    validation_rms_mm: float
    removed_mm: float | None
    axes_mm: tuple[float, float, float] | None = None

    def to_dict(self) -> dict:
        out = {"model": self.model, "validation_rms_mm": self.validation_rms_mm, "removed_mm": self.removed_mm}
        return out if self.axes_mm is None else {**out, "axes_rms_mm": dict(zip("xyz", self.axes_mm))}


@dataclass
class CalibrationResult:
    """Everything a calibration produced.  :meth:`to_dict` gives the JSON of MODEL §5.

    robot: the calibrated robot (frames included); initial: nominal geometry with the
    registered frames; nominal: the robot as given; names/x/uncertainty: the identified
    parameters, their deviations from ``initial`` (mm, rad) and standard uncertainties
    (None where not computed); optimization: the optimizer's own result.  model: what the
    model holds beyond geometry (``geometric``, ``compliance+harmonics``, …); model_selection:
    the ladder of ``--model auto``; error_budget: what each part removes on the validation
    poses; geometric: the geometric calibration beside a richer model, when one was fitted.
    """

    config: CalibrationConfig
    robot: Robot
    initial: Robot
    nominal: Robot
    names: list[str]
    x: np.ndarray
    uncertainty: np.ndarray | None
    identifiability: Identifiability
    optimization: OptimizeResult
    metrics: dict[str, Metrics]
    data: str = ""
    n_poses: int = 0
    full_pose: bool = False
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    time_s: float = 0.0
    timings: dict = field(default_factory=dict)
    measurements: Measurements | None = field(default=None, repr=False)
    validation: Measurements | None = field(default=None, repr=False)
    outliers: list[dict] = field(default_factory=list)
    reexpression_gap_mm: float | None = None
    noise: NoiseEstimate | None = None
    goodness_of_fit: GoodnessOfFit | None = None
    covariance: np.ndarray | None = field(default=None, repr=False)
    frames: str = "none"
    model: str = "geometric"
    model_selection: list[LadderRow] = field(default_factory=list)
    error_budget: list[BudgetRow] = field(default_factory=list)
    geometric: Robot | None = field(default=None, repr=False)
    instrument: InstrumentFit | None = None
    #: every calibration pose the data gave (outliers included), and the poses left out as asked
    all_rows: Measurements | None = field(default=None, repr=False)
    excluded: tuple[str, ...] = ()
    #: data whose rows touched unknown points or planes: their figures (point_spread_rms,
    #: plane_rms, distance_error_rms, mm) per set, ``before``/``after``/``validation_…``
    contact: dict = field(default_factory=dict)
    #: each identified parameter's prior σ (its own units; inf: free) and prior share (0: the data
    #: alone pin it; above :data:`robocal.model.prior.HELD`: held by its prior), None without a prior
    prior_sigma: np.ndarray | None = field(default=None, repr=False)
    prior_share: np.ndarray | None = field(default=None, repr=False)
    #: the verdict on whether the model is physical (:func:`robocal.calibration.judge.diagnostics.physicality`)
    physical: Physicality = field(default_factory=Physicality)
    #: the kept set's identifiability where the fit ended (:class:`~robocal.calibration.judge.judgement.AtEstimate`)
    at_estimate: AtEstimate | None = None
    #: what each kind of export hands its receiver (:class:`ExportFigures`), and what a URDF or a
    #: kinematics YAML carries (:func:`robocal.calibration.pipeline.geometry_for_receivers`)
    exports: ExportFigures | None = None
    #: data with camera rows: their reprojection RMS (px), over all and per camera, before/after and
    #: on validation data (:func:`robocal.model.metrics.camera_figures`)
    cameras: dict = field(default_factory=dict)
    #: rows of several kinds, each weighed by its own σ: that σ by kind (tracker, contact: mm;
    #: camera: px), else empty
    kind_sigma: dict = field(default_factory=dict)
    receiver: Robot | None = field(default=None, repr=False)
    #: how the held-out figures were made (:class:`~robocal.calibration.select.crossval.Scheme`)
    cross_validation: Scheme | None = None

    @property
    def held_out(self) -> str:
        """What the cross-validated figure predicts, and how: "a new session (leave-one-session-out,
        10 sessions)"."""
        s = self.cross_validation
        return "new poses (5-fold cross-validation of the calibration poses)" if s is None else s.held_out

    @property
    def selection_title(self) -> str:
        """What the model-selection table's figures are: "leave-one-session-out reprojection RMS (px)
        on the calibration data"."""
        s = self.cross_validation
        how = "5-fold cross-validated" if s is None else (f"{s.short}" if s.kind == "sessions" else
                                                          f"{s.k}-fold cross-validated")
        what = "reprojection" if self.unit == "px" else "position"
        return f"{how} {what} RMS ({self.unit}) on the calibration data"

    @property
    def held(self) -> list[str]:
        """The parameters the poses do not pin: their prior tells more of them than the data do."""
        if self.prior_share is None:
            return []
        return [n for n, h in zip(self.names, self.prior_share) if h > HELD]

    def headline(self) -> tuple[str, str, Metrics]:
        """The figure to lead with: (key, label, metrics): accuracy on the validation poses when
        given, else the cross-validated prediction, else (a model returned unchanged) the fit."""
        for key, label in (("validation_after", "on the validation poses"),
                           ("predicted", f"predicted on {self.held_out}")):
            if key in self.metrics:
                return key, label, self.metrics[key]
        return "after", "the fit itself (in-sample: not a prediction)", self.metrics["after"]

    def accuracy_columns(self) -> dict[str, Metrics]:
        """The metrics a table shows, labelled as what they are: the fit in-sample, the
        prediction from held-out folds, the validation poses."""
        m = self.metrics
        cols = {"before": m["before"]}
        if "predicted" in m:
            cols[f"predicted ({self.cross_validation.short if self.cross_validation else '5-fold CV'})"] = \
                m["predicted"]
        cols["after (fit)"] = m["after"]
        if "validation_before" in m:
            cols["validation before"], cols["validation after"] = m["validation_before"], m["validation_after"]
        return cols

    def figures(self) -> dict[str, float]:
        """The figures ``--require`` can hold a calibration to (mm): rms and max of the fit,
        cv_rms of the cross-validated prediction, validation_rms and validation_max; a figure
        the run has not got is NaN (and fails any requirement)."""
        m, nan = self.metrics, float("nan")
        pick = {"rms": ("after", "rms"), "max": ("after", "max"), "cv_rms": ("predicted", "rms"),
                "validation_rms": ("validation_after", "rms"), "validation_max": ("validation_after", "max")}
        out = {k: m[key].position[f] if key in m else nan for k, (key, f) in pick.items()}
        return {**out, "physical": self.physical.physical,
                "physical_reason": f"the calibrated model is not physical: {self.physical.listed()}"}

    def headline_text(self) -> str:
        """One line: the honest figure first, the fit beside it, labelled as what it is."""
        key, label, m = self.headline()
        fit = self.metrics["after"].position
        what = "position RMS" if not self.contact else "point spread RMS" if any(  # rows that touched points
            "point_spread_rms" in f for f in self.contact.values()) else "distance from the planes RMS"  # or planes
        unit = self.unit
        if unit == "px":
            what = "reprojection RMS"
        text = f"{what} {m.position['rms']:.4f} {unit}, max {m.position['max']:.4f} {unit} {label}"
        if m.at_marker is not None:  # what the pixels mean at the tool
            text = (f"{what} {m.position['rms']:.4f} {unit} ({m.at_marker['rms']:.3g} mm at the markers), max "
                    f"{m.position['max']:.4f} {unit} {label}")
        if key != "after":
            text += f"; the fit itself {fit['rms']:.4f} {unit} (in-sample)"
        if not self.physical.physical:  # the figure is not the model: a controller loads the model
            text += f"; the model is not physical ({self.physical.listed()}): check it before use"
        return text

    def headline_dict(self) -> dict:
        """The headline figure for the JSON: its key, unit, RMS and max (``position_rms_mm`` and
        ``position_max_mm`` too where it is a length)."""
        key, _, m = self.headline()
        out = {"figure": key, "unit": self.unit, "rms": m.position["rms"], "max": m.position["max"]}
        if m.at_marker is not None:
            out["at_marker_rms_mm"] = m.at_marker["rms"]
        if self.unit == "mm":
            out.update(position_rms_mm=m.position["rms"], position_max_mm=m.position["max"])
        return out

    @property
    def unit(self) -> str:
        """The unit of the position figures: mm, or px where every row is a camera's (reprojection)."""
        return "mm" if self.measurements is None else self.measurements.unit

    def per_pose(self) -> list[dict]:
        """Every calibration pose (outliers flagged) and validation pose, with the calibrated
        model's errors (:func:`robocal.model.metrics.per_pose`) and, where the model carries its
        covariance, its predicted position uncertainty (``sigma_mm``)."""
        from ..model.metrics import per_pose
        from ..model.uncertainty import known_targets, predicted_sigma

        rows = []
        meas = self.all_rows if self.all_rows is not None else self.measurements
        sets = ([(meas, "calibration", frozenset(o["row"] for o in self.outliers))] if meas is not None else []) + \
            ([(self.validation, "validation", frozenset())] if self.validation is not None else [])
        for m, label, outliers in sets:
            part = per_pose(self.robot, m, label, outliers)
            if self.robot.uncertainty is not None:
                sigma = predicted_sigma(self.robot, m.q, known_targets(self.robot, m), m.inputs, m.chain)
                for row, s in zip(part, sigma):
                    row["sigma_mm"] = float(s)
            rows += part
        return rows

    @cached_property
    def tcp_uncertainty(self) -> UncertaintyMap | None:
        """The predicted TCP's σ over the calibrated region and at the calibration poses
        (:func:`robocal.model.uncertainty.tcp_map`), worked out when first asked for."""
        if self.measurements is None:
            return None
        return tcp_map(self.robot, self.measurements, self.config.seed, self.config.map_over)

    @property
    def method(self) -> str:
        return self.config.method

    @property
    def seed(self) -> int | None:
        return self.config.seed

    @property
    def objective(self) -> str:
        return "sum_squares" if self.config.spec.swarm is None else self.config.objective_kind

    def parameter(self, name: str) -> float:
        """Identified deviation of one parameter (mm or rad)."""
        return float(self.x[self.names.index(name)])

    def deviations(self) -> dict[str, float]:
        """Identified deviations {name: value} (mm, rad)."""
        return dict(zip(self.names, map(float, self.x)))

    def per_target_metrics(self) -> dict[str, dict[str, Metrics]]:
        """Before/after (and validation) metrics of each reflector, when the data have several."""
        if self.measurements is None or len(self.measurements.target_names) < 2:
            return {}
        if self.robot.tree is not None and set(self.measurements.target_names) <= set(self.robot.tree.names):
            return {}  # each chain's own tool: the per-chain figures say it
        out: dict[str, dict[str, Metrics]] = {}
        val = {} if self.validation is None else self.validation.by_target()
        for t, m in self.measurements.by_target().items():
            name, _, session = t.rpartition("@") if self.robot.session_bases and "@" in t else (t, "", "")
            name = (name or "(tool)") + (f" (session {session})" if session else "")
            out[name] = {"before": Metrics.of(self.initial, m), "after": Metrics.of(self.robot, m)}
            if t in val and not self.robot.session_bases:  # (a session of its own: registered as a whole)
                out[name]["validation_before"] = Metrics.of(self.initial, val[t])
                out[name]["validation_after"] = Metrics.of(self.robot, val[t])
        return out

    def per_chain_metrics(self) -> dict[str, dict[str, Metrics]]:
        """Before/after (and validation) metrics of each chain of a tree that has rows (px or mm, with
        mm at the markers for camera rows); empty for a serial robot."""
        tree, meas = self.robot.tree, self.measurements
        if tree is None or meas is None or meas.chain is None:
            return {}
        out: dict[str, dict[str, Metrics]] = {}
        for name in tree.names:
            for key, data, robot in (("before", meas, self.initial), ("after", meas, self.robot),
                                     ("validation_before", self.validation, self.initial),
                                     ("validation_after", self.validation, self.robot)):
                rows = [] if data is None else [i for i, c in enumerate(data.chain or ()) if c == name]
                if rows:
                    out.setdefault(name, {})[key] = Metrics.of(robot, data.subset(rows))
        return {k: v for k, v in out.items() if "after" in v}

    def significant(self, i: int) -> bool | None:
        """|deviation| ≥ 2 standard uncertainties (None where no uncertainty is known)."""
        if self.uncertainty is None or not math.isfinite(self.uncertainty[i]):
            return None
        return bool(abs(self.x[i]) >= SIGNIFICANCE_SIGMAS * self.uncertainty[i])

    @property
    def k(self) -> float | None:
        """The orientation weight the fit used, (σp/σr)² in mm²/rad² (None for position data)."""
        if self.noise is None or self.noise.orientation is None:
            return None
        return (self.noise.position / self.noise.orientation) ** 2

    def to_dict(self) -> dict:
        ident = self.identifiability
        initial_values = nominal_values(self.initial)
        params = []
        for i, n in enumerate(self.names):
            nominal = initial_values.get(n, 0.0)
            shown, scale = reported_unit(n, self.robot.terms) or (unit(n), 1.0)
            prior = {}
            if self.prior_sigma is not None:
                sigma = float(self.prior_sigma[i])
                prior = {"prior_sigma": _finite_or_none(scale * sigma),
                         "prior_share": None if self.prior_share is None else float(self.prior_share[i]),
                         "pinned_by": "free" if not math.isfinite(sigma) else "prior" if n in self.held else "data"}
            params.append({
                "name": n, "unit": shown, "nominal": scale * nominal, "error": scale * float(self.x[i]),
                "value": scale * (nominal + float(self.x[i])),
                "uncertainty": None if self.uncertainty is None else _finite_or_none(scale * self.uncertainty[i]),
                "significant": self.significant(i),
                "absorbs": [{"name": d, "coefficient": c} for d, c in ident.absorbed_by(n)],
                **prior,
                # frame parameters are deviations from the closed-form registration, not from a file value
                **({"relative_to": "registration"} if is_frame(n) else {}),
            })
        opt = self.optimization
        cfg = self.config
        return {
            "schema_version": SCHEMA_VERSION,
            "method": cfg.method,
            "seed": cfg.seed,
            "objective": self.objective,
            "k_mm2_per_rad2": self.k,
            "noise": None if self.noise is None else self.noise.to_dict(),
            "goodness_of_fit": None if self.goodness_of_fit is None else self.goodness_of_fit.to_dict(),
            "physical": self.physical.to_dict(),
            "exports": None if self.exports is None else self.exports.to_dict(),
            "held_by_prior": self.held,
            "instrument": None if self.instrument is None else self.instrument.to_dict(),
            "excluded": list(self.excluded),
            "tcp_uncertainty": None if self.tcp_uncertainty is None else self.tcp_uncertainty.summary(),
            "loss": cfg.loss,
            "model": self.model,
            "model_selection": [r.to_dict() for r in self.model_selection],
            "cross_validation": None if self.cross_validation is None else self.cross_validation.to_dict(),
            "error_budget": [r.to_dict() for r in self.error_budget],
            "residual_model": None if self.robot.residual is None else self.robot.residual.summary(),
            "region": None if self.robot.region is None else self.robot.region.to_dict(),
            "frames": self.frames,
            "frames_requested": cfg.frames,
            "robot": self.nominal.name,
            "data": self.data,
            "n_poses": self.n_poses,
            "poses": None if self.measurements is None else self.measurements.describe(),
            "measure": "pose" if self.full_pose else "position",
            "parameters": params,
            "dropped": [{"name": n, "reason": ident.reasons[n].text(), **ident.reasons[n].to_dict()}
                        for n in ident.dropped],
            "identifiability": {**ident.to_dict(),
                                **({} if self.at_estimate is None else {"at_estimate": self.at_estimate.to_dict()})},
            "headline": self.headline_dict(),
            "metrics": {k: v.to_dict() for k, v in self.metrics.items()},
            **({"contact": dict(self.contact)} if self.contact else {}),
            **({"cameras": dict(self.cameras)} if self.cameras else {}),
            **({"sigma_by_kind": dict(self.kind_sigma)} if self.kind_sigma else {}),
            "metrics_per_target": {t: {k: v.to_dict() for k, v in m.items()}
                                   for t, m in self.per_target_metrics().items()},
            **({"metrics_per_chain": {c: {k: v.to_dict() for k, v in m.items()}
                                      for c, m in self.per_chain_metrics().items()}} if self.robot.tree else {}),
            "frames_registered": frames_dict(self.initial),
            "frames_identified": frames_dict(self.robot),
            "status": opt.status,
            "success": opt.success,
            "message": opt.message,
            "objective_value": opt.fun,
            "iterations": opt.nit,
            "evaluations": opt.nfev,
            "optimizer": {"method": opt.method, "time_s": opt.time_s, **_plain(opt.extra),
                          "reexpression_gap_mm": self.reexpression_gap_mm},
            "history": [float(h) for h in opt.history],
            "outliers": list(self.outliers),
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "time_s": self.time_s,
            "timings": dict(self.timings),
        }

    def save(self, path: str | Path) -> None:
        atomic_write(path, json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")

    def export(self, path: str | Path) -> list[Path]:
        """Write the calibrated robot as a robot file (loadable again), with its residual model in
        a sibling file when it has one; the paths written (:func:`robocal.calibration.exports.export`).
        A ``.urdf`` path writes a URDF (see :mod:`robocal.io.urdf`); joint terms and a residual model
        cannot live in one, so the whole model goes to a robot TOML beside it, ``NAME.robocal.toml``,
        as well."""
        return export(self, path)


def _finite_or_none(v: float):
    return float(v) if math.isfinite(v) else None


def _plain(d: dict) -> dict:
    """JSON-safe copy of optimizer extras (numpy scalars and arrays become Python values)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = _plain(v)
        elif isinstance(v, np.ndarray):
            out[k] = v.tolist()
        elif isinstance(v, (np.floating, float)):
            out[k] = _finite_or_none(float(v))
        elif isinstance(v, np.integer):
            out[k] = int(v)
        else:
            out[k] = v
    return out


def nominal_values(robot: Robot) -> dict[str, float]:
    """Joint geometry and joint terms of a robot by parameter name (mm, rad, rad/(N·m))."""
    out: dict[str, float] = {}
    for i, names in enumerate(joint_parameter_names(robot.convention, robot.geometry)):
        out.update(zip(names, map(float, robot.geometry[i, :len(names)])))
    if robot.terms is not None and not robot.terms.empty:
        spec = robot.terms.spec()
        out.update(zip(spec.names(robot.n_joints), map(float, robot.terms.vector(spec, robot.n_joints))))
    return out


def frames_dict(robot: Robot) -> dict:
    """Base and tool frames as xyz (mm) and rpy (deg)."""

    def one(T):
        xyz, rpy = transform_to_xyz_rpy(T)
        return {"xyz_mm": [float(v) for v in xyz], "rpy_deg": [float(v) for v in np.degrees(rpy)]}

    out = {"base": one(robot.base), "tool": one(robot.tool)}
    for name, T in robot.targets.items():
        out[f"tool[{name}]"] = one(T)
    for name, mount in robot.cameras.items():  # in the measuring frame, or its link's frame
        out[f"camera[{name}]"] = {**one(mount.pose), "link": mount.link, "known": mount.known,
                                  **({"of": mount.of} if mount.of else {})}
    return out
