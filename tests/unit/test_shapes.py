"""Markers of known shape: the residual of a body placed on its markers, its exact derivative, and the
values the shape fixes (3N − 6, a board's flatness among them)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.model.shapes import Shapes, kabsch, residual_derivative, rigid_basis


def _board(columns=4, rows=6, square=40.0):
    """A flat board's chessboard corners (N, 3) mm: a ChArUco board of 5 × 7 squares has 4 × 6."""
    return np.array([[i * square, j * square, 0.0] for j in range(rows) for i in range(columns)])


def test_the_placement_is_scipys_best_rotation_and_the_centroid(rng):
    template = _board()
    R = Rotation.from_rotvec(rng.normal(0, 1, 3))
    points = R.apply(template) + [100.0, -20.0, 300.0] + rng.normal(0, 0.2, template.shape)
    ours = kabsch(template, points)
    theirs, _ = Rotation.align_vectors(points - points.mean(0), template - template.mean(0))
    np.testing.assert_allclose(ours, theirs.apply(template - template.mean(0)) + points.mean(0), atol=1e-9)


@pytest.mark.parametrize("flat", [True, False])
def test_the_residuals_derivative_is_its_finite_difference(rng, flat):
    template = _board() if flat else rng.uniform(-50, 50, (9, 3))
    points = Rotation.from_rotvec(rng.normal(0, 1, 3)).apply(template) + rng.normal(0, 0.5, template.shape)
    D = residual_derivative(template, points)
    h = 1e-6
    fd = np.empty_like(D)
    for i in range(points.size):
        step = np.zeros(points.size)
        step[i] = h
        up = points + step.reshape(points.shape)
        down = points - step.reshape(points.shape)
        fd[:, i] = ((up - kabsch(template, up)) - (down - kabsch(template, down))).ravel() / (2 * h)
    np.testing.assert_allclose(D, fd, atol=1e-6)
    # where the markers keep the shape it is the projection off the six rigid motions
    kept = kabsch(template, points)
    Q = rigid_basis(kept)
    np.testing.assert_allclose(residual_derivative(template, kept), np.eye(points.size) - Q @ Q.T, atol=1e-9)


def test_a_board_of_n_corners_fixes_3n_minus_6_values():
    """A 5 × 7 ChArUco board's 24 corners: 72 residual rows of which the placement takes 6, so 66 values
    (the distances between every pair would have counted 276)."""
    template = _board()
    names = tuple(f"C:{k}" for k in range(len(template)))
    shapes = Shapes.of([(names, template)], names, template + 5.0, lambda n: [-1, -1, -1], 0.05)
    assert shapes.n_values == 72 and shapes.n_placements == 6 and shapes.n_values - shapes.n_placements == 66
    np.testing.assert_allclose(shapes.residuals(np.zeros(1)), 0.0, atol=1e-9)
