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
        """Whether pixels (..., 2) lie on the image (everywhere finite where its size is not stated).
        OpenCV puts pixel (i, j)'s centre at u = i, v = j: the image spans [−0.5, W − 0.5] ×
        [−0.5, H − 0.5]."""
        uv = np.asarray(uv, float)
        inside = np.all(np.isfinite(uv), axis=-1)
        if self.width is not None:
            inside &= (uv[..., 0] >= -0.5) & (uv[..., 0] <= self.width - 0.5)
        if self.height is not None:
            inside &= (uv[..., 1] >= -0.5) & (uv[..., 1] <= self.height - 0.5)
        return inside

    def normalized(self, uv: np.ndarray, iterations: int = 20) -> np.ndarray:
        """The undistorted normalised coordinates (x', y') (..., 2) of pixels (..., 2): the lens
        model inverted by fixed-point iteration, as OpenCV's undistortPoints does."""
        uv = np.asarray(uv, float)
        xd = np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], axis=-1)
        k1, k2, p1, p2, k3 = np.asarray(self.distortion, float)
        x = xd.copy()
        for _ in range(iterations):
            r2 = np.sum(x * x, axis=-1)
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dx = 2.0 * p1 * x[..., 0] * x[..., 1] + p2 * (r2 + 2.0 * x[..., 0] ** 2)
            dy = p1 * (r2 + 2.0 * x[..., 1] ** 2) + 2.0 * p2 * x[..., 0] * x[..., 1]
            x = np.stack([(xd[..., 0] - dx) / radial, (xd[..., 1] - dy) / radial], axis=-1)
        return x

    def pose_of(self, points: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """The pose (4 × 4) of the camera's frame in the points' frame from points (m, 3) and the
        pixels (m, 2) they were seen at (m ≥ 6; or m ≥ 4 on one plane): the direct linear
        transform on the undistorted rays (a homography where the points lie on a plane: a
        planar campaign, markers on one face), then least squares on the pixels.  A start for a
        calibration, which refines it with everything else.  Raises ValueError where the points
        cannot give a pose (all on one line, or too few)."""
        from scipy.optimize import least_squares

        from ..math.se3 import homogeneous
        from ..math.so3 import exp_so3

        P = np.asarray(points, float)
        x = self.normalized(uv)
        ok = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(x), axis=1)
        P, x, uv = P[ok], x[ok], np.asarray(uv, float)[ok]
        centre = P.mean(0) if len(P) else np.zeros(3)
        spread = np.linalg.svd(P - centre, compute_uv=False) if len(P) >= 3 else np.zeros(3)
        if len(P) < 4 or not spread[1] > 1e-6 * max(spread[0], 1e-300):
            raise ValueError(f"{len(P)} points {'on one line ' if len(P) >= 4 else ''}cannot give a camera's pose")
        planar = spread[2] <= 1e-3 * spread[0]
        if not planar and len(P) < 6:
            raise ValueError(f"{len(P)} points off one plane cannot give a camera's pose (at least 6)")
        R, t = _planar_start(P, x) if planar else _dlt_start(P, x)

        def residuals(v):
            pc = P @ (exp_so3(v[:3]) @ R).T + t + v[3:]
            return np.nan_to_num(self.project(pc) - uv, nan=1e6).ravel()

        fit = least_squares(residuals, np.zeros(6), method="lm")
        R, t = exp_so3(fit.x[:3]) @ R, t + fit.x[3:]
        return homogeneous(R.T, -R.T @ t)

    def project_jacobian(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (..., 2) and their derivative (..., 2, 3) with respect to points (..., 3) in the
        camera's frame: the chain rule through the pinhole division and the distortion above."""
        p = np.asarray(points, float)
        X, Y, Z = p[..., 0], p[..., 1], p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            iz = np.where(Z > 0, 1.0 / Z, np.nan)
        x, y = X * iz, Y * iz
        k1, k2, p1, p2, k3 = np.asarray(self.distortion, float)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # ∂radial/∂(r²)
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        # ∂(xd, yd)/∂(x, y): r² changes by 2x dx + 2y dy
        a = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        b = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        c = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        d = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        # ∂(x, y)/∂(X, Y, Z) = [[1/Z, 0, −x/Z], [0, 1/Z, −y/Z]]
        J = np.empty(p.shape[:-1] + (2, 3))
        J[..., 0, 0] = self.fx * a * iz
        J[..., 0, 1] = self.fx * b * iz
        J[..., 0, 2] = -self.fx * (a * x + b * y) * iz
        J[..., 1, 0] = self.fy * c * iz
        J[..., 1, 1] = self.fy * d * iz
        J[..., 1, 2] = -self.fy * (c * x + d * y) * iz
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)
        return uv, J


def _dlt_start(P: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) taking points (m, 3) into a camera that sees them along the undistorted rays x (m, 2):
    the direct linear transform on normalised points (economy SVD: a 2m × 12 system)."""
    from ..math.so3 import project_to_so3

    centre = P.mean(0)
    scale = max(float(np.sqrt(np.mean(np.sum((P - centre) ** 2, 1)))), 1e-9)
    Ph = np.column_stack([(P - centre) / scale, np.ones(len(P))])
    A = np.zeros((2 * len(P), 12))
    A[0::2, 0:4], A[0::2, 8:12] = Ph, -x[:, :1] * Ph
    A[1::2, 4:8], A[1::2, 8:12] = Ph, -x[:, 1:] * Ph
    M = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4)
    det = np.linalg.det(M[:, :3])
    if not abs(det) > 1e-300:
        raise ValueError("the points cannot give a camera's pose (degenerate)")
    M = M / np.cbrt(det)  # det 1: R up to the scale the SVD left
    if np.mean(Ph @ M[2]) < 0:  # the points in front of the camera
        M = -M
    R = project_to_so3(M[:, :3])
    t = M[:, 3] / np.linalg.norm(M[:, :3], axis=1).mean()
    # points (normalised) in the camera: R Pn + t → unnormalised: R P + (scale t − R centre)
    return R, scale * t - R @ centre


def _planar_start(P: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of :func:`_dlt_start` for points on one plane: the homography from the plane's own
    coordinates to the rays, H ∝ [r1 r2 t] (Zhang's decomposition)."""
    from ..math.so3 import project_to_so3

    centre = P.mean(0)
    basis = np.linalg.svd(P - centre, full_matrices=False)[2]  # rows: the plane's axes, then its normal
    if np.linalg.det(basis) < 0:
        basis[2] = -basis[2]
    local = (P - centre) @ basis[:2].T
    scale = max(float(np.sqrt(np.mean(np.sum(local ** 2, 1)))), 1e-9)
    Q = np.column_stack([local / scale, np.ones(len(P))])
    A = np.zeros((2 * len(P), 9))
    A[0::2, 0:3], A[0::2, 6:9] = Q, -x[:, :1] * Q
    A[1::2, 3:6], A[1::2, 6:9] = Q, -x[:, 1:] * Q
    H = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 3)
    H = H / np.mean(np.linalg.norm(H[:, :2], axis=0))
    if H[2, 2] < 0:  # the plane's centre in front of the camera
        H = -H
    r1, r2 = H[:, 0], H[:, 1]
    Rp = project_to_so3(np.column_stack([r1, r2, np.cross(r1, r2)]))
    # the plane's frame (basis, centre) in the camera: (Rp, H[:, 2] · scale); the points' frame's
    R = Rp @ basis
    return R, scale * H[:, 2] - R @ centre


@dataclass(frozen=True, eq=False)
class CameraMount:
    """Where a camera is: ``link`` 0 fixed in the measuring frame, k on the robot's link k (the
    frame its chain reaches after joint k, the frame forward kinematics with k joints gives);
    ``pose`` (4 × 4, mm) the camera's frame (z its optical axis) in that frame.  ``known``: the
    pose is given, not estimated.  ``of``: fixed to that camera instead, ``pose`` in its frame."""

    link: int = 0
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    known: bool = False
    #: the camera this one is fixed to (a stereo rig's calibrated pair): ``pose`` is then in that
    #: camera's frame, known, and ``link`` is that camera's
    of: str = ""

    def moved(self, pose: np.ndarray) -> CameraMount:
        return CameraMount(self.link, np.asarray(pose, float), self.known, self.of)
