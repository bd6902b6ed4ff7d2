"""Residuals and objectives of a calibration, batched over candidate solutions.

A :class:`Setup` ties a parameter space (around the initial robot), the measurements and
the noise weighting; :meth:`Setup.problem` gives the :class:`Problem` of one set of
estimated parameters.  A problem's vector ``x`` holds the estimated deviations only (mm,
rad); everything else stays at the initial robot.

Least squares works on whitened residuals: every position component divided by the
position noise σp (mm), every orientation component by the orientation noise σr (rad),
so that the sum of squares is χ² and the Jacobian gives the covariance directly.  Each kind
of row is one residual block (:mod:`robocal.calibration.fit.blocks`: tracker, contact and
camera rows' points, orientations, shapes, distances, the prior); the problem evaluates the
model once at every row, along each row's chain for a tree, and stacks the blocks.

Swarm objectives (MODEL §2), all evaluated for a whole swarm (P, k) in one batched call:

- ``sum_squares``: Wen et al. (2019) eq. 7, Σ_j k·|δ_j|² + |δp_j|² in mm², with the
  orientation weight k = (σp/σr)² mm²/rad² (position-only data reduce it to Σ|δp_j|²):
  σp² χ², so the swarms and least squares minimise the same thing.
- ``sum_norms``: Kou et al. (2022) eq. 4, Σ_j |δp_j| (mm).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ...backend import run_kernel
from ...math.so3 import orientation_error
from ...model.compiled import resolve
from ...model.kinematics import joint_kinds
from ...model.measurements import Measurements
from ...model.parameters import ParameterSpace, is_angle
from .blocks import (
    CameraRows,
    ContactRows,
    Distances,
    Evaluation,
    Orientations,
    PriorRows,
    ShapeBodies,
    TrackerRows,
    point_errors,
    point_jacobian,
)

if TYPE_CHECKING:
    from ...model.prior import Prior
    from ...model.shared import SharedErrors
    from .instrument import InstrumentWeights

#: default orientation weight k of the pose objective, mm²/rad², when no noise is stated: 1 rad
#: counts as 100 mm, so 0.01° weighs like 0.017 mm, about the ratio of a laser tracker's
#: position noise to its 6-DOF probe's orientation noise.  Wen et al. (2019) do not give k.
DEFAULT_K = 1.0e4
#: evaluations with the Jacobian a setup and those made from it keep (a hundred thousand full poses'
#: columns take about 120 MB each)
KEEP_EVALUATIONS = 2


class Kept(dict):
    """The evaluations a setup keeps (:attr:`Setup.evaluated`): a cache, so a setup sent to a
    worker process (``auto``'s pieces) travels without it."""

    def __reduce__(self):
        return (Kept, ())


@dataclass(frozen=True, eq=False)
class Setup:
    """What every problem of one calibration shares: space, measurements, noise weighting.

    sigma_position (mm) and sigma_orientation (rad): the standard deviation per axis that
    whitens each residual block; use_orientation: fit orientations when the data have them;
    backend: ``auto``, ``numba`` or ``numpy`` for swarm objectives.  instrument: per-point
    weight factors from the instrument's σ of each measured value (see
    :mod:`robocal.calibration.fit.instrument`), None to weigh every point of a block alike.
    prior: the prior σ of every parameter of the space (its own units; inf where free, see
    :mod:`robocal.model.prior`), or None for plain least squares.
    """

    space: ParameterSpace
    meas: Measurements
    sigma_position: float = 1.0
    sigma_orientation: float = 1.0 / DEFAULT_K**0.5
    use_orientation: bool = True
    backend: str = "auto"
    instrument: InstrumentWeights | None = None
    prior: np.ndarray | None = None
    #: camera rows: the error a pose's rows in one camera share (:mod:`robocal.model.shared`)
    shared: SharedErrors | None = None
    #: the prior kinds whose width the data sized, and that width (file units: mm, deg;
    #: :mod:`robocal.calibration.fit.widths`)
    sized: Mapping[str, float] = field(default_factory=dict)
    #: the model and its Jacobian columns at the last few solutions, shared by the setups made from
    #: this one (another noise, prior or width: the model's own Jacobian is theirs too; a setup of
    #: other measurements or another space is told apart by identity): the statistics after a fit
    #: ask for it at the estimate under several weightings (:meth:`Problem.evaluate`)
    evaluated: Kept = field(default_factory=Kept, repr=False, compare=False)

    @property
    def full_pose(self) -> bool:
        return self.use_orientation and self.meas.full_pose

    @property
    def k(self) -> float:
        """Orientation weight of the pose objective, (σp/σr)² mm²/rad²."""
        return (self.sigma_position / self.sigma_orientation) ** 2

    def problem(self, names: Sequence[str]) -> Problem:
        return Problem(self, self.space.index(list(names)))

    def with_measurements(self, meas: Measurements) -> Setup:
        return replace(self, meas=meas)

    def with_noise(self, sigma_position: float, sigma_orientation: float) -> Setup:
        return replace(self, sigma_position=sigma_position, sigma_orientation=sigma_orientation)

    def with_prior(self, prior: Prior | None) -> Setup:
        """The same setup with ``prior``'s σ for every parameter of its space (None: none).  A
        compliance's width is a deflection at the data's load: divided by the RMS over these
        poses of its basis, so that a fold of them keeps the whole data's σ."""
        if prior is None:
            return replace(self, prior=None)
        space = self.space
        load = {}
        joints = space.joint_data(self.meas.q, self.meas.inputs) if space.n_term_params else None
        if joints is not None:
            rms = np.sqrt(np.mean(np.sum(joints.basis ** 2, axis=1), axis=0))
            load = dict(zip(space.terms.names(space.robot.n_joints), rms))
        return replace(self, prior=prior.sigmas(space.names, space.robot.prismatic, load))

    def around(self, robot) -> Setup:
        """The same setup with the parameter space around another robot (e.g. the estimate)."""
        return replace(self, space=replace(self.space, robot=robot))


def warm_up(backend: str, full_pose: bool) -> float:
    """Compile (or load from numba's cache) the kernel the full-pose Jacobian uses before any
    fit, registration included, so that no optimizer's time includes it; returns the seconds
    spent (a first run after install compiles, about 1 s; later runs load, milliseconds).  Only
    when the run will use it.  The serial kernel is the one loaded: it starts no OpenMP layer,
    which would make a later fork of this process (the study's and the ladder's workers) abort."""
    import time

    if not full_pose or resolve(backend) != "numba":
        return 0.0
    start = time.perf_counter()
    from ...model import kernels

    kernels.apply_right_jacobian_inv(np.zeros((1, 3)), np.zeros((1, 1, 3)))
    return time.perf_counter() - start


class Problem:
    """Residuals, Jacobian and swarm objectives of one set of estimated parameters."""

    def __init__(self, setup: Setup, active: np.ndarray):
        self.setup = setup
        self.space = setup.space
        self.meas = setup.meas
        self.active = np.asarray(active, dtype=int)
        self.k = setup.k
        self._wp, self._wr = 1.0 / setup.sigma_position, 1.0 / setup.sigma_orientation
        self.uses_orientation = setup.full_pose
        # per-point factors σ_eff,i/σ̄_eff of each residual (m, 3), or None: every point alike
        self._fp, self._fr = setup.instrument.factors(self.meas) if setup.instrument is not None else (None, None)
        if self._fp is not None:
            self._wp = self._wp / self._fp.ravel()
        if self._fr is not None and self.uses_orientation:
            self._wr = self._wr / self._fr.ravel()
        self.target_idx = self.space.target_index(self.meas.targets)
        self.joints = self.space.joint_data(self.meas.q, self.meas.inputs)
        self._Rm = self.meas.rotation if self.uses_orientation else None
        # rows that touched an unknown point or plane, and stated distances (robocal.model.constraints)
        self.constraints = self.meas.constraints
        # rows a camera saw: pixels in the position slots (robocal.model.views)
        self.views = self.meas.views
        # each camera row's camera in the space's order (the views' own follows the files)
        self._camera_index = None if self.views is None else self.views.indices(self.space.cameras)
        # each row's session where sessions have measuring frames of their own (None: one frame)
        self._session = self.space.session_index(self.meas.session)
        # each row's chain of a tree (None: a serial chain)
        tree = self.space.robot.tree
        self.chain_index = None if tree is None else tree.index(self.meas.chain)
        # the whitening of what a pose's camera rows share (None: every row its own look)
        self._shared = None if setup.shared is None or self.views is None else setup.shared.transform(self.meas)
        self._shapes = self._shape_bodies()
        self._frames_active = bool(np.any(self.active >= self.space.n_joint_params))
        self._backend = resolve(setup.backend)  # read once: ROBOCAL_NO_NUMBA as it is when the problem is set up
        # the residual blocks (robocal.calibration.fit.blocks): each kind of row's points, then the rest
        self.point_blocks = [TrackerRows(self.meas.position)] + \
            ([] if self.constraints is None else [ContactRows(self.constraints)]) + \
            ([] if self.views is None else [CameraRows(self.views)])
        self.blocks = ([] if self._Rm is None else [Orientations(self._Rm, self._wr, self._backend)]) + \
            ([] if self._shapes is None else [ShapeBodies(self._shapes, self.meas.shape_sigma)]) + \
            ([] if self.n_distances == 0 else [Distances(self.constraints)])
        # the prior: one pseudo-observation x_i/σ_i of each estimated parameter (none where free)
        self.prior_sigma = np.full(len(self.active), np.inf) if setup.prior is None else setup.prior[self.active]
        self.prior = PriorRows(self.prior_sigma)

    @property
    def names(self) -> list[str]:
        return [self.space.names[i] for i in self.active]

    @property
    def angle_mask(self) -> np.ndarray:
        return np.array([is_angle(n) for n in self.names])

    @property
    def n_params(self) -> int:
        return len(self.active)

    @property
    def n_residuals(self) -> int:
        return self.meas.n_poses * (6 if self.uses_orientation else 3) + self.n_shapes + self.n_distances

    @property
    def n_prior(self) -> int:
        """Pseudo-observations of the prior: one per estimated parameter that is not free."""
        return self.prior.n

    @property
    def has_prior(self) -> bool:
        return self.n_prior > 0

    @property
    def n_values(self) -> float:
        """The data's values: three per measured point or point row, one per plane row (its
        offset along the plane's normal is all it says), three per orientation, one per stated
        distance; the eliminated points and planes are counted apart (:attr:`n_nuisance`)."""
        planes = 0 if self.constraints is None else int(self.constraints.rows_of("plane").sum())
        pixels = 0 if self.views is None else int(self.views.rows.sum())  # u, v: two values
        placed = 0 if self._shapes is None else self._shapes.n_placements  # a body's place: what it fits
        return self.n_residuals - 2 * planes - pixels - placed

    @property
    def n_shapes(self) -> int:
        """Rows that hold markers of known shape to it (:mod:`robocal.model.shapes`): three per marker."""
        return 0 if self._shapes is None else self._shapes.n_values

    def _shape_bodies(self):
        """The bodies of markers of known shape among this problem's targets (None: none)."""
        if not self.meas.shapes:
            return None
        from ...model.parameters import tool_prefix
        from ...model.shapes import Shapes

        where = {n: i for i, n in enumerate(self.active)}
        lookup = {n: i for i, n in enumerate(self.space.names)}
        return Shapes.of(self.meas.shapes, self.space.targets, self.space.nominal_tools()[:, :3, 3],
                         lambda t: [where.get(lookup.get(f"{tool_prefix(t)}_{ax}"), -1) for ax in "xyz"],
                         self.meas.shape_sigma)

    def shape_residuals(self, X: np.ndarray) -> np.ndarray:
        """(…, S) mm: each marker of a known shape off that shape placed where it fits them best."""
        return self._shapes.residuals(X)

    @property
    def n_distances(self) -> int:
        return 0 if self.constraints is None else len(self.constraints.distances)

    @property
    def n_nuisance(self) -> int:
        """The data's values the eliminated points and planes use (they count as parameters in
        every degrees-of-freedom sum)."""
        return 0 if self.constraints is None else self.constraints.n_unknowns

    def full(self, x: np.ndarray) -> np.ndarray:
        """Estimated deviations (…, k_active) → full deviation vector (…, k_space)."""
        x = np.asarray(x, dtype=float)
        out = np.zeros(x.shape[:-1] + (self.space.size,))
        out[..., self.active] = x
        return out

    def points(self, X: np.ndarray) -> np.ndarray:
        """The measured points (…, m, 3) mm the model predicts for parameter vectors X (…, k)."""
        return self.space.points(self.full(X), self.meas.q, self.target_idx, self.joints, self._session,
                                 self.chain_index)

    def pose(self, X: np.ndarray):
        """End rotations (…, m, 3, 3) and points (…, m, 3) mm the model predicts for X (…, k)."""
        return self.space.pose(self.full(X), self.meas.q, self.target_idx, self.joints, self._session,
                               self.chain_index)

    def evaluate(self, X: np.ndarray, jacobian: bool = False) -> Evaluation:
        """The model at every row for X (…, k) (one solution (k,) with ``jacobian``): what every
        residual block reads (:class:`~robocal.calibration.fit.blocks.Evaluation`)."""
        full = self.full(X)
        if jacobian:
            key = (id(self.space), id(self.meas), self.active.tobytes(), np.asarray(X, float).tobytes())
            kept = self.setup.evaluated.get(key)
            if kept is not None and kept[0] is self.space and kept[1] is self.meas:
                return kept[2]
            J, R, p = self.space.jacobian_columns(full, self.meas.q, self.target_idx, frames=self._frames_active,
                                                  joints=self.joints, active=self.active,
                                                  session=self._session, chain=self.chain_index)  # (k, m, 6)
            at = Evaluation(np.array(X, float), p, R, J)  # its own copy: it is kept
            if self.views is not None:
                at.frames, at.Jf = self.space.camera_frame_columns(full, self.meas.q, self._camera_index, self.joints,
                                                                   active=self.active)
            kept = self.setup.evaluated
            while len(kept) >= KEEP_EVALUATIONS:  # the oldest first: a dict keeps its order
                kept.pop(next(iter(kept)))
            kept[key] = (self.space, self.meas, at)  # the objects held: their ids stay theirs
            return at
        R, p = (None, self.points(X)) if self._Rm is None else self.pose(X)
        at = Evaluation(np.asarray(X, float), p, R)
        if self.views is not None:
            at.frames = self.space.camera_frames(full, self.meas.q, self._camera_index, self.joints)
        return at

    def errors(self, X: np.ndarray):
        """Errors of each row's point (…, m, 3): mm, px for a camera's row (its blocks'); and
        orientation errors (…, m, 3) rad (or None)."""
        at = self.evaluate(X)
        return point_errors(self.point_blocks, at), None if self._Rm is None else orientation_error(self._Rm, at.R)

    def scaled_errors(self, X: np.ndarray):
        """:meth:`errors` divided by each point's weight factor (the instrument's, relative):
        still mm and rad, and the same as :meth:`errors` where every point is weighed alike."""
        dp, dr = self.errors(X)
        dp = self._decorrelated(dp)
        if self._fp is not None:
            dp = dp / self._fp
        if dr is not None and self._fr is not None:
            dr = dr / self._fr
        return dp, dr

    def _decorrelated(self, values: np.ndarray) -> np.ndarray:
        """Position-slot values (…, m, 3) with what a pose's camera rows share whitened (see
        :mod:`robocal.model.shared`); as they are without it."""
        if self._shared is None:
            return values
        from ...model.shared import decorrelate

        return decorrelate(self._shared, values)

    def objective(self, X: np.ndarray, kind: str = "sum_squares", *, backend: str | None = None) -> np.ndarray:
        """Objective of each candidate in X (P, k_active) → (P,); mm² or mm.

        backend: overrides the setup's; both backends give the same numbers.
        """
        if kind not in ("sum_squares", "sum_norms"):
            raise ValueError(f"unknown objective {kind!r}")
        X = np.asarray(X, dtype=float)
        compiled = (self._backend if backend is None else resolve(backend)) == "numba"
        if X.ndim == 2 and compiled and self.joints is None and self._kernels_apply and self._fp is None \
                and self._fr is None and self.constraints is None and self.views is None and self._session is None \
                and self.chain_index is None:
            # the kernels move no joints, weigh every point alike and know measured points only
            return self._compiled_objective(X, kind)
        dp, dr = self.scaled_errors(X)
        if kind == "sum_norms":
            return np.sqrt(np.sum(dp * dp, axis=-1)).sum(-1)
        f = np.sum(dp * dp, axis=(-1, -2))
        if dr is not None:
            f = f + self.k * np.sum(dr * dr, axis=(-1, -2))
        if self.n_shapes:  # in the objective's units², weighed as χ² weighs them against σp
            ds = self.shape_residuals(X) * (self.setup.sigma_position / self.meas.shape_sigma)
            f = f + np.sum(ds * ds, axis=-1)
        if self.n_distances:  # in the objective's mm², weighed as χ² weighs them against σp
            p = self.points(X)
            dd = self.constraints.distance_residuals(p) * (self.setup.sigma_position / self.constraints.distance_sigma)
            f = f + np.sum(dd * dd, axis=-1)
        return f

    @cached_property
    def _kernels_apply(self) -> bool:
        """The compiled kernels chain turning DH-family joints; others take the numpy path."""
        from ...model.kernels import CONVENTION_CODE

        robot = self.space.robot
        return robot.convention in CONVENTION_CODE and not robot.prismatic.any()

    @cached_property
    def _kernel_inputs(self):
        from ...model import kernels

        m = self.meas.n_poses
        kinds = len(joint_kinds(self.space.robot.convention))
        tidx = np.zeros(m, dtype=np.int64) if self.target_idx is None else self.target_idx.astype(np.int64)
        _, base, tools = self.space.expand(np.zeros(self.space.size))
        return {
            "base": base,
            "tools": tools,
            "kernels": kernels,
            "conv": kernels.CONVENTION_CODE[self.space.robot.convention],
            # positions of the estimated joint parameters in the flat (n, width) geometry
            "geom_cols": ((self.active // kinds) * self.space.robot.geometry.shape[1]
                          + self.active % kinds).astype(np.int64),
            "qtrig": kernels.joint_trig(self.meas.q),
            "tidx": tidx,
            # numba compiles one specialisation per array layout: contiguous inputs always, so that
            # a view (rotations sliced from 4×4 poses) does not compile a second kernel mid-run
            "Rm": np.ascontiguousarray(self._Rm) if self._Rm is not None else np.zeros((1, 3, 3)),
            "pm": np.ascontiguousarray(self.meas.position),
        }

    def _compiled_objective(self, X: np.ndarray, kind: str) -> np.ndarray:
        c = self._kernel_inputs
        kernels = c["kernels"]
        common = (c["qtrig"], c["tidx"], c["pm"], c["Rm"], self._Rm is not None, self.k,
                  0 if kind == "sum_squares" else 1)
        work = len(X) * self.meas.n_poses
        if not self._frames_active:
            # each particle adds its joint deviations to the nominal geometry inside the kernel
            return run_kernel(kernels.objective_joints, kernels.objective_joints_parallel, work, c["conv"],
                              self.space.robot.geometry, c["geom_cols"], X, c["base"], c["tools"], *common)
        geom, base, tools = self.space.expand(self.full(X))
        return run_kernel(kernels.objective, kernels.objective_parallel, work, c["conv"], geom, base, tools, *common)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Whitened residual vector of one solution (k_active,), its squared norm χ²: the rows'
        points [δp/σp (3m)], then each further block's (orientations δ/σr (3m), shapes, distances)."""
        at = self.evaluate(x)
        out = [self._wp * self._decorrelated(point_errors(self.point_blocks, at)).ravel()]
        out += [block.residuals(at) for block in self.blocks]
        return out[0] if len(out) == 1 else np.concatenate(out)

    def n_position_rows(self) -> int:
        """The residual vector's first rows that are positions; then orientations (full-pose
        data), then stated distances (already whitened by their own σ)."""
        return 3 * self.meas.n_poses

    def n_orientation_rows(self) -> int:
        return 3 * self.meas.n_poses if self._Rm is not None else 0

    def residual_jacobian(self, x: np.ndarray) -> np.ndarray:
        """Exact ∂(whitened residuals)/∂x, (n_residuals, k_active), Fortran-ordered as MINPACK wants:
        each block's rows where :meth:`residuals` puts them.  The last one is kept: the statistics
        after a fit ask for it at the estimate again (a copy is returned, a solver may scale it)."""
        return self._jacobian_at(x).copy(order="F")

    def _jacobian_at(self, x: np.ndarray) -> np.ndarray:
        """The kept Jacobian at x (computed where it is another x): not to be written to."""
        key = np.asarray(x, float).tobytes()
        last = self.__dict__.get("_last_jacobian")
        if last is None or last[0] != key:
            last = self.__dict__["_last_jacobian"] = (key, self._residual_jacobian(x))
        return last[1]

    def _residual_jacobian(self, x: np.ndarray) -> np.ndarray:
        at = self.evaluate(x, jacobian=True)
        k, m = at.J.shape[0], at.J.shape[1]
        out = np.empty((k, self.n_residuals))
        out[:, : 3 * m] = self._wp * self._decorrelated(point_jacobian(self.point_blocks, at)).reshape(k, 3 * m)
        start = 3 * m
        for block in self.blocks:
            out[:, start:start + block.n] = block.jacobian(at)
            start += block.n
        return out.T

    def prior_information(self) -> np.ndarray:
        """The prior's information (k, k): diag(1/σ²), zero where free."""
        return np.diag(self.prior.weight ** 2)

    def map_residuals(self, x: np.ndarray) -> np.ndarray:
        """What least squares minimises: the whitened data residuals (:meth:`residuals`), then
        the prior's pseudo-observations x_i/σ_i (MAP; the deviations' prior mean is the nominal
        model, zero).  Without a prior, :meth:`residuals` itself."""
        r = self.residuals(x)
        if not self.has_prior:
            return r
        return np.concatenate([r, self.prior.residuals(x)])

    def map_jacobian(self, x: np.ndarray) -> np.ndarray:
        """∂(:meth:`map_residuals`)/∂x: the data's rows, then one row per prior (1/σ_i at i)."""
        if not self.has_prior:
            return self.residual_jacobian(x)
        J, P = self._jacobian_at(x), self.prior.jacobian(self.n_params)
        out = np.empty((J.shape[0] + P.shape[0], J.shape[1]), order="F")  # one copy, in MINPACK's order
        out[:J.shape[0]], out[J.shape[0]:] = J, P
        return out
