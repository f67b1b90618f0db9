"""Landmarks from stereo pixels: depth by disparity and by bearings, and the triangulation Jacobian.

Each function takes stereo pixels ``z`` (..., 4) ``[uL, vL, uR, vR]``, the left intrinsics ``K``
(3, 3), the baseline ``b`` (m) and the right camera's intrinsics ``K_right`` (default: ``K``):
the right pixels are first mapped into the left camera's intrinsics
(:func:`~visla_edu.camera.right_in_left_pixels`), where the single-intrinsics formulas hold.
Points are in the left camera frame. Raises ``ValueError`` unless ``K`` is a valid 3x3
intrinsics matrix and ``b`` is positive.
"""

import numpy as np

from visla_edu.camera._intrinsics import right_in_left_pixels, same_intrinsics
from visla_edu.validation import check_intrinsics, check_stereo_calibration

__all__ = ["triangulate_disparity", "triangulate_bearing", "triangulation_jacobian"]


def _check_pixels(z, name):
    z = np.asarray(z, dtype=float)
    if z.ndim == 0 or z.shape[-1] != 4:
        raise ValueError(f"{name}: pixels must have shape (..., 4) as [uL, vL, uR, vR], got {z.shape}")
    return z


def triangulate_disparity(z, K, b, K_right=None):
    """Points (..., 3) from stereo pixels by disparity; NaN rows where the disparity is not positive.

    ``depth = fsu b / (uL - uR)``, ``x = (uL - cu) depth / fsu``, ``y = (vL - cv) depth / fsv``.
    """
    z = _check_pixels(z, "triangulate_disparity")
    K, b = check_stereo_calibration(K, b, "triangulate_disparity")
    z = _in_left_pixels(z, K, K_right, "triangulate_disparity")
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    disparity = z[..., 0] - z[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(disparity > 0, fsu * b / disparity, np.nan)
    x = (z[..., 0] - cu) * depth / fsu
    y = (z[..., 1] - cv) * depth / fsv
    return np.stack([x, y, depth], axis=-1)


def triangulate_bearing(z, K, b, K_right=None):
    """Points (..., 3) by the course's bearing triangulation; NaN rows where ``lambda1`` is not positive.

    With normalised bearings ``z1 = K^-1 [uL, vL, 1]`` and ``z2 = K_right^-1 [uR, vR, 1]``,
    the right camera at ``p = [b, 0, 0]`` and ``R = I`` in the left frame,
    ``lambda1 z1 = m`` and ``lambda2 z2 = R^T (m - p)`` give in least squares
    ``lambda1 = a^T c / a^T a`` with ``a = R^T z1 - (e3^T R^T z1) z2`` and
    ``c = R^T p - (e3^T R^T p) z2``; then ``m = lambda1 z1``.
    On noise-free rectified pixels it equals :func:`triangulate_disparity`.
    """
    z = _check_pixels(z, "triangulate_bearing")
    K, b = check_stereo_calibration(K, b, "triangulate_bearing")
    K_inv = np.linalg.inv(K)
    K_right_inv = K_inv if same_intrinsics(K, K_right) else np.linalg.inv(
        check_intrinsics(K_right, "triangulate_bearing: K_right", "K_right"))
    ones = np.ones(z.shape[:-1] + (1,))
    z1 = np.concatenate([z[..., 0:2], ones], axis=-1) @ K_inv.T
    z2 = np.concatenate([z[..., 2:4], ones], axis=-1) @ K_right_inv.T
    p = np.array([b, 0.0, 0.0])
    a = z1 - z1[..., 2:3] * z2  # R = I
    c = p - p[2] * z2
    with np.errstate(divide="ignore", invalid="ignore"):
        lam1 = np.einsum("...i,...i->...", a, c) / np.einsum("...i,...i->...", a, a)
    lam1 = np.where(lam1 > 0, lam1, np.nan)
    return lam1[..., None] * z1


def triangulation_jacobian(z, K, b, K_right=None):
    """Jacobian (..., 3, 4) of :func:`triangulate_disparity` with respect to ``[uL, vL, uR, vR]``.

    With disparity ``d = uL - uR`` and ``p = [X, Y, Z]``::

        dZ/duL = -Z/d              dZ/duR = Z/d
        dX/duL = Z/fsu - X/d       dX/duR = X/d
        dY/duL = -Y/d              dY/duR = Y/d        dY/dvL = Z/fsv

    (``vR`` is not used.) With a right camera of its own intrinsics, ``d`` is taken after mapping
    ``uR`` and the ``uR`` column is multiplied by ``fsu / fsu'``. The triangulation covariance
    ``J (sigma^2 I) J^T`` grows with depth squared. Where the disparity is not positive, every entry
    that depends on the depth is NaN (the entries that are always zero, such as the ``vR`` column,
    stay 0).
    """
    z = _check_pixels(z, "triangulation_jacobian")
    K = np.asarray(K, dtype=float)
    z = _in_left_pixels(z, K, K_right, "triangulation_jacobian")
    p = triangulate_disparity(z, K, b)
    X, Y, Z = p[..., 0], p[..., 1], p[..., 2]
    d = z[..., 0] - z[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        J = np.zeros(z.shape[:-1] + (3, 4))
        J[..., 0, 0] = Z / K[0, 0] - X / d
        J[..., 0, 2] = X / d
        J[..., 1, 0] = -Y / d
        J[..., 1, 1] = Z / K[1, 1]
        J[..., 1, 2] = Y / d
        J[..., 2, 0] = -Z / d
        J[..., 2, 2] = Z / d
    if not same_intrinsics(K, K_right):
        J[..., 2] *= K[0, 0] / np.asarray(K_right, dtype=float)[0, 0]
    return J


def _in_left_pixels(z, K, K_right, name):
    """``z`` with the right pixels in ``K``'s intrinsics (``z`` itself for one intrinsics)."""
    if same_intrinsics(K, K_right):
        return z
    return right_in_left_pixels(z, K, check_intrinsics(K_right, f"{name}: K_right", "K_right"))
