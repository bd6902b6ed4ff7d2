"""Robot files (TOML, MODEL §5) and the built-in robots.

Files hold mm and degrees; a loaded :class:`~robocal.model.robot.Robot` holds mm and rad.
Loading validates every key and names the file, the joint and the key on error.  Saving
writes the shortest decimal degrees that convert back to the exact same radians, so
``load(save(robot))`` reproduces the robot bit for bit.

Joint terms beyond geometry (MODEL §4, :mod:`robocal.model.terms`) are per-joint keys:
``compliance`` (rad/(N·m)), ``harmonics = [[a1, b1], [a2, b2], …]`` (degrees: the amplitude
of cos(h q) and sin(h q)) and ``gravity_deflection = [[x, y, z], …]`` (degrees, one triple per
link from this joint's own to the last); a ``[gravity]`` table gives ``direction`` (base
frame, default [0, 0, -1]) and ``payload_com`` (mm, flange frame).  A learned residual
correction lives in a sibling JSON file named by the top-level key ``residual``.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from pathlib import Path

import numpy as np

from ..exceptions import InputError, RobocalWarning
from ..math.se3 import frame_from_values
from ..math.so3 import matrix_to_rpy
from ..model import urdf
from ..model.corrections import Correction, correction_from_dict
from ..model.coupled import CoupledJoint, check
from ..model.covariance import ParameterCovariance
from ..model.kinematics import CONVENTIONS, joint_parameter_names, prismatic_mask
from ..model.prior import Prior, unknown_names
from ..model.region import Region
from ..model.robot import Robot
from ..model.terms import TERMS, FileKey, JointTerms
from .atomic import atomic_write, read_text
from .builtins import builtin_names, builtin_text

TOP_KEYS = {"name", "convention", "joint", "base", "tool", "targets", "source", "gravity", "drift", "residual",
            "region", "fallback", "uncertainty", "controller", "prior", "cameras", "chains"}
CONTROLLER_KEYS = {"coupling"}
COUPLING_KEYS = {"joint", "plus", "factor"}
GEOMETRY_KEYS = {"a", "alpha", "d", "theta", "beta", "limits", "type", "name", "parent", "follows", "follows_offset"}
TERM_KEYS = {key.key for t in TERMS.values() for key in t.file_keys}
JOINT_KEYS = GEOMETRY_KEYS | TERM_KEYS
#: a urdf-convention robot's joints: origin xyz (mm) and rpy (deg), axis, type, zero offset
URDF_JOINT_KEYS = {"xyz", "rpy", "axis", "type", "offset", "limits", "name", "parent", "follows",
                   "follows_offset"} | TERM_KEYS
JOINT_TYPES = ("revolute", "prismatic")
GRAVITY_KEYS = {"direction", "payload_com"}
DRIFT_KEYS = {"clock", "reference"}
FRAME_KEYS = {"xyz", "rpy"}
#: a chain of a tree: the joint at its tip, and its own tool (a frame after that joint)
CHAIN_KEYS = {"tip", "tool"}
#: a camera's mounting: its link (0: fixed in the measuring frame), its frame there, whether it was
#: given rather than found, and the camera it is fixed to (a calibrated rig)
CAMERA_KEYS = FRAME_KEYS | {"link", "known", "of"}
_RADIAN_LOOKALIKES = (math.pi / 2, math.pi, math.pi / 4)


def load_robot(spec: str | Path | Robot, *, base_link: str | None = None, tip_link: str | None = None) -> Robot:
    """A robot from a file path (robot TOML; URDF: its chain from ``base_link`` to
    ``tip_link``, or the tree of several tips given as ``A,B``, see :mod:`robocal.io.urdf`; a UR
    kinematics YAML, see :mod:`robocal.io.ur`)
    or a built-in name (see :func:`builtin_names`)."""
    if isinstance(spec, Robot):
        return spec
    path = Path(spec)
    if path.suffix.lower() == ".urdf":
        from .urdf import parse_urdf, whole_model_file
        from .urdf_tree import parse_urdf_tree

        text = read_text(path, "URDF file")
        whole = whole_model_file(text, path)
        tips = [t.strip() for t in tip_link.split(",") if t.strip()] if tip_link else []
        if whole is None and len(tips) > 1:  # several tips: the tree of their chains
            return parse_urdf_tree(text, source=str(path), base_link=base_link, tips=tips)
        if whole is None:
            return parse_urdf(text, source=str(path), base_link=base_link, tip_link=tip_link)
        warnings.warn(f"{path} is the geometry of a model beyond geometry: the whole model is read from {whole}",
                      RobocalWarning, stacklevel=2)
        return load_robot(whole)
    for option, value in (("base_link", base_link), ("tip_link", tip_link)):
        if value is not None:
            raise InputError(f"applies to URDF robots only, not {spec}", option=option)
    if path.suffix.lower() in (".yaml", ".yml"):  # a UR controller's kinematics, as the ROS drivers extract it
        from .ur import parse_ur_kinematics

        return parse_ur_kinematics(read_text(path, "UR kinematics file"), source=str(path))
    if path.suffix.lower() == ".toml" or path.is_file():  # a folder named like a built-in robot is not a file
        if not path.is_file():
            raise InputError("no such robot file", source=path)
        return parse_robot(read_text(path, "robot file"), source=str(path), default_name=path.stem,
                           directory=path.parent)
    text = builtin_text(str(spec))
    if text is None:
        raise InputError(f"no robot file and no built-in robot of that name (built-in: {', '.join(builtin_names())})",
                         source=str(spec))
    return parse_robot(text, source=f"built-in {spec}", default_name=str(spec))


#: no length (mm) or angle (deg) of a robot file is larger: ten kilometres; beyond it a value is a
#: typo, and the arithmetic on it overflows
MAX_MAGNITUDE = 1e7


def _number(value, source, where) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {type(value).__name__} {value!r}", source=source, where=where)
    if not math.isfinite(value):
        raise InputError(f"value must be finite, got {value!r}", source=source, where=where)
    if abs(value) > MAX_MAGNITUDE:
        raise InputError(f"{value!r} is not a plausible value (beyond ±{MAX_MAGNITUDE:g}: mm, deg)", source=source,
                         where=where)
    return float(value)


def _vector(value, size, source, where) -> list[float]:
    if not isinstance(value, list) or len(value) != size:
        raise InputError(f"expected a list of {size} numbers, got {value!r}", source=source, where=where)
    return [_number(v, source, where) for v in value]


def _check_degrees(value: float, source, where, zero: bool = False) -> None:
    """A twist or frame angle near π/2, π or π/4 in degrees was typed in radians; a joint zero
    (``zero``) only when it is one of them to the digits a typed radian has: a calibrated zero
    of −0.785° is a real offset, not π/4.  A typed radian has a few decimals (1.5708, 3.14); a
    value of many (0.7860811966432728°, a calibrated frame's angle as robocal writes it) is measured."""
    near = 1e-4 if zero else 2e-3
    typed = round(value, 6) == value
    if value != 0 and typed and any(abs(abs(value) - r) < near for r in _RADIAN_LOOKALIKES):
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


def _joint_type(j: dict, where: str, source: str) -> bool:
    """True for ``type = "prismatic"``; revolute (the default) otherwise."""
    kind = j.get("type", "revolute")
    if kind not in JOINT_TYPES:
        raise InputError(f"unknown joint type {kind!r} (expected {' | '.join(JOINT_TYPES)})", source=source,
                         where=f"{where}, key 'type'")
    return kind == "prismatic"


def _limits(j: dict, where: str, source: str) -> tuple[float, float]:
    if "limits" not in j:
        return -math.inf, math.inf
    lo, hi = _vector(j["limits"], 2, source, f"{where}, key 'limits'")
    if not lo < hi:
        raise InputError(f"limits must be [low, high] with low < high, got {[lo, hi]}", source=source,
                         where=f"{where}, key 'limits'")
    return lo, hi


def _dh_joint(j: dict, i: int, conv: str, source: str) -> np.ndarray:
    """One [[joint]] table of the DH family → geometry row (mm, rad)."""
    where = f"joint {i + 1}"
    row = np.zeros(6)
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
        _check_degrees(row[k], source, f"{where}, key '{('a', 'alpha', 'theta', 'd', 'beta')[k]}'", zero=k == 2)
    row[[1, 2, 4]] = np.radians(row[[1, 2, 4]])
    row[5] = _joint_type(j, where, source)
    return row


def _urdf_joint(j: dict, i: int, source: str) -> np.ndarray:
    """One [[joint]] table of a urdf-convention robot → geometry row (mm, rad)."""
    where = f"joint {i + 1}"
    row = np.zeros(urdf.WIDTH)
    row[urdf.X:urdf.Z + 1] = _vector(j.get("xyz", [0.0, 0.0, 0.0]), 3, source, f"{where}, key 'xyz'")
    rpy = _vector(j.get("rpy", [0.0, 0.0, 0.0]), 3, source, f"{where}, key 'rpy'")
    for v in rpy:
        _check_degrees(v, source, f"{where}, key 'rpy'")
    row[urdf.ROLL:urdf.YAW + 1] = np.radians(rpy)
    if "axis" not in j:
        raise InputError("missing key 'axis'", source=source, where=where)
    axis = np.array(_vector(j["axis"], 3, source, f"{where}, key 'axis'"))
    if not np.linalg.norm(axis) > 0:
        raise InputError("the joint axis must not be zero", source=source, where=f"{where}, key 'axis'")
    row[urdf.AX:urdf.AZ + 1] = axis / np.linalg.norm(axis)
    row[urdf.PRISMATIC] = _joint_type(j, where, source)
    offset = _number(j.get("offset", 0.0), source, f"{where}, key 'offset'")
    row[urdf.OFFSET] = offset if row[urdf.PRISMATIC] else math.radians(offset)
    return row


def _joint(j: dict, i: int, conv: str, source: str) -> tuple[np.ndarray, tuple[float, float]]:
    """One [[joint]] table → geometry row (mm, rad) and limits as written (deg, or mm)."""
    where = f"joint {i + 1}"
    allowed = URDF_JOINT_KEYS if conv == "urdf" else JOINT_KEYS
    unknown = set(j) - allowed
    if unknown:
        raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: {', '.join(sorted(allowed))})",
                         source=source, where=where)
    row = _urdf_joint(j, i, source) if conv == "urdf" else _dh_joint(j, i, conv, source)
    return row, _limits(j, where, source)


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


def _pairs(value, width, source, where) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise InputError(f"expected a list of [{', '.join('xyz'[:width] if width == 3 else 'ab')}] lists, got "
                         f"{value!r}", source=source, where=where)
    return np.array([_vector(v, width, source, where) for v in value])


def _term_array(key: FileKey, joints: list[dict], n: int, source: str) -> np.ndarray | None:
    """One term array from the per-joint ``key`` of every [[joint]] table (None if no joint has it)."""
    if not any(key.key in j for j in joints):
        return None
    scale = math.pi / 180.0 if key.degrees else 1.0
    if key.shape == "scalar":
        return np.array([_number(j.get(key.key, 0.0), source, f"joint {i + 1}, key '{key.key}'")
                         for i, j in enumerate(joints)]) * scale
    if key.shape == "links":
        out = np.zeros((n, n, 3))
        for i, j in enumerate(joints):
            if key.key in j:
                rows = _pairs(j[key.key], 3, source, f"joint {i + 1}, key '{key.key}'")
                if len(rows) != n - i:
                    raise InputError(f"expected {n - i} [x, y, z] triples (links {i + 1}..{n}), got {len(rows)}",
                                     source=source, where=f"joint {i + 1}, key '{key.key}'")
                out[i, i:] = rows * scale
        return out
    rows = [_pairs(j[key.key], 2, source, f"joint {i + 1}, key '{key.key}'") if key.key in j else np.zeros((0, 2))
            for i, j in enumerate(joints)]
    width = max(len(r) for r in rows)
    if not width:
        return None
    out = np.zeros((n, width, 2))
    for i, r in enumerate(rows):
        out[i, :len(r)] = r * scale
    return out


def _terms(joints: list[dict], data: dict, n: int, source: str) -> JointTerms | None:
    """The joint terms of a robot file (the per-joint keys of :data:`robocal.model.terms.TERMS`),
    or None when it has none (and no [gravity] table)."""
    arrays = {key.array: a for t in TERMS.values() for key in t.file_keys
              if (a := _term_array(key, joints, n, source)) is not None}
    table = data.get("gravity")
    if not arrays and table is None:
        return None
    direction, com = np.array([0.0, 0.0, -1.0]), np.zeros(3)
    if isinstance(table, list):  # gravity = [x, y, z]: the direction alone
        table = {"direction": table}
    if table is not None:
        if not isinstance(table, dict):
            raise InputError("expected a [gravity] table with direction and payload_com", source=source,
                             where="key 'gravity'")
        unknown = set(table) - GRAVITY_KEYS
        if unknown:
            raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: {', '.join(sorted(GRAVITY_KEYS))})",
                             source=source, where="[gravity]")
        direction = np.array(_vector(table.get("direction", [0.0, 0.0, -1.0]), 3, source, "[gravity] direction"))
        if not np.linalg.norm(direction) > 0:
            raise InputError("the gravity direction must not be zero", source=source, where="[gravity] direction")
        com = np.array(_vector(table.get("payload_com", [0.0, 0.0, 0.0]), 3, source, "[gravity] payload_com"))
    return JointTerms(arrays, direction / np.linalg.norm(direction), com, _clock(data.get("drift"), arrays, source))


def _clock(table, arrays: dict, source: str) -> tuple[str, float] | None:
    """The drift's [drift] table: clock ``s`` or ``row`` and the reference time on it."""
    if table is None:
        if "drift" in arrays:
            raise InputError("joints have a drift key but the file has no [drift] table (clock and reference)",
                             source=source, where="[drift]")
        return None
    if not isinstance(table, dict):
        raise InputError("expected a [drift] table with clock and reference", source=source, where="key 'drift'")
    _known_keys(table, DRIFT_KEYS, source, "[drift]")
    clock = table.get("clock", "s")
    if clock not in ("s", "row"):
        raise InputError(f"clock {clock!r} is not s (a time column, seconds) or row (row numbers of the "
                         "calibration file)", source=source, where="[drift] clock")
    reference = table.get("reference", 0.0)
    if isinstance(reference, bool) or not isinstance(reference, int | float) or not np.isfinite(reference):
        raise InputError(f"reference {reference!r} is not a number", source=source, where="[drift] reference")
    return clock, float(reference)


def _sibling(value, key: str, kind: str, source: str, directory: Path | None, purpose: str = "") -> Path:
    """The file a robot file's ``key`` names (looked for beside the robot file): part of its model."""
    where = f"key '{key}'"
    if not isinstance(value, str) or not value:
        raise InputError(f"expected the name of a {kind}, got {value!r}", source=source, where=where)
    path = Path(value)
    if not path.is_absolute() and directory is not None:
        path = directory / path
    if not path.is_file():
        raise InputError(f"no such {kind} {str(path)!r}{purpose} (it is looked for beside the robot file)",
                         source=source, where=where)
    return path


def _residual(value, n: int, source: str, directory: Path | None) -> Correction:
    path = _sibling(value, "residual", "residual-model file", source, directory)
    import json

    try:
        model = correction_from_dict(json.loads(read_text(path, "residual-model file")))
    except InputError:
        raise
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"not a robocal residual model ({exc.__class__.__name__}: {exc})", source=path) from None
    if model.n_joints != n:
        raise InputError(f"residual model is for {model.n_joints} joints, the robot has {n}", source=path)
    return model


def _region(value, slide: np.ndarray, source: str) -> Region:
    where = "[region]"
    if not isinstance(value, dict) or "joints" not in value or set(value) - {"joints", "poses", "sigma_mm"}:
        raise InputError("expected a [region] table with joints = [[low, high], …], poses and sigma_mm",
                         source=source, where=where)
    ranges = _pairs(value["joints"], 2, source, f"{where} joints")
    if len(ranges) != len(slide) or np.any(ranges[:, 0] > ranges[:, 1]):
        raise InputError(f"expected {len(slide)} [low, high] pairs with low ≤ high", source=source,
                         where=f"{where} joints")
    poses = value.get("poses", 0)
    if isinstance(poses, bool) or not isinstance(poses, int) or poses < 0:
        raise InputError(f"expected a count of poses, got {poses!r}", source=source, where=f"{where} poses")
    sigma = None if "sigma_mm" not in value else _number(value["sigma_mm"], source, f"{where} sigma_mm")
    if sigma is not None and not sigma > 0:
        raise InputError(f"expected a positive uncertainty (mm), got {sigma!r}", source=source,
                         where=f"{where} sigma_mm")
    return Region.from_dict({"joints": ranges.tolist(), "poses": poses, "sigma_mm": sigma}, slide)


def parse_robot(text: str, *, source: str = "<robot>", default_name: str = "robot",
                directory: Path | None = None) -> Robot:
    """A robot from TOML text; every problem is an InputError naming ``source`` and the key.
    directory: where a ``residual`` file named in the text is looked for (default: the
    working directory)."""
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
    slide = prismatic_mask(conv, geom)
    names = [j.get("name") for j in joints]
    for i, nm in enumerate(names):
        if nm is not None and not isinstance(nm, str):
            raise InputError(f"expected a string, got {nm!r}", source=source, where=f"joint {i + 1}, key 'name'")
    finite = limits[~slide][np.isfinite(limits[~slide])]
    if finite.size >= 4 and np.all(np.abs(finite) <= math.pi + 1e-6) and np.any(np.abs(finite) > 1.0):
        raise InputError("joint limits all lie within ±π: they look like radians; robot files give limits in "
                         "degrees", source=source, where="key 'limits'")
    limits = np.where(slide[:, None], limits, np.radians(limits))  # a slide's limits are in mm
    base = _frame(data["base"], source, "base") if "base" in data else np.eye(4)
    tool = _frame(data["tool"], source, "tool") if "tool" in data else np.eye(4)
    targets = {}
    if "targets" in data:
        if not isinstance(data["targets"], dict):
            raise InputError("expected tables [targets.NAME]", source=source, where="key 'targets'")
        targets = {str(t): _frame(table, source, f"targets.{t}") for t, table in data["targets"].items()}
    terms = _terms(joints, data, len(joints), source)
    residual = None if "residual" not in data else _residual(data["residual"], len(joints), source, directory)
    region = None if "region" not in data else _region(data["region"], slide, source)
    if "fallback" in data:  # earlier files named a geometric fit for the poses outside the region
        warnings.warn(f"{source}: key 'fallback' ({data['fallback']!r}) is not used: a calibrated model is used whole "
                      "everywhere, and its predicted uncertainty says where it is less known", RobocalWarning,
                      stacklevel=3)
    uncertainty = None if "uncertainty" not in data else _covariance(data["uncertainty"], source)
    coupling = () if "controller" not in data else _coupling(data["controller"], len(joints), source)
    prior = None if "prior" not in data else _prior(data["prior"], conv, geom, source)
    cameras = {} if "cameras" not in data else _cameras(data["cameras"], len(joints), source)
    tree = _tree_spec(joints, data.get("chains"), source)
    followers = _followers(joints, slide, source)
    if tree is not None:  # each chain's own tool, a target named after the chain
        targets = {**_chain_tools(data["chains"], source), **targets}
    try:
        robot = Robot(conv, geom, limits, joint_names=tuple(nm or f"joint{i + 1}" for i, nm in enumerate(names))
                      if any(names) else None, base=base, tool=tool, targets=targets, name=name or default_name,
                      source=source, terms=terms, residual=residual, region=region, uncertainty=uncertainty,
                      coupling=coupling, prior=prior, cameras=cameras, tree=tree, coupled=followers)
    except ValueError as exc:  # what the parts cannot be together (a tree with joint terms)
        raise InputError(str(exc), source=source) from None
    if uncertainty is not None:
        _check_covariance_names(robot, uncertainty, source)
    return robot


def _tree_spec(joints: list[dict], chains, source: str):
    """A tree (:mod:`robocal.model.kinematic_tree`) where a joint names its ``parent`` (1-based; 0: the base; the
    one before it where not given) and ``[chains.NAME] tip = K`` names each chain's last joint; None
    for a serial robot (no parent and no chains)."""
    from ..model.kinematic_tree import TreeSpec

    stated = any("parent" in j for j in joints)
    if chains is None and not stated:
        return None
    if not isinstance(chains, dict) or not chains or not all(isinstance(v, dict) for v in chains.values()):
        raise InputError("a tree (joints with a parent) names its chains: tables [chains.NAME] with tip = K",
                         source=source, where="[chains]")
    n = len(joints)
    parents = []
    for i, j in enumerate(joints):
        p = j.get("parent", i)
        if not isinstance(p, int) or isinstance(p, bool) or not 0 <= p <= i:
            raise InputError(f"parent must be a joint before this one (1…{i}) or 0 (the base), got {p!r}",
                             source=source, where=f"joint {i + 1}, key 'parent'")
        parents.append(p - 1)
    paths = {}
    for name, table in chains.items():
        _known_keys(table, CHAIN_KEYS, source, f"[chains.{name}]")
        tip = table.get("tip")
        if not isinstance(tip, int) or isinstance(tip, bool) or not 1 <= tip <= n:
            raise InputError(f"tip must be a joint 1…{n}, got {tip!r}", source=source, where=f"[chains.{name}] tip")
        path, k = [], tip - 1
        while k >= 0:
            path.append(k)
            k = parents[k]
        paths[str(name)] = tuple(reversed(path))
    return TreeSpec(tuple(parents), paths)


def _chain_tools(chains: dict, source: str) -> dict:
    """Each chain's own tool (``[chains.NAME.tool]``, xyz mm and rpy deg after its tip joint; the
    tip joint's frame where not given), a target named after the chain."""
    return {str(name): _frame(table["tool"], source, f"chains.{name}.tool") if "tool" in table else np.eye(4)
            for name, table in chains.items()}


def _cameras(table, n: int, source: str) -> dict:
    """``[cameras.NAME]``: each camera's ``link`` (0: fixed in the measuring frame; k: on the link
    after joint k), its frame there (``xyz`` mm, ``rpy`` deg: z its optical axis), ``known`` (given,
    not found by a calibration) and ``of`` (fixed to that camera: its frame in that one's)."""
    from ..model.camera import CameraMount

    if not isinstance(table, dict) or not all(isinstance(v, dict) for v in table.values()):
        raise InputError("expected tables [cameras.NAME] with link, xyz and rpy", source=source, where="[cameras]")
    out = {}
    for name, entry in table.items():
        where = f"[cameras.{name}]"
        _known_keys(entry, CAMERA_KEYS, source, where)
        link = entry.get("link", 0)
        if not isinstance(link, int) or isinstance(link, bool) or not 0 <= link <= n:
            raise InputError(f"link must be a whole number 0…{n} (0: fixed in the measuring frame), got {link!r}",
                             source=source, where=f"{where} link")
        known = entry.get("known", False)
        of = entry.get("of", "")
        if not isinstance(known, bool) or not isinstance(of, str):
            raise InputError("known is true or false, of a camera's name", source=source, where=where)
        out[str(name)] = CameraMount(link, _frame({k: entry[k] for k in FRAME_KEYS & set(entry)}, source,
                                                  f"cameras.{name}"), known, of)
    for name, mount in out.items():
        if mount.of and (mount.of not in out or out[mount.of].of):
            raise InputError(f"is fixed to camera {mount.of!r}, which the file does not give as a camera of its own",
                             source=source, where=f"[cameras.{name}] of")
    return out


def _prior(table, convention: str, geom: np.ndarray, source: str) -> Prior:
    """``[prior]``: widths by kind (``length = 1.0`` mm, ``angle = 0.1`` deg, …) or by parameter
    name, or ``"free"`` (MODEL §3.1)."""
    if not isinstance(table, dict):
        raise InputError("expected a table [prior] of KEY = WIDTH (mm, deg) or \"free\"", source=source,
                         where="[prior]")
    try:
        prior = Prior.parse(table)
    except ValueError as exc:
        raise InputError(str(exc), source=source, where="[prior]") from None
    names = [n for joint in joint_parameter_names(convention, geom) for n in joint]
    if convention == "dh":  # β is offered on parallel axes (Hayati's): a prior may state its width
        names += [f"beta{i + 1}" for i in range(len(geom))]
    unknown = unknown_names(prior, names, len(geom))
    if unknown:
        raise InputError(f"names parameter {unknown[0]!r}, which this {convention} robot of {len(geom)} joints has "
                         f"not (its geometry: {', '.join(names[:6])}, …)", source=source, where="[prior]")
    return prior


def _check_covariance_names(robot: Robot, covariance: ParameterCovariance, source: str) -> None:
    """Every parameter the covariance names must be one of the model's: a name it lacks would
    be dropped, and the model would predict an uncertainty of zero from it."""
    from ..model.parameters import ParameterSpace
    from ..model.terms import TermSpec

    space = ParameterSpace.of(robot, None, robot.terms.spec() if robot.terms is not None else TermSpec())
    unknown = [n for n in covariance.names if n not in set(space.names)]
    if unknown:
        listed = ", ".join(unknown[:5]) + (" …" if len(unknown) > 5 else "")
        raise InputError(f"names {len(unknown)} parameter(s) the model has not: {listed} (its parameters are its "
                         f"joints' {', '.join(space.names[:5])}, …, the frames' base_x…tool_rz and its terms')",
                         source=source, where="[uncertainty] parameters")


def _known_keys(table: dict, allowed: set[str], source: str, where: str) -> None:
    """A table's keys must be among ``allowed``: a misspelt one would be ignored."""
    unknown = set(table) - allowed
    if unknown:
        raise InputError(f"unknown key {sorted(unknown)[0]!r} (allowed: {', '.join(sorted(allowed))})", source=source,
                         where=where)


def _followers(joints: list[dict], slide: np.ndarray, source: str) -> tuple[CoupledJoint, ...]:
    """Coupled joints: ``follows = [{joint = 2, factor = -1}, …]`` (1-based) and ``follows_offset`` (deg, mm
    where it slides): the joint's value is the offset plus each factor times that joint's."""
    out = []
    for i, j in enumerate(joints):
        if "follows" not in j:
            if "follows_offset" in j:
                raise InputError("follows_offset without follows", source=source, where=f"joint {i + 1}")
            continue
        where = f"joint {i + 1}, key 'follows'"
        items = j["follows"]
        if not isinstance(items, list) or not items or not all(isinstance(c, dict) and set(c) == {"joint", "factor"}
                                                                for c in items):
            raise InputError("expected a list of tables {joint = K, factor = F}", source=source, where=where)
        sources = [c["joint"] for c in items]
        if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= len(joints) and v != i + 1
                   for v in sources):
            raise InputError(f"each joint followed is another joint 1…{len(joints)}, got {sources}", source=source,
                             where=where)
        offset = _number(j.get("follows_offset", 0.0), source, f"joint {i + 1}, key 'follows_offset'")
        out.append(CoupledJoint(i, tuple(v - 1 for v in sources),
                                tuple(_number(c["factor"], source, where) for c in items),
                                offset if slide[i] else math.radians(offset)))
    try:
        check(out, len(joints))
    except ValueError as exc:
        raise InputError(str(exc), source=source, where="key 'follows'") from None
    return tuple(out)


def _follows_lines(robot: Robot, i: int) -> list[str]:
    c = next((c for c in robot.coupled if c.joint == i), None)
    if c is None:
        return []
    pairs = ", ".join(f"{{joint = {s + 1}, factor = {_num(f)}}}" for s, f in zip(c.sources, c.factors))
    offset = _num(c.offset) if robot.prismatic[i] else _deg(c.offset)
    return [f"follows = [{pairs}]  # its value: the offset plus each factor times that joint's"] + \
        ([f"follows_offset = {offset}"] if c.offset else [])


def _coupling(table, n: int, source: str) -> tuple[tuple[int, int, float], ...]:
    """``[controller] coupling = [{joint = 3, plus = 2, factor = 1.0}, …]`` (1-based joints)."""
    if not isinstance(table, dict):
        raise InputError("expected a table", source=source, where="key 'controller'")
    _known_keys(table, CONTROLLER_KEYS, source, "table [controller]")
    items = table.get("coupling", [])
    if not isinstance(items, list) or not all(isinstance(c, dict) for c in items):
        raise InputError("expected a list of tables {joint = J, plus = K, factor = F}", source=source,
                         where="key 'controller.coupling'")
    out = []
    for k, c in enumerate(items):
        where = f"controller.coupling[{k + 1}]"
        if set(c) != COUPLING_KEYS:
            raise InputError(f"expected the keys joint, plus and factor, got {', '.join(sorted(c))}", source=source,
                             where=where)
        j, p = (c[key] for key in ("joint", "plus"))
        if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= n for v in (j, p)) or j == p:
            raise InputError(f"joint and plus must be two different joints 1…{n}, got {j!r} and {p!r}",
                             source=source, where=where)
        out.append((j - 1, p - 1, _number(c["factor"], source, where)))
    if {j for j, _, _ in out} & {p for _, p, _ in out}:
        raise InputError("a joint added to another is itself coupled: give the coupling of each joint from the "
                         "controller's values", source=source, where="key 'controller.coupling'")
    return tuple(out)


def _covariance(table, source: str) -> ParameterCovariance:
    """[uncertainty]: the identified parameters' names and their covariance (mm, rad, term units)."""
    where = "[uncertainty]"
    if not isinstance(table, dict) or set(table) != {"parameters", "covariance"}:
        raise InputError("expected an [uncertainty] table with parameters and covariance", source=source, where=where)
    names = table["parameters"]
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
        raise InputError("parameters must be a list of distinct names", source=source, where=f"{where} parameters")
    try:
        C = np.array(table["covariance"], dtype=float)
    except (TypeError, ValueError):
        C = np.zeros(0)
    k = len(names)
    if C.shape != (k, k) or not np.all(np.isfinite(C)):
        raise InputError(f"covariance must be a {k}×{k} matrix of numbers (one row per parameter)", source=source,
                         where=f"{where} covariance")
    scale = np.sqrt(np.abs(np.outer(np.diag(C), np.diag(C))))  # each entry against its variances'
    if np.any(np.diag(C) < 0) or np.any(np.abs(C - C.T) > 1e-6 * scale + 1e-300):
        raise InputError("covariance must be symmetric with variances ≥ 0", source=source, where=f"{where} covariance")
    return ParameterCovariance(tuple(names), C)


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


def _list(values, fmt=_num) -> str:
    return "[" + ", ".join(fmt(v) for v in values) + "]"


def _term_lines(terms: JointTerms | None, i: int) -> list[str]:
    """Joint i's term keys (:data:`robocal.model.terms.TERMS`): a scalar when not zero, a list of
    pairs when any is not zero, the links' rows always."""
    if terms is None:
        return []
    lines = []
    for t in TERMS.values():
        for key in t.file_keys:
            values = terms.get(key.array)
            if values is None:
                continue
            values = np.degrees(values) if key.degrees else values
            comment = key.comment.format(i=i + 1)
            if key.shape == "scalar" and values[i] != 0:
                lines.append(f"{key.key} = {_num(values[i])}  # {comment}")
            elif key.shape == "links":
                lines.append(f"{key.key} = [{', '.join(_list(r) for r in values[i, i:])}]  # {comment}")
            elif key.shape == "pairs" and np.any(values[i]):
                lines.append(f"{key.key} = [{', '.join(_list(r) for r in values[i])}]  # {comment}")
    return lines


def _gravity_lines(terms: JointTerms | None) -> list[str]:
    if terms is None:
        return []
    default = np.allclose(terms.gravity_direction, [0, 0, -1]) and not np.any(terms.payload_com)
    if default and TERMS["compliance"].option_of(terms) is None:
        return []
    return ["[gravity]", f"direction = {_list(terms.gravity_direction)}  # base frame",
            f"payload_com = {_list(terms.payload_com)}  # mm, flange frame", ""]


def _drift_lines(terms: JointTerms | None) -> list[str]:
    if terms is None or terms.clock is None or terms.get("drift") is None:
        return []
    kind = terms.clock[0].split(":", 1)[0]
    said = ("seconds of the data's time column" if kind == "s" else
            "row numbers of the calibration file: other files are predicted at the reference")
    return ["[drift]", f'clock = "{kind}"  # {said}',
            f"reference = {_num(terms.clock[1])}  # the model predicts the robot as it was then (the last "
            "calibration pose)", ""]


def _geometry_lines(robot: Robot, i: int) -> list[str]:
    """A joint's geometry keys: a, alpha, d, theta (beta) for the DH family; xyz, rpy, axis
    (offset) for urdf, with an identified origin rotation folded into rpy."""
    g = robot.geometry[i]
    kind = ['type = "prismatic"'] if robot.prismatic[i] else []
    if robot.convention == "urdf":
        rpy = matrix_to_rpy(urdf.origin_rotation(g[None])[0])
        lines = [f"xyz = {_list(g[urdf.X:urdf.Z + 1])}  # mm", f"rpy = [{', '.join(_deg(v) for v in rpy)}]  # deg",
                 f"axis = {_list(g[urdf.AX:urdf.AZ + 1])}"] + kind
        if g[urdf.OFFSET]:
            lines.append(f"offset = {_num(g[urdf.OFFSET]) if robot.prismatic[i] else _deg(g[urdf.OFFSET])}")
        return lines
    a, al, th, d, be = g[:5]
    lines = [f"a = {_num(a)}", f"alpha = {_deg(al)}", f"d = {_num(d)}", f"theta = {_deg(th)}"]
    if robot.convention == "hayati":
        lines.append(f"beta = {_deg(be)}")
    return lines + kind


def residual_path(path: str | Path) -> Path:
    """Where a robot file's residual model is written: beside it, ``NAME.residual.json``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.residual.json")


def _region_lines(robot: Robot) -> list[str]:
    if robot.region is None:
        return []
    d = robot.region.to_dict()
    pairs = ", ".join(f"[{_num(round(a, 9))}, {_num(round(b, 9))}]" for a, b in d["joints"])
    sigma = [f"sigma_mm = {_num(d['sigma_mm'])}  # the median predicted position uncertainty at those poses"] \
        if "sigma_mm" in d else []
    return ["[region]  # the joint ranges (deg; mm where a joint slides) of the poses it was calibrated on",
            f"joints = [{pairs}]", f"poses = {d['poses']}", *sigma, ""]


def robot_to_toml(robot: Robot, comment: str | None = None, residual_file: str | None = None) -> str:
    """The robot file's text.  residual_file: the name under which the robot's residual model is
    saved beside it (see :func:`save_robot`); without it, it is left out, and the file says so."""
    lines = [f"# {c}" for c in comment.splitlines()] if comment else []
    lines += [f"name = {_quote(robot.name)}", f'convention = "{robot.convention}"']
    if robot.residual is not None:
        lines.append(f"residual = {_quote(residual_file)}  # learned correction of the pose ({robot.residual.kind})"
                     if residual_file else "# this robot's residual model was not saved with it")
    lines.append("")
    for i in range(robot.n_joints):
        lines += ["[[joint]]"] + ([f"name = {_quote(robot.joint_names[i])}"] if robot.joint_names else [])
        if robot.tree is not None:
            lines.append(f"parent = {robot.tree.parents[i] + 1}")
        lines += _geometry_lines(robot, i) + _follows_lines(robot, i)
        lo, hi = robot.limits[i]
        if np.isfinite(lo) and np.isfinite(hi):
            slide = robot.prismatic[i]
            lines.append(f"limits = [{_num(lo) if slide else _deg(lo)}, {_num(hi) if slide else _deg(hi)}]"
                         + ("  # mm" if slide else ""))
        lines += _term_lines(robot.terms, i)
        lines.append("")
    lines += _gravity_lines(robot.terms)
    lines += _drift_lines(robot.terms)
    lines += _frame_text("[base]", robot.base) + [""]
    lines += _frame_text("[tool]", robot.tool) + [""]
    chains = {} if robot.tree is None else robot.tree.chains
    for name, joints in chains.items():  # each chain's tip and its own tool
        lines += [f"[chains.{_quote(name)}]", f"tip = {joints[-1] + 1}", ""]
        lines += _frame_text(f"[chains.{_quote(name)}.tool]", robot.targets.get(name, np.eye(4))) + [""]
    for name, T in robot.targets.items():
        if name in chains:
            continue
        lines += _frame_text(f"[targets.{_quote(name)}]", T) + [""]
    for name, mount in robot.cameras.items():
        where = f"camera {mount.of!r}'s frame" if mount.of else \
            "the measuring frame" if mount.link == 0 else f"link {mount.link}'s frame"
        lines += _frame_text(f"[cameras.{_quote(name)}]  # its frame in {where} (z its optical axis)", mount.pose)
        lines += [f"link = {mount.link}"] + (["known = true"] if mount.known else []) + \
            ([f"of = {_quote(mount.of)}"] if mount.of else []) + [""]
    lines += _region_lines(robot)
    lines += _prior_lines(robot)
    lines += _uncertainty_lines(robot)
    if robot.coupling:
        pairs = ", ".join(f"{{joint = {j + 1}, plus = {p + 1}, factor = {_num(f)}}}" for j, p, f in robot.coupling)
        lines += ["[controller]  # the model's joint = the controller's + factor × the controller's plus joint",
                  f"coupling = [{pairs}]", ""]
    return "\n".join(lines)


def _prior_lines(robot: Robot) -> list[str]:
    if robot.prior is None or not robot.prior.widths:
        return []
    return ["[prior]  # widths of what is known before measuring (mm, deg; MODEL §3.1), over the defaults"] + \
        [f"{k if k.isidentifier() else _quote(k)} = {_quote(v) if isinstance(v, str) else _num(v)}"
         for k, v in robot.prior.to_table().items()] + [""]


def _uncertainty_lines(robot: Robot) -> list[str]:
    u = robot.uncertainty
    if u is None:
        return []
    # the written covariance is symmetric to the last digit: a product of floats (J⁻¹ and its
    # transpose) leaves asymmetries of 1e-16 relative that a reader's check would refuse
    matrix = (u.matrix + u.matrix.T) / 2
    rows = ",\n  ".join(_list(r, lambda v: repr(float(v))) for r in matrix)
    return ["[uncertainty]  # covariance of the identified parameters (mm, rad; joint terms in their own units)",
            f"parameters = [{', '.join(_quote(n) for n in u.names)}]", f"covariance = [\n  {rows},\n]", ""]


def save_robot(robot: Robot, path: str | Path, comment: str | None = None) -> list[Path]:
    """Write the robot file, and its residual model beside it when it has one; the paths written."""
    import json

    path = Path(path)
    written = []
    name = None
    if robot.residual is not None:
        side = residual_path(path)
        atomic_write(side, json.dumps(robot.residual.to_dict()) + "\n")
        written.append(side)
        name = side.name
    atomic_write(path, robot_to_toml(robot, comment, name))
    return [path, *written]
