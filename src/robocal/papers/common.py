"""Helpers shared by the reproductions: number formatting, the machine's description, outputs."""

from __future__ import annotations

import json
import math
import platform
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write

Say = Callable[[str], None]


def quiet(_: str) -> None:
    """A ``say`` that says nothing."""


#: figures below this are zero up to rounding (a sum of 1e-16s), shown as 0
ZERO = 1e-12


def fmt(x: float | None, digits: int = 4) -> str:
    """A figure for a summary table: fixed point, or 3 significant digits when tiny or huge; — when absent."""
    if x is None or not math.isfinite(x):
        return "—"
    if abs(x) < ZERO:
        return "0"
    return f"{x:.{digits}g}" if abs(x) < 1e-3 or abs(x) >= 1e4 else f"{x:.{digits}f}"


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}"


def write_json(path: Path, data: dict) -> None:
    atomic_write(path, json.dumps(data, indent=1, allow_nan=False, default=float) + "\n")
