"""What is known of a robot's parameters before it is measured: the prior of the identification.

A robot's drawing already says much about the real robot: its links are machined and assembled
to a fraction of a millimetre, its axes to a fraction of a degree, its joint zeros set by
mastering to within a degree or so; gears, cables and loads turn its joints by hundredths of a
degree.  A calibration is a measurement of how far the real robot lies from the drawing, and
that prior knowledge is part of it: the identification minimises

    χ²_data + Σ_i (x_i / σ_i)²

(maximum a posteriori, x the deviations from the nominal model), the second sum as one
pseudo-observation per parameter (MODEL §3.1).  Directions the poses determine are unchanged by
it to (σ_data/σ_i)² of their value; directions they cannot see stay at the nominal model, within
σ_i, instead of walking along a valley to values no robot has (a UR5's a5 at −48 mm).

Prior widths by kind (:data:`DEFAULTS`), each overridable per kind or per parameter in a robot
file's ``[prior]`` table or with ``--prior KEY=VALUE``, in the robot file's units:

=============  =================================================================  ==========
kind           parameters                                                         default
=============  =================================================================  ==========
``length``     DH a, d; URDF origin x, y, z; a sliding joint's zero               1 mm
``angle``      DH α, β; URDF origin rx, ry, rz; a sliding DH joint's θ            0.1°
``zero``       a turning joint's zero θ (encoder offset, set by mastering)         1°
``base``       the measuring frame (where the instrument stood)                    free
``tool``       the tool frames (where each reflector was mounted)                  free
``compliance`` compliance and gravity deflections: the deflection at the data's    0.1°
               RMS load of that parameter (its basis's RMS over the poses)
``harmonic``   a transmission harmonic's amplitude                                 0.05°
``backlash``   half a joint's dead band                                            0.05°
``drift``      a joint zero's drift per hour (time column) or per 1000 rows         0.05°
=============  =================================================================  ==========

A parameter named in the table (``a5 = 0.5``, ``compliance2 = 2e-5``) takes its own width: mm,
deg, or rad/(N·m) for a torque compliance.  ``free`` (or ``inf``) sets no prior; ``all`` sets
every kind but the frames.  Base and tool are always free: they are registered from the data.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

#: the kinds of parameter a prior width can be stated for, with their default width (file
#: units: mm, deg; compliance: deg of deflection at the data's RMS load; drift: deg per hour or
#: per 1000 rows) and the reason, as the documentation gives it
DEFAULTS: dict[str, tuple[float, str]] = {
    "length": (1.0, "links machined and assembled to a fraction of a millimetre"),
    "angle": (0.1, "axes parallel or square to a tenth of a degree (0.1° over 500 mm is 0.9 mm)"),
    "zero": (1.0, "joint zeros set by mastering to within a degree"),
    "base": (math.inf, "the measuring frame is where the instrument stood: registered from the data"),
    "tool": (math.inf, "a reflector is where it was mounted: registered from the data"),
    "camera": (math.inf, "a camera is where it was put: found from its pixels"),
    "compliance": (0.1, "joints deflect by hundredths to a tenth of a degree under their load"),
    "harmonic": (0.05, "gear and encoder transmission errors of hundredths of a degree"),
    "backlash": (0.05, "a dead band of a few arc minutes"),
    "drift": (0.05, "warm-up moves a joint zero by hundredths of a degree per hour"),
}
#: kinds whose width is always free (the frames are registered from the data)
FREE_KINDS = ("base", "tool", "camera")
#: the key that sets every kind but the frames
ALL = "all"
#: a parameter name a prior can name: joint geometry (any convention) or a joint term's
NAME = re.compile(r"^(?:(?:a|alpha|theta|d|beta|x|y|z|rx|ry|rz)\d+|compliance\d+|gravity\d+_\d+[xyz]"
                  r"|harmonic\d+_(?:cos|sin)\d+|backlash\d+|drift\d+)$")
_JOINT_KIND = re.compile(r"^([a-z]+)(\d+)$")
_LENGTHS = frozenset(("a", "d", "x", "y", "z"))
_ANGLES = frozenset(("alpha", "beta", "rx", "ry", "rz"))
#: a prior share (the posterior variance over the prior's) above which a parameter is held by
#: its prior: the poses tell it less than the prior does
HELD = 0.5


def kind_of(name: str, prismatic: np.ndarray | None = None) -> str:
    """The prior kind of a parameter name (``prismatic``: the joints that slide, 0-based)."""
    if name.startswith(("base_", "base[")):
        return "base"
    if name.startswith("tool"):
        return "tool"
    if name.startswith("camera["):
        return "camera"
    for prefix, kind in (("compliance", "compliance"), ("gravity", "compliance"), ("harmonic", "harmonic"),
                         ("backlash", "backlash"), ("drift", "drift")):
        if name.startswith(prefix):
            return kind
    m = _JOINT_KIND.match(name)
    if m is None:
        raise ValueError(f"no prior kind for parameter {name!r}")
    kind, joint = m.group(1), int(m.group(2)) - 1
    slides = prismatic is not None and joint < len(prismatic) and bool(prismatic[joint])
    if kind == "theta":
        return "angle" if slides else "zero"
    if kind in _LENGTHS:
        return "length"
    if kind in _ANGLES:
        return "angle"
    raise ValueError(f"no prior kind for parameter {name!r}")


def _scaled_by_load(name: str) -> bool:
    """Compliance widths are deflections at the data's load: divided by the basis's RMS."""
    return name.startswith(("compliance", "gravity"))


def _in_own_units(name: str, kind: str, named: bool) -> float:
    """The factor from a width as stated (file units) to the parameter's own (mm, rad, …): a
    torque compliance named explicitly is in rad/(N·m), as robot files hold it."""
    if kind == "length" or (named and name.startswith("compliance")):
        return 1.0
    return math.pi / 180.0


@dataclass(frozen=True)
class Prior:
    """Prior widths as stated: key (a kind of :data:`DEFAULTS`, ``all``, or a parameter name) →
    width in the robot file's units (inf: free).  Keys not stated take the defaults."""

    widths: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def parse(cls, items, where: str = "prior") -> Prior:
        """From ``KEY=VALUE`` items (a string, comma lists allowed, or a sequence of them) or a
        mapping; VALUE a width > 0 or ``free``.  Raises ValueError naming what is wrong."""
        if items is None:
            return cls()
        if isinstance(items, Prior):
            return items
        pairs: list[tuple[str, object]] = []
        if isinstance(items, Mapping):
            pairs = list(items.items())
        else:
            for item in [items] if isinstance(items, str) else list(items):
                if isinstance(item, tuple) and len(item) == 2:
                    pairs.append(item)
                    continue
                for text in str(item).split(","):
                    key, sep, value = text.partition("=")
                    if not sep or not key.strip() or not value.strip():
                        raise ValueError(f"expected KEY=WIDTH (a kind, 'all' or a parameter name; a width or "
                                         f"'free'), got {text.strip()!r}")
                    pairs.append((key.strip(), value.strip()))
        out: dict[str, float] = {}
        for key, value in pairs:
            key = str(key).strip()
            if key not in DEFAULTS and key != ALL and not NAME.match(key):
                raise ValueError(f"unknown prior key {key!r} (expected {' | '.join([*DEFAULTS, ALL])} or a "
                                 "parameter name such as a5, theta2, harmonic6_cos1)")
            width = _width(value, key)
            if key in FREE_KINDS and math.isfinite(width):
                raise ValueError(f"{key}: the {key} frame is registered from the data and takes no prior (only "
                                 f"'free'), got {value!r}")
            if key in out:
                raise ValueError(f"{key} given twice")
            out[key] = width
        return cls(out)

    def merged(self, other: Prior | None) -> Prior:
        """These widths with ``other``'s on top (a command line's over a robot file's)."""
        if other is None or not other.widths:
            return self
        return Prior({**self.widths, **other.widths})

    def width(self, name: str, prismatic: np.ndarray | None = None) -> float:
        """A parameter's width as stated (file units; a compliance's as a deflection in deg)."""
        if name in self.widths:
            return self.widths[name]
        kind = kind_of(name, prismatic)
        if kind in self.widths:
            return self.widths[kind]
        if kind not in FREE_KINDS and ALL in self.widths:
            return self.widths[ALL]
        return DEFAULTS[kind][0]

    def sigmas(self, names, prismatic: np.ndarray | None = None,
               load_rms: Mapping[str, float] | None = None) -> np.ndarray:
        """σ per parameter in its own units (mm, rad, rad/(N·m)); inf where free.

        load_rms: for compliance kinds, the RMS over the calibration poses of the parameter's
        basis (its Δq per unit of the parameter): a deflection width divided by it is the
        parameter's width.  A name stated explicitly is already in the parameter's own units."""
        out = np.empty(len(names))
        for i, name in enumerate(names):
            kind = kind_of(name, prismatic)
            width = self.width(name, prismatic)
            if not math.isfinite(width):
                out[i] = math.inf
                continue
            named = name in self.widths
            sigma = width * _in_own_units(name, kind, named)
            if _scaled_by_load(name) and not named:
                rms = (load_rms or {}).get(name, 0.0)
                sigma = sigma / rms if rms > 0 else math.inf  # no load at any pose: no effect to hold
            out[i] = sigma
        return out

    def to_table(self) -> dict[str, float | str]:
        """The widths as a robot file's ``[prior]`` table holds them (``free`` for inf)."""
        return {k: (v if math.isfinite(v) else "free") for k, v in self.widths.items()}

    def describe(self) -> str:
        """One line of the widths in effect: the defaults with what was stated."""
        parts = []
        for kind, (default, _) in DEFAULTS.items():
            if kind in FREE_KINDS:
                continue
            w = self.widths.get(kind, self.widths.get(ALL, default))
            unit = {"length": " mm", "drift": "°/h"}.get(kind, "°")
            parts.append(f"{kind} {'free' if not math.isfinite(w) else f'{w:g}{unit}'}")
        named = [k for k in self.widths if k not in DEFAULTS and k != ALL]
        if named:
            parts.append("and " + ", ".join(f"{k} {self.widths[k]:g}" if math.isfinite(self.widths[k])
                                             else f"{k} free" for k in named))
        return ", ".join(parts)


def unknown_names(prior: Prior, geometry_names, n_joints: int) -> list[str]:
    """The parameter names ``prior`` states that a robot of these geometry parameter names and
    ``n_joints`` joints has not (a typo, or another convention's name)."""
    known = set(geometry_names)
    out = []
    for key in prior.widths:
        if key in DEFAULTS or key == ALL:
            continue
        if key in known:
            continue
        m = re.match(r"^(compliance|gravity|harmonic|backlash|drift)(\d+)", key)
        if m is None or not 1 <= int(m.group(2)) <= n_joints:
            out.append(key)
    return out


#: the narrowest width a prior may state (mm or deg): a thousandth of a micrometre or of a degree's
#: millionth is below anything a calibration can weigh, and its inverse square (the information it
#: adds) would swamp the data's by more digits than a double holds
MIN_WIDTH = 1e-6


def _width(value, key: str) -> float:
    if isinstance(value, str) and value.strip().lower() in ("free", "inf", "none"):
        return math.inf
    try:
        width = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{key}: expected a width > 0 or 'free', got {value!r}") from None
    if math.isnan(width) or width <= 0:
        raise ValueError(f"{key}: expected a width > 0 or 'free', got {value!r}")
    if width < MIN_WIDTH:
        raise ValueError(f"{key}: a width of {value!r} is below {MIN_WIDTH:g} (mm or deg): it holds the parameter "
                         "fixed where a computer cannot weigh it against the data; leave the parameter out (--params) "
                         "instead")
    return width


def prior_shares(inverse_information: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
    """Each parameter's prior share h_i = C_ii/σ_i² (C the posterior covariance before any noise
    scale): the leverage of its prior pseudo-observation, 0 where the data determine it alone, 1
    where they say nothing of it; Σ(1 − h_i) is the parameters' effective number, tr H of the data."""
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.diag(inverse_information) / np.asarray(sigmas, float) ** 2
    return np.where(np.isfinite(sigmas), np.clip(np.nan_to_num(h, nan=1.0), 0.0, 1.0), 0.0)
