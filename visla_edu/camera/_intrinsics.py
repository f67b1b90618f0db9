"""The intrinsics of a rectified stereo pair: the stereo matrix ``Ks``, its pixel geometry.

A rectified pair (:mod:`visla_edu.camera`) may have two intrinsics, the left ``K`` and the right
``K_right = [[fsu', 0, cu'], [0, fsv', cv'], [0, 0, 1]]``; the stereo matrix becomes::

    Ks = [[fsu,  0,    cu,  0         ],
          [0,    fsv,  cv,  0         ],
          [fsu', 0,    cu', -fsu' * b ],
          [0,    fsv', cv', 0         ]]

so ``z = Ks pi(q)`` and every Jacobian built on ``Ks`` (:mod:`._projection`) hold unchanged. A
right pixel maps into the left camera's pixels by ``u -> cu + fsu (u - cu') / fsu'`` and
``v -> cv + fsv (v - cv') / fsv'`` (:func:`right_in_left_pixels`); in those pixels the course's
disparity ``uL - uR`` is again ``fsu b / depth`` (:func:`disparity`). With ``K_right = K`` (or
None) everything here is the single-intrinsics rig, bit for bit.
"""

import numpy as np

from visla_edu.validation import check_intrinsics, check_stereo_calibration

__all__ = ["STEREO_ROWS", "same_intrinsics", "single_intrinsics", "stereo_matrix", "stereo_rows",
           "right_in_left_pixels", "left_in_right_u", "disparity"]

#: Stereo rows ``[uL, vL, uR, vR]`` -> ``[uL, (vL + vR)/sqrt(2), uR]``, the exact reduction of
#: :func:`stereo_rows` when rows 2 and 4 of ``Ks`` are equal (one intrinsics).
STEREO_ROWS = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)], [0.0, 0.0, 1.0, 0.0]])


def same_intrinsics(K, K_right):
    """Whether a rig with left ``K`` and right ``K_right`` (None: the same) has one intrinsics."""
    return K_right is None or np.array_equal(np.asarray(K, dtype=float), np.asarray(K_right, dtype=float))


def single_intrinsics(Ks):
    """Whether the right rows of ``Ks`` (4, 4) repeat the left camera's but for the baseline term.

    True for a rig with one intrinsics: ``uR = uL + Ks[2, 3] / z`` and ``vR = vL`` exactly.
    """
    return bool(Ks[2, 0] == Ks[0, 0] and Ks[2, 2] == Ks[0, 2] and Ks[3, 1] == Ks[1, 1] and Ks[3, 2] == Ks[1, 2])


def stereo_matrix(K, b, K_right=None):
    """The 4x4 stereo calibration matrix ``Ks`` (module docstring) from the intrinsics and the baseline.

    ``K`` (3, 3): left intrinsics ``[[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]``; ``b``: baseline (m);
    ``K_right`` (3, 3): right intrinsics (default: ``K``).
    """
    K, b = check_stereo_calibration(K, b, "stereo_matrix")
    R = K if K_right is None else check_intrinsics(K_right, "stereo_matrix: K_right", "K_right")
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    fsu_r, fsv_r, cu_r, cv_r = R[0, 0], R[1, 1], R[0, 2], R[1, 2]
    return np.array(
        [
            [fsu, 0.0, cu, 0.0],
            [0.0, fsv, cv, 0.0],
            [fsu_r, 0.0, cu_r, -fsu_r * b],
            [0.0, fsv_r, cv_r, 0.0],
        ]
    )


def stereo_rows(Ks):
    """The exact reduction of the four stereo rows ``[uL, vL, uR, vR]`` to three, ``Ks`` (4, 4) -> (3, 4).

    ``vL`` and ``vR`` (rows ``[0, fsv, cv, 0]`` and ``[0, fsv', cv', 0]`` of ``Ks``) depend on the
    state only through ``y / z``: their Jacobians are ``fsv g`` and ``fsv' g`` for the same row
    ``g``. Rotating the pair orthonormally by ``(a, c) = (fsv, fsv') / hypot(fsv, fsv')`` keeps
    all of their information in ``a vL + c vR``; the other combination ``-c vL + a vR`` has a
    zero Jacobian, and with pixel noise ``sigma^2 I`` it is independent of the rest, so dropping
    it changes no update. The rows are orthonormal; the object :data:`STEREO_ROWS` when rows 2 and 4
    of ``Ks`` are equal.
    """
    if np.array_equal(Ks[1], Ks[3]):
        return STEREO_ROWS
    a, c = np.array([Ks[1, 1], Ks[3, 1]]) / np.hypot(Ks[1, 1], Ks[3, 1])
    return np.array([[1.0, 0.0, 0.0, 0.0], [0.0, a, 0.0, c], [0.0, 0.0, 1.0, 0.0]])


def right_in_left_pixels(z, K, K_right=None):
    """Stereo pixels (..., 4) with the right image's ``[uR, vR]`` mapped into the left camera's intrinsics.

    The map of the module docstring (the same normalised image point seen through ``K``); ``z``
    itself when ``K_right`` is None or equal to ``K``. ``K``, ``K_right``: (3, 3).
    """
    if same_intrinsics(K, K_right):
        return z
    K, R = np.asarray(K, dtype=float), np.asarray(K_right, dtype=float)
    out = np.array(z, dtype=float, copy=True)
    out[..., 2] = K[0, 2] + K[0, 0] * (out[..., 2] - R[0, 2]) / R[0, 0]
    out[..., 3] = K[1, 2] + K[1, 1] * (out[..., 3] - R[1, 2]) / R[1, 1]
    return out


def left_in_right_u(u, K, K_right=None):
    """The inverse map of :func:`right_in_left_pixels` for ``u``: ``cu' + fsu' (u - cu) / fsu`` (``u`` if one K)."""
    if same_intrinsics(K, K_right):
        return u
    K, R = np.asarray(K, dtype=float), np.asarray(K_right, dtype=float)
    return R[0, 2] + R[0, 0] * (np.asarray(u, dtype=float) - K[0, 2]) / K[0, 0]


def disparity(z, K, K_right=None):
    """Disparity in the left camera's pixels, ``uL - uR`` after :func:`right_in_left_pixels`: ``fsu b / depth``.

    ``z`` (..., 4) -> (...), positive for points in front of the rig. ``K``, ``K_right`` (3, 3);
    ``K_right`` None (or equal to ``K``): the course's ``uL - uR``, bit for bit.
    """
    z = np.asarray(z, dtype=float)
    return z[..., 0] - right_in_left_pixels(z, K, K_right)[..., 2]
