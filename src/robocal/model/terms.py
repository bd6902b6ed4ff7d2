"""Non-geometric joint terms: the joints reach q_eff = q + Δq(q, τ) (SPEC §10).

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

Every term is linear in its parameters: Δq = B(q, τ) · p with a basis B (m, n, T) that
depends on the commanded joints (a first-order choice: deflections of a few hundredths of a
degree do not change the basis) and the data, not on p.
"""

from __future__ import annotations

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


def gravity_basis(convention: str, geom: np.ndarray, q: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """φ_ij = g R_jᵀ (ĝ × a_i) for j ≥ i (zero for j < i), (m, n, n, 3) in N per kg·m of moment."""
    axes, _, links = joint_axes_and_links(convention, geom, q)
    g = G * np.asarray(direction, float) / np.linalg.norm(direction)
    lever = np.cross(g, axes)  # (m, n_i, 3)
    phi = np.einsum("mjab,mia->mijb", links, lever)  # R_jᵀ (g × a_i)
    n = geom.shape[-2]
    phi *= np.tril(np.ones((n, n))).T[None, :, :, None]  # only links at or beyond the joint
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
                 centres: np.ndarray) -> np.ndarray:
    """Gravity torque (m, n) N·m about each joint of point masses ``masses`` (n,) kg carried by the
    links, at ``centres`` (n, 3) mm in each link's own frame (link j: the frame after joint j):
    τ_i = a_i · Σ_{j ≥ i} (c_j − p_i) × m_j g, the load joint i holds (it gives way along it)."""
    axes, points, links = joint_axes_and_links(convention, geom, q)
    _, origins = chain_frames(convention, geom, q)
    o = np.stack([np.broadcast_to(x, origins[-1].shape) for x in origins[1:]], -2)  # (m, n, 3)
    c = o + np.einsum("mjab,jb->mja", links, np.asarray(centres, float))
    weight = G * np.asarray(direction, float) / np.linalg.norm(direction)
    force = np.asarray(masses, float)[:, None] * weight  # (n, 3) N
    arm = (c[:, None, :, :] - points[:, :, None, :]) / 1000.0  # (m, i, j, 3) m
    moment = np.cross(arm, force[None, None])  # (m, i, j, 3)
    n = geom.shape[-2]
    outboard = np.triu(np.ones((n, n)))[None, :, :, None]  # j ≥ i
    tau = np.einsum("mia,mia->mi", axes, np.sum(moment * outboard, axis=2))
    tau[:, prismatic_mask(convention, geom)] = 0.0
    return tau


def nominal_masses(convention: str, geom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A plausible mass model of an arm, for simulation: link j weighs 2 kg plus 15 kg per metre of
    its a and d, with its centre half-way along them (mm, in link j's frame).  Not an identified
    model: simulated torques need some load that varies with the pose as a real arm's does."""
    if convention == "urdf":  # link j reaches to the next joint's origin, given in link j's frame
        nxt = np.vstack([geom[1:, 0:3], np.zeros((1, 3))])
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
    """Which joint terms a model has: compliance form (``torque``, ``gravity`` or None),
    whether a varying payload gets its own compliances, and the number of harmonics."""

    compliance: str | None = None
    payload: bool = False
    harmonics: int = 0

    def names(self, n: int) -> list[str]:
        out = []
        if self.compliance == "torque" or (self.compliance == "gravity" and self.payload):
            out += [f"compliance{i + 1}" for i in range(n)]
        if self.compliance == "gravity":
            out += [f"gravity{i + 1}_{j + 1}{a}" for i in range(n) for j in range(i, n) for a in "xyz"]
        for i in range(n):
            for h in range(1, self.harmonics + 1):
                out += [f"harmonic{i + 1}_cos{h}", f"harmonic{i + 1}_sin{h}"]
        return out

    @property
    def empty(self) -> bool:
        return self.compliance is None and self.harmonics == 0


@dataclass(frozen=True, eq=False)
class JointTerms:
    """The values of a robot's joint terms (see the module docstring); None where absent.

    compliance (n,) rad/(N·m); gravity (n, n, 3) rad (entries j < i unused); harmonics
    (n, H, 2) rad as (cos, sin) pairs; gravity_direction (3,) in the base frame;
    payload_com (3,) mm in the flange frame.
    """

    compliance: np.ndarray | None = None
    gravity: np.ndarray | None = None
    harmonics: np.ndarray | None = None
    gravity_direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -1.0]))
    payload_com: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def empty(self) -> bool:
        return self.compliance is None and self.gravity is None and self.harmonics is None

    @property
    def needs_torques(self) -> bool:
        """Torque-form compliance: Δq acts on measured joint torques, which the data must give."""
        return self.compliance is not None and self.gravity is None and bool(np.any(self.compliance))

    def spec(self) -> TermSpec:
        form = "gravity" if self.gravity is not None else ("torque" if self.compliance is not None else None)
        return TermSpec(form, form == "gravity" and self.compliance is not None,
                        0 if self.harmonics is None else self.harmonics.shape[1])

    def vector(self, spec: TermSpec, n: int) -> np.ndarray:
        """Values in the order of ``spec.names(n)`` (zeros where this robot has none)."""
        out = []
        if spec.compliance == "torque" or (spec.compliance == "gravity" and spec.payload):
            out.append(np.zeros(n) if self.compliance is None else self.compliance)
        if spec.compliance == "gravity":
            g = np.zeros((n, n, 3)) if self.gravity is None else self.gravity
            out.append(np.concatenate([g[i, i:].ravel() for i in range(n)]))
        if spec.harmonics:
            h = np.zeros((n, spec.harmonics, 2))
            if self.harmonics is not None:
                k = min(spec.harmonics, self.harmonics.shape[1])
                h[:, :k] = self.harmonics[:, :k]
            out.append(h.ravel())
        return np.concatenate(out) if out else np.zeros(0)

    def with_vector(self, spec: TermSpec, n: int, values: np.ndarray) -> JointTerms:
        """These terms with the parameters of ``spec`` set to ``values``."""
        values = np.asarray(values, float)
        k = 0
        changes = {}
        if spec.compliance == "torque" or (spec.compliance == "gravity" and spec.payload):
            changes["compliance"], k = values[k:k + n].copy(), k + n
        if spec.compliance == "gravity":
            g = np.zeros((n, n, 3))
            for i in range(n):
                size = 3 * (n - i)
                g[i, i:] = values[k:k + size].reshape(n - i, 3)
                k += size
            changes["gravity"] = g
        if spec.harmonics:
            size = n * spec.harmonics * 2
            changes["harmonics"], k = values[k:k + size].reshape(n, spec.harmonics, 2), k + size
        return replace(self, **changes)


def basis(spec: TermSpec, convention: str, geom: np.ndarray, q: np.ndarray, torques: np.ndarray | None,
          payload: np.ndarray | None, terms: JointTerms | None = None) -> np.ndarray:
    """B (m, n, T) with Δq = B · p for the parameters p of ``spec`` (in ``spec.names`` order)."""
    m, n = q.shape
    terms = terms or JointTerms()
    cols = []
    if spec.compliance == "torque" or (spec.compliance == "gravity" and spec.payload):
        tau = _torque_input(spec, convention, geom, q, torques, payload, terms)
        cols.append(np.einsum("mi,ik->mik", tau, np.eye(n)))
    if spec.compliance == "gravity":
        phi = gravity_basis(convention, geom, q, terms.gravity_direction)
        blocks = []
        for i in range(n):
            b = np.zeros((m, n, 3 * (n - i)))
            b[:, i, :] = phi[:, i, i:].reshape(m, -1)
            blocks.append(b)
        cols.append(np.concatenate(blocks, axis=2))
    if spec.harmonics:
        h = np.arange(1, spec.harmonics + 1)
        trig = np.stack([np.cos(q[..., None] * h), np.sin(q[..., None] * h)], -1)  # (m, n, H, 2)
        trig[:, prismatic_mask(convention, geom)] = 0.0  # periodic in an angle: turning joints only
        b = np.zeros((m, n, n, spec.harmonics, 2))
        b[:, np.arange(n), np.arange(n)] = trig
        cols.append(b.reshape(m, n, -1))
    return np.concatenate(cols, axis=2) if cols else np.zeros((m, n, 0))


def _torque_input(spec, convention, geom, q, torques, payload, terms) -> np.ndarray:
    if spec.compliance == "torque":
        if torques is None:
            return np.zeros(q.shape)
        return np.where(prismatic_mask(convention, geom), 0.0, np.asarray(torques, float))
    mass = np.zeros(len(q)) if payload is None else np.asarray(payload, float)
    return payload_torque(convention, geom, q, terms.gravity_direction, mass, terms.payload_com)


def joint_offsets(terms: JointTerms | None, convention: str, geom: np.ndarray, q: np.ndarray,
                  torques: np.ndarray | None = None, payload: np.ndarray | None = None) -> np.ndarray:
    """Δq (m, n) rad of a robot's own terms at commanded joints q (zeros without terms)."""
    q = np.atleast_2d(q)
    if terms is None or terms.empty:
        return np.zeros(q.shape)
    spec = terms.spec()
    return np.einsum("mit,t->mi", basis(spec, convention, geom, q, torques, payload, terms),
                     terms.vector(spec, q.shape[1]))


def missing_torques(terms: JointTerms | None, torques, source: str) -> str | None:
    """A warning when a model's compliance needs torques that ``source`` does not give."""
    if terms is None or not terms.needs_torques or torques is not None:
        return None
    return (f"the model's joint compliance acts on joint torques, but {source} has no tau1..tauN columns: "
            "its compliance is left out (zero torque)")
