"""The parameters a calibration offers and the subset the data determine (steps 3, 4 and 8).

- :func:`choose_candidates`: the joint, frame and term parameters offered;
- :func:`analyse_identifiability`: the identifiable subset at the registered nominal model,
  the rest dropped with reasons (still joints, unvaried terms, the gauge of contact data);
- :func:`refine_at_estimate`: identifiability again where the fit ended.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ...exceptions import InputError
from ...model.candidates import frame_candidates, joint_candidates
from ...model.kinematics import joint_kinds
from ...model.parameters import is_angle, is_term
from ...model.terms import off_branch
from ..config import CalibrationConfig, resolve_params
from ..fit import cameras
from ..fit.methods import Estimate, fit_lm
from ..fit.problem import Setup
from ..judge import checks
from ..judge.identifiability import (
    DEPENDENT,
    NO_EFFECT,
    SECOND_ORDER,
    STILL,
    UNOBSERVABLE,
    UNVARIED,
    Identifiability,
    Reason,
    analyse,
)
from ..judge.statistics import f_test

#: significance level of the F-test that decides whether parameters that become
#: identifiable at the estimate are worth adding
ADD_SIGNIFICANCE = 0.01
#: residual evaluations allowed to the refit with the added parameters
REFIT_EVALUATIONS = 100
#: F-test p of the Gauss–Newton step's predicted decrease above which the refit is not tried:
#: fifty times the significance level, where the refit would need to find several times the
#: decrease the linearisation predicts
CLEARLY_NOT_SIGNIFICANT = 0.5


@dataclass(frozen=True)
class Candidates:
    """The parameters offered: joint names (``explicit`` when the user chose them) and frames."""

    joints: list[str]
    names: list[str]
    explicit: bool



def choose_candidates(setup: Setup, config: CalibrationConfig, frames_mode: str) -> Candidates:
    """Step 3: joint candidates (the convention's or the config's) and the frames' parameters."""
    robot = setup.space.robot
    requested = resolve_params(config.params, robot)
    joints = joint_candidates(robot) if requested is None else requested
    unknown = [n for n in joints if n not in setup.space.names]
    if unknown:
        raise InputError(f"unknown parameter '{unknown[0]}' for this {robot.convention} robot "
                         f"(known: {', '.join(setup.space.names[:8])}, …)", option="params")
    frames = frame_candidates(frames_mode, setup.meas.target_names, setup.full_pose) + \
        cameras.frame_names(robot, setup.meas)
    if frames_mode in ("base", "base+tool"):  # the sessions' own measuring frames
        from ...model.parameters import FRAME_AXES, session_prefix

        frames += [f"{session_prefix(label)}_{ax}" for label in setup.space.sessions for ax in FRAME_AXES]
    # a tree's joint carries its own branch alone: the gravity terms of another branch's links are no parameters
    parents = None if robot.tree is None else robot.tree.parents
    terms = [n for n in setup.space.terms.names(robot.n_joints) if not off_branch(n, parents)]
    # a named set (zeros, frames) is a choice of kind, not of parameters: what it offers that the data
    # cannot see is dropped as any default's would be
    explicit = requested is not None and config.params not in ("zeros", "frames")
    return Candidates(joints, joints + [n for n in frames + terms if n not in joints], explicit)


def _still_reasons(setup: Setup, ident: Identifiability, names: list[str],
                   prefer: list[str] = ()) -> tuple[Identifiability, np.ndarray | None]:
    """With joints that never moved, identifiability is judged with each held at its mean: a
    joint's read-back jitter of a few thousandths of a degree must not make its geometry look
    separable from the frames that absorb it (it would be fitted to the jitter).  Parameters
    kept on the data as measured but not when held still are dropped for that reason."""
    still = checks.still_joints(setup.meas)
    if not still:
        return ident, None
    probe = setup.with_measurements(checks.held_still(setup.meas)).problem(names)
    J = probe.residual_jacobian(np.zeros(probe.n_params))
    held = analyse(J, names, probe.angle_mask, setup.meas.n_poses, setup.space.robot.reach(), prefer=prefer)
    newly = [n for n in held.dropped if n in ident.kept]
    if not newly:
        return ident, J
    joints = tuple(i + 1 for i in still)
    reasons = {**held.reasons, **{n: Reason(STILL, held.reasons[n].related, coefficients=held.reasons[n].coefficients,
                                            joints=joints) for n in newly}}
    return held.with_changes(reasons=reasons), J


def _still_warning(ident: Identifiability) -> Identifiability:
    """The warning that names what the still joints dropped (after the prior kept what it can hold)."""
    newly = [n for n in ident.dropped if ident.reasons[n].kind == STILL]
    if not newly:
        return ident
    joints = ident.reasons[newly[0]].joints
    many = len(joints) > 1
    return ident.with_changes(warnings=ident.warnings + [
        f"joint{'s' if many else ''} {', '.join(map(str, joints))} never move{'' if many else 's'}: "
        f"{', '.join(newly)} dropped (absorbed by the frames and the other joints)"])


#: fewest poses at which a joint term's basis must differ from its most common value: with fewer,
#: the term is a constant offset (absorbed by the geometry) plus what one or two poses say
MIN_TERM_SUPPORT = 3


def term_support(basis: np.ndarray, groups: np.ndarray) -> tuple[int, int]:
    """(joint index, poses) of one term parameter's basis (m, n): the joint it acts on most, and
    how many poses (``groups``: pose index per row) hold a value other than its most common one."""
    joint = int(np.argmax(np.linalg.norm(basis, axis=0)))
    v = basis[:, joint]
    scale = float(np.max(np.abs(v))) or 1.0
    values, counts = np.unique(np.round(v / scale, 9), return_counts=True)
    mode = values[np.argmax(counts)]
    return joint, len(np.unique(groups[np.round(v / scale, 9) != mode]))


def unvaried_terms(setup: Setup, names: list[str]) -> dict[str, Reason]:
    """Joint terms among ``names`` whose input the poses did not vary, with the reason: a
    backlash from poses all approached one way (its column is the joint's offset, but for the
    pose whose direction is unknown), a drift over one time, any term whose column is constant
    but at a pose or two.  Numerically separable, such a term would be fitted to those few
    poses' noise and reported as if measured."""
    from ...model.terms import term_of

    space = setup.space
    terms = [n for n in names if is_term(n)]
    data = space.joint_data(setup.meas.q, setup.meas.inputs) if terms else None
    if data is None:
        return {}
    groups = np.unique(np.array(setup.meas.pose_ids if setup.meas.pose_ids is not None else
                                [str(r) for r in setup.meas.rows]), return_inverse=True)[1]
    order = list(space.terms.names(space.robot.n_joints))
    reasons = {}
    for name in terms:
        column = data.basis[:, :, order.index(name)]
        joint, support = term_support(column, groups)
        if support < MIN_TERM_SUPPORT:
            zero = not np.any(np.abs(column) > 1e-12 * max(1.0, float(np.abs(data.basis).max())))
            joint = int(re.match(r"[a-z]+(\d+)", name).group(1)) - 1 if zero else joint  # its own joint
            reasons[name] = Reason(UNVARIED, joints=(joint + 1,), detail=term_of(name).never(joint + 1, name) if zero
                                   else term_of(name).unvaried(joint + 1, support))
    return reasons


def _said_once(reasons: dict[str, Reason]) -> list[str]:
    """One line per reason: the parameters it drops named together (a joint's 54 gravity terms are one
    choice, not 54 faults)."""
    by_detail: dict[str, list[str]] = {}
    for name, r in reasons.items():
        by_detail.setdefault(r.detail, []).append(name)
    out = []
    for detail, names in by_detail.items():
        named = names[0] if len(names) == 1 else ", ".join(names) if len(names) <= 3 else \
            f"{names[0]} … {names[-1]} ({len(names)} terms)"
        out.append(f"{named} dropped: {detail}")
    return out


def gauge_names(setup: Setup) -> list[str]:
    """The base frame's parameters when every row touched an unknown point or plane: such data
    are the same in any frame (their points and planes move with it), so the parameters that
    only move the whole robot (θ1 and d1, a URDF's first origin) must be told from that motion
    and dropped; it is scanned first, then left out."""
    c = setup.meas.constraints
    return [] if c is None or not c.only else [n for n in setup.space.names if n.startswith("base_")]


def _without_gauge(setup: Setup, ident: Identifiability, gauge: list[str], names: list[str]) -> Identifiability:
    """The analysis with the base frame left out (said why), and, without a stated distance, the
    length scale fixed by the longest link (said why: points and planes see shapes, not sizes)."""
    if not gauge:
        return ident
    reasons = dict(ident.reasons)
    for n in gauge:
        reasons[n] = Reason(UNOBSERVABLE, detail="the frame the robot stands in: the rows touched points or planes "
                                                 "whose place is unknown, so any frame fits them alike")
    kept = [n for n in ident.kept if n not in gauge]
    said = []
    c = setup.meas.constraints
    if not c.distances:
        robot = setup.space.robot
        kinds = len(joint_kinds(robot.convention))
        lengths = [n for n in kept if setup.space.names.index(n) < setup.space.n_joint_params and not is_angle(n)]
        if lengths:
            value = {n: abs(float(robot.geometry.reshape(-1, robot.geometry.shape[1])[i // kinds, i % kinds]))
                     for n in lengths for i in [setup.space.names.index(n)]}
            longest = max(lengths, key=lambda n: value[n])
            reasons[longest] = Reason(UNOBSERVABLE, detail=(
                f"the length scale, held by {longest} at its nominal {value[longest]:.4g} mm: points and planes "
                "see the robot's shape, not its size; a known distance between two points (point_distance "
                "A,B=MM) or tracker rows make it visible"))
            kept.remove(longest)
            said.append(f"{longest} held at nominal: without a known distance the length scale is not observable "
                        "from points or planes")
    dropped = [n for n in names if n in reasons and n not in kept]
    return ident.with_changes(kept=kept, dropped=dropped, reasons=reasons, warnings=ident.warnings + said)


def _prior_held(setup: Setup, ident: Identifiability, J: np.ndarray, names: list[str]) -> Identifiability:
    """Camera rows: a parameter dependent on others is kept where it or the direction it shares with
    them has a prior, and the priors share out what the pixels cannot tell apart (the cell's scale
    above all: a pinhole sees directions, so every length trades against the others; and cameras on
    one link turn about a joint's axis together as that joint's offset does).  Dropping it would pin
    it where it started with no uncertainty: at its nominal value, or a camera at the pose its pixels
    first gave, whose error the others would then absorb.  A frame parameter whose dependence is on
    free frames alone is dropped as before: the frames absorb it.  ``J``: the data's Jacobian of
    ``names`` the analysis ran on."""
    if setup.prior is None:
        return ident
    index = {n: i for i, n in enumerate(setup.space.names)}
    finite = np.array([n in index and bool(np.isfinite(setup.prior[index[n]])) for n in names])
    norms = np.linalg.norm(J, axis=0)
    Jn = J / np.where(norms > 0, norms, 1.0)
    column = {n: i for i, n in enumerate(names)}
    kept = [column[n] for n in ident.kept]
    back = []
    for n, r in ident.reasons.items():
        if r.kind not in (DEPENDENT, STILL) or n not in column:
            continue
        c = np.linalg.lstsq(Jn[:, kept], Jn[:, column[n]], rcond=None)[0]
        shared = float(np.linalg.norm(c[finite[kept]]) / max(np.linalg.norm(c), 1e-300))
        if finite[column[n]] or shared > 1e-2:
            back.append(n)
            kept.append(column[n])
    if not back:
        return ident
    reasons = {n: r for n, r in ident.reasons.items() if n not in back}
    return ident.with_changes(kept=[n for n in names if n in set(ident.kept) | set(back)],
                              dropped=[n for n in ident.dropped if n not in back], reasons=reasons)


def analyse_identifiability(setup: Setup, candidates: Candidates) -> tuple[Identifiability, list[str]]:
    """Step 4: the identifiable subset at the initial robot; parameters that need the motion of a
    joint that never moved are dropped (see :func:`_still_reasons`)."""
    unvaried = unvaried_terms(setup, candidates.names)
    names = [n for n in candidates.names if n not in unvaried]
    gauge = gauge_names(setup)
    probe = setup.problem(gauge + names)
    J = probe.residual_jacobian(np.zeros(probe.n_params))
    if not np.all(np.isfinite(J)):  # a row the start cannot place (no analysis of NaN is an answer)
        row = int(np.argmax(~np.all(np.isfinite(J), axis=1))) // 3
        where = setup.meas.label(min(row, setup.meas.n_poses - 1))
        raise InputError(f"the rows give no derivative at the nominal robot ({where}): check its joints, the "
                         "robot file and, for camera rows, the camera's link and file", source=setup.meas.source)
    # sessions with measuring frames of their own keep each frame whole (a held-out session is registered
    # by all six of its frame's values): the shared joint offsets they trade with go instead
    first = gauge + ([n for n in names if n.startswith(("base_", "base["))] if setup.space.sessions else [])
    ident = analyse(J, gauge + names, probe.angle_mask, setup.meas.n_poses, setup.space.robot.reach(), prefer=first)
    ident, still = _still_reasons(setup, ident, gauge + names, first)
    if setup.meas.views is not None:  # on the Jacobian the analysis ended on: with still joints held still
        ident = _prior_held(setup, ident, J if still is None else still, gauge + names)
    ident = _without_gauge(setup, _still_warning(ident), gauge, candidates.names)
    if unvaried:
        reasons = {**ident.reasons, **unvaried}
        ident = ident.with_changes(dropped=[n for n in candidates.names if n in reasons], reasons=reasons,
                                   warnings=ident.warnings + _said_once(unvaried))
    notes = list(ident.warnings)
    if setup.prior is not None and np.any(np.isfinite(setup.prior[:setup.space.n_joint_params])):
        # the prior bounds what the poses leave open: the uncertainties are not large, they are the prior's
        notes = [n.replace("; expect large uncertainties", "; what they do not pin is held by its prior (named in "
                           "the parameters table)") if n.startswith("identification is ill-conditioned") else n
                 for n in notes]
    if candidates.explicit:
        bad = [n for n in candidates.joints if n in ident.reasons]
        if bad:
            notes.append(f"requested parameters not identifiable from these data, left at nominal: {', '.join(bad)}")
    if not ident.kept:
        raise InputError("no parameter is identifiable from these measurements", source=setup.meas.source)
    if probe.n_residuals < probe.n_params:
        notes.append(f"only {setup.meas.n_poses} poses ({probe.n_residuals} residuals) for {probe.n_params} "
                     f"candidate parameters: {len(ident.dropped)} dropped; measure more poses")
    return ident, notes


def searched_names(candidates: Candidates, ident: Identifiability) -> list[str]:
    """What a swarm searches: every geometric candidate that has any effect on the data (joint
    terms are left to LM, which hybrid runs after the swarm)."""
    return [n for n in candidates.names if not is_term(n)
            and (n not in ident.reasons or ident.reasons[n].kind not in (NO_EFFECT, STILL, UNVARIED))]




def refine_at_estimate(est: Estimate, ident: Identifiability, candidates: Candidates,
                       config: CalibrationConfig) -> tuple[Estimate, Identifiability]:
    """Step 7: re-check identifiability at the estimate; add what the data determine there.

    Identifiability is judged from the Jacobian at a linearisation point.  At the nominal
    model some dependencies hold only to first order: with parallel axes 2 ∥ 3 in standard
    DH, d2 and d3 have identical columns, but a robot whose α2 is off by δ separates them by
    an angle ~δ; a tool point off axis 6 by the deviation of a6 makes θ6 act.  The analysis
    is repeated at the estimate with the kept set offered first; parameters that became
    independent are added and LM continues, and the addition is accepted only if a
    nested-model F-test says the fit improved significantly (p < ADD_SIGNIFICANCE).
    """
    if not config.least_squares or est.optimization.status != "converged":
        return est, ident
    setup = est.problem.setup
    # judged with still joints held still: their parameters stay out whatever the estimate
    gauge = gauge_names(setup)
    probe = setup.with_measurements(checks.held_still(setup.meas)).problem(gauge + candidates.names)
    deviation = est.problem.full(est.x)
    again = analyse(probe.residual_jacobian(deviation[probe.active]), gauge + candidates.names, probe.angle_mask,
                    setup.meas.n_poses, setup.space.robot.reach(), prefer=gauge + ident.kept)
    added = [n for n in again.kept if n not in ident.kept and n not in gauge
             and ident.reasons[n].kind not in (STILL, UNVARIED, UNOBSERVABLE)]
    if not added:
        return est, ident
    names = ident.kept + added
    wider = setup.problem(names)
    dof = wider.n_values - len(names) - wider.n_nuisance
    # First the Gauss–Newton step from the estimate: the decrease of χ² it predicts is what the
    # refit would reach where the problem is near linear.  Far from significant, the refit
    # (LM crawling along a weakly separated valley, most of a calibration's time) cannot change
    # the verdict, and is not run.
    x0 = deviation[wider.active]
    r, J = wider.map_residuals(x0), wider.map_jacobian(x0)
    step = np.linalg.lstsq(J, -r, rcond=None)[0]
    p = f_test(float(r @ r), float(np.sum((r + J @ step) ** 2)), len(added), dof)
    lm = None
    if p < CLEARLY_NOT_SIGNIFICANT:
        # A parameter that separates only weakly makes LM crawl along a valley; the refit is a
        # test of whether the addition pays, so it gets a bounded budget.
        lm = fit_lm(wider, x0, config, max_nfev=REFIT_EVALUATIONS)
        p = f_test(est.optimization.fun, lm.fun, len(added), dof)
    if lm is None or lm.status != "converged" or p >= ADD_SIGNIFICANCE:
        second = {n: Reason(SECOND_ORDER, ident.reasons[n].related, p, ident.reasons[n].coefficients) for n in added}
        reasons = {**ident.reasons, **second}
        return est, ident.with_changes(reasons=reasons)
    final = analyse(wider.residual_jacobian(lm.x), names, wider.angle_mask, setup.meas.n_poses,
                    setup.space.robot.reach(), prefer=names)
    kept = [n for n in candidates.names if n in set(names)]
    refined = Identifiability(
        kept=kept, dropped=[n for n in candidates.names if n not in set(names)],
        reasons={n: r for n, r in ident.reasons.items() if n not in added},
        singular_values=final.singular_values, condition=final.condition, observability=final.observability,
        length_scale=final.length_scale, n_poses=final.n_poses,
        warnings=final.warnings + [f"{', '.join(added)} identifiable only away from the nominal model (added after "
                                   f"the first fit, F-test p={p:.2g}); expect large uncertainties"],
    )
    merged = est.optimization.then(lm, method=est.optimization.method, extra={"added_at_estimate": added},
                                   message=f"{est.optimization.message}; refit adding {', '.join(added)}: "
                                           f"{lm.message}")
    order = [names.index(n) for n in kept]
    return Estimate(setup.problem(kept), merged, lm.x[order], est.reexpression_gap_mm), refined
