"""URDF robots: a serial chain read from a URDF file, and calibrated robots written as URDF.

Reading (:func:`parse_urdf`): the chain runs from a base link (default: the root) to a tip
link (default: the leaf with the most movable joints on its path; robocal's own ``target``
link when there is one).  Revolute, continuous and prismatic joints become joints of the
``urdf`` convention (:mod:`robocal.model.urdf`); fixed joints fold into their neighbours:
those before the first movable joint into the base frame, those between two movable joints
into the next one's origin, those after the last into the tool.  URDF is SI: lengths become
mm (a prismatic joint's values and limits too), angles stay rad.  Comments, meshes,
inertials, collisions and other elements are kept for the export and otherwise ignored.

Writing (:func:`urdf_text`): a robot read from a URDF is written back as that file with its
chain's joint origins corrected (an identified joint zero folds into its origin), a root link
``measuring_frame`` carrying the identified base, and the identified tool: a tracker's reflector
on a link ``target`` (``target_NAME`` for named reflectors) on a fixed joint from the tip link;
the probe of data that touched points or planes on the chain's own tip link, when fixed joints
lead to it from the flange (the last of them is corrected: the tip link is the tool point).  Links, visuals, inertials,
joint names and limits stay as they were.  A DH, Hayati or Craig robot is written as a new
URDF of the same kinematics.  The standard library's XML keeps the file faithful, comments
included, where a URDF object model would re-serialise it.
"""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError, RobocalWarning
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


def parse_urdf(text: str, *, source: str = "<urdf>", base_link: str | None = None,
               tip_link: str | None = None) -> Robot:
    """The serial chain of a URDF from ``base_link`` to ``tip_link`` as a urdf-convention robot
    (mm, rad); see the module docstring.  The choice of a default tip is said as a
    :class:`~robocal.exceptions.RobocalWarning`."""
    root = _parse_xml(text, source)
    links, by_child, children, top = _tree(root, source)
    base = _choose_link(base_link, links, "base_link", source) or top
    tip = _choose_link(tip_link, links, "tip_link", source)
    note = None
    if tip is None:
        try:
            tip, note = _default_tip(links, by_child, children, base)
        except InputError as exc:
            raise InputError(exc.what, source=source, option="tip_link") from None
    path = _path(by_child, base, tip)
    if path is None:
        raise InputError(f"link '{tip}' is not below link '{base}'", source=source, option="tip_link")
    bad = [j for j in path if j.kind not in JOINT_TYPES]
    if bad:
        raise InputError(f"{bad[0].kind} joints are not supported in a serial chain", source=source,
                         where=f"joint '{bad[0].name}'")
    movable = [k for k, j in enumerate(path) if j.kind in MOVABLE]
    for k in movable:
        mimic = path[k].element.find("mimic")
        if mimic is not None:
            raise InputError(f"mimics joint '{mimic.get('joint')}' (<mimic>): robocal does "
                             "not calibrate coupled joints; end the chain before it (--tip-link) or drop the "
                             "coupling", source=source, where=f"joint '{path[k].name}'")
    if not movable:
        raise InputError(f"no movable joint between '{base}' and '{tip}'", source=source)
    lead = np.eye(4)
    for j in path[:movable[0]]:
        lead = lead @ j.origin
    rows, limits, folded = [], [], []
    for n, k in enumerate(movable):
        fixed = np.eye(4)
        for j in path[(movable[n - 1] + 1 if n else k):k]:
            fixed = fixed @ j.origin
        joint = path[k]
        T = fixed @ joint.origin
        row = np.zeros(urdf.WIDTH)
        row[urdf.X:urdf.Z + 1] = T[:3, 3]
        row[urdf.ROLL:urdf.YAW + 1] = matrix_to_rpy(T[:3, :3])
        row[urdf.AX:urdf.AZ + 1] = joint.axis
        row[urdf.PRISMATIC] = joint.kind == "prismatic"
        rows.append(row)
        limits.append(joint.limits)
        folded.append(fixed)
    tail = np.eye(4)
    for j in path[movable[-1] + 1:]:
        tail = tail @ j.origin
    _check_size(path, source)
    if note:  # only once the chain is known to be sound: an error is the one line said
        warnings.warn(note, RobocalWarning, stacklevel=2)
    flange = path[movable[-1]].child
    targets, target_joints = _targets(by_child, children, flange, tip)
    chain = UrdfChain(text, base, tip, tuple(path[k].name for k in movable), tuple(folded), lead,
                      tuple(j.name for j in path[:movable[0]]), tail, flange, target_joints)
    return Robot("urdf", np.array(rows), np.array(limits), base=lead, tool=tail, targets=targets,
                 name=root.get("name") or Path(source).stem, source=source,
                 joint_names=tuple(path[k].name for k in movable), urdf=chain)


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


def _targets(by_child, children, flange: str, tip: str) -> tuple[dict, dict]:
    """robocal's reflector links ``target_NAME`` below the flange (fixed joints only), as named
    tool frames; and the joints that carry ``target`` links, for the export to update."""
    targets, joints = {}, {}
    stack = [(flange, np.eye(4))]
    while stack:
        link, T = stack.pop()
        for j in children[link]:
            if j.kind != "fixed":
                continue
            Tj = T @ j.origin
            if j.child == TARGET or j.child.startswith(TARGET + "_"):
                joints[j.child] = j.name
                if j.child.startswith(TARGET + "_") and j.child != tip:
                    targets[j.child[len(TARGET) + 1:]] = Tj
            stack.append((j.child, Tj))
    return targets, joints


def whole_model_file(text: str, path: str | Path) -> Path | None:
    """For a URDF that robocal exported as the geometry of a richer model (``<robocal
    whole_model="…"/>``), the robot file beside it that holds the whole model; else None.  A
    missing one is an input error: the URDF alone would be a silently partial model."""
    marker = _parse_xml(text, str(path)).find(WHOLE_MODEL)
    whole = None if marker is None else marker.get("whole_model")
    if not whole:
        return None
    side = Path(path).with_name(Path(whole).name)
    if not side.is_file():
        raise InputError(f"this URDF holds only the geometry of a calibrated model whose joint terms and residual "
                         f"correction are in {side.name!r}, which is missing: put it beside the URDF (or delete the "
                         f"<{WHOLE_MODEL}> element to use the geometry alone)", source=path)
    return side


# --- writing ------------------------------------------------------------------------------

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


def _from_file(robot: Robot, tool_at_tip: bool = False) -> ET.Element:
    chain: UrdfChain = robot.urdf
    root = _parse_xml(chain.text, robot.source)
    joints = {j.get("name"): j for j in root.findall("joint")}
    links = {link.get("name") for link in root.findall("link")}
    for name, fixed, g in zip(chain.joints, chain.folded, robot.geometry):
        _set_origin(joints[name], invert(fixed) @ _folded_origin(g), "\n    ")
    # the measuring frame: robocal's own from an earlier export is updated, else added at the root
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
    _write_targets(robot, root, joints, chain, tool_at_tip)
    return root


def _write_targets(robot: Robot, root: ET.Element, joints: dict, chain: UrdfChain, tool_at_tip: bool = False) -> None:
    tools = {"": robot.tool, **robot.targets}
    for name, T in tools.items():
        link = TARGET if name == "" else f"{TARGET}_{name}"
        if name == "" and chain.tip_link == TARGET:
            continue  # the tip is robocal's target: the tool is its chain, updated below
        if name == "" and tool_at_tip and chain.tip_link != chain.flange_link and link not in chain.target_joints:
            # the user's own tip (a probe's ball, a TCP link) sits on fixed joints after the flange:
            # its last one carries the identified tool, so the tip link is the calibrated tool point
            by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
            joint = by_child[chain.tip_link]
            before = _fixed_before(root, chain.flange_link, joint.find("parent").get("link"), robot.source)
            _set_origin(joint, invert(before) @ T, "\n    ")
            continue
        if link in chain.target_joints:
            joint = joints[chain.target_joints[link]]
            before = _fixed_before(root, chain.flange_link, joint.find("parent").get("link"), robot.source)
            _set_origin(joint, invert(before) @ T, "\n    ")
            continue
        # a fixed joint from the tip link; the tool is relative to the flange (the last moving
        # link), and the tip sits on it by the fixed joints folded into the tail
        _append(root, ET.Element("link", {"name": link}),
                _fixed_joint(f"{link}_joint", chain.tip_link, link, invert(chain.tail) @ T))
    if chain.tip_link == TARGET and TARGET in chain.target_joints:
        # the chain to target ends in its own fixed joint: it alone carries the tool
        path_joint = joints[chain.target_joints[TARGET]]
        parent = path_joint.find("parent").get("link")
        before = _fixed_before(root, chain.flange_link, parent, robot.source)
        _set_origin(path_joint, invert(before) @ robot.tool, "\n    ")


def _fixed_before(root: ET.Element, flange: str, link: str, source: str) -> np.ndarray:
    """The fixed transform from the flange link down to ``link`` (mm)."""
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    T = np.eye(4)
    while link != flange:
        j = by_child[link]
        T = _origin(j.find("origin"), source, j.get("name")) @ T
        link = j.find("parent").get("link")
    return T


def _from_dh(robot: Robot) -> ET.Element:
    """A DH-family robot as a URDF of the same kinematics: joint i turns (slides) along z of the
    frame after the fixed part of the joint before it."""
    root = ET.Element("robot", {"name": robot.name or "robot"})
    root.text = "\n  "
    elements = [ET.Element("link", {"name": MEASURING_FRAME}), ET.Element("link", {"name": "base_link"})]
    elements.append(_fixed_joint(f"{MEASURING_FRAME}_joint", MEASURING_FRAME, "base_link", robot.base))
    names = robot.joint_names or tuple(f"joint_{i + 1}" for i in range(robot.n_joints))
    previous, parent = np.eye(4), "base_link"
    for i, g in enumerate(robot.geometry):
        child = f"link_{i + 1}"
        elements.append(ET.Element("link", {"name": child}))
        kind = "prismatic" if robot.prismatic[i] else "revolute"
        before, after = _dh_split(robot.convention, g)
        j = ET.Element("joint", {"name": names[i], "type": kind})
        ET.SubElement(j, "parent", {"link": parent})
        ET.SubElement(j, "child", {"link": child})
        T = previous @ before
        origin = ET.SubElement(j, "origin")
        origin.set("xyz", " ".join(_num(v / 1000.0) for v in T[:3, 3]))
        origin.set("rpy", " ".join(_num(v) for v in matrix_to_rpy(T[:3, :3])))
        ET.SubElement(j, "axis", {"xyz": "0 0 1"})
        lo, hi = robot.limits[i]
        if np.isfinite(lo) and np.isfinite(hi):
            scale = 1000.0 if robot.prismatic[i] else 1.0
            ET.SubElement(j, "limit", {"lower": _num(lo / scale), "upper": _num(hi / scale), "effort": "0",
                                       "velocity": "0"})
        elif kind == "revolute":
            j.set("type", "continuous")
        _indent(j)
        elements.append(j)
        previous, parent = after, child
    elements += [ET.Element("link", {"name": "flange"}),
                 _fixed_joint("flange_joint", parent, "flange", previous)]
    elements += [ET.Element("link", {"name": TARGET}), _fixed_joint(f"{TARGET}_joint", "flange", TARGET, robot.tool)]
    for name, T in robot.targets.items():
        link = f"{TARGET}_{name}"
        elements += [ET.Element("link", {"name": link}), _fixed_joint(f"{link}_joint", "flange", link, T)]
    for e in elements:
        e.tail = "\n  "
    _append(root, *elements)
    return root


def _dh_split(convention: str, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A DH-family joint transform A(q) = B · M(q) · C: the fixed part before its motion and after.
    The motion (Rz(q), or Tz(q) when it slides) commutes with what the convention puts around it,
    so A(0) is all of it: before the motion for craig (Rx(α) Tx(a) Rz(θ) Tz(d)), after it for dh
    and hayati (Rz(θ) Tz(d) Tx(a) Rx(α) Ry(β))."""
    R, p = chain_pose(convention, g[None], np.zeros((1, 1)))
    fixed = homogeneous(R[0], p[0])
    return (fixed, np.eye(4)) if convention == "craig" else (np.eye(4), fixed)


def urdf_text(robot: Robot, comment: str | None = None, whole_model: str | None = None,
              tool_at_tip: bool = False) -> str:
    """The URDF of a robot (see the module docstring); joint terms and residual corrections
    cannot live in a URDF and are left out (:func:`robocal.io.robotfile.save_robot` writes them):
    ``whole_model`` names the robot file beside it that holds them, so that the URDF alone is
    never taken for the whole model.  ``tool_at_tip``: the identified tool is the tip link itself
    (a probe's ball that touched points or planes), corrected on the fixed joint that leads to
    it; otherwise (a tracker's reflector) it hangs from the tip on robocal's ``target`` link."""
    root = _from_file(robot, tool_at_tip) if robot.urdf is not None and robot.convention == "urdf" \
        else _from_dh(robot)
    for old in root.findall(WHOLE_MODEL):  # an earlier export's: this one says its own
        root.remove(old)
    if whole_model:
        _append(root, ET.Element(WHOLE_MODEL, {"whole_model": whole_model}))
    head = '<?xml version="1.0"?>\n'
    if comment:
        head += "".join(f"<!-- {line.replace('--', '—')} -->\n" for line in comment.splitlines())
    return head + ET.tostring(root, encoding="unicode") + "\n"


def dh_urdf_equivalent(robot: Robot) -> Robot:
    """The urdf-convention robot of a DH-family robot (for checks): parse of its own export."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return parse_urdf(urdf_text(robot), source=f"{robot.name} (urdf)")



def link_frame(robot: Robot, name: str) -> tuple[int, np.ndarray]:
    """Where a link of a URDF robot rides: (k, T), k the movable joints of the chain above it (0:
    fixed in the cell) and T (4 × 4, mm) the link's frame in the frame robocal's chain reaches after
    joint k (the fixed joints between them; for k = 0, in the base link's frame).  The link is on the
    chain, or hangs from it by fixed joints (a camera's link on a torso); by a joint that moves, it is
    not on this chain."""
    chain = robot.urdf
    source = robot.source or "<urdf>"
    if not isinstance(chain, UrdfChain):
        raise InputError(f"names link {name!r}, but {source} is no URDF: give the link's number", option="camera")
    root = _parse_xml(chain.text, source)
    links, by_child, _, _ = _tree(root, source)
    if name not in links:
        raise InputError(f"names link {name!r}, which {source} has not", option="camera")
    path = _path(by_child, chain.base_link, chain.tip_link) or []
    on_chain = [chain.base_link] + [j.child for j in path]
    below = np.eye(4)
    link = name
    while link not in on_chain:
        joint = by_child.get(link)
        if joint is None:
            raise InputError(f"link {name!r} is not on the chain from {chain.base_link} to {chain.tip_link}",
                             option="camera")
        if joint.kind in MOVABLE:
            raise InputError(f"link {name!r} moves by joint {joint.name!r}, which is not in the calibrated chain",
                             option="camera")
        below = joint.origin @ below
        link = joint.parent
    k, T = 0, np.eye(4)
    for joint in path[:on_chain.index(link)]:
        if joint.kind in MOVABLE:
            k, T = k + 1, np.eye(4)
        else:
            T = T @ joint.origin
    return k, T @ below
