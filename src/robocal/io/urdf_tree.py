"""URDF trees: a robot of several chains read from a URDF's tips, and a tree robot written as one URDF.

Reading (:func:`parse_urdf_tree`): every movable joint on the paths from the base link to the tips
once, in the order the paths meet them (the data's q1..qn), each with the fixed joints between it
and the movable joint above it folded into its origin; the fixed joints every path starts with
into the base; each chain (named after its tip link) ends in its own tool, the fixed joints after
its last movable joint, or robocal's ``target_TIP`` link below the tip where an earlier export
wrote the identified one.

Writing (:func:`tree_urdf`): a tree read from a URDF is written back as that file with every
branch's joint origins corrected (an identified zero folded in, as for a chain), the identified
base on ``measuring_frame``, each chain's identified tool on a link ``target_CHAIN`` below its tip
and each camera's optical frame on a link ``camera_NAME_optical`` (z the optical axis, x the
image's right) on the link it rides.  A tree from a robot file is written as a new URDF of the same
kinematics.  A ROS tool reads every branch from the one file.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..math.se3 import invert
from ..math.so3 import matrix_to_rpy
from ..model import urdf
from ..model.kinematic_tree import TreeSpec
from ..model.robot import Robot
from .urdf_xml import (
    JOINT_TYPES,
    MEASURING_FRAME,
    MOVABLE,
    TARGET,
    UrdfChain,
    _append,
    _check_size,
    _choose_link,
    _fixed_joint,
    _folded_origin,
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


def parse_urdf_tree(text: str, *, source: str = "<urdf>", base_link: str | None = None,
                    tips: list[str]) -> Robot:
    """The tree of a URDF from ``base_link`` (default: the root) to each of ``tips`` (see the module
    docstring), a urdf-convention robot (mm, rad) whose chains are named after their tips."""
    root = _parse_xml(text, source)
    links, by_child, children, top = _tree(root, source)
    base = _choose_link(base_link, links, "base_link", source) or top
    paths = {tip: _tree_path(by_child, base, tip, links, source) for tip in tips}
    # the base: the fixed joints every path starts with, down to a movable joint or a fork
    lead, common = np.eye(4), 0
    first = next(iter(paths.values()))
    while all(len(p) > common and p[common] is first[common] for p in paths.values()) and \
            first[common].kind == "fixed":
        lead = lead @ first[common].origin
        common += 1
    order: list[str] = []
    joint_of, parent_of, folded_of = {}, {}, {}
    chains, tools = {}, {}
    for tip, path in paths.items():
        above, fixed, ids = -1, np.eye(4), []
        for j in path[common:]:
            if j.kind == "fixed":
                fixed = fixed @ j.origin
                continue
            if j.name not in joint_of:
                joint_of[j.name] = len(order)
                order.append(j.name)
                parent_of[j.name], folded_of[j.name] = above, fixed
            elif parent_of[j.name] != above or not np.allclose(folded_of[j.name], fixed):
                raise InputError(f"joint '{j.name}' is reached two ways", source=source)
            above, fixed = joint_of[j.name], np.eye(4)
            ids.append(above)
        chains[tip] = tuple(ids)
        # an earlier export's identified tool hangs below the tip on robocal's target link
        written = next((j for j in children[tip] if j.kind == "fixed" and j.child == f"{TARGET}_{tip}"), None)
        tools[tip] = fixed if written is None else fixed @ written.origin
    by_name = {j.name: j for path in paths.values() for j in path}
    rows, limits = [], []
    for name in order:
        rows.append(geometry_row(by_name[name], folded_of[name]))
        limits.append(by_name[name].limits)
    tree = TreeSpec(tuple(parent_of[n] for n in order), chains)
    record = UrdfChain(text, base, ",".join(tips), tuple(order), tuple(folded_of[n] for n in order), lead,
                       tuple(j.name for j in first[:common]), np.eye(4), "", {})
    coupled = mimics([by_name[name] for name in order], source)
    try:
        return Robot("urdf", np.array(rows), np.array(limits), base=lead, targets=tools,
                     name=root.get("name") or Path(source).stem, source=source, joint_names=tuple(order), tree=tree,
                     urdf=record, coupled=coupled)
    except ValueError as exc:  # a mimic of a mimic
        raise InputError(str(exc), source=source) from None


def _tree_path(by_child, base: str, tip: str, links, source: str):
    _choose_link(tip, links, "tip_link", source)
    path = _path(by_child, base, tip)
    if path is None:
        raise InputError(f"link '{tip}' is not below link '{base}'", source=source, option="tip_link")
    bad = next((j for j in path if j.kind not in JOINT_TYPES), None)
    if bad is not None:
        raise InputError(f"{bad.kind} joints are not supported in a tree", source=source, where=f"joint '{bad.name}'")
    if not any(j.kind in MOVABLE for j in path):
        raise InputError(f"no movable joint between '{base}' and '{tip}'", source=source, option="tip_link")
    _check_size(path, source)
    return path


# --- writing ------------------------------------------------------------------------------

def tree_urdf(robot: Robot) -> ET.Element:
    """The URDF element of a tree robot (see the module docstring)."""
    if robot.urdf is not None and robot.convention == "urdf":
        return _from_file(robot)
    return _from_geometry(robot)


def _from_file(robot: Robot) -> ET.Element:
    record: UrdfChain = robot.urdf
    root, joints = rewritten(robot)
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    child_of = {name: joints[name].find("child").get("link") for name in record.joints}
    for chain, path in robot.tree.chains.items():
        tip = chain  # a chain read from a URDF is named after its tip link
        tail = fixed_between(by_child, child_of[record.joints[path[-1]]], tip, robot.source)
        _put(root, by_child, tip, f"{TARGET}_{tip}", invert(tail) @ robot.targets.get(chain, tail))
    for name, mount in robot.cameras.items():
        parent = _camera_parent(robot, mount, lambda k: child_of[record.joints[k - 1]])
        _put(root, by_child, parent, f"camera_{name}_optical", mount.pose)
    return root


def _camera_parent(robot: Robot, mount, link_after) -> str:
    """The link a camera's optical frame hangs from: the link after its joint, the measuring frame
    for a fixed camera, or the camera it is fixed to."""
    if mount.of:
        return f"camera_{mount.of}_optical"
    return MEASURING_FRAME if mount.link == 0 else link_after(mount.link)


def _put(root: ET.Element, by_child: dict, parent: str, link: str, T: np.ndarray) -> None:
    """A fixed link ``link`` at T (mm) in ``parent``: an earlier export's is updated, else added."""
    if link in by_child:
        _set_origin(by_child[link], T, "\n    ")
        return
    joint = _fixed_joint(f"{link}_joint", parent, link, T)
    element = ET.Element("link", {"name": link})
    element.tail = "\n  "
    _append(root, element, joint)
    by_child[link] = joint


def _from_geometry(robot: Robot) -> ET.Element:
    """A tree from a robot file as a new URDF: joint i's origin (its identified turn and zero folded
    in) in its parent joint's link, its axis as it is."""
    root = ET.Element("robot", {"name": robot.name or "robot"})
    root.text = "\n  "
    elements = [ET.Element("link", {"name": MEASURING_FRAME}), ET.Element("link", {"name": "base_link"}),
                _fixed_joint(f"{MEASURING_FRAME}_joint", MEASURING_FRAME, "base_link", robot.base)]
    names = robot.joint_names or tuple(f"joint_{i + 1}" for i in range(robot.n_joints))
    for i, g in enumerate(robot.geometry):  # a tree's joints are urdf origins (robocal.model.robot)
        T, axis, p = _folded_origin(g), g[urdf.AX:urdf.AZ + 1], robot.tree.parents[i]
        j = ET.Element("joint", {"name": names[i], "type": "prismatic" if robot.prismatic[i] else "revolute"})
        ET.SubElement(j, "parent", {"link": "base_link" if p < 0 else f"link_{p + 1}"})
        ET.SubElement(j, "child", {"link": f"link_{i + 1}"})
        ET.SubElement(j, "origin", {"xyz": " ".join(_num(v / 1000.0) for v in T[:3, 3]),
                                    "rpy": " ".join(_num(v) for v in matrix_to_rpy(T[:3, :3]))})
        ET.SubElement(j, "axis", {"xyz": " ".join(_num(v) for v in axis)})
        lo, hi = robot.limits[i]
        if np.isfinite(lo) and np.isfinite(hi):
            scale = 1000.0 if robot.prismatic[i] else 1.0
            ET.SubElement(j, "limit", {"lower": _num(lo / scale), "upper": _num(hi / scale), "effort": "0",
                                       "velocity": "0"})
        else:
            j.set("type", "continuous" if not robot.prismatic[i] else "prismatic")
        c = next((c for c in robot.coupled if c.joint == i), None)
        if c is not None and len(c.sources) == 1:
            ET.SubElement(j, "mimic", {"joint": names[c.sources[0]], "multiplier": _num(c.factors[0]),
                                       "offset": _num(c.offset / (1000.0 if robot.prismatic[i] else 1.0))})
        elif c is not None:  # a URDF's mimic follows one joint
            j.insert(0, ET.Comment(f" {c.describe(names)}: a URDF mimics one joint; the robot file states it "))
        _indent(j)
        elements += [ET.Element("link", {"name": f"link_{i + 1}"}), j]
    for chain, path in robot.tree.chains.items():
        tip = path[-1]
        elements += [ET.Element("link", {"name": f"{TARGET}_{chain}"}),
                     _fixed_joint(f"{TARGET}_{chain}_joint", f"link_{tip + 1}", f"{TARGET}_{chain}",
                                  robot.targets.get(chain, np.eye(4)))]
    for name, mount in robot.cameras.items():
        parent = _camera_parent(robot, mount, lambda k: f"link_{k}")
        elements += [ET.Element("link", {"name": f"camera_{name}_optical"}),
                     _fixed_joint(f"camera_{name}_optical_joint", parent, f"camera_{name}_optical", mount.pose)]
    for e in elements:
        e.tail = "\n  "
    _append(root, *elements)
    return root
