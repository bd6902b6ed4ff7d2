"""The options of a calibration, validated once, in one place, for the API and the CLI alike."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace

from .. import options as opt
from ..backend import BACKENDS
from ..exceptions import InputError
from ..io.measurements import ReadOptions, robot_fields
from ..model.candidates import FRAME_CHOICES
from ..model.prior import Prior
from ..model.terms import TERMS
from ..model.uncertainty import MAP_OVER
from ..optimize.lm import LOSSES
from .fit.instrument import Instrument
from .fit.noise import NoiseModel
from .registry import METHODS as _REGISTRY
from .registry import Method

METHODS = tuple(_REGISTRY)
OBJECTIVES = ("sum_squares", "sum_norms")
#: IPSO's start: a Halton sequence scrambled with the seed, or the plain sequence
HALTON = ("scrambled", "plain")
#: the learned corrections a model may hold on top of its parametric part (MODEL §4, §10)
LEARNED = ("trees", "residual")
#: what a model may hold beyond geometry (MODEL §4); ``auto`` chooses among them by cross-validation
MODEL_TERMS = (*TERMS, *LEARNED)
#: named candidate sets: chosen by held-out data where the rows are a camera's, else every joint
#: parameter (``auto``); every joint parameter (``all``); each joint's zero (``zeros``); none, the
#: frames alone (``frames``); a paper's 24
PARAMETER_SETS = ("auto", "all", "zeros", "frames", "wen2019", "kou2022")


@dataclass(frozen=True)
class SwarmSettings:
    """What a swarm method runs with besides its paper's settings: particles and iterations
    (None: the paper's), the search box (± mm, ± rad; None: the method's), IPSO's Halton
    start, further overrides of the paper's settings (``w``, ``c1``, …, those the method
    allows) and the objectives' backend."""

    method: Method
    particles: int | None = None
    iterations: int | None = None
    box: tuple[float, float] | None = None
    halton: str = "scrambled"
    overrides: Mapping[str, float] = field(default_factory=dict)
    backend: str = "auto"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "particles", opt.optional_integer(self.particles, "particles", minimum=1))
        set_(self, "iterations", opt.optional_integer(self.iterations, "iterations", minimum=1))
        if self.box is not None:
            box = opt.floats(self.box, "box", (2,))
            if min(box) <= 0:
                raise InputError(f"half-widths must be > 0, got {self.box!r}", option="box")
            set_(self, "box", box)
        allowed = self.method.overridable
        for key, value in dict(self.overrides).items():
            if key not in allowed:
                raise InputError(f"unknown setting {key!r} for {self.method.name} (allowed: "
                                 f"{', '.join(allowed) or 'none'})", option="swarm")
            opt.number(value, f"swarm {key}", minimum=0.0)
        set_(self, "overrides", dict(self.overrides))
        opt.choice(self.halton, HALTON, "halton", "Halton start")
        opt.choice(self.backend, BACKENDS, "backend", "backend")

    def settings(self) -> dict:
        """The settings of a run: the paper's, overridden."""
        out = {**self.method.settings, **self.overrides}
        if self.particles is not None:
            out["particles"] = self.particles
        if self.iterations is not None:
            out["iterations"] = self.iterations
        return out


@dataclass(frozen=True)
class ModelSettings:
    """What the model holds beyond geometry: ``geometric``, ``auto`` or terms joined by ``+``
    (canonical order), the harmonics' count H, and a payload (kg) where the data have none."""

    name: str = "geometric"
    harmonics: int = 2
    payload: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", _model(self.name))
        object.__setattr__(self, "harmonics", opt.integer(self.harmonics, "harmonics", minimum=1))
        if self.payload is not None:
            object.__setattr__(self, "payload", opt.number(self.payload, "payload", minimum=0.0))

    @property
    def terms(self) -> frozenset[str]:
        """The terms beyond geometry asked for (empty for geometric and auto)."""
        return frozenset() if self.name in ("geometric", "auto") else frozenset(self.name.split("+")) - {"geometric"}


@dataclass(frozen=True)
class CalibrationConfig:
    """What a calibration is asked to do.  Units: mm, rad (k in mm²/rad²).

    The options are given flat, as keywords (the command line's names); each group is checked
    by its own typed settings, which the calibration reads: :attr:`noise_model` (noise,
    angle_noise, k), :attr:`swarm_settings` (particles, iterations, box, halton, swarm,
    backend), :attr:`model_settings` (model, harmonics, payload) and :attr:`read_settings`
    (joint_unit, length_unit, delimiter, decimal, euler); method, frames, params, seed, objective, loss and f_scale,
    max_evaluations and use_orientation are its own.

    noise / angle_noise: the measuring device's standard deviation per axis, position (mm)
    and orientation (rad, as a rotation vector); residuals are whitened by them.  A value
    not stated is estimated from the fit (see :mod:`robocal.calibration.fit.noise`).  k: the
    older way to weigh orientation, a fixed (σp/σr)² in mm²/rad² instead of angle_noise.

    method: ``lm``, ``pso``, ``ipso``, ``ldpso-bt`` or ``hybrid`` (IPSO then LM).
    frames: ``auto`` (registered when the data are not in the robot's frame, and said),
    ``none`` (base and tool as in the robot), ``base`` (identify the measuring frame),
    ``base+tool`` (also a tool offset per target: 3 for position data, 6 for full pose).
    params: candidate joint parameters: None/``auto``/``all`` for every parameter of the
    convention, ``wen2019``/``kou2022`` for the papers' 24, or names (a sequence or a comma
    list).  objective: ``sum_squares`` (Wen eq. 7 with weight k) or ``sum_norms`` (Kou eq. 4),
    default per method.  loss/f_scale: robust loss of LM with its scale (mm).
    particles/iterations/box: override the swarm's paper settings; box = (± mm, ± rad) around
    the initial estimate.  halton: IPSO's start, ``scrambled`` or ``plain``.  swarm: further
    paper settings to override (``w``, ``c1``, …).  max_evaluations: cap on LM's residual
    evaluations.  backend: ``auto``, ``numba`` or ``numpy`` for the swarm objectives.
    joint_unit / length_unit: ``deg``/``rad`` and ``mm``/``m`` of the data files, overriding
    robocal's unit checks (default: degrees and millimetres, checked).
    model: ``geometric``, ``auto`` (chosen by cross-validation) or terms joined by ``+``
    (``compliance``, ``harmonics``, ``backlash``, ``drift``, ``residual``; geometry is always
    included).  harmonics:
    their count H per joint.  payload: a payload mass (kg) for every pose, where the data have
    no ``payload`` column.  instrument: an MPE-style statement ``"A+B/m"`` (mm, mm per metre
    of distance from the instrument; ``k=K`` for U = K σ, default 2) that sets each point's
    position σ (see :mod:`robocal.calibration.fit.instrument`); files may give σ per point instead.
    exclude: pose ids (or ``row N`` for files without them) to leave out of the calibration.
    point_distance: known distances between two points of a setup (``"A,B=MM"`` or (A, B, mm)),
    for data whose rows touched unknown points (:mod:`robocal.model.constraints`); distance_sigma:
    their standard uncertainty, mm.
    prior: the widths of what is known of the parameters before measuring, over the robot file's
    ``[prior]`` and the defaults (``KEY=WIDTH`` items, a mapping or a
    :class:`~robocal.model.prior.Prior`: a kind such as ``length``/``angle``/``zero``/``harmonic``,
    ``all``, or a parameter name; mm or deg, ``free`` for none).  row_order: the rows are in the
    order they were measured, so that terms of time (drift) and of the direction of approach
    (backlash) may take it where the data have no time or dir1..dirN columns.
    cameras: the cameras that saw the data's camera rows (``NAME=FILE`` or ``NAME=FILE,link=K``
    items, or :class:`CameraSpec`): each one's intrinsics file and where it is, fixed (link 0) or on
    the robot's link K; camera_poses: cameras whose pose is known (``NAME=x,y,z,rx,ry,rz`` items, mm
    and deg, in the measuring frame or the camera's link's frame; or a mapping to (mm…, rad…)), which
    are then not estimated; markers: a CSV of the markers' known offsets on the flange (``marker, x,
    y, z``, mm), else they are identified; pixel_noise: the pixel σ (px) of the camera rows, else
    estimated.
    """

    method: str = "lm"
    frames: str = "auto"
    params: str | tuple[str, ...] | None = None
    seed: int | None = 0
    objective: str | None = None
    noise: float | None = None
    angle_noise: float | None = None
    k: float | None = None
    use_orientation: bool = True
    loss: str = "linear"
    f_scale: float = 1.0
    particles: int | None = None
    iterations: int | None = None
    box: tuple[float, float] | None = None
    halton: str = "scrambled"
    swarm: Mapping[str, float] = field(default_factory=dict)
    max_evaluations: int | None = None
    backend: str = "auto"
    joint_unit: str | None = None
    length_unit: str | None = None
    model: str = "geometric"
    harmonics: int = 2
    payload: float | None = None
    instrument: str | None = None
    delimiter: str = ","
    decimal: str = "."
    euler: str = "xyz"
    exclude: tuple[str, ...] = ()
    point_distance: tuple[tuple[str, str, float], ...] = ()
    distance_sigma: float = 0.05
    prior: Prior | None = None
    row_order: bool = False
    cameras: tuple[CameraSpec, ...] = ()
    camera_poses: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    markers: str | None = None
    pixel_noise: float | None = None
    #: where the report's uncertainty map draws joint sets (:data:`robocal.model.uncertainty.MAP_OVER`)
    map_over: str = "workspace"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        opt.choice(self.method, METHODS, "method", "method")
        opt.choice(self.frames, FRAME_CHOICES, "frames", "frames mode")
        set_(self, "params", _params(self.params))
        if self.seed is not None:
            set_(self, "seed", opt.integer(self.seed, "seed", minimum=0))
        if self.objective is not None:
            opt.choice(self.objective, OBJECTIVES, "objective", "objective")
        noise = NoiseModel.checked(self.noise, self.angle_noise, self.k)
        if self.instrument is not None:
            Instrument.parse(self.instrument)
            if noise.position is not None:
                raise InputError("give the instrument's statement or the position noise, not both", option="instrument")
        set_(self, "noise", noise.position)
        set_(self, "angle_noise", noise.orientation)
        set_(self, "k", noise.k)
        opt.choice(self.loss, LOSSES, "loss", "loss")
        opt.choice(self.map_over, MAP_OVER, "map_over", "uncertainty map's region")
        if self.loss != "linear" and not self.spec.least_squares:
            raise InputError(f"a robust loss applies to lm and hybrid, not {self.method}", option="loss")
        set_(self, "f_scale", opt.number(self.f_scale, "f_scale", minimum=0.0, strict=True))
        set_(self, "max_evaluations", opt.optional_integer(self.max_evaluations, "max_evaluations", minimum=1))
        swarm = self.swarm_settings
        for name in ("particles", "iterations", "box"):
            set_(self, name, getattr(swarm, name))
        set_(self, "swarm", swarm.overrides)
        _ = self.read_settings  # checks the file-reading options
        set_(self, "exclude", _exclude(self.exclude))
        set_(self, "point_distance", point_distances(self.point_distance))
        set_(self, "distance_sigma", opt.number(self.distance_sigma, "distance_sigma", minimum=0.0, strict=True))
        try:
            set_(self, "prior", None if self.prior is None else Prior.parse(self.prior))
        except ValueError as exc:
            raise InputError(str(exc), option="prior") from None
        set_(self, "cameras", camera_specs(self.cameras))
        set_(self, "camera_poses", camera_poses(self.camera_poses, self.cameras))
        if self.pixel_noise is not None:
            set_(self, "pixel_noise", opt.number(self.pixel_noise, "pixel_noise", minimum=0.0, strict=True))
        if not isinstance(self.row_order, bool):
            raise InputError(f"expected true or false, got {self.row_order!r}", option="row_order")
        model = ModelSettings(self.model, self.harmonics, self.payload)
        set_(self, "model", model.name)
        set_(self, "harmonics", model.harmonics)
        set_(self, "payload", model.payload)
        if not self.spec.least_squares and (self.model == "auto" or self.model_terms - set(LEARNED)):
            raise InputError(f"joint terms ({self.model}) are fitted by lm or hybrid, not {self.method}",
                             option="model")

    def read_options(self, robot, columns=None) -> dict:
        """How to read data files for ``robot``: the keywords of the measurement loaders."""
        return asdict(ReadOptions(columns=columns, joint_unit=self.joint_unit, length_unit=self.length_unit,
                                  delimiter=self.delimiter, decimal=self.decimal, euler=self.euler,
                                  **robot_fields(robot)))

    @classmethod
    def build(cls, config: CalibrationConfig | None = None, **options) -> CalibrationConfig:
        """A config from keyword options, or ``config`` with some of them changed."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - names)
        if unknown:
            raise TypeError(f"unknown calibration option {unknown[0]!r}")
        return cls(**options) if config is None else replace(config, **options)

    @property
    def model_terms(self) -> frozenset[str]:
        """The terms beyond geometry the model asks for (empty for geometric and auto)."""
        return self.model_settings.terms

    @property
    def noise_model(self) -> NoiseModel:
        """The noise stated: σp (mm), σr (rad) or the weight k."""
        return NoiseModel(self.noise, self.angle_noise, self.k)

    @property
    def swarm_settings(self) -> SwarmSettings:
        return SwarmSettings(self.spec, self.particles, self.iterations, self.box, self.halton, self.swarm,
                             self.backend)

    @property
    def model_settings(self) -> ModelSettings:
        return ModelSettings(self.model, self.harmonics, self.payload)

    @property
    def read_settings(self) -> ReadOptions:
        """How data files are read: their joint and length units (the robot's part comes with
        :meth:`read_options`)."""
        return ReadOptions(joint_unit=self.joint_unit, length_unit=self.length_unit, delimiter=self.delimiter,
                           decimal=self.decimal, euler=self.euler)

    @property
    def spec(self) -> Method:
        """The method's entry of :data:`robocal.calibration.registry.METHODS`."""
        return _REGISTRY[self.method]

    @property
    def least_squares(self) -> bool:
        """LM gives or finishes the estimate: refits, outlier screening and uncertainties apply."""
        return self.spec.least_squares

    @property
    def objective_kind(self) -> str:
        """The objective the swarms minimise: the given one or the method's paper's."""
        return self.objective or self.spec.objective

    @property
    def halton_scramble(self) -> bool:
        return self.halton == "scrambled"

    @property
    def is_swarm(self) -> bool:
        """A swarm alone gives the estimate."""
        return self.spec.swarm_only


@dataclass(frozen=True)
class CameraSpec:
    """A camera named in the data: its intrinsics file and its link (0: fixed in the cell)."""

    name: str
    path: str
    #: 0: fixed in the cell; k: on the link after joint k; a name: a URDF link (or a joint's name,
    #: the link after it), resolved against the robot
    link: int | str = 0


def camera_specs(value) -> tuple[CameraSpec, ...]:
    """``NAME=FILE`` or ``NAME=FILE,link=K`` items (K a number, or a URDF link's or a joint's name;
    or :class:`CameraSpec`), each camera once."""
    items = [value] if isinstance(value, (str, CameraSpec)) else list(value or ())
    out: list[CameraSpec] = []
    for item in items:
        if isinstance(item, str):
            name, _, rest = item.partition("=")
            path, *extra = [x.strip() for x in rest.split(",")]
            link = 0
            for e in extra:
                key, _, val = e.partition("=")
                if key.strip() != "link" or not val.strip():
                    raise InputError(f"expected NAME=FILE or NAME=FILE,link=K, got {item!r} ({e!r} is not link=K)",
                                     option="camera")
                val = val.strip()
                link = opt.integer(val, "camera", minimum=0) if val.lstrip("-").isdigit() else val
            if not name.strip() or not path:
                raise InputError(f"expected NAME=FILE or NAME=FILE,link=K, got {item!r}", option="camera")
            item = CameraSpec(name.strip(), path, link)
        if not isinstance(item, CameraSpec):
            raise InputError(f"expected NAME=FILE[,link=K], got {item!r}", option="camera")
        if any(o.name == item.name for o in out):
            raise InputError(f"camera {item.name!r} is given twice", option="camera")
        out.append(item)
    return tuple(out)


def camera_poses(value, specs: Sequence[CameraSpec]) -> dict[str, tuple[float, ...]]:
    """Known camera poses: ``NAME=x,y,z,rx,ry,rz`` items (mm, deg) or {name: (mm…, rad…)}; each names
    a camera of ``specs``; ``NAME@OTHER=…`` is NAME's pose in OTHER's frame (a calibrated rig: OTHER
    found, NAME fixed to it)."""
    if isinstance(value, Mapping):
        named = {str(k): tuple(float(x) for x in v) for k, v in value.items()}
        for name, v in named.items():
            if len(v) != 6 or not all(math.isfinite(x) for x in v):
                raise InputError(f"{name}: expected x, y, z, rx, ry, rz (six finite numbers)", option="camera_pose")
    else:
        unnamed, named = opt.named_frames(value, "camera_pose")
        if unnamed is not None or any(len(v) != 6 for v in named.values()):
            raise InputError("expected NAME=x,y,z,rx,ry,rz (mm, deg) for each camera whose pose is known",
                             option="camera_pose")
    known = {s.name for s in specs}
    for key in named:
        name, _, of = key.partition("@")  # NAME@OTHER: NAME's pose in OTHER's frame (a calibrated rig)
        for n in (name, of) if of else (name,):
            if n not in known:
                raise InputError(f"camera {n!r} has a pose but no --camera {n}=FILE", option="camera_pose")
        if of and (of == name or any(k.startswith(f"{of}@") for k in named)):
            raise InputError(f"{key}: a camera is fixed to another that is not itself fixed to a third",
                             option="camera_pose")
    return named


def point_distances(value) -> tuple[tuple[str, str, float], ...]:
    """Known distances between two points: ``"A,B=MM"`` items (or (A, B, mm) tuples), each pair once."""
    if value is None:
        return ()
    items = [value] if isinstance(value, str) else list(value)
    out: list[tuple[str, str, float]] = []
    for item in items:
        if isinstance(item, str):
            names, _, mm = item.partition("=")
            pair = [n.strip() for n in names.split(",")]
            if len(pair) != 2 or not all(pair) or pair[0] == pair[1] or not mm.strip():
                raise InputError(f"expected A,B=MM (two different point labels and their distance), got {item!r}",
                                 option="point_distance")
            d = opt.number(mm.strip(), "point_distance", minimum=0.0, strict=True)
        else:
            try:
                a, b, d = item
            except (TypeError, ValueError):
                raise InputError(f"expected (A, B, mm), got {item!r}", option="point_distance") from None
            pair, d = [str(a), str(b)], opt.number(d, "point_distance", minimum=0.0, strict=True)
        key = tuple(sorted(pair))
        if any(tuple(sorted(o[:2])) == key for o in out):
            raise InputError(f"the distance of {pair[0]} and {pair[1]} is given twice", option="point_distance")
        out.append((pair[0], pair[1], float(d)))
    return tuple(out)


def _exclude(value) -> tuple[str, ...]:
    """Pose ids (or ``row N``) to leave out: a comma list or a sequence of strings."""
    if value is None:
        return ()
    items = value.split(",") if isinstance(value, str) else list(value)
    if not all(isinstance(v, str) for v in items):
        raise InputError(f"expected pose ids, got {value!r}", option="exclude")
    out = tuple(v.strip() for v in items if v.strip())
    if not out and (isinstance(value, str) or items):
        raise InputError(f"names no pose (expected pose ids or 'row N', comma-separated), got {value!r}",
                         option="exclude")
    return out


def _model(value) -> str:
    """``geometric``, ``auto``, or known terms joined by ``+`` in a canonical order."""
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"expected geometric, auto or TERM[+TERM…], got {value!r}", option="model")
    if value in ("geometric", "auto"):
        return value
    parts = [p.strip() for p in value.split("+") if p.strip()]
    unknown = [p for p in parts if p not in MODEL_TERMS + ("geometric",)]
    if unknown:
        raise InputError(f"unknown model term {unknown[0]!r} (expected geometric | auto | "
                         f"{' | '.join(MODEL_TERMS)}, joined by +)", option="model")
    terms = [t for t in MODEL_TERMS if t in parts]
    return "+".join(terms) if terms else "geometric"


def _params(value) -> str | tuple[str, ...] | None:
    if value is None or value in PARAMETER_SETS:
        return None if value in (None, "auto") else value
    names = [p.strip() for p in value.split(",")] if isinstance(value, str) else [str(p) for p in value]
    names = [n for n in names if n]
    if not names:
        raise InputError("no parameter names given", option="params")
    return tuple(dict.fromkeys(names))


def resolve_params(params: str | Sequence[str] | None, robot) -> list[str] | None:
    """The candidate joint names a config asks for of ``robot``, or None for the convention's defaults."""
    from ..model.candidates import zero_candidates
    from ..presets import kou2022, wen2019

    n_joints = robot.n_joints
    if params is None or params == "all":
        return None
    if params == "zeros":
        return zero_candidates(robot)
    if params == "frames":
        return []
    if params == "wen2019":
        return list(wen2019.PARAMETERS)
    if params == "kou2022":
        return list(kou2022.parameters(n_joints))
    return list(params)
