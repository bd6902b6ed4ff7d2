"""Fitting the residual model: Gaussian processes on the joint angles (scikit-learn).

What the parametric model leaves at each pose, e = measured − model (position mm and, for
full-pose data, orientation rad, in the measuring frame), is regressed on the commanded joint
angles with an anisotropic RBF kernel plus white noise, one kernel for the positions and one
for the orientations.  Length scales are bounded below by :data:`MIN_LENGTH_SCALE` and the
white noise by :data:`MIN_NOISE`, so that a process cannot memorise the measurement noise.
Hyperparameters are fitted on at most :data:`HYPER_POINTS` poses and the process itself on at
most :data:`MAX_POINTS` (both drawn with the seed); a kernel given for a block is used as it is.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..model.residual import Block, ResidualModel

#: shortest length scale of the kernel (rad): about 11°, so one pose cannot bend the correction alone
MIN_LENGTH_SCALE = 0.2
MAX_LENGTH_SCALE = 100.0
#: smallest white-noise level of the standardised targets
MIN_NOISE = 1e-2
HYPER_POINTS = 1000
MAX_POINTS = 2000


def _block(q, y, pick, keep, kernel) -> tuple[Block, object]:
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    n = q.shape[1]
    if kernel is None:
        tuned = GaussianProcessRegressor(
            ConstantKernel(1.0, (1e-3, 1e2)) * RBF(np.ones(n), (MIN_LENGTH_SCALE, MAX_LENGTH_SCALE))
            + WhiteKernel(0.5, (MIN_NOISE, 10.0)), normalize_y=True, random_state=0)
        with warnings.catch_warnings():  # a length scale at its upper bound just means "no dependence on this joint"
            warnings.simplefilter("ignore")
            tuned.fit(q[pick], y[pick])
        kernel = tuned.kernel_
    final = GaussianProcessRegressor(kernel, normalize_y=True, optimizer=None).fit(q[keep], y[keep])
    signal = final.kernel_.k1  # ConstantKernel * RBF; the white noise acts on the training diagonal only
    block = Block(alpha=np.asarray(final.alpha_, float).reshape(len(keep), -1),
                  length_scales=np.atleast_1d(signal.k2.length_scale).astype(float),
                  amplitude=float(signal.k1.constant_value),
                  y_mean=np.atleast_1d(final._y_train_mean).astype(float),
                  y_scale=np.atleast_1d(final._y_train_std).astype(float))
    return block, kernel


def fit_residual(q: np.ndarray, errors: np.ndarray, seed: int | None = 0,
                 kernels: tuple | None = None) -> tuple[ResidualModel, tuple]:
    """A :class:`ResidualModel` of ``errors`` (m, 3 or 6) at commanded joints ``q`` (m, n) rad,
    and its kernels.  ``kernels``: one per block (positions, orientations), None to fit it."""
    rng = np.random.default_rng(seed)
    q, errors = np.asarray(q, float), np.asarray(errors, float)
    pick = rng.permutation(len(q))[:HYPER_POINTS]
    keep = np.sort(rng.permutation(len(q))[:MAX_POINTS])
    blocks, fitted = [], []
    for k, cols in enumerate((slice(0, 3), slice(3, 6))[: errors.shape[1] // 3]):
        given = None if kernels is None or k >= len(kernels) else kernels[k]
        block, kernel = _block(q, errors[:, cols], pick, keep, given)
        blocks.append(block)
        fitted.append(kernel)
    return ResidualModel(q[keep].copy(), tuple(blocks)), tuple(fitted)
