"""The calibration pipeline: nominal robot + measurements → calibrated robot and honest figures.

Steps: register the measuring frame (and tool offsets) in closed form; choose the
candidate parameters; keep the identifiable subset (dropping the rest with a
reason); minimise the objective with the chosen method; estimate standard
uncertainties; report before/after metrics on the calibration data and, when
given, on validation data.

"Before" figures use the nominal joint geometry with the registered frames, i.e.
the best a rigid re-mounting of the nominal model can do, so that the improvement
shown is the calibration's own and not that of finding the tracker frame.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .errors import InputError, RobocalWarning, atomic_write
from .frames import FRAME_MODES, register_frames
from .identifiability import Identifiability, analyse
from .kinematics import Robot
from .measurements import Measurements, load_measurements
from .metrics import Metrics
from .objectives import DEFAULT_K, OBJECTIVES, Problem
from .optimizers import (
    IPSO_DEFAULTS,
    LDPSO_DEFAULTS,
    METHODS,
    PSO_DEFAULTS,
    OptimizeResult,
    Progress,
    ipso,
    ldpso_bt,
    levenberg_marquardt,
    pso,
)
from .parameters import FRAME_AXES, ParameterSpace, is_angle, joint_kinds, tool_prefix
from .robotfile import load_robot, robot_to_toml
from .simulate import parallel_pairs

#: Wen et al. (2019) §1.2: the 24 errors identified for the ER10L-C10 (axes 2 ∥ 3)
WEN2019_PARAMS = (
    [f"a{i}" for i in range(1, 7)]
    + ["d1"] + [f"d{i}" for i in range(3, 7)]
    + [f"alpha{i}" for i in range(1, 7)]
    + ["beta2"]
    + [f"theta{i}" for i in range(1, 7)]
)  # fmt: skip

#: default swarm search box per method: (± mm, ± rad) around the initial estimate
SWARM_BOX = {"ipso": (0.5, 0.01), "hybrid": (0.5, 0.01), "pso": (0.25, 0.05), "ldpso-bt": (0.25, 0.05)}
#: swarms search frame parameters at least this far (mm, rad) around the registration
FRAME_BOX = (5.0, 0.01)
#: default objective of each method (its paper's)
DEFAULT_OBJECTIVE = {
    "lm": "sum_squares",
    "hybrid": "sum_squares",
    "ipso": "sum_squares",
    "pso": "sum_norms",
    "ldpso-bt": "sum_norms",
}
#: generations of the swarm stage of ``hybrid`` (IPSO, paper's 20 particles): enough to
#: land in LM's basin, a fraction of the paper's 2000
HYBRID_GENERATIONS = 300


def joint_candidates(robot: Robot) -> list[str]:
    """Default candidate joint parameters: a, α, θ, d of every joint, plus β of hayati
    joints whose axis is parallel to the next one (where β replaces the ill-defined d)."""
    kinds = [k for k in joint_kinds(robot.convention) if k != "beta"]
    names = [f"{k}{i + 1}" for i in range(robot.n_joints) for k in kinds]
    if robot.convention == "hayati":
        names += [f"beta{i + 1}" for i in parallel_pairs(robot)]
    return names


def frame_candidates(mode: str, targets: Sequence[str], full_pose: bool) -> list[str]:
    names = []
    if mode in ("base", "base+tool"):
        names += [f"base_{a}" for a in FRAME_AXES]
    if mode == "base+tool":
        axes = FRAME_AXES if full_pose else FRAME_AXES[:3]
        for t in targets:
            names += [f"{tool_prefix(t)}_{a}" for a in axes]
    return names


@dataclass
class CalibrationResult:
    """Everything a calibration produced.  ``to_dict`` gives the JSON of SPEC §6.

    robot: the calibrated robot (frames included); initial: nominal geometry with the
    registered frames; names/x/uncertainty: estimated parameters (mm, rad) and their
    standard uncertainties (None where not computed).
    """

    method: str
    seed: int | None
    objective: str
    k: float
    frames: str
    robot: Robot
    initial: Robot
    nominal: Robot
    names: list[str]
    x: np.ndarray
    uncertainty: np.ndarray | None
    identifiability: Identifiability
    optimisation: OptimizeResult
    metrics: dict[str, Metrics]
    loss: str = "linear"
    data: str = ""
    n_poses: int = 0
    full_pose: bool = False
    warnings: list[str] = field(default_factory=list)
    time_s: float = 0.0
    measurements: Measurements | None = field(default=None, repr=False)
    validation: Measurements | None = field(default=None, repr=False)
    outliers: list[dict] = field(default_factory=list)

    def parameter(self, name: str) -> float:
        return float(self.x[self.names.index(name)])

    def errors(self) -> dict[str, float]:
        return dict(zip(self.names, map(float, self.x)))

    def to_dict(self) -> dict:
        ident = self.identifiability
        initial_values = _nominal_values(self.initial)
        params = []
        for i, n in enumerate(self.names):
            nominal = initial_values.get(n, 0.0)
            params.append({
                "name": n,
                "unit": "rad" if is_angle(n) else "mm",
                "nominal": nominal,
                "error": float(self.x[i]),
                "value": nominal + float(self.x[i]),
                "uncertainty": None if self.uncertainty is None else _finite_or_none(self.uncertainty[i]),
            })  # fmt: skip
        opt = self.optimisation
        return {
            "method": self.method,
            "seed": self.seed,
            "objective": self.objective,
            "k_mm2_per_rad2": self.k,
            "loss": self.loss,
            "frames": self.frames,
            "robot": self.nominal.name,
            "data": self.data,
            "n_poses": self.n_poses,
            "measure": "pose" if self.full_pose else "position",
            "parameters": params,
            "dropped": [{"name": n, "reason": ident.reasons[n]} for n in ident.dropped],
            "identifiability": ident.to_dict(),
            "metrics": {k: v.to_dict() for k, v in self.metrics.items()},
            "frames_identified": _frames_dict(self.robot),
            "status": opt.status,
            "message": opt.message,
            "objective_value": opt.fun,
            "iterations": opt.nit,
            "evaluations": opt.nfev,
            "optimiser": {k: v for k, v in opt.extra.items()},
            "history": [float(h) for h in opt.history],
            "outliers": list(self.outliers),
            "warnings": list(self.warnings),
            "time_s": self.time_s,
        }

    def save(self, path: str | Path) -> None:
        import json

        atomic_write(path, json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")

    def export(self, path: str | Path) -> None:
        """Write the calibrated robot as a robot file (loadable again)."""
        atomic_write(
            path,
            robot_to_toml(
                self.robot,
                comment=f"Calibrated by robocal ({self.method}, objective {self.objective}, seed {self.seed}) "
                f"from {self.data or 'measurements'}; {len(self.names)} parameters identified, "
                f"{len(self.identifiability.dropped)} left at nominal.",
            ),
        )


def _finite_or_none(v: float):
    return float(v) if math.isfinite(v) else None


def _nominal_values(robot: Robot) -> dict[str, float]:
    out: dict[str, float] = {}
    kinds = joint_kinds(robot.convention)
    col = {"a": 0, "alpha": 1, "theta": 2, "d": 3, "beta": 4}
    for i in range(robot.n_joints):
        for k in kinds:
            out[f"{k}{i + 1}"] = float(robot.geometry[i, col[k]])
    return out


def _frames_dict(robot: Robot) -> dict:
    from .transforms import transform_to_xyz_rpy

    def one(T):
        xyz, rpy = transform_to_xyz_rpy(T)
        return {"xyz_mm": [float(v) for v in xyz], "rpy_deg": [float(v) for v in np.degrees(rpy)]}

    out = {"base": one(robot.base), "tool": one(robot.tool)}
    for name, T in robot.targets.items():
        out[f"tool[{name}]"] = one(T)
    return out


def _resolve_params(params, robot: Robot, space: ParameterSpace) -> tuple[list[str], bool]:
    """Candidate joint-parameter names and whether the user chose them explicitly."""
    if params is None or params in ("auto", "all"):
        return joint_candidates(robot), False
    if isinstance(params, str):
        if params == "wen2019":
            names = list(WEN2019_PARAMS)
        elif params == "kou2022":
            names = [f"{k}{i + 1}" for i in range(robot.n_joints) for k in ("a", "d", "alpha", "theta")]
        else:
            names = [p.strip() for p in params.split(",") if p.strip()]
    else:
        names = list(params)
    unknown = [n for n in names if n not in space.names]
    if unknown:
        raise InputError(
            f"unknown parameter '{unknown[0]}' for this {robot.convention} robot "
            f"(known: {', '.join(space.names[:8])}, …)",
            source="--params",
        )
    return list(dict.fromkeys(names)), True


def _check_units(robot: Robot, meas: Measurements, frames: str) -> None:
    """Catch metres-for-millimetres and similar: compare the spread of measured points with
    the spread the nominal model predicts for the same joints."""
    model = robot.positions(meas.q, meas.targets if meas.targets and frames == "none" else None)
    spread_m = np.linalg.norm(meas.position - meas.position.mean(0), axis=1).max()
    spread_n = np.linalg.norm(model - model.mean(0), axis=1).max()
    if spread_n > 10 and spread_m < spread_n / 100:
        raise InputError(
            f"measured points spread over {spread_m:.4g} but the robot predicts {spread_n:.4g} mm: "
            "positions look like metres; measurement files give mm",
            source=meas.source,
        )
    if spread_n > 10 and spread_m > spread_n * 100:
        raise InputError(
            f"measured points spread over {spread_m:.4g} but the robot predicts {spread_n:.4g} mm: "
            "positions look like µm or wrong units; measurement files give mm",
            source=meas.source,
        )


def _load(robot, data, n_joints=None) -> Measurements:
    if isinstance(data, Measurements):
        if n_joints is not None and data.n_joints != n_joints:
            raise InputError(f"data have {data.n_joints} joints, the robot has {n_joints}", source=data.source)
        return data
    return load_measurements(data, n_joints=n_joints)


def calibrate(
    robot: str | Path | Robot,
    data: str | Path | Measurements,
    method: str = "lm",
    *,
    frames: str = "none",
    params: str | Sequence[str] | None = None,
    validate: str | Path | Measurements | None = None,
    seed: int | None = 0,
    objective: str | None = None,
    k: float = DEFAULT_K,
    use_orientation: bool = True,
    loss: str = "linear",
    f_scale: float = 1.0,
    particles: int | None = None,
    iterations: int | None = None,
    box: tuple[float, float] | None = None,
    swarm_options: dict | None = None,
    progress: Progress | None = None,
) -> CalibrationResult:
    """Calibrate ``robot`` on ``data`` (file path or :class:`Measurements`).

    method: ``lm``, ``pso``, ``ipso``, ``ldpso-bt`` or ``hybrid`` (IPSO then LM).
    frames: ``none`` (base and tool as in the robot), ``base`` (identify the measuring
    frame), ``base+tool`` (also a tool offset per target: 3 for position data, 6 for
    full pose).  params: candidate joint parameters — None for all of the convention,
    ``wen2019`` / ``kou2022`` for the papers' 24, or a list of names.  objective:
    ``sum_squares`` (Wen eq. 7 with weight k mm²/rad²) or ``sum_norms`` (Kou eq. 4);
    default per method.  loss/f_scale: robust loss of LM (``huber``, ``soft_l1``, …)
    with its scale in mm.  particles/iterations/box override the method's paper
    settings; box = (± mm, ± rad) of the swarm search around the initial estimate.
    """
    start = time.perf_counter()
    if method not in METHODS:
        raise InputError(f"unknown method {method!r} (expected {' | '.join(METHODS)})", source="--method")
    if frames not in FRAME_MODES:
        raise InputError(f"unknown frames mode {frames!r} (expected {' | '.join(FRAME_MODES)})", source="--frames")
    objective = objective or DEFAULT_OBJECTIVE[method]
    if objective not in OBJECTIVES:
        raise InputError(f"unknown objective {objective!r} (expected {' | '.join(OBJECTIVES)})", source="--objective")
    if not (math.isfinite(k) and k >= 0):
        raise InputError(f"orientation weight must be finite and ≥ 0, got {k}", source="--k")
    nominal = load_robot(robot)
    meas = _load(nominal, data, nominal.n_joints)
    val = None if validate is None else _load(nominal, validate, nominal.n_joints)
    full_pose = meas.full_pose and use_orientation
    if not full_pose:
        meas = meas.position_only()
        val = None if val is None else val.position_only()
    if frames != "base+tool":
        missing = [t for t in meas.target_names if t and t not in nominal.targets]
        if missing:
            raise InputError(
                f"target '{missing[0]}' has no tool frame in the robot; identify it with "
                "--frames base+tool or add [targets.NAME] to the robot file",
                source=meas.source,
            )
    _check_units(nominal, meas, frames)
    caught: list[str] = _degeneracy_warnings(nominal, meas)
    initial = register_frames(nominal, meas, frames)
    space = ParameterSpace.of(initial, meas.target_names if frames == "base+tool" else None)
    joint_names, explicit = _resolve_params(params, nominal, space)
    candidates = joint_names + [
        n for n in frame_candidates(frames, meas.target_names, full_pose) if n not in joint_names
    ]
    probe = Problem(space, space.index(candidates), meas, k=k, use_orientation=full_pose)
    ident = analyse(
        probe.residual_jacobian(np.zeros(len(candidates))),
        candidates,
        np.array([is_angle(n) for n in candidates]),
        meas.n_poses,
        initial.reach(),
    )
    caught += ident.warnings
    if explicit:
        bad = [n for n in joint_names if n in ident.reasons]
        if bad:
            caught.append(f"requested parameters not identifiable from these data, left at nominal: {', '.join(bad)}")
    if not ident.kept:
        raise InputError("no parameter is identifiable from these measurements", source=meas.source)
    if probe.n_residuals < len(candidates):
        caught.append(
            f"only {meas.n_poses} poses ({probe.n_residuals} residuals) for {len(candidates)} candidate "
            f"parameters: {len(ident.dropped)} dropped; measure more poses"
        )
    problem = Problem(space, space.index(ident.kept), meas, k=k, use_orientation=full_pose)
    searched = [n for n in candidates if not ident.reasons.get(n, "").startswith("no effect")]
    search = Problem(space, space.index(searched), meas, k=k, use_orientation=full_pose)
    opt = _optimise(
        problem,
        search,
        method,
        objective,
        seed,
        loss,
        f_scale,
        particles,
        iterations,
        box,
        swarm_options or {},
        progress,
    )
    outliers: list[dict] = []
    all_rows = meas
    if method in ("lm", "hybrid") and loss != "linear" and opt.status == "converged":
        flagged, sigma = _outlier_rows(problem, opt.x)
        if flagged.size:
            outliers = _describe_outliers(problem, opt.x, flagged)
            meas = meas.subset(np.setdiff1d(np.arange(meas.n_poses), flagged))
            probe = Problem(space, space.index(candidates), meas, k=k, use_orientation=full_pose)
            problem = Problem(space, space.index(ident.kept), meas, k=k, use_orientation=full_pose)
            # refit the inliers by plain least squares: the answer as if the outliers were never measured
            lm = levenberg_marquardt(problem.residuals, problem.residual_jacobian, opt.x)
            opt = OptimizeResult(
                method=opt.method, x=lm.x, fun=lm.fun, history=np.concatenate([opt.history, lm.history]),
                nit=opt.nit + lm.nit, nfev=opt.nfev + lm.nfev, status=lm.status,
                message=f"{opt.message}; {len(flagged)} outliers removed, inliers refitted: {lm.message}",
                time_s=opt.time_s + lm.time_s, extra={**opt.extra, "robust_scale_mm": sigma},
            )  # fmt: skip
            caught.append(
                f"{len(flagged)} outlier poses (residual > {OUTLIER_SIGMAS:g} σ̂, σ̂ = {sigma:.3g} mm) "
                f"left out: rows {', '.join(str(o['row']) for o in outliers[:10])}"
                + (" …" if len(outliers) > 10 else "")
            )
    elif method in ("lm", "hybrid") and opt.status == "converged":
        flagged, sigma = _outlier_rows(problem, opt.x)
        if flagged.size:
            rows = ", ".join(str(int(meas.rows[i])) for i in flagged[:10])
            caught.append(
                f"rows {rows}{' …' if flagged.size > 10 else ''} look like outliers (residual > "
                f"{OUTLIER_SIGMAS:g} σ̂, σ̂ = {sigma:.3g} mm); a robust fit (--loss huber) would leave them out"
            )
    if opt.status in ("diverged", "failed"):
        caught.append(f"optimiser {opt.method} {opt.status}: {opt.message}")
    elif method in ("lm", "hybrid") and opt.status != "converged":
        caught.append(f"Levenberg–Marquardt stopped before converging: {opt.message}")
    if method in ("lm", "hybrid") and opt.status == "converged":
        problem, ident, opt = _refine_identifiable(
            probe, candidates, problem, ident, opt, initial, meas, k, full_pose, loss, f_scale
        )
    x = opt.x
    unc = _uncertainty(problem, x) if method in ("lm", "hybrid") else None
    calibrated = space.apply(problem.full(x)).replace(name=f"{nominal.name} (calibrated)")
    metrics = {"before": Metrics.of(initial, meas), "after": Metrics.of(calibrated, meas)}
    if outliers:
        metrics["after_all_rows"] = Metrics.of(calibrated, all_rows)
    if val is not None:
        metrics["validation_before"] = Metrics.of(initial, val)
        metrics["validation_after"] = Metrics.of(calibrated, val)
    for w in caught:
        warnings.warn(w, RobocalWarning, stacklevel=2)
    return CalibrationResult(
        method=method, seed=seed, objective=objective if method != "lm" else "sum_squares", k=k, frames=frames,
        robot=calibrated, initial=initial, nominal=nominal, names=ident.kept, x=x, uncertainty=unc,
        identifiability=ident, optimisation=opt, metrics=metrics, loss=loss, data=meas.source,
        n_poses=meas.n_poses, full_pose=full_pose, warnings=caught, time_s=time.perf_counter() - start,
        measurements=meas, validation=val, outliers=outliers,
    )  # fmt: skip


#: a pose whose position residual exceeds this many robust σ is an outlier.  For
#: isotropic Gaussian noise |δp| follows a Maxwell law; P(|δp| > 6σ) ≈ 1e-7.
OUTLIER_SIGMAS = 6.0
#: median of the Maxwell distribution in units of the per-axis σ
_MAXWELL_MEDIAN = 1.5382


def _outlier_rows(problem: Problem, x: np.ndarray) -> tuple[np.ndarray, float]:
    """Poses whose position residual is beyond OUTLIER_SIGMAS robust standard deviations."""
    dp, _ = problem.errors(x)
    norm = np.linalg.norm(dp, axis=1)
    sigma = float(np.median(norm)) / _MAXWELL_MEDIAN
    if problem.meas.n_poses < 8:
        return np.zeros(0, dtype=int), sigma
    return np.flatnonzero(norm > OUTLIER_SIGMAS * max(sigma, 1e-9)), sigma


def _describe_outliers(problem: Problem, x: np.ndarray, flagged: np.ndarray) -> list[dict]:
    dp, _ = problem.errors(x)
    meas = problem.meas
    return [
        {
            "row": int(meas.rows[i]),
            "pose_id": None if meas.pose_ids is None else meas.pose_ids[i],
            "error_mm": float(np.linalg.norm(dp[i])),
        }
        for i in flagged
    ]


def _degeneracy_warnings(robot: Robot, meas: Measurements) -> list[str]:
    """Degenerate but valid data: say what is off; identifiability then drops what it must."""
    out = []
    q = meas.q
    if meas.n_poses > 1 and np.all(np.ptp(q, axis=0) < 1e-9):
        out.append(f"all {meas.n_poses} poses command the same joints: only what a single pose shows can be identified")
    else:
        still = [i + 1 for i in range(q.shape[1]) if np.ptp(q[:, i]) < math.radians(0.05)]
        if still:
            out.append(
                f"joint{'s' if len(still) > 1 else ''} {', '.join(map(str, still))} never move"
                f"{'' if len(still) > 1 else 's'} in these data: parameters that need "
                f"{'their' if len(still) > 1 else 'its'} motion are dropped"
            )
    from .compensation import _condition

    cond = _condition(robot, q, meas.full_pose, 1000.0)
    bad = np.flatnonzero(cond > 1e4)
    if bad.size:
        rows = ", ".join(str(int(meas.rows[i])) for i in bad[:10])
        out.append(
            f"rows {rows}{' …' if bad.size > 10 else ''} are near-singular configurations (joint Jacobian "
            "condition > 1e4): they pin down little"
        )
    return out


def _swarm_box(problem: Problem, method: str, box):
    length, angle = box or SWARM_BOX[method]
    upper = np.array([
        (max(angle, FRAME_BOX[1]) if is_angle(n) else max(length, FRAME_BOX[0])) if n.startswith(("base", "tool"))
        else (angle if is_angle(n) else length)
        for n in problem.names
    ])  # fmt: skip
    return -upper, upper


def _reexpress(search: Problem, xs: np.ndarray, problem: Problem) -> tuple[np.ndarray, float]:
    """Express a swarm solution over the candidate set in the identifiable parameters.

    The swarm searches every candidate, dependent ones included, as the papers do
    (a swarm does not need full rank, and the planted errors lie inside its box); its
    values for dependent parameters are arbitrary along the dependency.  The model it
    found is re-expressed by fitting the identifiable parameters to that model's own
    predictions at the measured joints (not to the data), so the swarm's accuracy is
    reported as it is.  Returns the identifiable values and the largest position
    difference (mm) between the two expressions.
    """
    R, p = search.space.pose(search.full(xs), search.meas.q, search.target_idx)
    synthetic = replace(search.meas, position=p, rotation=R if problem.use_orientation else None)
    fit = Problem(problem.space, problem.active, synthetic, k=problem.k, use_orientation=problem.use_orientation)
    x0 = search.full(xs)[problem.active]
    lm = levenberg_marquardt(fit.residuals, fit.residual_jacobian, x0)
    dp, _ = fit.errors(lm.x)
    return lm.x, float(np.linalg.norm(dp, axis=-1).max())


def _optimise(
    problem: Problem,
    search: Problem,
    method,
    objective,
    seed,
    loss,
    f_scale,
    particles,
    iterations,
    box,
    options,
    progress,
) -> OptimizeResult:
    """Run ``method``; LM works on the identifiable set (problem), swarms on the candidates (search)."""

    def f(X):
        return search.objective(X, objective)

    def settings(defaults):
        out = {key: options.get(key, val) for key, val in defaults.items()}
        if particles is not None:
            out["particles"] = particles
        if iterations is not None:
            out["iterations"] = iterations
        return out

    if method == "lm":
        return levenberg_marquardt(
            problem.residuals,
            problem.residual_jacobian,
            np.zeros(problem.n_params),
            loss=loss,
            f_scale=f_scale,
            max_nfev=options.get("max_evaluations"),
            callback=progress,
        )
    lower, upper = _swarm_box(search, method, box)
    if method == "pso":
        swarm = pso(f, lower, upper, seed=seed, callback=progress, **settings(PSO_DEFAULTS))
    elif method in ("ipso", "hybrid"):
        s = settings(IPSO_DEFAULTS if method == "ipso" else {**IPSO_DEFAULTS, "iterations": HYBRID_GENERATIONS})
        swarm = ipso(
            f, lower, upper, seed=seed, callback=progress, halton_scramble=options.get("halton_scramble", True), **s
        )
    else:
        swarm = ldpso_bt(f, lower, upper, seed=seed, callback=progress, **settings(LDPSO_DEFAULTS))
    x_id, gap = _reexpress(search, swarm.x, problem)
    swarm.extra.update({"reexpression_gap_mm": gap, "searched": search.names})
    if method != "hybrid":
        swarm.x = x_id
        return swarm
    # hybrid: the swarm lands in the basin, LM finishes from there
    lm = levenberg_marquardt(problem.residuals, problem.residual_jacobian, x_id, loss=loss, f_scale=f_scale)
    swarm_best = float(search.objective(swarm.x[None], "sum_squares")[0])
    return OptimizeResult(
        method="hybrid",
        x=lm.x,
        fun=lm.fun,
        history=np.concatenate([swarm.history, lm.history]) if objective == "sum_squares" else lm.history,
        nit=swarm.nit + lm.nit,
        nfev=swarm.nfev + lm.nfev,
        status=lm.status,
        message=f"IPSO {swarm.nit} generations (best {swarm_best:.6g}), then LM: {lm.message}",
        time_s=swarm.time_s + lm.time_s,
        extra={"swarm": swarm.extra, "swarm_generations": swarm.nit, "swarm_best": swarm_best, **lm.extra},
    )


#: significance level of the F-test that decides whether parameters that become
#: identifiable at the estimate are worth adding
ADD_SIGNIFICANCE = 0.01
#: residual evaluations allowed to the refit with the added parameters
REFIT_EVALUATIONS = 100


def _refine_identifiable(probe, candidates, problem, ident, opt, initial, meas, k, full_pose, loss, f_scale):
    """Re-check identifiability at the estimate; add what the data determine there.

    Identifiability is judged from the Jacobian at a linearisation point.  At the
    nominal model some dependencies hold only to first order: with parallel axes
    2 ∥ 3 in standard DH, d2 and d3 have identical columns, but a robot whose α2 is
    off by δ separates them by an angle ~δ; a tool point off axis 6 by the error in
    a6 makes θ6 act.  The analysis is repeated at the estimate with the kept set
    offered first; parameters that became independent are added and LM continues,
    and the addition is accepted only if a nested-model F-test says the fit improved
    significantly (p < 0.01) — otherwise they stay dropped as second-order only.
    """
    from scipy.stats import f as f_dist

    space = problem.space
    delta = problem.full(opt.x)
    angle = np.array([is_angle(n) for n in candidates])
    again = analyse(
        probe.residual_jacobian(delta[probe.active]),
        candidates,
        angle,
        meas.n_poses,
        initial.reach(),
        prefer=ident.kept,
    )
    added = [n for n in again.kept if n not in ident.kept]
    if not added:
        return problem, ident, opt
    names = ident.kept + added
    new = Problem(space, space.index(names), meas, k=k, use_orientation=full_pose)
    # A parameter that separates only weakly makes LM crawl along a valley; the refit is a
    # test of whether the addition pays, so it gets a bounded budget.
    lm = levenberg_marquardt(
        new.residuals, new.residual_jacobian, delta[new.active], loss=loss, f_scale=f_scale, max_nfev=REFIT_EVALUATIONS
    )
    n_res, k_new = new.n_residuals, len(names)
    rss_old, rss_new = opt.fun, lm.fun  # both sums of squared residuals (LM stage of lm and hybrid)
    dof = n_res - k_new
    if dof > 0 and rss_new < rss_old:
        stat = ((rss_old - rss_new) / len(added)) / max(rss_new / dof, 1e-300)
        p = float(f_dist.sf(stat, len(added), dof))
    else:
        p = 1.0
    if lm.status != "converged" or p >= ADD_SIGNIFICANCE:
        for n in added:
            ident.reasons[n] = (
                f"{ident.reasons[n].split(' (')[0]} at the nominal model; separable only to second "
                f"order at the estimate, which did not improve the fit significantly (F-test p={p:.2g})"
            )
        return problem, ident, opt
    keep = set(names)
    final = analyse(
        new.residual_jacobian(lm.x),
        names,
        angle[[candidates.index(n) for n in names]],
        meas.n_poses,
        initial.reach(),
        prefer=names,
    )
    dropped = [n for n in candidates if n not in keep]
    reasons = {n: ident.reasons[n] for n in dropped if n in ident.reasons}
    for n in added:
        ident.reasons.pop(n, None)
    refined = Identifiability(
        kept=[n for n in candidates if n in keep], dropped=dropped, reasons=reasons,
        singular_values=final.singular_values, condition=final.condition, observability=final.observability,
        length_scale=final.length_scale, n_poses=final.n_poses,
        warnings=final.warnings + [f"{', '.join(added)} identifiable only away from the nominal model "
                                   f"(added after the first fit, F-test p={p:.2g}); expect large uncertainties"],
    )  # fmt: skip
    merged = OptimizeResult(
        method=opt.method, x=lm.x, fun=lm.fun, history=np.concatenate([opt.history, lm.history]),
        nit=opt.nit + lm.nit, nfev=opt.nfev + lm.nfev, status=lm.status,
        message=f"{opt.message}; refit adding {', '.join(added)}: {lm.message}",
        time_s=opt.time_s + lm.time_s, extra={**opt.extra, "added_at_estimate": added},
    )  # fmt: skip
    order = [names.index(n) for n in refined.kept]
    merged.x = lm.x[order]
    return Problem(space, space.index(refined.kept), meas, k=k, use_orientation=full_pose), refined, merged


def _uncertainty(problem: Problem, x: np.ndarray) -> np.ndarray | None:
    """Standard uncertainties sqrt(diag(σ̂² (JᵀJ)⁻¹)), σ̂² = |r|² / (N − k), in mm and rad."""
    r = problem.residuals(x)
    dof = r.size - x.size
    if dof <= 0:
        return np.full(x.size, np.nan)
    J = problem.residual_jacobian(x)
    if J.shape[0] > 4 * J.shape[1]:
        J = np.linalg.qr(J, mode="r")  # same singular values and right vectors, k×k
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    if s[-1] <= s[0] * 1e-14:
        return np.full(x.size, np.nan)
    cov = (Vt.T / s**2) @ Vt * (float(r @ r) / dof)
    return np.sqrt(np.diag(cov))
