"""Robot files (TOML, SPEC §6) and the built-in robots.

Files hold mm and degrees; a loaded :class:`~robocal.model.robot.Robot` holds mm and rad.
Loading validates every key and names the file, the joint and the key on error.  Saving
writes the shortest decimal degrees that convert back to the exact same radians, so
``load(save(robot))`` reproduces the robot bit for bit.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..math.se3 import frame_from_values
from ..math.so3 import matrix_to_rpy
from ..model.kinematics import CONVENTIONS
from ..model.robot import Robot
from .atomic import atomic_write, read_text
from .builtins import builtin_names, builtin_text

TOP_KEYS = {"name", "convention", "joint", "base", "tool", "targets", "source"}
JOINT_KEYS = {"a", "alpha", "d", "theta", "beta", "limits"}
FRAME_KEYS = {"xyz", "rpy"}
_RADIAN_LOOKALIKES = (math.pi / 2, math.pi, math.pi / 4)


def load_robot(spec: str | Path | Robot) -> Robot:
    """A robot from a file path or a built-in name (see :func:`builtin_names`)."""
    if isinstance(spec, Robot):
        return spec
    path = Path(spec)
    if path.suffix.lower() == ".toml" or path.exists():
        if not path.is_file():
            raise InputError("no such robot file", source=path)
        return parse_robot(read_text(path, "robot file"), source=str(path), default_name=path.stem)
    text = builtin_text(str(spec))
    if text is None:
        raise InputError(f"no robot file and no built-in robot of that name (built-in: {', '.join(builtin_names())})",
                         source=str(spec))
    return parse_robot(text, source=f"built-in {spec}", default_name=str(spec))


def _number(value, source, where) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {type(value).__name__} {value!r}", source=source, where=where)
    if not math.isfinite(value):
        raise InputError(f"value must be finite, got {value!r}", source=source, where=where)
    return float(value)


def _vector(value, size, source, where) -> list[float]:
    if not isinstance(value, list) or len(value) != size:
        raise InputError(f"expected a list of {size} numbers, got {value!r}", source=source, where=where)
    return [_number(v, source, where) for v in value]


def _check_degrees(value: float, source, where) -> None:
    if value != 0 and any(abs(abs(value) - r) < 2e-3 for r in _RADIAN_LOOKALIKES):
        raise InputError(f"{value!r} looks like radians (≈ π/2, π or π/4); robot files give angles in degrees",
                         source=source, where=where)


def _frame(table, source, key) -> np.ndarray:
    if not isinstance(table, dict):
        raise InputError("expected a table with xyz and rpy", source=source, where=f"key '{key}'")
    unknown = set(table) - FRAME_KEYS
    if unknown:
        raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: xyz, rpy)", source=source, where=f"[{key}]")
    xyz = _vector(table.get("xyz", [0.0, 0.0, 0.0]), 3, source, f"[{key}] xyz")
    rpy = _vector(table.get("rpy", [0.0, 0.0, 0.0]), 3, source, f"[{key}] rpy")
    for v in rpy:
        _check_degrees(v, source, f"[{key}] rpy")
    return frame_from_values(xyz + [math.radians(v) for v in rpy])


def _joint(j: dict, i: int, conv: str, source: str) -> tuple[np.ndarray, tuple[float, float]]:
    """One [[joint]] table → geometry row (mm, deg as written) and limits (deg)."""
    where = f"joint {i + 1}"
    unknown = set(j) - JOINT_KEYS
    if unknown:
        raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: {', '.join(sorted(JOINT_KEYS))})",
                         source=source, where=where)
    row = np.zeros(5)
    for k, key in enumerate(("a", "alpha", "theta", "d")):
        if key not in j:
            raise InputError(f"missing key '{key}'", source=source, where=where)
        row[k] = _number(j[key], source, f"{where}, key '{key}'")
    if "beta" in j:
        if conv != "hayati":
            raise InputError(f"key 'beta' is only allowed with convention 'hayati' (this robot is '{conv}')",
                             source=source, where=where)
        row[4] = _number(j["beta"], source, f"{where}, key 'beta'")
    for k in (1, 2, 4):
        _check_degrees(row[k], source, f"{where}, key '{('a', 'alpha', 'theta', 'd', 'beta')[k]}'")
    limits = (-math.inf, math.inf)
    if "limits" in j:
        lo, hi = _vector(j["limits"], 2, source, f"{where}, key 'limits'")
        if not lo < hi:
            raise InputError(f"limits must be [low, high] with low < high, got {[lo, hi]}", source=source,
                             where=f"{where}, key 'limits'")
        limits = (lo, hi)
    return row, limits


def _header(data: dict, source: str) -> tuple[str, str]:
    unknown = set(data) - TOP_KEYS
    if unknown:
        raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: {', '.join(sorted(TOP_KEYS))})", source=source)
    name = data.get("name", "")
    if not isinstance(name, str):
        raise InputError("expected a string", source=source, where="key 'name'")
    if "convention" not in data:
        raise InputError(f"missing key 'convention' ({' | '.join(CONVENTIONS)})", source=source)
    conv = data["convention"]
    if conv not in CONVENTIONS:
        raise InputError(f"unknown convention {conv!r} (expected {' | '.join(CONVENTIONS)})", source=source,
                         where="key 'convention'")
    return name, conv


def parse_robot(text: str, *, source: str = "<robot>", default_name: str = "robot") -> Robot:
    """A robot from TOML text; every problem is an InputError naming ``source`` and the key."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", source=source) from None
    name, conv = _header(data, source)
    joints = data.get("joint")
    if not isinstance(joints, list) or not joints or not all(isinstance(j, dict) for j in joints):
        raise InputError("needs at least one [[joint]] table", source=source)
    rows, limits = zip(*(_joint(j, i, conv, source) for i, j in enumerate(joints)))
    geom, limits = np.array(rows), np.array(limits)
    finite = limits[np.isfinite(limits)]
    if finite.size >= 4 and np.all(np.abs(finite) <= math.pi + 1e-6) and np.any(np.abs(finite) > 1.0):
        raise InputError("joint limits all lie within ±π: they look like radians; robot files give limits in "
                         "degrees", source=source, where="key 'limits'")
    geom[:, [1, 2, 4]] = np.radians(geom[:, [1, 2, 4]])
    base = _frame(data["base"], source, "base") if "base" in data else np.eye(4)
    tool = _frame(data["tool"], source, "tool") if "tool" in data else np.eye(4)
    targets = {}
    if "targets" in data:
        if not isinstance(data["targets"], dict):
            raise InputError("expected tables [targets.NAME]", source=source, where="key 'targets'")
        targets = {str(t): _frame(table, source, f"targets.{t}") for t, table in data["targets"].items()}
    return Robot(conv, geom, np.radians(limits), base=base, tool=tool, targets=targets, name=name or default_name,
                 source=source)


def _deg(x_rad: float) -> str:
    """Shortest decimal degrees whose conversion gives back exactly ``x_rad``: 120.0, not
    119.99999999999999, for a limit the user wrote as 120; never -0.0."""
    deg = math.degrees(x_rad)
    for digits in range(0, 18):
        text = _num(round(deg, digits))
        if math.radians(float(text)) == x_rad:
            return text
    for _ in range(8):  # no short decimal: the nearest doubles of the degree value
        if math.radians(float(repr(deg))) == x_rad:
            return _num(deg)
        deg = math.nextafter(deg, math.inf if math.radians(deg) < x_rad else -math.inf)
    return _num(math.degrees(x_rad))


def _num(x: float) -> str:
    """Shortest round-trip decimal of a float, with 0.0 for -0.0."""
    x = float(x)
    return repr(x + 0.0 if x == 0 else x)


def _frame_text(header: str, T: np.ndarray) -> list[str]:
    xyz, rpy = T[:3, 3], matrix_to_rpy(T[:3, :3])
    return [
        header,
        f"xyz = [{', '.join(_num(v) for v in xyz)}]  # mm",
        f"rpy = [{', '.join(_deg(v) for v in rpy)}]  # deg, R = Rz(rpy[2]) Ry(rpy[1]) Rx(rpy[0])",
    ]


def _quote(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def robot_to_toml(robot: Robot, comment: str | None = None) -> str:
    lines = [f"# {c}" for c in comment.splitlines()] if comment else []
    lines += [f"name = {_quote(robot.name)}", f'convention = "{robot.convention}"', ""]
    for i in range(robot.n_joints):
        a, al, th, d, be = robot.geometry[i]
        lines += ["[[joint]]", f"a = {_num(a)}", f"alpha = {_deg(al)}", f"d = {_num(d)}", f"theta = {_deg(th)}"]
        if robot.convention == "hayati":
            lines.append(f"beta = {_deg(be)}")
        lo, hi = robot.limits[i]
        if np.isfinite(lo) and np.isfinite(hi):
            lines.append(f"limits = [{_deg(lo)}, {_deg(hi)}]")
        lines.append("")
    lines += _frame_text("[base]", robot.base) + [""]
    lines += _frame_text("[tool]", robot.tool) + [""]
    for name, T in robot.targets.items():
        lines += _frame_text(f"[targets.{_quote(name)}]", T) + [""]
    return "\n".join(lines)


def save_robot(robot: Robot, path: str | Path, comment: str | None = None) -> None:
    atomic_write(path, robot_to_toml(robot, comment))
