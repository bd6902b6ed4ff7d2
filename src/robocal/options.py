"""Checks of option values shared by every configuration: one place for the one-line errors.

Each check returns the coerced value or raises :class:`InputError` naming the option.
Strings are accepted where the command line passes text (``box="0.5,0.01"``), so the
command line and the Python API go through the same checks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .exceptions import InputError


def choice(value, allowed: Sequence[str], option: str, what: str = "value") -> str:
    if value not in allowed:
        raise InputError(f"unknown {what} {value!r} (expected {' | '.join(allowed)})", option=option)
    return value


def number(value, option: str, *, minimum: float | None = None, strict: bool = False,
           maximum: float | None = None) -> float:
    """A finite float ≥ minimum (> minimum when strict) and ≤ maximum."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"expected a number, got {value!r}", option=option) from None
    if not math.isfinite(v):
        raise InputError(f"must be finite, got {value!r}", option=option)
    if minimum is not None and (v <= minimum if strict else v < minimum):
        raise InputError(f"must be a finite value {'>' if strict else '≥'} {minimum:g}, got {v:g}", option=option)
    if maximum is not None and v > maximum:
        raise InputError(f"must be ≤ {maximum:g}, got {v:g}", option=option)
    return v


def integer(value, option: str, *, minimum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise InputError(f"expected an integer, got {value!r}", option=option)
    try:
        v = int(value)
    except (TypeError, ValueError):
        raise InputError(f"expected an integer, got {value!r}", option=option) from None
    if isinstance(value, float) and value != v:
        raise InputError(f"expected an integer, got {value!r}", option=option)
    if minimum is not None and v < minimum:
        raise InputError(f"must be ≥ {minimum}, got {v}", option=option)
    return v


def optional_integer(value, option: str, *, minimum: int | None = None) -> int | None:
    return None if value is None else integer(value, option, minimum=minimum)


def floats(value, option: str, sizes: tuple[int, ...]) -> tuple[float, ...]:
    """A comma list (or sequence) of finite numbers whose count is one of ``sizes``."""
    if isinstance(value, str):
        try:
            values = [float(v) for v in value.split(",")]
        except ValueError:
            raise InputError(f"expected {' or '.join(map(str, sizes))} comma-separated numbers, got {value!r}",
                             option=option) from None
    else:
        try:
            values = [float(v) for v in value]
        except (TypeError, ValueError):
            raise InputError(f"expected {' or '.join(map(str, sizes))} numbers, got {value!r}", option=option) from None
    if len(values) not in sizes or not all(math.isfinite(v) for v in values):
        raise InputError(f"expected {' or '.join(map(str, sizes))} finite comma-separated numbers, got {value!r}",
                         option=option)
    return tuple(values)


def frame_values(value, option: str) -> tuple[float, ...] | None:
    """x,y,z[,rx,ry,rz] with angles in deg (as typed) → (mm…, rad…), or None."""
    if value is None:
        return None
    v = floats(value, option, (3, 6))
    return v[:3] + tuple(math.radians(a) for a in v[3:])


def named_frames(items, option: str) -> tuple[tuple[float, ...] | None, dict[str, tuple[float, ...]]]:
    """``[NAME=]x,y,z,rx,ry,rz`` items (mm, deg) → the unnamed one (or None) and the named ones,
    as :func:`frame_values` gives them; a name twice, or two unnamed, is an error."""
    unnamed, named = None, {}
    for item in items or ():
        name, sep, values = str(item).rpartition("=")
        if sep and not name.strip():
            raise InputError(f"expected NAME=x,y,z,rx,ry,rz or x,y,z,rx,ry,rz, got {item!r}", option=option)
        frame = frame_values(values, option)
        if not sep:
            if unnamed is not None:
                raise InputError("given twice without a name (name each: NAME=x,y,z,rx,ry,rz)", option=option)
            unnamed = frame
        elif name.strip() in named:
            raise InputError(f"{name.strip()!r} given twice", option=option)
        else:
            named[name.strip()] = frame
    return unnamed, named


#: the word a --tool names the calibrated model's own tool by (MODEL §1.1)
CALIBRATED = "calibrated"


def tool_frames(items, option: str = "tool") -> tuple[tuple[float, ...] | None, dict[str, tuple[float, ...]],
                                                       frozenset[str]]:
    """``[NAME=][x,y,z[,rx,ry,rz]][,calibrated]`` items: as :func:`named_frames`, and the tools the
    calibration measured (their names; "" for the unnamed one: every target's tool), whose data,
    where given, are the controller's and whose calibrated model's tool stands in for them."""
    plain, measured = [], set()
    for item in items or ():
        text = str(item)
        name, sep, values = text.rpartition("=")
        parts = [v.strip() for v in values.split(",")]
        if parts[-1].lower() != CALIBRATED:
            plain.append(text)
            continue
        key = name.strip() if sep else ""
        if sep and not key:
            raise InputError(f"expected NAME=calibrated or calibrated, got {text!r}", option=option)
        if key in measured:
            raise InputError(f"{key or 'the unnamed tool'} is said calibrated twice", option=option)
        measured.add(key)
        if len(parts) > 1:
            plain.append((f"{key}=" if sep else "") + ",".join(parts[:-1]))
    unnamed, named = named_frames(plain, option)
    return unnamed, named, frozenset(measured)


def column_map(items) -> dict[str, str] | None:
    """``FILE=ROBOCAL`` pairs, each item possibly a comma list (``J1=q1,J2=q2``)."""
    if not items:
        return None
    if isinstance(items, dict):
        return {str(k): str(v) for k, v in items.items()}
    out: dict[str, str] = {}
    for item in items:
        for pair in str(item).split(","):
            if "=" not in pair:
                raise InputError(f"expected FILE_COLUMN=ROBOCAL_COLUMN, got {pair!r}", option="column")
            old, new = pair.split("=", 1)
            out[old.strip()] = new.strip()
    return out


def joint_limits(text: str | None, n: int, option: str = "limits"):
    """'lo:hi,lo:hi,…' (deg, one per joint) → (n, 2) rad, or None."""
    if text is None:
        return None
    import numpy as np

    parts = [p.strip() for p in text.split(",")]
    if len(parts) != n:
        raise InputError(f"expected {n} ranges lo:hi (deg), got {len(parts)}", option=option)
    out = []
    for j, p in enumerate(parts):
        try:
            lo, hi = (float(v) for v in p.split(":"))
        except ValueError:
            raise InputError(f"joint {j + 1}: expected lo:hi in degrees, got {p!r}", option=option) from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise InputError(f"joint {j + 1}: need finite lo < hi, got {p!r}", option=option)
        out.append((math.radians(lo), math.radians(hi)))
    return np.array(out)


def joint_values(text: str | None, option: str) -> dict[int, float] | None:
    """'J=V,J=V…' (1-based joints) → {joint: value}, or None."""
    if text is None:
        return None
    out: dict[int, float] = {}
    for pair in str(text).split(","):
        if "=" not in pair:
            raise InputError(f"expected JOINT=VALUE[,JOINT=VALUE…], got {pair!r}", option=option)
        j, v = pair.split("=", 1)
        out[integer(j.strip(), option, minimum=1)] = number(v.strip(), option)
    return out


def harmonic_specs(items, option: str = "harmonic") -> dict[int, list[tuple[float, float]]] | None:
    """'J:H=A,B' items (joint, order h ≥ 1, amplitudes of cos(h q) and sin(h q) in deg) →
    {joint: [(a_1, b_1), …]} rad, orders not given left at zero; or None."""
    if not items:
        return None
    out: dict[int, dict[int, tuple[float, float]]] = {}
    for item in items:
        head, sep, values = str(item).partition("=")
        j, colon, h = head.partition(":")
        if not (sep and colon):
            raise InputError(f"expected JOINT:ORDER=A_COS,B_SIN (deg), e.g. 2:1=0.01,0.005, got {item!r}",
                             option=option)
        a, b = floats(values, option, (2,))
        out.setdefault(integer(j.strip(), option, minimum=1), {})[integer(h.strip(), option, minimum=1)] = (
            math.radians(a), math.radians(b))
    return {j: [orders.get(h, (0.0, 0.0)) for h in range(1, max(orders) + 1)] for j, orders in out.items()}
