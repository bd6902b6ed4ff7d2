"""Study files (TOML, MODEL §5): which cells, how many seeds, and what every run does.

```toml
robot = "kr5-arc"              # built-in name or robot file (TOML or URDF)
errors = "uniform:0.25,0.05"   # planted deviations, as in simulate
measure = "position"           # or "pose"
frames = "none"                # as in calibrate
poses = [30]                   # one cell per value
noise = [0.0, 0.02]            # mm per axis, one cell per value
methods = ["lm", "ldpso-bt"]   # one cell per value
seeds = 12                     # seeds 0..11 in every cell
validate = 200                 # fresh poses per run
```

Optional keys follow the command line's names and apply to every run: ``angle_noise`` and
``joint_noise`` (deg, of the simulation), and the calibration's ``model``, ``harmonics``,
``params``, ``objective``, ``loss``, ``f_scale``, ``particles``, ``iterations``, ``halton``.
Everything is checked before the first run; an error names the file and the key.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .. import options as opt
from ..exceptions import InputError

REQUIRED = ("robot", "methods", "poses", "seeds")
LISTS = ("poses", "noise", "methods")
SIMULATION_OPTIONS = ("angle_noise", "joint_noise")
CALIBRATION_OPTIONS = ("model", "harmonics", "params", "objective", "loss", "f_scale", "particles", "iterations",
                       "halton")
KEYS = set(REQUIRED) | {"errors", "measure", "frames", "noise", "validate", "name"} | set(SIMULATION_OPTIONS) \
    | set(CALIBRATION_OPTIONS)


@dataclass(frozen=True, order=True)
class RunKey:
    """One run: one seed of one cell (method, poses, noise mm)."""

    method: str
    poses: int
    noise: float
    seed: int

    @property
    def cell(self) -> tuple[str, int, float]:
        return self.method, self.poses, self.noise


@dataclass(frozen=True)
class Study:
    """A validated study file: the cells' axes and what every run shares."""

    robot: str
    methods: tuple[str, ...]
    poses: tuple[int, ...]
    noise: tuple[float, ...]
    seeds: int
    errors: str = "uniform:0.25,0.05"
    measure: str = "position"
    frames: str = "none"
    validate: int = 200
    angle_noise: float = 0.0
    joint_noise: float = 0.0
    calibration: dict = field(default_factory=dict)
    name: str = ""
    source: str = "<study>"

    def runs(self) -> list[RunKey]:
        """Every run, cell by cell, seeds 0..seeds−1."""
        return [RunKey(m, p, n, s) for m, p, n in itertools.product(self.methods, self.poses, self.noise)
                for s in range(self.seeds)]

    def identity(self) -> dict:
        """What, besides a run's key (method, poses, noise, seed), changes its result: the
        robot (its file's bytes, or a built-in's name), the planted errors, what is measured,
        the frames, the validation poses, the simulation's noises and the calibration options."""
        import hashlib

        path = Path(self.robot)
        robot = hashlib.sha256(path.read_bytes()).hexdigest()[:16] if path.is_file() else self.robot
        return {"robot": robot, "errors": self.errors, "measure": self.measure, "frames": self.frames,
                "validate": self.validate, "angle_noise": number_key(self.angle_noise),
                "joint_noise": number_key(self.joint_noise),
                **{k: str(v) for k, v in sorted(self.calibration.items())}}

    def fingerprint(self) -> str:
        """A short hash of :meth:`identity`: the ``spec`` column of runs.csv."""
        import hashlib
        import json

        return hashlib.sha256(json.dumps(self.identity(), sort_keys=True).encode()).hexdigest()[:12]

    def to_dict(self) -> dict:
        """Plain values, to send to the workers and to record."""
        return {k: getattr(self, k) for k in ("robot", "methods", "poses", "noise", "seeds", "errors", "measure",
                                              "frames", "validate", "angle_noise", "joint_noise", "calibration",
                                              "name", "source")}


def _list(value, key: str, source: str, kind) -> tuple:
    values = value if isinstance(value, list) else [value]
    if not values:
        raise InputError("needs at least one value", source=source, where=f"key '{key}'")
    out = []
    for v in values:
        try:
            out.append(kind(v))
        except InputError as exc:
            raise InputError(exc.what, source=source, where=f"key '{key}'") from None
    if len(set(out)) != len(out):
        raise InputError(f"repeated values in {values!r}", source=source, where=f"key '{key}'")
    return tuple(out)


def parse_study(text: str, *, source: str = "<study>") -> Study:
    """A study from TOML text; every problem is an InputError naming ``source`` and the key."""
    from ..calibration.config import METHODS, CalibrationConfig
    from ..io.robotfile import load_robot
    from ..simulation import MEASURES, planted_deviations

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", source=source) from None
    unknown = sorted(set(data) - KEYS)
    if unknown:
        raise InputError(f"unknown key '{unknown[0]}' (allowed: {', '.join(sorted(KEYS))})", source=source)
    missing = [k for k in REQUIRED if k not in data]
    if missing:
        raise InputError(f"missing key '{missing[0]}'", source=source)

    def where(key):
        return {"source": source, "where": f"key '{key}'"}

    def check(key, fn):
        try:
            return fn()
        except InputError as exc:
            raise InputError(exc.what, **where(key)) from None

    robot_spec = data["robot"]
    if not isinstance(robot_spec, str):
        raise InputError("expected a built-in name or a robot file", **where("robot"))
    if not Path(robot_spec).is_absolute() and (Path(source).parent / robot_spec).is_file():
        robot_spec = str(Path(source).parent / robot_spec)  # a robot file beside the study
    robot = check("robot", lambda: load_robot(robot_spec))
    methods = _list(data["methods"], "methods", source, lambda m: opt.choice(m, METHODS, "methods", "method"))
    poses = _list(data["poses"], "poses", source, lambda v: opt.integer(v, "poses", minimum=3))
    noise = _list(data.get("noise", [0.0]), "noise", source, lambda v: opt.number(v, "noise", minimum=0.0))
    seeds = check("seeds", lambda: opt.integer(data["seeds"], "seeds", minimum=1))
    validate = check("validate", lambda: opt.integer(data.get("validate", 200), "validate", minimum=1))
    measure = check("measure", lambda: opt.choice(data.get("measure", "position"), MEASURES, "measure", "measure"))
    errors = data.get("errors", "uniform:0.25,0.05")
    if not isinstance(errors, str):
        raise InputError("expected a spec: none | paper | uniform:LEN_MM,ANGLE_RAD", **where("errors"))
    import numpy as np

    check("errors", lambda: planted_deviations(robot, errors, np.random.default_rng(0)))
    sim = {k: check(k, lambda k=k: opt.number(data.get(k, 0.0), k, minimum=0.0)) for k in SIMULATION_OPTIONS}
    calibration = {k: data[k] for k in CALIBRATION_OPTIONS if k in data}
    frames = data.get("frames", "none")
    for method in methods:  # every option checked once, here, as the command line checks them
        try:
            CalibrationConfig(method=method, frames=frames, **calibration)
        except InputError as exc:
            raise InputError(exc.what, **where(exc.option or "frames")) from None
    name = data.get("name", Path(source).stem)
    return Study(robot_spec, methods, poses, noise, seeds, errors, measure, frames, validate,
                 sim["angle_noise"], sim["joint_noise"], calibration, str(name), source)


def load_study(path: str | Path) -> Study:
    from ..io.atomic import read_text

    return parse_study(read_text(path, "study file"), source=str(path))


def number_key(x: float) -> str:
    """How a float is written to runs.csv and compared when resuming: 10 significant digits,
    identical whichever machine computed it."""
    return "nan" if not math.isfinite(x) else format(float(x), ".10g")
