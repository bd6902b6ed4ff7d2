"""The kinds of rows a calibration fits, each one residual block (MODEL §2, §9, §10, §11).

Every row of the data is one kind of observation of a point the model predicts (along its chain's
path, for a tree):

- :class:`TrackerRows`: a measured point, mm: measured less predicted;
- :class:`ContactRows`: a point or plane a probe touched, mm: the row's offset from the best fit of
  its group (:mod:`robocal.model.constraints`);
- :class:`CameraRows`: a camera's pixel, px: measured less projected (:mod:`robocal.model.views`).

Beside the rows' points, full-pose rows observe an orientation (:class:`Orientations`, rad),
bodies of known shape their markers' offsets (:class:`ShapeBodies`, mm), stated distances the
distance between two groups' points (:class:`Distances`, mm), and the prior one pseudo-observation
of each parameter it holds (:class:`PriorRows`, in the parameter's units).

Each block knows its rows, its unit and σ, its errors and their derivative with respect to the
estimated parameters, from one evaluation of the model at every row (:class:`Evaluation`: the
predicted points and orientations, the Jacobian columns, the cameras' frames).  The problem
(:mod:`robocal.calibration.fit.problem`) stacks them into one whitened residual vector: first the
rows' points, three values a row in the data's order (a pixel fills two; its third stays zero, so
that every statistic of the point rows keeps one layout: :attr:`CameraRows.values` says two), then
orientations, shapes and distances, and, for the MAP fit, the prior.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...math.so3 import apply_right_jacobian_inv, orientation_error


@dataclass
class Evaluation:
    """The model at every row for parameter vectors X (…, k): points p (…, m, 3) mm, orientations
    R (…, m, 3, 3) or None; with the Jacobian, its columns J (k, m, 6) (position mm, rotation rad);
    for camera rows each row's camera frame (…, m, 4, 4) and, with the Jacobian, its columns Jf."""

    X: np.ndarray
    p: np.ndarray
    R: np.ndarray | None = None
    J: np.ndarray | None = None
    frames: np.ndarray | None = None
    Jf: np.ndarray | None = None


class TrackerRows:
    """Measured points (mm): the rows no other point block claims."""

    kind, unit, values = "tracker", "mm", 3

    def __init__(self, measured: np.ndarray):
        self.measured = measured

    def errors(self, at: Evaluation) -> np.ndarray:
        return self.measured - at.p

    def jacobian(self, at: Evaluation) -> np.ndarray:
        return -at.J[:, :, :3]


class ContactRows:
    """Rows that touched an unknown point or plane (mm): each row's offset from its group's fit."""

    kind, unit, values = "contact", "mm", 3

    def __init__(self, constraints):
        self.constraints = constraints
        self.rows, self.only = constraints.rows, constraints.only

    def errors(self, at: Evaluation) -> np.ndarray:
        return self.constraints.errors(at.p)

    def jacobian(self, at: Evaluation) -> np.ndarray:
        return self.constraints.error_jacobian(at.J[:, :, :3], at.p)


class CameraRows:
    """Rows a camera saw (px): measured less projected pixel, in a row's first two slots."""

    kind, unit, values = "camera", "px", 2
    needs_frames = True

    def __init__(self, views):
        self.views = views
        self.rows, self.only = views.rows, views.only

    def errors(self, at: Evaluation) -> np.ndarray:
        return self.views.errors(at.p, at.frames)

    def jacobian(self, at: Evaluation) -> np.ndarray:
        return self.views.error_jacobian(at.J[:, :, :3], at.Jf, at.p, at.frames)


def point_errors(blocks: list, at: Evaluation) -> np.ndarray:
    """The rows' point errors (…, m, 3), each row its block's (the tracker's where none claims it)."""
    out = blocks[0].errors(at)
    for block in blocks[1:]:
        out = np.where(block.rows[:, None], block.errors(at), out)
    return out


def point_jacobian(blocks: list, at: Evaluation) -> np.ndarray:
    """∂(point errors)/∂x (k, m, 3), each row its block's."""
    out = blocks[0].jacobian(at)
    for block in blocks[1:]:
        out = block.jacobian(at) if block.only else np.where(block.rows[None, :, None], block.jacobian(at), out)
    return out


class Orientations:
    """Measured orientations of full-pose rows (rad): the rotation taking the predicted to the
    measured, as a rotation vector about the measuring frame's axes, whitened by σr (per row where
    the instrument states it)."""

    kind, unit = "orientation", "rad"

    def __init__(self, measured: np.ndarray, weight, backend: str):
        self.measured, self.weight, self.backend = measured, weight, backend
        self.n = 3 * len(measured)

    def errors(self, at: Evaluation) -> np.ndarray:
        return orientation_error(self.measured, at.R)

    def residuals(self, at: Evaluation) -> np.ndarray:
        return self.weight * self.errors(at).ravel()

    def jacobian(self, at: Evaluation) -> np.ndarray:
        dr = orientation_error(self.measured, at.R)
        w = np.ascontiguousarray(at.J[:, :, 3:])
        if self.backend == "numba":  # this kernel is convention-free
            from ...backend import run_kernel
            from ...model import kernels

            Jr = run_kernel(kernels.apply_right_jacobian_inv, kernels.apply_right_jacobian_inv_parallel,
                            w.size // 3, dr, w)
        else:
            Jr = apply_right_jacobian_inv(dr, w)
        return -self.weight * Jr.reshape(len(Jr), -1)


class ShapeBodies:
    """Markers of a body of known shape (mm): each marker's offset from the shape placed where it
    fits them best (:mod:`robocal.model.shapes`), whitened by their σ."""

    kind, unit = "shape", "mm"

    def __init__(self, shapes, sigma: float):
        self.shapes, self.sigma = shapes, sigma
        self.n = shapes.n_values

    def errors(self, at: Evaluation) -> np.ndarray:
        return self.shapes.residuals(at.X)

    def residuals(self, at: Evaluation) -> np.ndarray:
        return self.errors(at) / self.sigma

    def jacobian(self, at: Evaluation) -> np.ndarray:
        return self.shapes.jacobian(at.X, at.J.shape[0])


class Distances:
    """Stated distances between the points of two groups (mm), whitened by their σ."""

    kind, unit = "distance", "mm"

    def __init__(self, constraints):
        self.constraints, self.sigma = constraints, constraints.distance_sigma
        self.n = len(constraints.distances)

    def errors(self, at: Evaluation) -> np.ndarray:
        return self.constraints.distance_residuals(at.p)

    def residuals(self, at: Evaluation) -> np.ndarray:
        return self.errors(at) / self.sigma

    def jacobian(self, at: Evaluation) -> np.ndarray:
        return self.constraints.distance_jacobian(at.J[:, :, :3], at.p) / self.sigma


class PriorRows:
    """The prior: one pseudo-observation x_i/σ_i of each estimated parameter it holds (its mean is
    the nominal model, zero deviation); none where a parameter is free."""

    kind, unit = "prior", "parameter"

    def __init__(self, sigma: np.ndarray):
        self.sigma = sigma
        finite = np.isfinite(sigma)
        self.weight = np.where(finite, 1.0 / np.where(finite, sigma, 1.0), 0.0)
        self.rows = np.flatnonzero(self.weight > 0)
        self.n = len(self.rows)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.weight[self.rows] * np.asarray(x)[self.rows]

    def jacobian(self, k: int) -> np.ndarray:
        P = np.zeros((self.n, k))
        P[np.arange(self.n), self.rows] = self.weight[self.rows]
        return P
