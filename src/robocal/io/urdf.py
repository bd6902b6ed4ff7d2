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

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..exceptions import InputError, RobocalWarning
from ..math.se3 import invert
from ..math.so3 import matrix_to_rpy
from ..model.robot import Robot
from .urdf_xml import (
    JOINT_TYPES,
    MEASURING_FRAME,
    MOVABLE,
    TARGET,
    WHOLE_MODEL,
    UrdfChain,
    _append,
    _check_size,
    _choose_link,
    _default_tip,
    _dh_split,
    _fixed_joint,
    _indent,
    _num,
    _parse_xml,
    _path,
    _set_origin,
    _tree,
    fixed_between,
    geometry_row,
    mimics,
    rewritten,
)


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
        rows.append(geometry_row(path[k], fixed))
        limits.append(path[k].limits)
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
    coupled = mimics([path[k] for k in movable], source)
    try:
        return Robot("urdf", np.array(rows), np.array(limits), base=lead, tool=tail, targets=targets,
                     name=root.get("name") or Path(source).stem, source=source,
                     joint_names=tuple(path[k].name for k in movable), urdf=chain, coupled=coupled)
    except ValueError as exc:  # a mimic of a mimic
        raise InputError(str(exc), source=source) from None


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

def _from_file(robot: Robot, tool_at_tip: bool = False) -> ET.Element:
    chain: UrdfChain = robot.urdf
    root, joints = rewritten(robot)
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
    return fixed_between({j.find("child").get("link"): j for j in root.findall("joint")}, flange, link, source)


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


def urdf_text(robot: Robot, comment: str | None = None, whole_model: str | None = None,
              tool_at_tip: bool = False) -> str:
    """The URDF of a robot (see the module docstring); joint terms and residual corrections
    cannot live in a URDF and are left out (:func:`robocal.io.robotfile.save_robot` writes them):
    ``whole_model`` names the robot file beside it that holds them, so that the URDF alone is
    never taken for the whole model.  ``tool_at_tip``: the identified tool is the tip link itself
    (a probe's ball that touched points or planes), corrected on the fixed joint that leads to
    it; otherwise (a tracker's reflector) it hangs from the tip on robocal's ``target`` link."""
    if robot.tree is not None:
        from .urdf_tree import tree_urdf

        root = tree_urdf(robot)
    elif robot.urdf is not None and robot.convention == "urdf":
        root = _from_file(robot, tool_at_tip)
    else:
        root = _from_dh(robot)
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
    """Where a link of a URDF robot rides: (k, T), k the movable joint it hangs from by fixed joints
    (1-based in the robot's joints; 0: fixed in the cell) and T (4 × 4, mm) the link's frame in the
    frame robocal reaches after joint k (the fixed joints between them; for k = 0, in the base
    link's frame).  A link below a joint the robot does not hold (one off its chain or its tree's
    chains) moves by it: refused."""
    chain = robot.urdf
    source = robot.source or "<urdf>"
    if not isinstance(chain, UrdfChain):
        raise InputError(f"names link {name!r}, but {source} is no URDF: give the link's number", option="camera")
    root = _parse_xml(chain.text, source)
    links, by_child, _, _ = _tree(root, source)
    if name not in links:
        raise InputError(f"names link {name!r}, which {source} has not", option="camera")
    names = tuple(robot.joint_names or ())
    below, link = np.eye(4), name
    while link != chain.base_link:
        joint = by_child.get(link)
        if joint is None:
            raise InputError(f"link {name!r} is not below {chain.base_link}, where the robot starts", option="camera")
        if joint.kind in MOVABLE:
            if joint.name not in names:
                raise InputError(f"link {name!r} moves by joint {joint.name!r}, which the calibrated robot does not "
                                 "hold (name that link's chain's tip among the tips)", option="camera")
            return names.index(joint.name) + 1, below
        below = joint.origin @ below
        link = joint.parent
    return 0, below
