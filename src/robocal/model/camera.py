"""A camera as calibration sees it: its intrinsics and OpenCV's lens model (MODEL §10).

A point p = (X, Y, Z) in the camera's frame (z along the optical axis, x to the image's right,
y down; any length unit) is seen at the pixel (u, v) of OpenCV's pinhole model with its
distortion ``k1 k2 p1 p2 k3``: x' = X/Z, y' = Y/Z, r² = x'² + y'²,

    x'' = x'·(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x'y' + p2 (r² + 2x'²)
    y'' = y'·(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y'²) + 2 p2 x'y'
    u = fx x'' + cx,  v = fy y'' + cy.

The intrinsics are the camera maker's or a camera calibration's (an OpenCV FileStorage file or a
ROS ``camera_info``: :mod:`robocal.io.camera`); robocal calibrates the robot and where the camera
is, not the lens.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: OpenCV's distortion coefficients robocal's model holds, in OpenCV's order
DISTORTION = ("k1", "k2", "p1", "p2", "k3")


@dataclass(frozen=True)
class Camera:
    """Intrinsics (px): focal lengths fx, fy, principal point cx, cy, OpenCV's distortion
    (k1, k2, p1, p2, k3) and the image size (None: not stated)."""

    name: str
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(len(DISTORTION)))
    width: int | None = None
    height: int | None = None
    source: str = ""

    @property
    def matrix(self) -> np.ndarray:
        """The 3 × 3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of points (..., 3) in the camera's frame (NaN behind the camera)."""
        p = np.asarray(points, float)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = p[..., 0] / z, p[..., 1] / z
        k1, k2, p1, p2, k3 = np.asarray(self.distortion, float)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)
        return np.where((z > 0)[..., None], uv, np.nan)

    def in_image(self, uv: np.ndarray) -> np.ndarray:
        """Whether pixels (..., 2) lie on the image (everywhere finite where its size is not stated)."""
        uv = np.asarray(uv, float)
        inside = np.all(np.isfinite(uv), axis=-1)
        if self.width is not None:
            inside &= (uv[..., 0] >= 0.0) & (uv[..., 0] <= self.width)
        if self.height is not None:
            inside &= (uv[..., 1] >= 0.0) & (uv[..., 1] <= self.height)
        return inside
