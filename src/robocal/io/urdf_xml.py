"""The XML of URDF files, shared by the chain's reader and writer (:mod:`robocal.io.urdf`) and the
tree's (:mod:`robocal.io.urdf_tree`): joints and links with their origins (mm), the paths between
links, and the elements an export writes (origins, fixed joints, the measuring frame).  The
standard library's XML keeps a user's file as written."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError
from ..math.se3 import homogeneous, invert
from ..math.so3 import exp_so3, matrix_to_rpy, rpy_to_matrix
from ..model import urdf
from ..model.kinematics import chain_pose
from ..model.robot import Robot

MOVABLE = ("revolute", "continuous", "prismatic")
JOINT_TYPES = MOVABLE + ("fixed",)
MEASURING_FRAME = "measuring_frame"
TARGET = "target"
#: the element by which a URDF names the robot file holding its whole model (joint terms, a
#: residual correction): URDF readers ignore elements they do not know
WHOLE_MODEL = "robocal"


@dataclass(frozen=True, eq=False)
class UrdfChain:
    """What a robot read from a URDF keeps for a faithful export: the text, the chain's ends,
    its movable joints, the fixed transforms folded into each (mm), and the fixed joints before
    the first movable joint (folded into the base) and after the last (into the tool)."""

    text: str
    base_link: str
    tip_link: str
    joints: tuple[str, ...]
    folded: tuple[np.ndarray, ...]
    lead: np.ndarray
    lead_joints: tuple[str, ...]
    tail: np.ndarray
    flange_link: str
    target_joints: dict


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray  # 4×4, mm
    axis: np.ndarray
    limits: tuple[float, float]
    element: ET.Element


def _floats(text: str | None, count: int, source: str, where: str, default: list[float]) -> list[float]:
    if text is None:
        return list(default)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise InputError(f"expected {count} numbers, got {text!r}", source=source, where=where) from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InputError(f"expected {count} finite numbers, got {text!r}", source=source, where=where)
    return values


def _origin(element: ET.Element | None, source: str, where: str) -> np.ndarray:
    """<origin xyz rpy> → 4×4 with the translation in mm."""
    if element is None:
        return np.eye(4)
    xyz = _floats(element.get("xyz"), 3, source, f"{where}, <origin xyz>", [0.0, 0.0, 0.0])
    rpy = _floats(element.get("rpy"), 3, source, f"{where}, <origin rpy>", [0.0, 0.0, 0.0])
    return homogeneous(rpy_to_matrix(np.array(rpy)), 1000.0 * np.array(xyz))


def _joint(element: ET.Element, source: str) -> _Joint:
    name = element.get("name")
    if not name:
        raise InputError("a <joint> has no name", source=source)
    where = f"joint '{name}'"
    kind = element.get("type")
    if kind not in JOINT_TYPES + ("floating", "planar"):
        raise InputError(f"unknown joint type {kind!r} (expected {' | '.join(JOINT_TYPES)})", source=source,
                         where=where)
    links = {}
    for tag in ("parent", "child"):
        node = element.find(tag)
        if node is None or not node.get("link"):
            raise InputError(f"missing <{tag} link=…>", source=source, where=where)
        links[tag] = node.get("link")
    axis = np.array(_floats(None if element.find("axis") is None else element.find("axis").get("xyz"), 3, source,
                            f"{where}, <axis xyz>", [1.0, 0.0, 0.0]))  # URDF's default axis is x
    if kind in MOVABLE and not np.linalg.norm(axis) > 0:
        raise InputError("the joint axis must not be zero", source=source, where=f"{where}, <axis xyz>")
    limits = (-math.inf, math.inf)
    limit = element.find("limit")
    if kind in ("revolute", "prismatic") and limit is not None:
        lo, hi = (_floats(limit.get(k), 1, source, f"{where}, <limit {k}>", [0.0])[0] for k in ("lower", "upper"))
        if lo > hi:
            raise InputError(f"<limit> lower {lo:g} is above upper {hi:g}", source=source, where=where)
        if hi > lo:  # URDF defaults both to 0: no range stated
            scale = 1000.0 if kind == "prismatic" else 1.0
            limits = (scale * lo, scale * hi)
    return _Joint(name, kind, links["parent"], links["child"], _origin(element.find("origin"), source, where),
                  axis / (np.linalg.norm(axis) or 1.0), limits, element)


def rewritten(robot: Robot) -> tuple[ET.Element, dict]:
    """The URDF a robot was read from, its movable joints' origins set to the robot's geometry (the
    fixed joints before each folded back out) and its base on ``measuring_frame``: (root, joint name →
    element) for the writer to add the rest."""
    record: UrdfChain = robot.urdf
    root = _parse_xml(record.text, robot.source)
    joints = {j.get("name"): j for j in root.findall("joint")}
    for name, fixed, g in zip(record.joints, record.folded, robot.geometry):
        _set_origin(joints[name], invert(fixed) @ _folded_origin(g), "\n    ")
    measuring_frame(root, joints, record, robot)
    return root, joints


def fixed_between(by_child: dict, top: str, link: str, source: str) -> np.ndarray:
    """The fixed joints' transform (mm) from link ``top`` down to ``link`` (``by_child``: each link's
    joint element, by its child link)."""
    T = np.eye(4)
    while link != top:
        j = by_child[link]
        T = _origin(j.find("origin"), source, j.get("name")) @ T
        link = j.find("parent").get("link")
    return T


def geometry_row(joint: _Joint, fixed: np.ndarray) -> np.ndarray:
    """A movable joint's row of the urdf convention: its origin with the fixed joints before it folded in
    (``fixed``, mm), its axis and its kind."""
    T = fixed @ joint.origin
    row = np.zeros(urdf.WIDTH)
    row[urdf.X:urdf.Z + 1] = T[:3, 3]
    row[urdf.ROLL:urdf.YAW + 1] = matrix_to_rpy(T[:3, :3])
    row[urdf.AX:urdf.AZ + 1] = joint.axis
    row[urdf.PRISMATIC] = joint.kind == "prismatic"
    return row


def mimics(joints: list[_Joint], source: str):
    """The coupled joints (:mod:`robocal.model.coupled`) of a robot's movable ``joints`` (in the data's
    order) that ``<mimic joint= multiplier= offset=>`` another of them (offset rad, or m for a slide)."""
    from ..model.coupled import CoupledJoint

    index = {j.name: k for k, j in enumerate(joints)}
    out = []
    for k, j in enumerate(joints):
        mimic = j.element.find("mimic")
        if mimic is None:
            continue
        where = f"joint '{j.name}', <mimic>"
        of = mimic.get("joint")
        if of not in index:
            raise InputError(f"mimics joint '{of}', which is not a movable joint of the chains read: give its chain "
                             "(--tip-link), or state the coupling in a robot file", source=source, where=where)
        factor = _floats(mimic.get("multiplier"), 1, source, where, [1.0])[0]
        offset = _floats(mimic.get("offset"), 1, source, where, [0.0])[0]
        out.append(CoupledJoint(k, (index[of],), (factor,), offset * (1000.0 if j.kind == "prismatic" else 1.0)))
    return tuple(out)


def _parse_xml(text: str, source: str) -> ET.Element:
    # files generated by xacro may start with a blank line before the XML declaration
    body = text.lstrip("\ufeff \t\r\n")
    try:
        root = ET.fromstring(body, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise InputError(f"not valid XML: {exc}", source=source) from None
    if root.tag != "robot":
        raise InputError(f"not a URDF: the root element is <{root.tag}>, not <robot>", source=source)
    return root


def _unique(names: list[str], what: str, source: str) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise InputError(f"two {what}s are named '{name}'; names must be unique", source=source)
        seen.add(name)


def _loop(by_child: dict, start: str) -> list[str] | None:
    """The links of a loop met walking up from ``start`` through the parents, or None."""
    seen: list[str] = []
    link = start
    while link in by_child:
        if link in seen:
            return seen[seen.index(link):]
        seen.append(link)
        link = by_child[link].parent
    return None


def _tree(root: ET.Element, source: str):
    """Links, the joint above each link, the joints below each link, and the root link; a link
    with two parents, a loop of links, repeated names or several roots are input errors."""
    links = [link.get("name") for link in root.findall("link")]
    if any(not name for name in links):
        raise InputError("a <link> has no name", source=source)
    _unique(links, "link", source)
    joints = [_joint(j, source) for j in root.findall("joint")]
    _unique([j.name for j in joints], "joint", source)
    by_child, children = {}, {name: [] for name in links}
    for j in joints:
        for end in (j.parent, j.child):
            if end not in children:
                raise InputError(f"link '{end}' is not defined", source=source, where=f"joint '{j.name}'")
        if j.child in by_child:
            raise InputError(f"link '{j.child}' has two parents ('{by_child[j.child].name}' and '{j.name}')",
                             source=source)
        by_child[j.child] = j
        children[j.parent].append(j)
    for name in links:  # every walk up must end at a root: a loop would never end
        loop = _loop(by_child, name)
        if loop:
            raise InputError(f"the links {' → '.join(loop + loop[:1])} form a loop (joints "
                             f"{', '.join(by_child[link].name for link in loop)}); a URDF is a tree", source=source)
    roots = [name for name in links if name not in by_child]
    if len(roots) != 1:
        raise InputError(f"a URDF has one root link, this one has {len(roots)} ({', '.join(roots) or 'none'})",
                         source=source)
    return links, by_child, children, roots[0]


def _path(by_child: dict, base: str, tip: str) -> list[_Joint] | None:
    out, link = [], tip
    while link != base:
        if link not in by_child:
            return None
        out.append(by_child[link])
        link = by_child[link].parent
    return out[::-1]


def _choose_link(name: str | None, links: list[str], option: str, source: str) -> str | None:
    if name is not None and name not in links:
        raise InputError(f"no link named '{name}' (links: {', '.join(links)})", source=source, option=option)
    return name


def _default_tip(links, by_child, children, base) -> tuple[str, str]:
    leaves = [link for link in links if not children[link] and link != base
              and _path(by_child, base, link) is not None]
    if not leaves:
        raise InputError("the base link has no links below it", option="tip_link")
    count = {leaf: sum(j.kind in MOVABLE for j in _path(by_child, base, leaf)) for leaf in leaves}
    best = max(count.values())
    top = [leaf for leaf in leaves if count[leaf] == best]
    own = [leaf for leaf in top if leaf == TARGET]  # robocal's export: the measured point
    tip = (own or top)[0]
    others = [leaf for leaf in leaves if leaf != tip]
    note = (f"URDF tip link '{tip}' chosen ({best} movable joints from '{base}')"
            + (f"; other leaves: {', '.join(others)} (choose with --tip-link)" if others else ""))
    return tip, note


#: a chain longer than this (mm, sum of its joint origins' offsets) is not a robot in metres
MAX_CHAIN_MM = 50_000.0


def _check_size(path: list[_Joint], source: str) -> None:
    """A URDF written in millimetres reads as a robot hundreds of metres long: say so here, where
    the culprit is, rather than blame the measurements for not matching it."""
    length = sum(float(np.linalg.norm(j.origin[:3, 3])) for j in path)
    if length > MAX_CHAIN_MM:
        longest = max(path, key=lambda j: np.linalg.norm(j.origin[:3, 3]))
        raise InputError(f"the chain is {length / 1000:.4g} m long (joint '{longest.name}' alone "
                         f"{np.linalg.norm(longest.origin[:3, 3]) / 1000:.4g} m): implausible for a robot; URDF "
                         "lengths are metres: was the file written in millimetres?", source=source)


def _num(x: float) -> str:
    x = float(x)
    return repr(x + 0.0 if x == 0 else x)


def _set_origin(element: ET.Element, T: np.ndarray, tail: str) -> None:
    origin = element.find("origin")
    if origin is None:
        origin = ET.SubElement(element, "origin")
        origin.tail = tail
        element.remove(origin)
        element.insert(0, origin)
    origin.set("xyz", " ".join(_num(v / 1000.0) for v in T[:3, 3]))
    origin.set("rpy", " ".join(_num(v) for v in matrix_to_rpy(T[:3, :3])))


def _folded_origin(g: np.ndarray) -> np.ndarray:
    """A urdf joint's origin with its identified rotation and zero offset folded in (mm): the
    motion by the offset commutes with the motion by q about (along) the same axis."""
    R = urdf.origin_rotation(g[None])[0]
    axis = g[urdf.AX:urdf.AZ + 1]
    if g[urdf.PRISMATIC]:
        shift = homogeneous(np.eye(3), axis * g[urdf.OFFSET])
    else:
        shift = homogeneous(exp_so3(axis * g[urdf.OFFSET]), np.zeros(3))
    return homogeneous(R, g[urdf.X:urdf.Z + 1]) @ shift


def _fixed_joint(name: str, parent: str, child: str, T: np.ndarray) -> ET.Element:
    j = ET.Element("joint", {"name": name, "type": "fixed"})
    for tag, link in (("parent", parent), ("child", child)):
        ET.SubElement(j, tag, {"link": link})
    origin = ET.SubElement(j, "origin")
    origin.set("xyz", " ".join(_num(v / 1000.0) for v in T[:3, 3]))
    origin.set("rpy", " ".join(_num(v) for v in matrix_to_rpy(T[:3, :3])))
    _indent(j)
    return j


def _indent(element: ET.Element, level: int = 1) -> None:
    element.text = "\n" + "  " * (level + 1) if len(element) else None
    for k, child in enumerate(element):
        child.tail = "\n" + "  " * (level + (1 if k < len(element) - 1 else 0))
    element.tail = "\n" + "  " * level


def _append(root: ET.Element, *elements: ET.Element) -> None:
    if len(root):
        root[-1].tail = "\n  "
    for e in elements:
        root.append(e)
    root[-1].tail = "\n"


def measuring_frame(root: ET.Element, joints: dict, chain: UrdfChain, robot: Robot) -> None:
    """The identified base on robocal's ``measuring_frame``: an earlier export's is updated, else
    one is added at the root (below the base link where the chain starts inside the tree)."""
    links = {link.get("name") for link in root.findall("link")}
    if chain.lead_joints and chain.base_link == MEASURING_FRAME:
        first = joints[chain.lead_joints[0]]
        rest = np.eye(4)
        for name in chain.lead_joints[1:]:
            rest = rest @ _origin(joints[name].find("origin"), robot.source, name)
        _set_origin(first, robot.base @ invert(rest), "\n    ")
    elif MEASURING_FRAME not in links:
        base_link = ET.Element("link", {"name": MEASURING_FRAME})
        base_link.tail = "\n  "
        is_root = not any(j.find("child").get("link") == chain.base_link for j in joints.values())
        if is_root:
            joint = _fixed_joint(f"{MEASURING_FRAME}_joint", MEASURING_FRAME, chain.base_link,
                                 robot.base @ invert(chain.lead))
        else:  # the chain starts inside the tree: the measuring frame hangs below its base link
            joint = _fixed_joint(f"{MEASURING_FRAME}_joint", chain.base_link, MEASURING_FRAME,
                                 chain.lead @ invert(robot.base))
        _append(root, base_link, joint)


def _dh_split(convention: str, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A DH-family joint transform A(q) = B · M(q) · C: the fixed part before its motion and after.
    The motion (Rz(q), or Tz(q) when it slides) commutes with what the convention puts around it,
    so A(0) is all of it: before the motion for craig (Rx(α) Tx(a) Rz(θ) Tz(d)), after it for dh
    and hayati (Rz(θ) Tz(d) Tx(a) Rx(α) Ry(β))."""
    R, p = chain_pose(convention, g[None], np.zeros((1, 1)))
    fixed = homogeneous(R[0], p[0])
    return (fixed, np.eye(4)) if convention == "craig" else (np.eye(4), fixed)
