"""Configurations to record at a socket: for calibration without a tracker (MODEL §9).

The ball on the flange sits in a socket at a known place (roughly: the nominal model's base
frame, mm); many joint configurations reach it, by the arm's null space and the flange's
orientation.  Which ones are recorded decides what the calibration can see.  Candidates are the
nominal robot's configurations that put its tool point on each socket (damped least squares from
random starts inside the joint ranges); from them, ``poses`` per socket are chosen greedily, a
socket at a time in turn, to maximise log det of the information the recorded rows carry once
each socket's unknown place is eliminated: per socket Σ JᵢᵀJᵢ − (Σ Jᵢ)ᵀ(Σ Jᵢ)/n, J the tool
point's Jacobian over the parameters such data can see (the base frame left out, the longest
link held for the scale, as the calibration does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import options as opt
from ..calibration.judge.identifiability import analyse
from ..exceptions import InputError
from ..model.candidates import complete, frame_candidates, joint_candidates
from ..model.kinematics import joint_kinds
from ..model.parameters import ParameterSpace, is_angle
from ..model.robot import Robot
from ..simulation import _reach, joint_ranges, random_joints


@dataclass
class ContactPlan:
    """Configurations to record: q (N, n) rad, the socket of each (index), log det of the
    information per parameter for the plan and for random choices from the same candidates."""

    q: np.ndarray
    socket: np.ndarray
    value: float
    names: list[str]
    random_values: list[float] = field(default_factory=list)
    reachable: list[int] = field(default_factory=list)

    def summary(self) -> dict:
        return {"configurations": int(len(self.q)), "sockets": int(self.socket.max() + 1),
                "criterion": "log det of the information per parameter (sockets eliminated)",
                "value": self.value, "random_median": float(np.median(self.random_values)),
                "candidates_reaching_each_socket": list(self.reachable), "parameters": list(self.names)}


def _information(blocks: np.ndarray) -> np.ndarray:
    """Σ JᵢᵀJᵢ − (Σ Jᵢ)ᵀ(Σ Jᵢ)/n of one socket's rows (n, 3, k)."""
    s = blocks.sum(0)
    return np.einsum("nik,nil->kl", blocks, blocks) - s.T @ s / len(blocks)


def _logdet(M: np.ndarray) -> float:
    sign, value = np.linalg.slogdet(M)
    return float(value) if sign > 0 else -math.inf


def plan_contacts(robot: Robot, sockets, per_socket: int, *, candidates: int = 300, seed: int = 0,
                  joint_range=None, random_sets: int = 20) -> ContactPlan:
    """``per_socket`` configurations at each socket (x, y, z mm in the robot's base frame) of
    ``robot`` (its tool: the ball), chosen from ``candidates`` reaching configurations each."""
    sockets = np.atleast_2d(np.asarray(sockets, float))
    if sockets.shape[1] != 3 or not np.all(np.isfinite(sockets)):
        raise InputError("a socket is x,y,z (mm, the robot's base frame)", option="socket")
    per_socket = opt.integer(per_socket, "poses", minimum=2)
    candidates = opt.integer(candidates, "candidates", minimum=per_socket)
    rng = np.random.default_rng(seed)
    robot = complete(robot)
    lim = joint_ranges(robot, joint_range)
    reach, found = [], []
    for k, c in enumerate(sockets):
        q, ok = _reach(robot, np.tile(c, (candidates, 1)), random_joints(robot, candidates, rng, joint_range), lim)
        q = q[ok]
        if len(q):  # one of each configuration: starts that ended together are one
            q = q[np.unique(np.round(q, 6), axis=0, return_index=True)[1]]
        if len(q) < per_socket:
            raise InputError(f"socket {k + 1} at {', '.join(f'{v:g}' for v in c)} mm: the robot reaches it in "
                             f"{len(q)} distinct configurations of {candidates} tries, fewer than {per_socket}: "
                             "move it inside the workspace or draw more candidates", option="socket")
        reach.append(q)
        found.append(len(q))
    space = ParameterSpace.of(robot)
    names = joint_candidates(robot) + frame_candidates("tcp", ("",), False)
    cols = space.index(names)

    def blocks(q):
        J, _, _ = space.jacobian_columns(np.zeros(space.size), q)
        return np.moveaxis(J[cols][:, :, :3], 0, -1)  # (m, 3, k)

    B = [blocks(q) for q in reach]
    centred = np.concatenate([(b - b.mean(0)).reshape(-1, len(names)) for b in B])
    base = [n for n in space.names if n.startswith("base_")]
    Jb, _, _ = space.jacobian_columns(np.zeros(space.size), np.vstack(reach))
    gauge = np.concatenate([(np.moveaxis(Jb[space.index(base)][:, :, :3], 0, -1)[i:i + len(q)]
                             - np.moveaxis(Jb[space.index(base)][:, :, :3], 0, -1)[i:i + len(q)].mean(0)
                             ).reshape(-1, len(base)) for i, q in zip(np.cumsum([0] + found[:-1]), reach)])
    ident = analyse(np.hstack([gauge, centred]), base + names, np.array([is_angle(n) for n in base + names]),
                    sum(found), robot.reach(), prefer=base)
    kept = [n for n in ident.kept if n not in base]
    kinds = len(joint_kinds(robot.convention))
    lengths = [n for n in kept if space.names.index(n) < space.n_joint_params and not is_angle(n)]
    if lengths:  # the scale: held by the longest link, as a calibration without a distance holds it
        value = {n: abs(float(robot.geometry[space.names.index(n) // kinds, space.names.index(n) % kinds]))
                 for n in lengths}
        kept.remove(max(lengths, key=lambda n: value[n]))
    use = [names.index(n) for n in kept]
    B = [b[:, :, use] for b in B]
    k = len(kept)
    scale = np.where([is_angle(n) for n in kept], robot.reach(), 1.0)
    B = [b * scale for b in B]  # angles in mm at the arm's reach: the criterion compares like with like
    ridge = 1e-9 * np.trace(sum(np.einsum("nik,nil->kl", b, b) for b in B)) / k * np.eye(k)

    def total(choice):
        return sum(_information(b[c]) for b, c in zip(B, choice) if len(c) > 1) + ridge

    chosen: list[list[int]] = [[] for _ in B]
    for _ in range(per_socket):
        for s, b in enumerate(B):
            others = total([c if t != s else [] for t, c in enumerate(chosen)])
            free = [i for i in range(len(b)) if i not in chosen[s]]
            if not chosen[s]:
                pick = free[int(rng.integers(len(free)))]  # one row of a socket carries nothing alone
            else:
                pick = max(free, key=lambda i: _logdet(others + _information(b[chosen[s] + [i]])))
            chosen[s].append(pick)
    value = _logdet(total(chosen)) / k
    randoms = [_logdet(total([list(rng.choice(len(b), per_socket, replace=False)) for b in B])) / k
               for _ in range(random_sets)]
    q = np.vstack([r[c] for r, c in zip(reach, chosen)])
    socket = np.repeat(np.arange(len(B)), per_socket)
    return ContactPlan(q, socket, value, kept, randoms, found)
