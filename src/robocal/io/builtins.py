"""The built-in robots: which there are, their TOML text and a listing (no numpy needed).

Loading one as a :class:`~robocal.model.robot.Robot` is :func:`robocal.io.robotfile.load_robot`.
"""

from __future__ import annotations

import tomllib
from importlib import resources


def _builtin_dir():
    return resources.files("robocal.io") / "robots"


def builtin_names() -> list[str]:
    return sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".toml"))


def builtin_text(name: str) -> str | None:
    f = _builtin_dir() / f"{name.lower()}.toml"
    return f.read_text(encoding="utf-8") if f.is_file() else None


def builtin_summaries() -> list[dict[str, str | int]]:
    """Name, robot, convention, joint count and source of every built-in robot, read from the
    files alone (a listing needs no kinematics; the tests load each one fully)."""
    out = []
    for name in builtin_names():
        data = tomllib.loads(builtin_text(name))
        out.append({"name": name, "robot": str(data.get("name", name)), "convention": str(data["convention"]),
                    "joints": len(data["joint"]), "source": str(data.get("source", ""))})
    return out
