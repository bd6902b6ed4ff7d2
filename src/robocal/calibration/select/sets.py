"""The parameters a calibration from camera rows estimates, chosen by held-out data (``--params auto``).

Pixels see a robot's joint geometry weakly, and through everything a camera calibration leaves
out: the lens beyond its calibration, the detector's bias, the markers' mounting, what changes
between sessions.  Twelve markers of one pose share all of that.  A model of every joint
parameter fitted to such rows buys misfit with geometry: it fits the calibration's own sessions
and predicts the next one worse than a model that moves less.  So the sets are compared as
``--model auto`` compares terms (:func:`robocal.calibration.select.choice.choose`):

1. ``frames``: the cameras' poses (and the markers' where their offsets are not given), the joints
   as the robot file has them;
2. ``zeros``: and each joint's zero (the joint's offset: θ, or d where it slides);
3. ``all``: and every joint parameter (each held by its prior where the pixels do not pin it).

Each is fitted and held out by the data's cross-validation scheme (whole sessions where the rows
name several, :mod:`robocal.calibration.select.crossval`), and the simplest that predicts the held-out
rows as well as the best is kept: a richer set must beat it by the paired test, session by session.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ...exceptions import InputError, Note
from ..config import CalibrationConfig
from ..fit.parametric import Fit, fit_parametric, term_spec
from ..inputs import Inputs
from ..result import LadderRow
from .choice import Candidate, choose
from .crossval import CrossValidation, cross_validate, held_groups

#: the sets compared, simplest first
SETS = ("frames", "zeros", "all")
#: a simpler set is kept where the paired test cannot tell it worse than the best at this level: one
#: standard error of the difference (the one-standard-error rule of cross-validation).  A few
#: sessions make a weak test; at the 1 % of ``--model auto`` the frames alone would win wherever the
#: sessions are few, and a robot whose zeros are off by a degree would keep them
SET_SIGNIFICANCE = 0.16
#: what each set holds, for the notes
MEANING = {"frames": "the cameras' and markers' frames alone", "zeros": "the frames and each joint's zero",
           "all": "the frames and every joint parameter"}


@dataclass
class SetChoice:
    """The set kept (``name``), the config that asks for it, its fit and held-out errors, the
    rows of the comparison and what was said."""

    name: str
    config: CalibrationConfig
    fit: Fit
    cv: CrossValidation
    rows: list[LadderRow]
    notes: list[str]


def offered(inputs: Inputs, config: CalibrationConfig) -> bool:
    """Whether the set is chosen by held-out data: every row a camera's, the parameters not
    named (``--params auto``), and a least-squares fit (a swarm searches what it is given)."""
    return inputs.meas.unit == "px" and config.params is None and config.least_squares


def choose_set(inputs: Inputs, config: CalibrationConfig, progress=None, say=None) -> SetChoice:
    """Fit each set of :data:`SETS` and keep the simplest that predicts held-out data as well as
    the best (:func:`robocal.calibration.select.choice.choose`, paired by session where there are several)."""
    say = say or (lambda step, steps, text: None)
    fitted: list[tuple[str, Candidate, CrossValidation]] = []
    for step, name in enumerate(SETS):
        say(step, len(SETS), f"parameters {step + 1}/{len(SETS)}: {name}, fit and held-out folds")
        cfg = replace(config, params=name)
        try:
            fit = fit_parametric(inputs, cfg, term_spec((), inputs.meas, cfg), progress if name == "all" else None)
        except InputError:
            if name == "frames":  # nothing to estimate but joints (every camera and marker known)
                continue
            raise
        cv = cross_validate(fit, cfg)
        fitted.append((name, Candidate((), "", fit, cv.errors), cv))
    kept = choose([c for _, c, _ in fitted], held_groups(inputs.meas), SET_SIGNIFICANCE)
    name, _, cv = next(f for f in fitted if f[1] is kept)
    rows = [LadderRow(n, c.cv_rms, c.fit.n_params) for n, c, _ in fitted]
    unit = inputs.meas.unit
    others = "; ".join(f"{n} {c.cv_rms:.4g} {unit}" for n, c, _ in fitted if c is not kept)
    notes = [Note(f"parameters auto: {name}, {MEANING[name]} (reprojection RMS {kept.cv_rms:.4g} {unit} predicted "
                  f"on {cv.scheme.new}, {cv.scheme.phrase}; {others}): a richer set is kept only if it predicts "
                  f"held-out data better by more than its standard error; --params all estimates every joint "
                  "parameter")]
    return SetChoice(name, replace(config, params=name), kept.fit, cv, rows, notes)
