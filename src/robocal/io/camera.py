"""Camera files as users have them: an OpenCV FileStorage file (YAML or JSON, as ``cv::FileStorage``
and ``cv2.FileStorage`` write a camera calibration) or a ROS ``camera_info`` YAML (as
``camera_calibration`` writes it, ROS 1 and 2).

Read: the camera matrix (``camera_matrix``, ``cameraMatrix``, ``K`` or ``k``: fx, fy, cx, cy),
OpenCV's distortion (``distortion_coefficients``, ``dist_coeffs``, ``distCoeffs``, ``D`` or ``d``:
k1 k2 p1 p2 [k3]; the plumb-bob model, others refused), and the image size (``image_width``,
``image_height``, or ``width``, ``height``).  A matrix is a mapping with ``rows``, ``cols`` and
``data`` (OpenCV's ``!!opencv-matrix``, ROS's layout) or a flat list.  Enough YAML for these files:
mappings by indentation, flow lists and flow mappings (over several lines), quoted scalars (a ``#``
in quotes is no comment), tags and the ``%YAML`` directive.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..model.camera import DISTORTION, Camera
from .atomic import read_text
from .table import split_top

MATRIX_KEYS = ("camera_matrix", "cameraMatrix", "K", "k", "intrinsic_matrix")
DISTORTION_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "distortion", "D", "d")
WIDTH_KEYS, HEIGHT_KEYS = ("image_width", "width"), ("image_height", "height")
#: the distortion models robocal's lens model is (ROS names)
PLUMB_BOB = ("plumb_bob", "radtan", "")


def _scalar(text: str):
    text = text.strip().strip("'\"")
    try:
        return float(text)
    except ValueError:
        return text


def _uncommented(raw: str) -> str:
    """A line without its comment: ``#`` at its start or after a space, outside quotes (``"cam#2"`` is a name)."""
    quote = None
    for i, c in enumerate(raw):
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or raw[i - 1] in " \t"):
            return raw[:i].rstrip()
    return raw.rstrip()


def _open(text: str) -> int:
    """How many flow collections (``[``, ``{``) ``text`` leaves open, outside quotes."""
    depth, quote = 0, None
    for c in text:
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        else:
            depth += {"[": 1, "{": 1, "]": -1, "}": -1}.get(c, 0)
    return depth


def _flow(value: str, source: str, number: int):
    """A flow list ``[a, b]`` or a flow mapping ``{rows: 3, data: [ … ]}`` (as cv2.FileStorage writes one,
    ``rows:3`` without a space), or a scalar."""
    value = re.sub(r"^!!?[\w:.-]+\s*", "", value.strip())
    if value.startswith("["):
        return [_flow(v, source, number) for v in split_top(value.strip()[1:-1], quotes=True) if v.strip()]
    if value.startswith("{"):
        out = {}
        for item in filter(str.strip, split_top(value.strip()[1:-1], quotes=True)):
            key, colon, rest = item.partition(":")
            if not colon or not re.fullmatch(r"[A-Za-z_][\w-]*", key.strip()):
                raise InputError(f"cannot read {item.strip()!r} in a mapping (expected key: value)", source=source,
                                 where=f"line {number}")
            out[key.strip()] = _flow(rest, source, number)
        return out
    return _scalar(value)


def _yaml(text: str, source: str) -> dict:
    """The nested mappings, flow lists and mappings and scalars of a camera YAML (see the module docstring)."""
    lines, pending = [], ""
    for number, raw in enumerate(text.splitlines(), 1):
        line = _uncommented(raw) if not raw.lstrip().startswith("%") else ""
        if pending:  # a flow list or mapping over several lines
            pending += " " + line.strip()
            if _open(pending) <= 0:
                lines.append((number, pending))
                pending = ""
            continue
        if not line.strip() or line.strip() in ("---", "..."):
            continue
        if _open(line) > 0:
            pending = line
            continue
        lines.append((number, line))
    if pending:
        raise InputError("a list or mapping is not closed (expected ']' or '}')", source=source)
    root: dict = {}
    stack: list[tuple[int, dict]] = [(-1, root)]
    for number, line in lines:
        m = re.fullmatch(r"(\s*)([A-Za-z_][\w-]*)\s*:\s*(.*)", line)
        if not m:
            raise InputError(f"cannot read {line.strip()!r} (expected key: value)", source=source,
                             where=f"line {number}")
        indent, key, value = len(m.group(1)), m.group(2), re.sub(r"^!!?[\w:.-]+\s*", "", m.group(3).strip())
        while indent <= stack[-1][0]:
            stack.pop()
        parent = stack[-1][1]
        if value == "":
            parent[key] = {}
            stack.append((indent, parent[key]))
        elif value.startswith(("[", "{")):
            parent[key] = _flow(value, source, number)
        else:
            parent[key] = _scalar(value)
    return root


def _find(data: dict, keys: tuple[str, ...]):
    for key in keys:
        if key in data:
            return key, data[key]
    return None, None


def _numbers(value, source: str, key: str) -> np.ndarray:
    """A matrix's numbers: a mapping with ``data`` (and ``rows``/``cols``), or a flat list."""
    data = value.get("data") if isinstance(value, dict) else value
    if not isinstance(data, list) or not data:
        raise InputError(f"'{key}' holds no list of numbers (expected data: [...])", source=source, where=key)
    bad = next((v for v in data if not isinstance(v, float | int) or not math.isfinite(v)), None)
    if bad is not None:
        raise InputError(f"'{key}' holds {bad!r}, not a finite number", source=source, where=key)
    out = np.array(data, float)
    if isinstance(value, dict) and "rows" in value and "cols" in value and \
            int(value["rows"]) * int(value["cols"]) != out.size:
        raise InputError(f"'{key}' says {int(value['rows'])} × {int(value['cols'])} but holds {out.size} numbers",
                         source=source, where=key)
    return out


def parse_camera(text: str, *, source: str = "<camera>", name: str | None = None, json_text: bool = False) -> Camera:
    """A :class:`~robocal.model.camera.Camera` from the text of a camera file."""
    if json_text:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"not JSON: {exc.msg}", source=source, where=f"line {exc.lineno}") from None
    else:
        data = _yaml(text, source)
    if not isinstance(data, dict):
        raise InputError("expected a mapping of the camera's keys", source=source)
    key, matrix = _find(data, MATRIX_KEYS)
    if key is None:
        raise InputError(f"missing the intrinsics: no camera matrix ({' or '.join(MATRIX_KEYS[:3])}: fx, fy, cx, cy)",
                         source=source)
    K = _numbers(matrix, source, key)
    if K.size != 9:
        raise InputError(f"'{key}' holds {K.size} numbers, not the 9 of a 3 × 3 camera matrix", source=source,
                         where=key)
    K = K.reshape(3, 3)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (fx > 0 and fy > 0) or abs(K[1, 0]) + abs(K[2, 0]) + abs(K[2, 1]) > 0 or K[2, 2] != 1:
        raise InputError(f"'{key}' is not a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
                         source=source, where=key)
    if abs(K[0, 1]) > 1e-9 * fx:
        raise InputError(f"'{key}' has a skew of {K[0, 1]:g}: robocal's lens model has none", source=source,
                         where=key)
    model = str(data.get("distortion_model", "")).strip()
    if model not in PLUMB_BOB:
        raise InputError(f"distortion model '{model}': robocal reads OpenCV's plumb-bob model (k1 k2 p1 p2 k3)",
                         source=source, where="distortion_model")
    dkey, dist = _find(data, DISTORTION_KEYS)
    distortion = np.zeros(len(DISTORTION))
    if dkey is not None:
        d = _numbers(dist, source, dkey)
        if d.size not in (4, 5) and not (d.size > 5 and np.all(d[5:] == 0)):
            raise InputError(f"'{dkey}' holds {d.size} coefficients: robocal's lens model takes k1 k2 p1 p2 [k3]",
                             source=source, where=dkey)
        distortion[:min(d.size, 5)] = d[:5]
    size = []
    for keys in (WIDTH_KEYS, HEIGHT_KEYS):
        k, v = _find(data, keys)
        if v is not None and (not isinstance(v, float | int) or not v > 0 or v != int(v)):
            raise InputError(f"'{k}' is {v!r}, not a whole number of pixels", source=source, where=k)
        size.append(None if v is None else int(v))
    label = name or str(data.get("camera_name") or Path(source).stem)
    return Camera(label, float(fx), float(fy), float(cx), float(cy), distortion, size[0], size[1], source)


def load_camera(path: str | Path, name: str | None = None) -> Camera:
    """A camera file (OpenCV FileStorage YAML or JSON, ROS camera_info YAML)."""
    path = Path(path)
    text = read_text(path, "camera file")
    return parse_camera(text, source=str(path), name=name, json_text=path.suffix.lower() == ".json")
