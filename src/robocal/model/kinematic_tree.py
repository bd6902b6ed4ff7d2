"""Kinematic trees: several chains from one root that share their trunk (MODEL §11).

A tree robot is a :class:`~robocal.model.robot.Robot` whose geometry holds every movable joint of
the tree once (its rows in the robot's convention, each relative to its parent joint's frame, or
to the base for a joint on the root) and a :class:`TreeSpec` that says each joint's parent and
each chain's joints from the root to its tip.  A joint shared by two chains (a torso's, a
turntable's) is one row of the geometry: one set of parameters, whichever chain a row measured.

A row names its chain (a ``chain`` column): its point is on that chain's tip (the chain's own
tool, or a target on it), and the pose runs base · A(joints of the chain's path) · tool.  A camera
on a link rides the path to that link, whatever chain the marker it sees is on: a head's camera
on a neck sees a hand on an arm through the trunk they share.  A serial robot is the tree with
one chain; it has no TreeSpec, and every code path of a serial robot is the one it always was.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class TreeSpec:
    """The shape of a tree: ``parents`` (n,) each joint's parent joint (−1: on the root) and
    ``chains`` each chain's name → its joints from the root to its tip (0-based).  ``joint names``
    are the tree's own (a URDF's), in the geometry's order: the data's q1..qn."""

    parents: tuple[int, ...]
    chains: Mapping[str, tuple[int, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "parents", tuple(int(p) for p in self.parents))
        object.__setattr__(self, "chains", {str(k): tuple(int(j) for j in v) for k, v in self.chains.items()})
        for name, joints in self.chains.items():
            for a, b in zip((-1,) + joints[:-1], joints):
                if self.parents[b] != a:
                    raise ValueError(f"chain {name!r}: joint {b + 1} hangs from joint {self.parents[b] + 1}, "
                                     f"not from {a + 1}")

    @property
    def n_joints(self) -> int:
        return len(self.parents)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.chains)

    def path(self, joint: int) -> tuple[int, ...]:
        """The joints from the root through ``joint`` (0-based), in order; () for −1 (the root)."""
        out = []
        while joint >= 0:
            out.append(joint)
            joint = self.parents[joint]
        return tuple(reversed(out))

    def index(self, labels: Sequence[str] | None) -> np.ndarray:
        """Each row's chain as an index into :attr:`names` (raises ValueError naming one it has not)."""
        lookup = {c: i for i, c in enumerate(self.chains)}
        if labels is None:
            raise ValueError(f"a tree's rows name their chain ({', '.join(self.chains)}): a chain column")
        unknown = next((c for c in labels if c not in lookup), None)
        if unknown is not None:
            raise ValueError(f"chain {unknown!r} is not one of the tree's ({', '.join(self.chains)})")
        return np.array([lookup[c] for c in labels], int)

    def groups(self, chain: np.ndarray | None, m: int) -> list[tuple[np.ndarray | slice, np.ndarray]]:
        """(rows, path) for each chain the rows hold: the rows of that chain and its joints."""
        if chain is None:
            raise ValueError(f"a tree's rows name their chain ({', '.join(self.chains)}): a chain column")
        out = []
        for c, joints in enumerate(self.chains.values()):
            rows = chain == c
            if rows.any():
                out.append((rows, np.array(joints, int)))
        return out

    def shared(self) -> tuple[int, ...]:
        """The joints on more than one chain (the trunk), 0-based."""
        counts = np.bincount([j for joints in self.chains.values() for j in joints], minlength=self.n_joints)
        return tuple(int(j) for j in np.flatnonzero(counts > 1))

    def describe(self, joint_names: Sequence[str] | None = None) -> str:
        """The joints as parameters number them, each run of a chain's own joints with its chain
        and the trunk with every chain it carries: "1 turntable (left, right); 2–7 left_1…left_6 (left)"."""
        label = (lambda j: joint_names[j]) if joint_names else (lambda j: f"joint {j + 1}")
        owners = [[c for c, joints in self.chains.items() if j in joints] for j in range(self.n_joints)]
        parts, start = [], 0
        for j in range(1, self.n_joints + 1):
            if j < self.n_joints and owners[j] == owners[start] and self.parents[j] == j - 1:
                continue
            span = f"{start + 1}" if j - 1 == start else f"{start + 1}–{j}"
            names = label(start) if j - 1 == start else f"{label(start)}…{label(j - 1)}"
            parts.append(f"{span} {names} ({', '.join(owners[start]) or 'no chain'})")
            start = j
        return "; ".join(parts)

    def to_dict(self, joint_names: Sequence[str] | None = None) -> dict:
        label = (lambda j: joint_names[j]) if joint_names else (lambda j: f"q{j + 1}")
        return {name: [label(j) for j in joints] for name, joints in self.chains.items()}


_PARAMETER = re.compile(r"^([a-z_]+?)(\d+)$")


def chain_robot(robot, name: str):
    """One chain of a tree robot as a serial robot (what ``filter`` and ``compensate`` take for one
    arm): its joints from the root to its tip (q1..qk, in that order), the tree's base, the chain's
    own tool as the tool, the targets, the fixed cameras and those on its links (renumbered), and of
    the covariance, the prior, the region and the coupling what concerns its joints.  Joint terms
    and a residual correction of the whole tree do not split by chain: a tree that has them refuses."""
    tree = robot.tree
    if tree is None:
        raise ValueError(f"{robot.name} is a serial robot: it has no chains")
    if name not in tree.chains:
        raise ValueError(f"chain {name!r} is not one of {', '.join(tree.chains)}")
    if robot.terms is not None or robot.residual is not None:
        raise ValueError("a tree's joint terms and residual correction do not split by chain: export the geometric "
                         "model (--model geometric) for per-chain files")
    path = list(tree.chains[name])
    where = {j: k for k, j in enumerate(path)}
    renamed = {}

    def rename(parameter: str) -> str | None:
        if parameter in renamed:
            return renamed[parameter]
        out = parameter
        match = _PARAMETER.match(parameter)
        if match and not parameter.startswith(("base", "tool", "camera")):
            joint = int(match.group(2)) - 1
            out = None if joint not in where else f"{match.group(1)}{where[joint] + 1}"
        elif parameter.startswith("tool["):
            label = parameter[5:parameter.index("]")]
            out = parameter.replace(f"tool[{label}]", "tool") if label == name else \
                None if label in tree.chains else parameter  # another chain's tool is not on this one
        renamed[parameter] = out
        return out

    cameras = {}
    for c, mount in robot.cameras.items():
        if mount.of or mount.link == 0:
            cameras[c] = mount
        elif mount.link - 1 in where:
            cameras[c] = replace(mount, link=where[mount.link - 1] + 1)
    cameras = {c: m for c, m in cameras.items() if not m.of or m.of in cameras}
    uncertainty = robot.uncertainty
    if uncertainty is not None:
        keep = [i for i, n in enumerate(uncertainty.names) if rename(n) is not None and
                not (n.startswith("camera[") and n[7:n.index("]")] not in cameras)]
        uncertainty = type(uncertainty)(tuple(rename(uncertainty.names[i]) for i in keep),
                                        uncertainty.matrix[np.ix_(keep, keep)])
    prior = robot.prior
    if prior is not None:
        prior = type(prior)({rename(k) or k: v for k, v in prior.widths.items() if rename(k) is not None})
    region = robot.region
    if region is not None:
        region = replace(region, lo=region.lo[path], hi=region.hi[path], prismatic=region.prismatic[path])
    coupling = []
    for joint, plus, factor in robot.coupling:
        if joint in where and plus in where:
            coupling.append((where[joint], where[plus], factor))
        elif joint in where or plus in where:
            raise ValueError(f"joint {joint + 1} follows joint {plus + 1}, and only one of them is on chain {name!r}")
    coupled = []
    for c in robot.coupled:
        if c.joint in where and all(j in where for j in c.sources):
            coupled.append(replace(c, joint=where[c.joint], sources=tuple(where[j] for j in c.sources)))
        elif c.joint in where:
            raise ValueError(f"joint {c.joint + 1} follows a joint that is not on chain {name!r}")
    targets = {t: T for t, T in robot.targets.items() if t not in tree.chains}
    return robot.replace(geometry=robot.geometry[path], limits=robot.limits[path], tree=None,
                         joint_names=None if robot.joint_names is None else
                         tuple(robot.joint_names[j] for j in path),
                         tool=robot.targets.get(name, np.eye(4)), targets=targets, cameras=cameras,
                         uncertainty=uncertainty, prior=prior, region=region, coupling=tuple(coupling),
                         coupled=tuple(coupled),
                         name=f"{robot.name} ({name})", urdf=None)
