"""Rows a camera saw: a marker's pixel in one camera's image (MODEL §10).

A camera row says that the marker (a point on the tool: the row's target) was seen at the pixel
(u, v) by the camera named in the row.  Its error is the measured pixel less the pixel the model
predicts: the marker's point p in the measuring frame (the robot's forward kinematics) taken into
the camera's frame, p_c = R_cᵀ (p − t_c), and projected by the camera's lens model
(:class:`robocal.model.camera.Camera`).  (R_c, t_c) is the camera's frame in the measuring frame:
a fixed camera's pose, or, for a camera on a link, the base, the chain up to that link and its
mounting (:meth:`robocal.model.robot.Robot.camera_frames`).

The errors sit in the first two of a row's three position slots (px; the third is zero), so that
every figure and test that works on position errors works on them, in pixels.  Their derivative
is the chain rule: ∂p_c = R_cᵀ (∂p − ∂t_c + (p − t_c) × ∂ω_c), ∂t_c and ∂ω_c the camera frame's
twist, then the lens model's derivative.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .camera import Camera

#: the unit of a camera row's errors
PIXEL = "px"
#: the pixel a marker behind its camera is given (px): far off any image, finite
BEHIND = 1.0e6
#: the grid (columns, rows) an image is cut into to say what part of it the rows covered
COVERAGE_GRID = (8, 6)


@dataclass(frozen=True, eq=False)
class Views:
    """The camera rows of a set of rows: the cameras' intrinsics (in ``names`` order), each row's
    camera (index into ``names``; −1: not a camera row) and its measured pixel (m, 2)."""

    names: tuple[str, ...]
    cameras: tuple[Camera, ...]
    index: np.ndarray
    pixels: np.ndarray

    @classmethod
    def of(cls, labels: Sequence[str], pixels: np.ndarray, cameras: Mapping[str, Camera]) -> Views:
        # the cameras in the mapping's order, whichever row comes first: a subset of the rows (a
        # fold) keeps every camera's index
        names = tuple(cameras) + tuple(dict.fromkeys(c for c in labels if c and c not in cameras))
        lookup = {n: i for i, n in enumerate(names)}
        return cls(names, tuple(cameras[n] for n in names), np.array([lookup.get(c, -1) for c in labels], int),
                   np.asarray(pixels, float))

    def coverage(self) -> dict[str, tuple[float, np.ndarray]]:
        """Per camera (whose image size is stated), the share of its image the rows fell in and the
        cells (rows × columns of :data:`COVERAGE_GRID`, True where a row fell): the lens is tested
        only where markers were seen."""
        columns, rows = COVERAGE_GRID
        out = {}
        for c, (name, camera) in enumerate(zip(self.names, self.cameras)):
            uv = self.pixels[self.index == c]
            if camera.width is None or camera.height is None or not len(uv):
                continue
            i = np.clip(((uv[:, 0] + 0.5) / camera.width * columns).astype(int), 0, columns - 1)
            j = np.clip(((uv[:, 1] + 0.5) / camera.height * rows).astype(int), 0, rows - 1)
            cells = np.zeros((rows, columns), bool)
            cells[j, i] = True
            out[name] = (float(cells.mean()), cells)
        return out

    def indices(self, order: Sequence[str]) -> np.ndarray:
        """Each row's camera as an index into ``order`` (a parameter space's cameras; −1: not a
        camera row)."""
        lookup = np.array([list(order).index(n) if n in order else -1 for n in self.names] + [-1], int)
        return lookup[self.index]

    @property
    def rows(self) -> np.ndarray:
        """Mask (m,) of the camera rows."""
        return self.index >= 0

    @property
    def only(self) -> bool:
        return bool(np.all(self.index >= 0))

    def project(self, p: np.ndarray, frames: np.ndarray, jacobian: bool = False):
        """Predicted pixels (…, m, 2) of points p (…, m, 3) mm in the measuring frame seen from each
        row's camera frame (…, m, 4, 4); with ``jacobian`` also ∂uv/∂p_c (…, m, 2, 3), the points in
        the camera's frame (…, m, 3) and the offsets p − t_c (…, m, 3).  NaN at rows no camera saw."""
        R, t = frames[..., :3, :3], frames[..., :3, 3]
        d = p - t
        pc = np.einsum("...ji,...j->...i", R, d)
        uv = np.full(p.shape[:-1] + (2,), np.nan)
        J = np.zeros(p.shape[:-1] + (2, 3)) if jacobian else None
        for c, camera in enumerate(self.cameras):
            rows = self.index == c
            if jacobian:
                uv[..., rows, :], J[..., rows, :, :] = camera.project_jacobian(pc[..., rows, :])
            else:
                uv[..., rows, :] = camera.project(pc[..., rows, :])
        return (uv, J, pc, d) if jacobian else uv

    def errors(self, p: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """The camera rows' errors (…, m, 3): measured less predicted pixel (px) in the first two
        slots, zero in the third; zeros at other rows.  A marker behind its camera has no pixel:
        its error is :data:`BEHIND` px, finite, so that a step that takes a marker there is
        refused by the fit instead of ending it (the start is checked:
        :func:`robocal.calibration.fit.cameras.check_in_front`)."""
        uv = np.nan_to_num(self.project(p, frames), nan=BEHIND)
        e = np.zeros(p.shape)
        e[..., :2] = np.where(self.rows[:, None], self.pixels - uv, 0.0)
        return e

    def behind(self, p: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """Mask (m,) of the camera rows whose marker lies behind (or on) its camera's image plane."""
        R, t = frames[..., :3, :3], frames[..., :3, 3]
        depth = np.einsum("...j,...j->...", R[..., :, 2], p - t)
        return self.rows & ~(depth > 0)

    def error_jacobian(self, Jp: np.ndarray, Jf: np.ndarray, p: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """∂(errors)/∂x (k, m, 3) from the points' Jacobian Jp (k, m, 3) and the camera frames'
        twist Jacobian Jf (k, m, 6) (origin mm, rotation about the measuring frame's axes) at points
        p (m, 3) and frames (m, 4, 4); zeros at other rows."""
        _, Jpi, _, d = self.project(p, frames, jacobian=True)
        # ∂e = −∂uv/∂p_c Rᵀ (∂p − ∂t_c + d × ∂ω_c), d = p − t_c: with A = ∂uv/∂p_c Rᵀ, a row a of A
        # gives a·(d × w) = (a × d)·w, so ∂e = −A (∂p − ∂t_c) − B ∂ω_c, B's rows a × d: two (2 × 3)
        # matrices a row, applied to every column at once
        A = np.nan_to_num(Jpi) @ np.swapaxes(frames[:, :3, :3], 1, 2)
        B = np.cross(A, d[:, None, :])
        moved, turned = Jp - Jf[..., :3], Jf[..., 3:]
        out = np.zeros(Jp.shape)
        for a in range(2):
            out[..., a] = -(A[:, a, 0] * moved[..., 0] + A[:, a, 1] * moved[..., 1] + A[:, a, 2] * moved[..., 2]) \
                - (B[:, a, 0] * turned[..., 0] + B[:, a, 1] * turned[..., 1] + B[:, a, 2] * turned[..., 2])
        return out if self.only else np.where(self.rows[None, :, None], out, 0.0)
