"""Markers of known shape whose place is unknown: a square marker of known size, a ChArUco board, a
marker cube (MODEL §10).

Each such body's markers are identified one by one (their offsets on the flange), and held to the
body's known shape: the template T (N, 3) mm in the body's own frame, placed where it best fits the
markers' current offsets X (N, 3) by a rigid motion (Kabsch: rotation and translation, no scale).
The shape's residual is X less that placement, 3N values of which the placement takes 6: exactly
the 3N − 6 that the shape fixes (a board's flatness among them), where the distances between every
pair would count N(N − 1)/2 values, most of them repeats of the others.

The placement is eliminated as the points and planes of :mod:`robocal.model.constraints` are, and
the residual's derivative is exact (:func:`residual_derivative`): where the markers keep the shape
it is the projection of dX off the six rigid motions of the placed template.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


def _fit(template: np.ndarray, points: np.ndarray):
    """(R (…, 3, 3), the template centred (N, 3), the points' centroid (…, 1, 3)): the rotation
    that turns the centred template onto the points best (Kabsch), p ≈ R t̃ + c."""
    tc = template - template.mean(-2, keepdims=True)
    centre = points.mean(-2, keepdims=True)
    H = np.swapaxes(tc, -1, -2) @ (points - centre)  # Σ t̃ x̃ᵀ (…, 3, 3)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.zeros(H.shape)
    D[..., 0, 0] = D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    return np.swapaxes(U @ D @ Vt, -1, -2), tc, centre


def kabsch(template: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The template (N, 3) moved rigidly onto points (…, N, 3) as well as it goes (least squares)."""
    R, tc, centre = _fit(template, points)
    return tc @ np.swapaxes(R, -1, -2) + centre


def residual_derivative(template: np.ndarray, points: np.ndarray) -> np.ndarray:
    """∂r/∂X (3N, 3N) of r = X − kabsch(template, X) at points X (N, 3), exactly: with M = Σ x̃ t̃ᵀ =
    R S (S symmetric), a change dX turns the placement by ω = (tr S I − S)⁻¹ Σ_i t̃_i × Rᵀ dx_i (in the
    template's axes) and moves it by the mean of dX, so ∂r_j/∂x_i = (δ_ij − 1/N) I + R [t̃_j]× K [t̃_i]× Rᵀ,
    K = (tr S I − S)⁻¹.  Where the markers keep the shape (r = 0) it is the projection off the six
    rigid motions."""
    R, tc, centre = _fit(template, points)
    n = len(tc)
    S = R.T @ ((points - centre).T @ tc)  # Rᵀ M, symmetric
    K = np.linalg.pinv(np.trace(S) * np.eye(3) - S)  # a line of markers: no turn about it
    skew = np.zeros((n, 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -tc[:, 2], tc[:, 1], -tc[:, 0]
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = tc[:, 2], -tc[:, 1], tc[:, 0]
    left, right = R @ skew, skew @ R.T  # R [t̃_j]×, [t̃_i]× Rᵀ
    D = np.einsum("jab,bc,icd->jaid", left, K, right)
    D += np.einsum("ji,ad->jaid", np.eye(n) - 1.0 / n, np.eye(3))
    return D.reshape(3 * n, 3 * n)


def rigid_basis(placed: np.ndarray) -> np.ndarray:
    """An orthonormal basis (3N, r) of the rigid motions of points (N, 3): three translations and
    three turns about their centroid (fewer where the points lie on a line)."""
    c = placed - placed.mean(0)
    n = len(placed)
    moves = [np.tile(np.eye(3)[k], n) for k in range(3)]
    moves += [np.cross(np.eye(3)[k], c).ravel() for k in range(3)]
    U, s, _ = np.linalg.svd(np.column_stack(moves), full_matrices=False)
    return U[:, s > 1e-9 * s[0]]


@dataclass(frozen=True)
class Shapes:
    """The bodies of a problem: for each, the positions in x of its markers' offsets (N, 3; −1
    where not estimated), their nominal offsets (N, 3) mm in the flange frame, and the template."""

    columns: tuple[np.ndarray, ...]
    nominal: tuple[np.ndarray, ...]
    templates: tuple[np.ndarray, ...]
    sigma: float
    #: the values each body's placement takes: six, five for markers on one line (a turn about it
    #: moves none of them)
    placements: tuple[int, ...] = ()

    @classmethod
    def of(cls, bodies: Sequence[tuple[tuple[str, ...], np.ndarray]], targets: Sequence[str],
           nominal: np.ndarray, column_of, sigma: float) -> Shapes | None:
        """From bodies ((marker names, template (N, 3)), …) whose markers are among ``targets``
        (nominal: their tool frames' origins (T, 3)); column_of(name) → the positions in x of its
        x, y, z offsets (−1: not estimated)."""
        kept = [(names, np.asarray(t, float)) for names, t in bodies if all(n in targets for n in names)]
        if not kept:
            return None
        index = {t: i for i, t in enumerate(targets)}
        return cls(tuple(np.array([column_of(n) for n in names]) for names, _ in kept),
                   tuple(nominal[[index[n] for n in names]] for names, _ in kept),
                   tuple(t for _, t in kept), sigma, tuple(rigid_basis(t).shape[1] for _, t in kept))

    @property
    def n_values(self) -> int:
        """Residual rows: three per marker of every body."""
        return sum(3 * len(t) for t in self.templates)

    @property
    def n_placements(self) -> int:
        """The values the bodies' placements take (six each, five for a line of markers)."""
        return sum(self.placements)

    def _offsets(self, X: np.ndarray, b: int) -> np.ndarray:
        X = np.asarray(X, float)
        take = np.concatenate([X, np.zeros(X.shape[:-1] + (1,))], axis=-1)  # index −1: not estimated, 0
        return self.nominal[b] + take[..., self.columns[b]]

    def residuals(self, X: np.ndarray) -> np.ndarray:
        """(…, S) mm: each marker's offset less the body's template placed on them, for estimates
        X (…, k)."""
        out = []
        for b, template in enumerate(self.templates):
            points = self._offsets(X, b)
            out.append((points - kabsch(template, points)).reshape(points.shape[:-2] + (-1,)))
        return np.concatenate(out, axis=-1)

    def jacobian(self, x: np.ndarray, k: int) -> np.ndarray:
        """∂(residuals / σ)/∂x (k, S) at x (k,): the placement's motions projected out."""
        out = np.zeros((k + 1, self.n_values))  # row k: offsets not estimated
        first = 0
        for b, template in enumerate(self.templates):
            D = residual_derivative(template, self._offsets(x, b)) / self.sigma  # (3N rows, 3N offsets)
            cols = self.columns[b].ravel()
            np.add.at(out, (cols, slice(first, first + len(D))), D.T)
            first += len(D)
        return out[:k]
