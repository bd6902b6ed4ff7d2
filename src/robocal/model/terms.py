"""Non-geometric joint terms: the joints reach q_eff = q + Δq(q, τ) (MODEL §4).

- ``compliance`` — a joint gives way under load, Δq_i = c_i τ_i (c in rad/(N·m)).
  * With measured torques (``tau1..tauN`` columns, N·m), τ is as the file gives it
    (torque form, parameters ``compliance1..N``).  With τ the load the joint carries, a
    compliant joint has c > 0; a controller that reports its holding torque gives c < 0.
  * Without torques, τ comes from gravity (gravity form).  The torque of the arm's own weight
    about joint i is τ_i = Σ_{j ≥ i} H_j · φ_ij(q), φ_ij = R_jᵀ (ĝ × a_i) g: H_j is link j's
    first mass moment (kg·m, in link j's frame, the masses of the links beyond folded in),
    R_j link j's orientation, a_i joint i's axis and ĝ the gravity direction (the robot
    file's ``gravity``, default −z of the base).  Masses are unknown, so the products
    c_i H_j g are identified: parameters ``gravity{i}_{j}x``, ``…y``, ``…z`` (rad), the
    deflection of joint i per unit of link j's weight moment along that axis of its frame.
    A known payload (``payload`` column or option, kg, centre of mass in the robot file)
    adds c_i times its own torque, with ``compliance{i}`` as parameters when it varies.
- ``harmonics`` — transmission errors periodic in the joint's own angle,
  Δq_i = Σ_{h=1..H} a_ih cos(h q_i) + b_ih sin(h q_i): ``harmonic{i}_cos{h}``,
  ``harmonic{i}_sin{h}`` (rad).
- ``backlash`` — Δq_i = b_i dir_i, the joint stands half its dead band off on the side of its
  last move: ``backlash{i}`` (rad, reported in deg).
- ``drift`` — joint zeros that move linearly with time, Δq_i = r_i (t − t₀)/S: ``drift{i}``
  (rad per S, reported in deg/h on a clock of seconds, S = 3600 s, or deg per 1000 poses
  on the row index, S = 1000 rows, where the data have no time column).  t₀ (the reference)
  is the last calibration pose: the model predicts the robot as it was then, and at the
  data's own time where a file gives one on the same clock.

Every term is linear in its parameters: Δq = B(q, τ) · p with a basis B (m, n, T) that
depends on the commanded joints (a first-order choice: deflections of a few hundredths of a
degree do not change the basis) and the data, not on p.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ..math.so3 import rot_x
from .kinematics import chain_frames, joint_axes, prismatic_mask

#: standard gravity, m/s²
G = 9.80665
COMPLIANCE_FORMS = ("torque", "gravity")


def joint_axes_and_links(convention: str, geom: np.ndarray, q: np.ndarray):
    """Joint axes (m, n, 3), points on them (m, n, 3) mm, and link orientations (m, n, 3, 3),
    all in the robot's base frame at joints q (m, n) rad.  Link j is the frame after joint j."""
    axes, points = joint_axes(convention, geom, q)
    Rs, _ = chain_frames(convention, geom, q)
    return axes, points, np.stack(Rs[1:], -3)


def tree_axes_and_links(convention: str, geom: np.ndarray, q: np.ndarray, parents: tuple[int, ...]):
    """As :func:`joint_axes_and_links` for a tree (``parents``: each joint's parent, −1 on the root):
    every joint's axis, point and link orientation along its own path from the root."""
    n = len(parents)
    axes, points = np.empty(q.shape[:-1] + (n, 3)), np.empty(q.shape[:-1] + (n, 3))
    links = np.empty(q.shape[:-1] + (n, 3, 3))
    for leaf in sorted(set(range(n)) - set(parents)):  # every joint lies on some leaf's path
        path, j = [], leaf
        while j >= 0:
            path.append(j)
            j = parents[j]
        path = path[::-1]
        a, p, L = joint_axes_and_links(convention, geom[path], q[..., path])
        axes[..., path, :], points[..., path, :], links[..., path, :, :] = a, p, L
    return axes, points, links


def outboard(n: int, parents: tuple[int, ...] | None = None) -> np.ndarray:
    """(n, n) bool: link j is carried by joint i (j = i or beyond it: j ≥ i on a chain, j in i's
    subtree on a tree).  The links of another branch load a joint not."""
    if parents is None:
        return np.triu(np.ones((n, n), bool))
    out = np.eye(n, dtype=bool)
    for j in range(n):
        i = parents[j]
        while i >= 0:
            out[i, j] = True
            i = parents[i]
    return out


def gravity_basis(convention: str, geom: np.ndarray, q: np.ndarray, direction: np.ndarray,
                  parents: tuple[int, ...] | None = None) -> np.ndarray:
    """φ_ij = g R_jᵀ (ĝ × a_i) for the links j joint i carries (zero for the others: j < i on a chain,
    another branch on a tree), (m, n, n, 3) in N per kg·m of moment."""
    axes, _, links = joint_axes_and_links(convention, geom, q) if parents is None else \
        tree_axes_and_links(convention, geom, q, parents)
    g = G * np.asarray(direction, float) / np.linalg.norm(direction)
    lever = np.cross(g, axes)  # (m, n_i, 3)
    phi = np.einsum("mjab,mia->mijb", links, lever)  # R_jᵀ (g × a_i)
    n = geom.shape[-2]
    phi *= outboard(n, parents)[None, :, :, None]  # only links at or beyond the joint
    phi[:, prismatic_mask(convention, geom)] = 0.0  # the terms model turning joints
    return phi


def payload_torque(convention: str, geom: np.ndarray, q: np.ndarray, direction: np.ndarray, mass: np.ndarray,
                   com: np.ndarray) -> np.ndarray:
    """Torque (m, n) N·m of a payload of ``mass`` kg (m,) with centre of mass ``com`` (mm, flange frame)."""
    axes, points, links = joint_axes_and_links(convention, geom, q)
    Rs, origins = chain_frames(convention, geom, q)
    p = origins[-1] + np.einsum("mab,b->ma", Rs[-1], np.asarray(com, float))  # mm
    force = (G * np.asarray(direction, float) / np.linalg.norm(direction))[None, :] * np.asarray(mass)[:, None]
    arm = (p[:, None, :] - points) / 1000.0  # m
    tau = np.einsum("mia,mia->mi", axes, np.cross(arm, force[:, None, :]))
    tau[:, prismatic_mask(convention, geom)] = 0.0
    return tau


def mass_torques(convention: str, geom: np.ndarray, q: np.ndarray, direction: np.ndarray, masses: np.ndarray,
                 centres: np.ndarray, parents: tuple[int, ...] | None = None) -> np.ndarray:
    """Gravity torque (m, n) N·m about each joint of point masses ``masses`` (n,) kg carried by the
    links, at ``centres`` (n, 3) mm in each link's own frame (link j: the frame after joint j):
    τ_i = a_i · Σ_{j ≥ i} (c_j − p_i) × m_j g, the load joint i holds (it gives way along it)."""
    if parents is None:
        axes, points, links = joint_axes_and_links(convention, geom, q)
        _, origins = chain_frames(convention, geom, q)
        o = np.stack([np.broadcast_to(x, origins[-1].shape) for x in origins[1:]], -2)  # (m, n, 3)
    else:  # a tree's links are urdf frames: each sits at its joint's origin, on its axis
        axes, points, links = tree_axes_and_links(convention, geom, q, parents)
        o = points
    c = o + np.einsum("mjab,jb->mja", links, np.asarray(centres, float))
    weight = G * np.asarray(direction, float) / np.linalg.norm(direction)
    force = np.asarray(masses, float)[:, None] * weight  # (n, 3) N
    arm = (c[:, None, :, :] - points[:, :, None, :]) / 1000.0  # (m, i, j, 3) m
    moment = np.cross(arm, force[None, None])  # (m, i, j, 3)
    carried = outboard(geom.shape[-2], parents)[None, :, :, None]  # the links joint i carries
    tau = np.einsum("mia,mia->mi", axes, np.sum(moment * carried, axis=2))
    tau[:, prismatic_mask(convention, geom)] = 0.0
    return tau


def nominal_masses(convention: str, geom: np.ndarray, parents: tuple[int, ...] | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A plausible mass model of an arm, for simulation: link j weighs 2 kg plus 15 kg per metre of
    its a and d, with its centre half-way along them (mm, in link j's frame).  Not an identified
    model: simulated torques need some load that varies with the pose as a real arm's does."""
    if convention == "urdf":  # link j reaches to the next joint's origin (its first child's, on a tree)
        n = geom.shape[0]
        child = [next((k for k in range(n) if (parents[k] if parents else k - 1) == j), None) for j in range(n)]
        nxt = np.array([geom[k, 0:3] if k is not None else np.zeros(3) for k in child])
        return 2.0 + 15.0 * np.linalg.norm(nxt, axis=1) / 1000.0, nxt / 2
    a, d = np.abs(geom[:, 0]), np.abs(geom[:, 3])
    masses = 2.0 + 15.0 * (a + d) / 1000.0
    if convention == "craig":  # link j's frame sits at its joint; the link reaches towards the next
        nxt = np.vstack([geom[1:], np.zeros((1, geom.shape[1]))])
        centres = np.einsum("jab,jb->ja", rot_x(nxt[:, 1]),
                            np.column_stack([nxt[:, 0], np.zeros(len(geom)), nxt[:, 3]])) / 2
    else:  # link j's frame sits at its far end: the link lies behind it, along −x and −z of joint j's motion
        centres = np.column_stack([-geom[:, 0] / 2, np.zeros(len(geom)), np.zeros(len(geom))])
        centres = centres - np.einsum("jab,jb->ja", rot_x(-geom[:, 1]), np.column_stack(
            [np.zeros(len(geom)), np.zeros(len(geom)), geom[:, 3] / 2]))
    return masses, centres



@dataclass(frozen=True)
class TermSpec:
    """Which joint terms a model has: term name → its option (see each :class:`Term`), e.g.
    ``{"compliance": ("gravity", True), "harmonics": 2}``; absent terms are left out."""

    options: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = set(self.options) - set(TERMS)
        if unknown:
            raise ValueError(f"unknown joint term {sorted(unknown)[0]!r} (known: {', '.join(TERMS)})")
        object.__setattr__(self, "options", {k: v for k, v in self.options.items() if v})

    def terms(self):
        """(term, option) of every term the spec has, in registry order (the parameter order)."""
        return [(t, self.options[name]) for name, t in TERMS.items() if name in self.options]

    def names(self, n: int) -> list[str]:
        return [name for t, option in self.terms() for name in t.names(option, n)]

    @property
    def empty(self) -> bool:
        return not self.options


@dataclass(frozen=True, eq=False)
class JointTerms:
    """The values of a robot's joint terms (see the module docstring): ``arrays`` maps each
    term's array names to values (compliance (n,) rad/(N·m); gravity (n, n, 3) rad, entries
    j < i unused; harmonics (n, H, 2) rad as (cos, sin) pairs); gravity_direction (3,) in the
    base frame; payload_com (3,) mm in the flange frame."""

    arrays: Mapping[str, np.ndarray] = field(default_factory=dict)
    gravity_direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -1.0]))
    payload_com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: the drift term's time base: (clock, reference), see :class:`Drift`
    clock: tuple[str, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "arrays", {k: np.asarray(v, float) for k, v in self.arrays.items() if v is not None})

    def get(self, array: str) -> np.ndarray | None:
        return self.arrays.get(array)

    @property
    def empty(self) -> bool:
        return not self.arrays

    @property
    def needs_torques(self) -> bool:
        """Torque-form compliance: Δq acts on measured joint torques, which the data must give."""
        return any(t.needs_torques(self) for t in TERMS.values())

    def spec(self) -> TermSpec:
        return TermSpec({name: t.option_of(self) for name, t in TERMS.items()})

    def vector(self, spec: TermSpec, n: int) -> np.ndarray:
        """Values in the order of ``spec.names(n)`` (zeros where this robot has none)."""
        parts = [t.values(self, option, n) for t, option in spec.terms()]
        return np.concatenate(parts) if parts else np.zeros(0)

    def with_vector(self, spec: TermSpec, n: int, values: np.ndarray) -> JointTerms:
        """These terms with the parameters of ``spec`` set to ``values``."""
        values = np.asarray(values, float)
        arrays, k = dict(self.arrays), 0
        for t, option in spec.terms():
            size = len(t.names(option, n))
            arrays.update(t.arrays_of(option, n, values[k:k + size]))
            k += size
        clock = spec.options.get("drift", self.clock)
        return replace(self, arrays=arrays, clock=tuple(clock) if clock else None)


@dataclass(frozen=True, eq=False)
class JointInputs:
    """Per pose, what joint terms act on besides the commanded joints: torques (m, n) N·m,
    payload (m,) kg, directions (m, n) of each joint's move into the pose (+1, −1; 0 unknown)
    and time (m,) on ``clock``: ``s`` (a time column, seconds) or ``row:SOURCE`` (the line
    numbers of one file, which mean nothing in another); None where the data do not give one."""

    torques: np.ndarray | None = None
    payload: np.ndarray | None = None
    directions: np.ndarray | None = None
    time: np.ndarray | None = None
    clock: str = ""

    def subset(self, rows) -> JointInputs:
        def pick(a):
            return None if a is None else np.asarray(a)[rows]

        return JointInputs(pick(self.torques), pick(self.payload), pick(self.directions), pick(self.time), self.clock)


NO_INPUTS = JointInputs()


@dataclass(frozen=True)
class TermInputs:
    """What a term's basis is computed from: the chain (convention, geometry (n, w)), the
    commanded joints q (m, n) rad, the data's :class:`JointInputs`, and the robot's own terms
    (for the gravity direction and the payload's centre)."""

    convention: str
    geom: np.ndarray
    q: np.ndarray
    inputs: JointInputs
    terms: JointTerms
    #: a tree's joints' parents (:class:`robocal.model.kinematic_tree.TreeSpec`), None for a chain
    parents: tuple[int, ...] | None = None

    @property
    def torques(self) -> np.ndarray | None:
        return self.inputs.torques

    @property
    def payload(self) -> np.ndarray | None:
        return self.inputs.payload


@dataclass(frozen=True)
class FileKey:
    """A per-joint key of robot files holding one of a term's arrays: ``scalar`` (one number),
    ``links`` (one [x, y, z] per link j ≥ i) or ``pairs`` ([cos, sin] per harmonic);
    ``degrees``: written in degrees, held in rad."""

    key: str
    array: str
    shape: str
    degrees: bool
    comment: str


class Term:
    """One kind of joint term: Δq = B(q, τ) · p, linear in its parameters p.

    A term names its parameters for an option (:meth:`names`), builds their basis
    (:meth:`basis`), moves values between the parameter vector and its arrays
    (:meth:`values`, :meth:`arrays_of`), reads its option off a robot's arrays
    (:meth:`option_of`), and says how robot files hold it (:attr:`file_keys`) and how a
    simulation plants it (:meth:`plant`).  Adding a term is a subclass and an entry in
    :data:`TERMS`; the parameter space, the pipeline, robot files and simulation take it from
    there.
    """

    name: str = ""
    #: the prefixes of its parameter names
    prefixes: tuple[str, ...] = ()
    #: where ``--model auto`` tries it among terms of as many: the cheaper first
    rung: int = 0
    file_keys: tuple[FileKey, ...] = ()

    def unit_of(self, parameter: str) -> str:
        """The unit of one of its parameters' values (rad unless said otherwise)."""
        return "rad"

    def reported(self, parameter: str, terms: JointTerms | None = None) -> tuple[str, float]:
        """The unit a result reports the parameter in, and the factor from its own unit
        (``terms``: the model's, for a unit that depends on them)."""
        return self.unit_of(parameter), 1.0

    def names(self, option, n: int) -> list[str]:
        raise NotImplementedError

    def basis(self, option, inputs: TermInputs) -> np.ndarray:
        raise NotImplementedError

    def values(self, terms: JointTerms, option, n: int) -> np.ndarray:
        raise NotImplementedError

    def arrays_of(self, option, n: int, values: np.ndarray) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def option_of(self, terms: JointTerms):
        raise NotImplementedError

    def needs_torques(self, terms: JointTerms) -> bool:
        return False

    #: what the data must give for the term to be fitted at all ("" when any poses do)
    needs: str = ""
    #: what its basis varies with over the poses, and the motion that makes it vary ({j}: the joint)
    varies_with: str = "input"
    remedy: str = "measure poses where it varies"

    def unvaried(self, joint: int, support: int) -> str:
        """Why a parameter of joint ``joint`` (1-based) is not identifiable when its basis differs
        from its most common value at ``support`` poses only, and what motion would show it."""
        where = "at no pose" if support == 0 else f"at {support} pose{'s' if support > 1 else ''} only"
        return (f"the {self.name} of joint {joint} needs its {self.varies_with.format(j=joint)} to vary over the "
                f"poses, which it does {where}: the rest is a constant offset the geometry absorbs; "
                f"{self.remedy.format(j=joint)}")

    def never(self, joint: int, parameter: str) -> str:
        """Why ``parameter`` of joint ``joint`` (1-based), whose basis is zero at every pose, is no parameter
        (a term whose input the poses could vary: as :meth:`unvaried` says)."""
        return self.unvaried(joint, 0)

    def plant(self, planted, n: int) -> dict[str, np.ndarray]:
        """Arrays of a simulated truth from the simulation's option (1-based joints)."""
        raise NotImplementedError

    def option_for(self, meas, settings: Mapping[str, object]):
        """Its option in a model fitted to measurements ``meas`` with the calibration's settings."""
        raise NotImplementedError


class Compliance(Term):
    """Δq_i = c_i τ_i: option ``("torque", False)`` on measured torques, or ``("gravity", payload)``
    under gravity (``payload``: a varying payload adds its own compliances)."""

    name = "compliance"
    prefixes = ("compliance", "gravity")
    rung = 2
    varies_with = "load (torque, or gravity's moment)"
    remedy = "measure poses that load joint {j} differently (the arm stretched and folded, with and without payload)"

    def unit_of(self, parameter):
        return "rad/(N·m)" if parameter.startswith("compliance") else "rad"

    def never(self, joint, parameter):
        if parameter.startswith("compliance"):
            return f"joint {joint}'s torque is zero at every pose: nothing loads it"
        return (f"gravity has no moment about joint {joint}'s axis at any pose (the axis stays along gravity): "
                "nothing loads it")
    file_keys = (FileKey("compliance", "compliance", "scalar", False, "rad/(N·m)"),
                 FileKey("gravity_deflection", "gravity", "links", True, "deg, links {i}.."))

    @staticmethod
    def _own(option) -> bool:
        form, payload = option
        return form == "torque" or (form == "gravity" and payload)

    def names(self, option, n):
        out = [f"compliance{i + 1}" for i in range(n)] if self._own(option) else []
        if option[0] == "gravity":
            out += [f"gravity{i + 1}_{j + 1}{a}" for i in range(n) for j in range(i, n) for a in "xyz"]
        return out

    def basis(self, option, x):
        m, n = x.q.shape
        cols = []
        if self._own(option):
            if option[0] == "torque":
                tau = np.zeros(x.q.shape) if x.torques is None else \
                    np.where(prismatic_mask(x.convention, x.geom), 0.0, np.asarray(x.torques, float))
            else:
                if x.parents is not None:  # which chain's tip carries it is not said
                    from ..exceptions import InputError

                    raise InputError("a payload's own compliance on a tree: which chain carries the payload is not "
                                     "said; give the payload as torques (tau columns) or leave it out",
                                     option="payload")
                mass = np.zeros(m) if x.payload is None else np.asarray(x.payload, float)
                tau = payload_torque(x.convention, x.geom, x.q, x.terms.gravity_direction, mass, x.terms.payload_com)
            cols.append(np.einsum("mi,ik->mik", tau, np.eye(n)))
        if option[0] == "gravity":
            phi = gravity_basis(x.convention, x.geom, x.q, x.terms.gravity_direction, x.parents)
            for i in range(n):
                b = np.zeros((m, n, 3 * (n - i)))
                b[:, i, :] = phi[:, i, i:].reshape(m, -1)
                cols.append(b)
        return np.concatenate(cols, axis=2)

    def values(self, terms, option, n):
        out = []
        if self._own(option):
            c = terms.get("compliance")
            out.append(np.zeros(n) if c is None else c)
        if option[0] == "gravity":
            g = terms.get("gravity")
            g = np.zeros((n, n, 3)) if g is None else g
            out.append(np.concatenate([g[i, i:].ravel() for i in range(n)]))
        return np.concatenate(out)

    def arrays_of(self, option, n, values):
        out, k = {}, 0
        if self._own(option):
            out["compliance"], k = values[:n].copy(), n
        if option[0] == "gravity":
            g = np.zeros((n, n, 3))
            for i in range(n):
                size = 3 * (n - i)
                g[i, i:] = values[k:k + size].reshape(n - i, 3)
                k += size
            out["gravity"] = g
        return out

    def option_of(self, terms):
        if terms.get("gravity") is not None:
            return ("gravity", terms.get("compliance") is not None)
        return ("torque", False) if terms.get("compliance") is not None else None

    def option_for(self, meas, settings):
        """On measured torques where the data have them, else under gravity, with the payload's
        own compliances when it varies."""
        if meas.torques is not None:
            return ("torque", False)
        return ("gravity", meas.payload is not None and bool(np.ptp(meas.payload) > 0))

    def needs_torques(self, terms):
        c = terms.get("compliance")
        return c is not None and terms.get("gravity") is None and bool(np.any(c))

    def plant(self, planted, n):
        c = np.zeros(n)
        for j, value in planted.items():
            c[j - 1] = value
        return {"compliance": c}


class Harmonics(Term):
    """Δq_i = Σ_{h=1..H} a_ih cos(h q_i) + b_ih sin(h q_i): option H, the number of harmonics."""

    name = "harmonics"
    prefixes = ("harmonic",)
    rung = 1
    varies_with = "angle"
    remedy = "spread the poses over joint {j}'s turn"
    file_keys = (FileKey("harmonics", "harmonics", "pairs", True, "deg: [cos(h q), sin(h q)], h = 1, 2, …"),)

    def names(self, option, n):
        return [f"harmonic{i + 1}_{kind}{h}" for i in range(n) for h in range(1, option + 1) for kind in ("cos", "sin")]

    def basis(self, option, x):
        m, n = x.q.shape
        h = np.arange(1, option + 1)
        trig = np.stack([np.cos(x.q[..., None] * h), np.sin(x.q[..., None] * h)], -1)  # (m, n, H, 2)
        trig[:, prismatic_mask(x.convention, x.geom)] = 0.0  # periodic in an angle: turning joints only
        b = np.zeros((m, n, n, option, 2))
        b[:, np.arange(n), np.arange(n)] = trig
        return b.reshape(m, n, -1)

    def values(self, terms, option, n):
        h = np.zeros((n, option, 2))
        own = terms.get("harmonics")
        if own is not None:
            k = min(option, own.shape[1])
            h[:, :k] = own[:, :k]
        return h.ravel()

    def arrays_of(self, option, n, values):
        return {"harmonics": values.reshape(n, option, 2)}

    def option_of(self, terms):
        h = terms.get("harmonics")
        return None if h is None else h.shape[1]

    def option_for(self, meas, settings):
        return int(settings["harmonics"])

    def plant(self, planted, n):
        width = max(len(v) for v in planted.values())
        h = np.zeros((n, width, 2))
        for j, pairs in planted.items():
            for k, pair in enumerate(pairs):
                h[j - 1, k] = pair
        return {"harmonics": h}


class PerJointTerm(Term):
    """A term of one parameter per joint (``NAME1..NAMEn``), held as one array named after it,
    planted from {joint (1-based): value}."""

    def names(self, option, n):
        return [f"{self.name}{i + 1}" for i in range(n)]

    def values(self, terms, option, n):
        v = terms.get(self.name)
        return np.zeros(n) if v is None else v

    def arrays_of(self, option, n, values):
        return {self.name: values.copy()}

    def plant(self, planted, n):
        v = np.zeros(n)
        for j, value in planted.items():
            v[j - 1] = value
        return {self.name: v}


class Backlash(PerJointTerm):
    """Δq_i = b_i · dir_i: the joint stands b_i off its commanded angle on the side of its last
    move (half its dead band), dir_i = +1 or −1 from ``dir1..dirN`` columns or the measuring
    order (0 where unknown, before a joint's first move).  Option: 1."""

    name = "backlash"
    prefixes = ("backlash",)
    rung = 3
    varies_with = "direction of approach"
    remedy = ("approach joint {j}'s poses from both sides (a dir{j} column with +1 and −1, or a measuring order in "
              "which joint {j} reverses)")
    file_keys = (FileKey("backlash", "backlash", "scalar", True, "deg, taken up along the joint's last move"),)

    def reported(self, parameter, terms=None):
        return "deg", 180.0 / np.pi

    def basis(self, option, x):
        m, n = x.q.shape
        d = np.zeros((m, n)) if x.inputs.directions is None else np.asarray(x.inputs.directions, float)
        d = np.where(prismatic_mask(x.convention, x.geom), 0.0, d)  # turning joints: an angle's dead band
        return np.einsum("mi,ik->mik", d, np.eye(n))

    def option_of(self, terms):
        return None if terms.get("backlash") is None else 1

    #: what the data must give for the term to be fitted at all
    needs = ("the direction each joint approached each pose from: dir1..dirN columns, a time column, or the "
             "rows in measuring order (--row-order)")

    def option_for(self, meas, settings):
        """Directions from dir1..dirN columns or the time column's order; from the rows' order only
        where the user says the rows are in measuring order (a file sorted otherwise, a grid scan
        written row by row, would give directions no joint took)."""
        if meas.order == "row order" and not settings.get("row_order", False):
            return None
        return 1


#: the drift's time scale S per clock: rates per hour of seconds, per 1000 rows of a file
DRIFT_SCALE = {"s": 3600.0, "row": 1000.0}


def clock_kind(clock: str) -> str:
    """``s`` or ``row`` of a clock (``row:SOURCE`` is a file's own row clock)."""
    return clock.split(":", 1)[0]


class Drift(PerJointTerm):
    """Joint zeros that move linearly with time: Δq_i = r_i (t − t₀)/S.  Option: (clock, t₀),
    the clock ``s`` (a time column) or ``row:SOURCE`` (the line numbers of that file; a model
    read back from a robot file has ``row``, which matches no file) and the reference t₀ on it.
    Data on another clock are predicted at t₀ (Δq = 0)."""

    name = "drift"
    prefixes = ("drift",)
    rung = 4
    varies_with = "time"
    remedy = "measure over time (poses at different times: a time column that changes, or rows in measuring order)"
    file_keys = (FileKey("drift", "drift", "scalar", True, "deg per hour (clock s) or per 1000 rows (clock row)"),)

    def reported(self, parameter, terms=None):
        kind = clock_kind(terms.clock[0]) if terms is not None and terms.clock else "s"
        return ("deg/h" if kind == "s" else "deg/1000 rows"), 180.0 / np.pi

    def basis(self, option, x):
        m, n = x.q.shape
        clock, reference = option
        same = x.inputs.time is not None and x.inputs.clock == clock
        elapsed = (np.asarray(x.inputs.time, float) - reference) / DRIFT_SCALE[clock_kind(clock)] if same \
            else np.zeros(m)
        d = np.where(prismatic_mask(x.convention, x.geom), 0.0, 1.0)
        return np.einsum("m,i,ik->mik", elapsed, d, np.eye(n))

    def option_of(self, terms):
        if terms.get("drift") is None:
            return None
        return terms.clock or ("s", 0.0)

    needs = "when each pose was measured: a time column, or the rows in measuring order (--row-order)"

    def option_for(self, meas, settings):
        """The data's clock, and their last pose as the reference: the robot as calibration left it.
        Without a time column the rows' numbers stand for time only where the user says the rows
        are in measuring order."""
        if meas.time is None and not settings.get("row_order", False):
            return None
        inputs = meas.inputs
        if inputs.time is None:
            return None
        return (inputs.clock, float(np.max(inputs.time)))


#: the joint terms, in the order their parameters follow the geometry's
TERMS: dict[str, Term] = {t.name: t for t in (Compliance(), Harmonics(), Backlash(), Drift())}


def reported_unit(parameter: str, terms: JointTerms | None = None) -> tuple[str, float] | None:
    """The unit a result reports a joint-term parameter in and the factor to it (None for others)."""
    t = term_of(parameter)
    return None if t is None else t.reported(parameter, terms)


def term_unit(parameter: str) -> str | None:
    """The unit of a joint-term parameter (None for other parameters)."""
    t = term_of(parameter)
    return None if t is None else t.unit_of(parameter)


def term_of(parameter: str) -> Term | None:
    """The term a parameter name belongs to, or None for a geometric or frame parameter."""
    for t in TERMS.values():
        if parameter.startswith(t.prefixes):
            return t
    return None


def basis(spec: TermSpec, convention: str, geom: np.ndarray, q: np.ndarray, inputs: JointInputs | None = None,
          terms: JointTerms | None = None, parents: tuple[int, ...] | None = None) -> np.ndarray:
    """B (m, n, T) with Δq = B · p for the parameters p of ``spec`` (in ``spec.names`` order); ``parents``:
    a tree's (its joints' loads are those of their own branches)."""
    inputs = TermInputs(convention, geom, q, inputs or NO_INPUTS, terms or JointTerms(), parents)
    cols = [t.basis(option, inputs) for t, option in spec.terms()]
    return np.concatenate(cols, axis=2) if cols else np.zeros(q.shape + (0,))


def joint_offsets(terms: JointTerms | None, convention: str, geom: np.ndarray, q: np.ndarray,
                  inputs: JointInputs | None = None, parents: tuple[int, ...] | None = None) -> np.ndarray:
    """Δq (m, n) rad of a robot's own terms at commanded joints q (zeros without terms)."""
    q = np.atleast_2d(q)
    if terms is None or terms.empty:
        return np.zeros(q.shape)
    spec = terms.spec()
    return np.einsum("mit,t->mi", basis(spec, convention, geom, q, inputs, terms, parents),
                     terms.vector(spec, q.shape[1]))


def off_branch(name: str, parents: tuple[int, ...] | None) -> bool:
    """A tree's gravity term of a link that joint i does not carry (``gravity{i}_{j}…`` with j on
    another branch): zero by construction, never a parameter to offer."""
    m = re.fullmatch(r"gravity(\d+)_(\d+)[xyz]", name)
    if parents is None or m is None:
        return False
    i, j = int(m.group(1)) - 1, int(m.group(2)) - 1
    return not outboard(len(parents), parents)[i, j]


def missing_torques(terms: JointTerms | None, torques, source: str) -> str | None:
    """A warning when a model's compliance needs torques that ``source`` does not give."""
    if terms is None or not terms.needs_torques or torques is not None:
        return None
    return (f"the model's joint compliance acts on joint torques, but {source} has no tau1..tauN columns: "
            "its compliance is left out (zero torque)")


def drift_note(terms: JointTerms | None, inputs: JointInputs, source: str) -> str | None:
    """When a model's drift predicts: at the data's own times on its clock (said when they
    reach past the reference, where a linear drift is extrapolated), else at its reference."""
    if terms is None or terms.get("drift") is None or not np.any(terms.get("drift")):
        return None
    clock, reference = terms.clock or ("s", 0.0)
    kind = clock_kind(clock)
    if inputs.time is None or inputs.clock != clock:
        where = f"t = {reference:g} s" if kind == "s" else f"row {reference:g} of its calibration file"
        why = "no time column" if kind == "s" else "no rows of the calibration file"
        return (f"drift: {source} has {why}; the model predicts the robot as it was at {where} (its last "
                "calibration pose)")
    beyond = float(np.max(inputs.time)) - reference
    if kind == "s" and beyond > 0:
        return (f"drift: predicted at each pose's time; {source} reaches {beyond / 3600:.3g} h past the last "
                f"calibration pose (t = {reference:g} s): the drift there is extrapolated")
    return None
