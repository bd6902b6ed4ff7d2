"""Files of the parallel mechanism: its geometry (TOML) and tables of poses or lengths (CSV)."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .. import options as opt
from ..exceptions import InputError
from ..io.atomic import atomic_write, read_text
from ..io.table import numbers, read_csv
from .geometry import PKMGeometry, chen2023

_KEYS = {"name", "fixed", "moving", "rod_zero", "rod_limits", "hooke_limit", "source"}
BUILTIN = ("2tpr2tps", "chen2023")


def _points(data: dict, table: str, prefix: str, path) -> np.ndarray:
    if not isinstance(data.get(table), dict):
        raise InputError(f"missing table [{table}]", source=path)
    t = data[table]
    extra = set(t) - {f"{prefix}{i}" for i in range(1, 5)}
    if extra:
        raise InputError(f"unknown key '{sorted(extra)[0]}'", source=path, where=f"[{table}]")
    out = []
    for i in range(1, 5):
        v = t.get(f"{prefix}{i}")
        ok = isinstance(v, list) and len(v) == 3 and all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)
        if not ok:
            raise InputError(f"expected 3 finite numbers (mm), got {v!r}", source=path, where=f"[{table}] {prefix}{i}")
        out.append([float(c) for c in v])
    return np.array(out)


def load_pkm(spec: str | Path | PKMGeometry | None = None) -> PKMGeometry:
    """Geometry from a TOML file, or the built-in ``2tpr2tps`` (Chen et al. Table 2)."""
    if isinstance(spec, PKMGeometry):
        return spec
    if spec is None or str(spec).lower() in BUILTIN:
        return chen2023()
    path = Path(spec)
    if not path.is_file():
        raise InputError("no such mechanism file (built-in: 2tpr2tps)", source=path)
    try:
        data = tomllib.loads(read_text(path, "mechanism file"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", source=path) from None
    unknown = set(data) - _KEYS
    if unknown:
        raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: {', '.join(sorted(_KEYS))})", source=path)
    rz = data.get("rod_zero", [0.0] * 4)
    if not (isinstance(rz, list) and len(rz) == 4 and all(isinstance(c, (int, float)) for c in rz)):
        raise InputError(f"expected 4 numbers (mm), got {rz!r}", source=path, where="rod_zero")
    lim = data.get("rod_limits", [300.0, 520.0])
    if not (isinstance(lim, list) and len(lim) == 2 and all(isinstance(c, (int, float)) for c in lim)
            and lim[0] < lim[1]):
        raise InputError(f"expected [low, high] mm, got {lim!r}", source=path, where="rod_limits")
    hk = data.get("hooke_limit", 60.0)
    if not isinstance(hk, (int, float)) or not 0 < hk <= 90:
        raise InputError(f"expected degrees in (0, 90], got {hk!r}", source=path, where="hooke_limit")
    return PKMGeometry(_points(data, "fixed", "T", path), _points(data, "moving", "B", path), np.array(rz, float),
                       (float(lim[0]), float(lim[1])), math.radians(hk), str(data.get("name", path.stem)))


def pkm_to_toml(geom: PKMGeometry, comment: str | None = None) -> str:
    lines = [f"# {c}" for c in (comment or "").splitlines()]
    # top-level keys first: in TOML everything after a [table] header belongs to that table
    lines += [
        f'name = "{geom.name}"',
        f"rod_zero = [{', '.join(repr(float(v)) for v in geom.rod_zero)}]  # mm",
        f"rod_limits = [{geom.rod_limits[0]!r}, {geom.rod_limits[1]!r}]  # mm",
        f"hooke_limit = {math.degrees(geom.hooke_limit)!r}  # deg",
        "",
        "[fixed]  # mm, fixed-platform frame",
    ]
    lines += [f"T{i + 1} = [{', '.join(repr(float(v)) for v in geom.T[i])}]" for i in range(4)]
    lines += ["", "[moving]  # mm, moving-platform frame"]
    lines += [f"B{i + 1} = [{', '.join(repr(float(v)) for v in geom.B[i])}]" for i in range(4)]
    return "\n".join(lines + [""])


def save_pkm(geom: PKMGeometry, path: str | Path, comment: str | None = None) -> None:
    atomic_write(path, pkm_to_toml(geom, comment))


def read_rows(values: str | None, path: str | Path | None, names: Sequence[str], option: str) -> np.ndarray:
    """Rows of numbers (rows, len(names)) from a comma list (one row) or a CSV file with the
    named columns: exactly one of the two."""
    if (values is None) == (path is None):
        raise InputError(f"give either a comma list or a file of {', '.join(names)}", option=option)
    if values is not None:
        return np.array([opt.floats(values, option, (len(names),))])
    table = read_csv(read_text(path, "file"), source=str(path))
    table.require(names)
    return numbers(table, names)
