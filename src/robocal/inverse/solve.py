"""Every inverse solution of a batch of goals, and the one a target names.

:func:`all_solutions` finds every solution of each goal pose, batched over the goals:

- in closed form where the chain's DH equivalent is one of :mod:`.closed_form`'s (exactly, for a
  geometric model: the nominal models of industrial arms), else on its nearest ideal form and
  polished on the whole model (a calibrated model: its terms and residual included);
- otherwise by damped least squares from well-conditioned and random starts, restarted for a
  goal that no start reached, the distinct solutions kept.

A solution's revolute joints lie in (−π, π]; turning a joint by whole turns within its limits
gives the same pose, and :func:`choose` picks the turns together with the solution: the one that
matches what the target says (its configuration data, as a :class:`Request`), then the one nearest
the taught joints (``hint``), so that a target never silently changes branch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.jointspace import ready_configurations
from ..model.robot import Robot
from . import closed_form
from .configuration import TOLERANCE_RAD, Arm, arm_configuration
from .equivalent import dh_equivalent, wrap
from .local import ROT_WEIGHT, refuse_coupled, solve_ik

#: a solution reaches its goal within these (mm, rad)
REACHED_MM, REACHED_RAD = 1e-5, 1e-8
#: two solutions closer than this in every joint (rad, after whole turns) are one
DISTINCT_RAD = 1e-4
#: random starts of the multi-start search, beside the well-conditioned ones, and the restarts
#: (each with fresh random starts) of the goals none of them reached
RANDOM_STARTS, RESTARTS = 16, 2
#: whole turns tried per joint
TURNS = np.arange(-2, 3)
#: goals chosen among at once (the candidates' arrays are goals × solutions × joints × turns)
BLOCK = 2048
#: how far (rad) a closed form's seed on a branch boundary is nudged each way, joint by joint, so
#: that the polish finds both solutions that meet there
NUDGE = 0.2


@dataclass
class Solutions:
    """Every solution of m goals: ``q`` (m, k, n) rad, NaN where a goal has fewer than k;
    ``valid`` (m, k); ``method`` (``closed form (spherical)``, ``… polished``, ``multi-start``)
    and the starts tried per goal (``searches``).  :meth:`facts` gives each solution's
    configuration facts, which a language's ``encode`` turns into its configuration data."""

    q: np.ndarray
    valid: np.ndarray
    method: str
    searches: int

    @property
    def count(self) -> np.ndarray:
        return self.valid.sum(axis=1)

    def facts(self, robot: Robot) -> dict[str, np.ndarray] | None:
        """``front``, ``elbow``, ``lower`` (m, k) of every solution (see :mod:`.configuration`)."""
        return _facts(robot, np.nan_to_num(self.q))

    def rows(self, rows) -> Solutions:
        return Solutions(self.q[rows], self.valid[rows], self.method, self.searches)


def _goal_parts(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return T[:, :3, 3], T[:, :3, :3]


def _distinct(q: np.ndarray, ok: np.ndarray, prismatic: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solutions (m, k, n) with duplicates (within DISTINCT_RAD, whole turns apart) marked invalid."""
    m, k, _ = q.shape
    keep = ok.copy()
    for j in range(1, k):
        diff = q[:, :j] - q[:, j:j + 1]
        diff = np.where(prismatic, diff, wrap(diff))
        same = (np.abs(diff).max(axis=2) < DISTINCT_RAD) & keep[:, :j]
        keep[:, j] &= ~same.any(axis=1)
    return q, keep


def _pack(q: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Valid solutions first, the columns no goal uses dropped."""
    order = np.argsort(~valid, axis=1, kind="stable")
    q = np.take_along_axis(q, order[..., None], axis=1)
    valid = np.take_along_axis(valid, order, axis=1)
    k = max(1, int(valid.sum(axis=1).max()))
    q, valid = q[:, :k], valid[:, :k]
    return np.where(valid[..., None], q, np.nan), valid


def _polish(robot: Robot, T: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Seeds (m, k, n) polished on the robot's whole model; which reached their goal."""
    m, k, n = seeds.shape
    p, R = _goal_parts(np.repeat(T, k, axis=0))
    start = np.nan_to_num(seeds.reshape(-1, n))
    sol = solve_ik(robot, p, R, start, limits=False)
    ok = (sol.position_error <= REACHED_MM) & (sol.rotation_error <= REACHED_RAD)
    q = np.where(robot.prismatic, sol.q, wrap(sol.q))
    return q.reshape(m, k, n), ok.reshape(m, k)


def _starts(robot: Robot, rng: np.random.Generator, count: int) -> np.ndarray:
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    lo, hi = np.where(np.isfinite(lo), lo, -np.pi), np.where(np.isfinite(hi), hi, np.pi)
    return rng.uniform(lo, hi, (count, robot.n_joints))


def _multi_start(robot: Robot, T: np.ndarray, hint: np.ndarray | None, seed: int) -> tuple[np.ndarray, np.ndarray, int]:
    m = len(T)
    rng = np.random.default_rng(seed)
    fixed = np.array(ready_configurations(robot)[:8])
    searches = 0
    found_q, found_ok = [], []
    todo = np.arange(m)
    for attempt in range(1 + RESTARTS):
        starts = np.vstack([fixed, _starts(robot, rng, RANDOM_STARTS)]) if attempt == 0 else \
            _starts(robot, rng, len(fixed) + RANDOM_STARTS)
        seeds = np.repeat(starts[None], len(todo), axis=0)
        if hint is not None and attempt == 0:
            seeds = np.concatenate([np.nan_to_num(hint[todo])[:, None], seeds], axis=1)
        searches += seeds.shape[1]
        q, ok = _polish(robot, T[todo], seeds)
        full_q = np.full((m,) + q.shape[1:], np.nan)
        full_ok = np.zeros((m, q.shape[1]), bool)
        full_q[todo], full_ok[todo] = q, ok
        found_q.append(full_q)
        found_ok.append(full_ok)
        todo = todo[~ok.any(axis=1)]
        if todo.size == 0:
            break
    q, ok = np.concatenate(found_q, axis=1), np.concatenate(found_ok, axis=1)
    return (*_distinct(q, ok, robot.prismatic), searches)


def all_solutions(robot: Robot, T: np.ndarray, *, hint: np.ndarray | None = None, seed: int = 0) -> Solutions:
    """Every solution (base turns: revolute joints in (−π, π]) with which ``robot`` (its whole
    model) puts its tool at the poses T (m, 4, 4), mm, in its measuring frame.  Limits are not
    applied here (:func:`choose` does, with the turns).  hint (m, n) rad: joints to start from
    first where the search is numerical; seed: its random starts."""
    refuse_coupled(robot)
    T = np.asarray(T, float)
    eq = dh_equivalent(robot)
    kind, exact = closed_form.form_of(eq)
    if kind is not None:
        ideal = eq if exact else closed_form.idealized(eq, kind)
        q, ideal_ok = closed_form.solve(ideal, kind, T)
        if exact and robot.geometric:
            return Solutions(*_pack(*_distinct(q, ideal_ok, robot.prismatic)), f"closed form ({kind})", 8)
        if hint is not None:  # the taught joints seed a polish too: the branch they name is never lost
            q = np.concatenate([q, np.asarray(hint, float)[:, None]], axis=1)
        # a polished seed that meets its goal is a solution, whatever the ideal form said of the seed
        q, ok = _polish(robot, T, q)
        # where the ideal form has no solution for some branch (the goal near a stretched or folded
        # arm, or by the shoulder, where two branches meet), its seeds sit on that boundary and their
        # polish may find one of two nearby solutions: the seeds are nudged each way, joint by joint
        doubtful = ~ideal_ok.all(axis=1)
        if doubtful.any():
            seeds = closed_form.solve(ideal, kind, T[doubtful])[0]
            nudges = np.concatenate([np.eye(robot.n_joints) * s * NUDGE for s in (-1.0, 1.0)])
            nudged = (seeds[:, :, None, :] + nudges[None, None]).reshape(len(seeds), -1, robot.n_joints)
            more_q, more_ok = _polish(robot, T[doubtful], nudged)
            q = np.concatenate([q, np.full((len(T),) + more_q.shape[1:], np.nan)], axis=1)
            ok = np.concatenate([ok, np.zeros((len(T), more_q.shape[1]), bool)], axis=1)
            q[doubtful, -more_q.shape[1]:], ok[doubtful, -more_q.shape[1]:] = more_q, more_ok
        missing = ~ok.any(axis=1)
        if missing.any():  # a goal the ideal form's solutions did not lead to: search it
            more_q, more_ok, _ = _multi_start(robot, T[missing], None if hint is None else hint[missing], seed)
            k = q.shape[1]
            q = np.concatenate([q, np.full((len(T),) + more_q.shape[1:], np.nan)], axis=1)
            ok = np.concatenate([ok, np.zeros((len(T), more_q.shape[1]), bool)], axis=1)
            q[missing, k:], ok[missing, k:] = more_q, more_ok
        return Solutions(*_pack(*_distinct(q, ok, robot.prismatic)), f"closed form ({kind}), polished", q.shape[1])
    q, ok, searches = _multi_start(robot, T, hint, seed)
    return Solutions(*_pack(q, ok), "multi-start", searches)


@dataclass(frozen=True)
class Request:
    """What a target says of its solution: the configuration facts it names (+1/−1; 0 for
    any: see :class:`~robocal.inverse.configuration.Arm`) and, per joint, a closed interval
    (rad) its value must lie in (a sign, a quadrant, a turn), None where it says nothing."""

    front: int = 0
    elbow: int = 0
    lower: int = 0
    joints: tuple = field(default_factory=tuple)

    @property
    def empty(self) -> bool:
        return not (self.front or self.elbow or self.lower or any(j is not None for j in self.joints))


@dataclass
class Choice:
    """The chosen solution per goal: joints ``q`` (m, n) rad (NaN where none), its index among
    the goal's solutions, how many of the target's configuration data it misses (``mismatch``:
    0 is the configuration named), its distance to the hint (rad, L2), and its facts."""

    q: np.ndarray
    index: np.ndarray
    mismatch: np.ndarray
    distance: np.ndarray
    arm: Arm | None

    @property
    def found(self) -> np.ndarray:
        return self.index >= 0


def _intervals(requests, m: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.full((m, n), -np.inf), np.full((m, n), np.inf)
    for i, r in enumerate(requests):
        if r is None:
            continue
        for j, bounds in enumerate(r.joints[:n]):
            if bounds is not None:
                lo[i, j], hi[i, j] = bounds
    return lo - TOLERANCE_RAD, hi + TOLERANCE_RAD


def _turned(robot: Robot, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, hint: np.ndarray | None):
    """Per solution (m, k, n) the whole turns of each revolute joint: inside the limits, inside the
    target's interval where one is, then nearest the hint, else the fewest turns; how many
    intervals could not be met (m, k), and whether the limits could (m, k).

    The turns are tried one at a time, each kept where it costs strictly less than the best so far:
    the first of equal costs wins, as an argmin over all turns at once would pick, without the
    (m, k, n, turns) arrays (ten thousand goals' candidates were 80 ms of a controller's inverse)."""
    turns = np.where(robot.prismatic[:, None], 0, TURNS)  # (n, t)
    shifts = 2.0 * np.pi * turns
    lim_lo, lim_hi = robot.limits[:, 0] - TOLERANCE_RAD, robot.limits[:, 1] + TOLERANCE_RAD
    lo, hi = lo[:, None, :], hi[:, None, :]
    if hint is not None:
        h = hint[:, None, :]
        unhinted, h = np.isnan(h), np.nan_to_num(h)
    chosen = best = allowed = None
    for t in range(turns.shape[1]):
        cand = q + shifts[:, t]  # (m, k, n)
        in_limits = (cand >= lim_lo) & (cand <= lim_hi)
        in_interval = (cand >= lo) & (cand <= hi)
        cost = np.where(in_limits, 0.0, np.inf) + np.where(in_interval, 0.0, 1e6)
        away = np.abs(turns[:, t])
        cost += away if hint is None else np.where(unhinted, away, np.abs(cand - h))
        both = (in_limits & in_interval).astype(np.int8)
        if best is None:
            chosen, best, allowed = cand, cost, both
            continue
        better = cost < best
        np.copyto(chosen, cand, where=better)
        np.copyto(best, cost, where=better)
        allowed += both
    limits_ok = np.isfinite(best).all(axis=-1)
    missed = (np.where(np.isfinite(best), best, 0.0) >= 1e6).sum(axis=-1)
    # whether any joint has another turn the limits and the target allow (then the hint decides)
    choice = (allowed > 1).any(axis=-1)
    return chosen, missed, limits_ok, choice


def _facts(robot: Robot, q: np.ndarray, valid: np.ndarray | None = None) -> dict[str, np.ndarray] | None:
    """The configuration facts (turn-invariant) of solutions (m, k, n); 0 for those not ``valid``
    (m, k) (about half of a closed form's eight: no score takes them)."""
    m, k, n = q.shape
    keep = np.ones(m * k, bool) if valid is None else np.asarray(valid, bool).reshape(-1)
    arm = arm_configuration(robot, np.nan_to_num(q).reshape(-1, n)[keep])
    if arm is None:
        return None
    out = {}
    for f in ("front", "elbow", "lower"):
        fact = np.zeros(m * k, int)
        fact[keep] = getattr(arm, f)
        out[f] = fact.reshape(m, k)
    return out


#: where a goal's own data leave the choice free, a solution this close to a joint limit (rad) is taken
#: only if no other is: a correction would push it over
MARGIN_RAD = np.radians(5.0)


def _score(robot, q, valid, facts, lo, hi, wants, hint, roomy=None):
    """Turned solutions, their mismatch count and distance to the hint, and their score (lower is
    better; inf: outside the limits); ``roomy`` (m,): rows that prefer a margin to the limits."""
    chosen, missed, limits_ok, choice = _turned(robot, q, lo, hi, hint)
    mismatch = missed.astype(float)
    if facts is not None:
        for name, want in wants.items():
            fact = facts[name]
            mismatch += (want[:, None] != 0) & (fact != 0) & (fact != want[:, None])
    if hint is None:
        dist = np.zeros(mismatch.shape)
    else:
        dist = np.sqrt(np.nansum((chosen - hint[:, None]) ** 2, axis=2))
    score = np.where(valid & limits_ok, mismatch * 1e3 + np.minimum(dist, 999.0), np.inf)
    if roomy is not None and roomy.any():
        margin = np.min(np.minimum(chosen - robot.limits[:, 0], robot.limits[:, 1] - chosen), axis=2)
        score = score + np.where(roomy[:, None] & (margin < MARGIN_RAD), 100.0, 0.0)
    return chosen, mismatch, dist, score, choice


def choose(robot: Robot, solutions: Solutions, requests=None, hint: np.ndarray | None = None,
           follow: bool = False, roomy: np.ndarray | None = None) -> Choice:
    """The solution each goal's target names (see the module docstring): inside the joint
    limits; fewest configuration data missed; then nearest ``hint`` (m, n) rad, else the first.
    requests: a :class:`Request` or None per goal.  follow: a goal whose hint row is NaN (or
    every goal, without a hint) takes the previous goal's choice as its hint, as a robot moving
    through them in order (the first: the first solution).  roomy (m,): goals whose choice is
    robocal's own (no hint of theirs), which keep clear of the joint limits where they can."""
    q, valid = np.nan_to_num(solutions.q), solutions.valid
    m, k, n = q.shape
    requests = [None] * m if requests is None else list(requests)
    lo, hi = _intervals(requests, m, n)
    facts = _facts(robot, q, valid)
    wants = {f: np.array([0 if r is None else getattr(r, f) for r in requests]) for f in ("front", "elbow", "lower")}
    if hint is None and follow:
        hint = np.full((m, n), np.nan)
    roomy = np.zeros(m, bool) if roomy is None else np.asarray(roomy, bool)
    chosen, mismatch, dist, score, choice = _score(robot, q, valid, facts, lo, hi, wants, hint, roomy)
    index = np.argmin(score, axis=1)
    if follow:  # in order: each goal without its own hint follows the one before, where that decides
        level = np.floor(np.min(score, axis=1, keepdims=True) / 1e3)
        tied = ((np.floor(score / 1e3) == level) & np.isfinite(score)).sum(axis=1) > 1
        decides = tied | choice[np.arange(m), index]
        for i in np.flatnonzero(np.isnan(hint).all(axis=1) & decides):
            if i == 0 or not np.isfinite(score[i - 1, index[i - 1]]):
                continue
            h = chosen[i - 1, index[i - 1]][None]
            sub = slice(i, i + 1)
            c, mm, d, sc, _ = _score(robot, q[sub], valid[sub], None if facts is None else
                                     {f: v[sub] for f, v in facts.items()}, lo[sub], hi[sub],
                                     {f: v[sub] for f, v in wants.items()}, h, roomy[sub])
            chosen[i], mismatch[i], dist[i], score[i] = c[0], mm[0], d[0], sc[0]
            index[i] = np.argmin(sc[0])
    rows = np.arange(m)
    found = np.isfinite(score[rows, index])
    q_out = np.where(found[:, None], chosen[rows, index], np.nan)
    arm = None if facts is None else Arm(*(facts[f][rows, index] for f in ("front", "elbow", "lower")), q_out)
    return Choice(q_out, np.where(found, index, -1), np.where(found, mismatch[rows, index], np.nan),
                  np.where(found, dist[rows, index], np.nan), arm)


def controller_joints(nominal: Robot, T: np.ndarray, hint: np.ndarray | None = None, requests=None,
                   seed: int = 0) -> tuple[np.ndarray, list[str], list[str], str]:
    """The joints a controller running ``nominal`` goes to for goal poses T (m, 4, 4) in its world:
    every solution of its model, the one each request names, nearest ``hint`` (m, n) rad, else
    the previous goal's (the first goal: the best-conditioned ready configuration's).  Returns the joints (NaN where no
    solution), a status (``ok``, ``unreachable``, ``limit``, ``configuration``) and a reason per
    goal, and how they were solved."""
    m, n = len(T), nominal.n_joints
    if m == 0:
        return np.zeros((0, n)), [], [], "no goals"
    sols = all_solutions(nominal, T, hint=hint, seed=seed)
    hint = np.full((m, n), np.nan) if hint is None else np.array(hint, float)
    own = np.isnan(hint).all(axis=1)
    if m and own[0]:  # the first goal with nothing to go by: nearest a ready, upright arm
        hint[0] = ready_configurations(nominal)[0]
    requests = list(requests or [None] * m)
    free = own & np.array([r is None or r.empty for r in requests])
    picks = []
    for start in range(0, m, BLOCK):  # in blocks, so that the candidates' arrays stay small
        rows = slice(start, start + BLOCK)
        h = hint[rows].copy()
        if picks and np.isnan(h[0]).all() and picks[-1].found[-1]:
            h[0] = picks[-1].q[-1]  # a block's first goal follows the previous block's last
        block = sols.rows(rows)
        picks.append(choose(nominal, block, requests[rows], h, follow=True, roomy=free[rows]))
    pick = Choice(*(np.concatenate([getattr(p, f) for p in picks]) for f in ("q", "index", "mismatch", "distance")),
                  None if picks[0].arm is None else Arm(*(np.concatenate([getattr(p.arm, f) for p in picks])
                                                         for f in ("front", "elbow", "lower", "q"))))
    status, reasons = [], []
    count, found = sols.count, pick.found
    for i in range(len(T)):
        if count[i] == 0:
            status.append("unreachable")
            reasons.append(f"the nominal model reaches no solution ({sols.method}, {sols.searches} starts)")
        elif not found[i]:
            status.append("limit")
            reasons.append(f"the nominal model's {count[i]} solution(s) all lie beyond a joint limit")
        elif pick.mismatch[i] > 0:
            status.append("configuration")
            reasons.append("no solution of the nominal model in the configuration the target names "
                           f"({int(pick.mismatch[i])} of its configuration data missed)")
        else:
            status.append("ok")
            reasons.append("reached")
    return pick.q, status, reasons, sols.method


__all__ = ["ROT_WEIGHT", "Choice", "Request", "Solutions", "all_solutions", "choose", "controller_joints"]
