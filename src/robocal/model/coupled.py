"""Coupled joints: a joint whose value follows others (MODEL §11).

A humanoid's torso keeps its chest level by a last joint that turns against the two before it;
a gripper's fingers mirror each other.  Such a joint is a joint of the model (its origin, axis
and zero are calibrated as any other's), but its value is not commanded: it is
``offset + Σ factor_k · q[source_k]`` (rad; mm for a sliding joint), the URDF's ``<mimic>`` with
one source, a robot file's ``follows`` with several.

A data file gives either every joint's value (a coupled joint's own encoder: the file's value is
used, and a row where it strays from its coupling by more than :data:`STRAY_DEG` is said) or only
the free joints' values, q1..qk in the robot's order with the coupled joints left out; robocal
fills them in.  Poses robocal makes (``simulate``, ``plan``) hold every coupling.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: a file's coupled joint that strays from its coupling by more than this (deg, or mm) is said
STRAY_DEG = 0.01


@dataclass(frozen=True)
class CoupledJoint:
    """``joint`` (0-based) = ``offset`` + Σ ``factors[k]`` · q[``sources[k]``] (rad, or mm)."""

    joint: int
    sources: tuple[int, ...]
    factors: tuple[float, ...]
    offset: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "sources", tuple(int(s) for s in self.sources))
        object.__setattr__(self, "factors", tuple(float(f) for f in self.factors))
        if len(self.sources) != len(self.factors) or not self.sources:
            raise ValueError(f"joint {self.joint + 1}: one factor per joint it follows")

    def value(self, q: np.ndarray, scale=1.0) -> np.ndarray:
        """Its value (…,) at joints q (…, n); ``scale`` (one, or one per joint) converts the
        offset (rad, or mm) to q's unit (180/π for a file's degrees)."""
        q = np.asarray(q, float)
        s = float(scale) if np.ndim(scale) == 0 else float(np.asarray(scale)[self.joint])
        return self.offset * s + sum(f * q[..., s] for s, f in zip(self.sources, self.factors))

    def describe(self, names: Sequence[str] | None = None) -> str:
        label = (lambda j: names[j]) if names else (lambda j: f"q{j + 1}")
        terms = " ".join(f"{'−' if f < 0 else '+'} {'' if abs(f) == 1 else f'{abs(f):g}·'}{label(s)}"
                         for s, f in zip(self.sources, self.factors)).lstrip("+ ")
        terms = "−" + terms[2:] if terms.startswith("− ") else terms
        offset = f" {'−' if self.offset < 0 else '+'} {abs(np.degrees(self.offset)):g}°" if self.offset else ""
        return f"{label(self.joint)} = {terms}{offset}"


def check(coupled: Sequence[CoupledJoint], n: int) -> None:
    """Raise ValueError unless every coupled joint follows free joints of an n-joint robot."""
    own = {c.joint for c in coupled}
    if len(own) != len(coupled):
        raise ValueError("a joint is coupled twice")
    for c in coupled:
        if not 0 <= c.joint < n or any(not 0 <= s < n for s in c.sources):
            raise ValueError(f"joint {c.joint + 1} follows a joint the robot has not (1…{n})")
        chained = next((s for s in c.sources if s in own), None)
        if chained is not None:
            raise ValueError(f"joint {c.joint + 1} follows joint {chained + 1}, itself coupled: give each coupled "
                             "joint from free joints")


def free(coupled: Sequence[CoupledJoint], n: int) -> np.ndarray:
    """The free joints (0-based, in order): those a file of the free joints' values gives."""
    own = {c.joint for c in coupled}
    return np.array([j for j in range(n) if j not in own], int)


def couple(coupled: Sequence[CoupledJoint], q: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """q (…, n) with every coupled joint set from the joints it follows (a copy)."""
    out = np.array(q, float, copy=True)
    for c in coupled:
        out[..., c.joint] = c.value(out, scale)
    return out


def expand(coupled: Sequence[CoupledJoint], q_free: np.ndarray, n: int, scale: float = 1.0) -> np.ndarray:
    """Every joint's value (m, n) from the free joints' (m, n − len(coupled))."""
    q_free = np.asarray(q_free, float)
    out = np.zeros(q_free.shape[:-1] + (n,))
    out[..., free(coupled, n)] = q_free
    return couple(coupled, out, scale)


def strays(coupled: Sequence[CoupledJoint], q: np.ndarray, scale: float = 1.0) -> list[tuple[int, int, float]]:
    """(joint, row, |difference|) of each coupled joint whose given values stray from its coupling
    by more than :data:`STRAY_DEG` (q's unit): the worst row of each."""
    out = []
    for c in coupled:
        d = np.abs(np.asarray(q, float)[:, c.joint] - c.value(q, scale))
        if d.size and d.max() > STRAY_DEG:
            out.append((c.joint, int(np.argmax(d)), float(d.max())))
    return out
