"""The intrinsics of a rectified stereo pair: their checks and the stereo matrix ``Ks``."""

import numpy as np

__all__ = ["check_calibration", "stereo_matrix"]


def check_calibration(K, b, name):
    """Return ``K`` as a (3, 3) float array and ``b`` as a positive float, or raise ValueError.

    ``K`` must be ``[[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]`` with finite entries and positive
    focal lengths: the stereo model has no skew, so a skew ``K[0, 1]`` is refused, not ignored.
    """
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3):
        raise ValueError(f"{name}: K must have shape (3, 3), got {K.shape}")
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{name}: K needs finite entries and positive focal lengths, got {K.tolist()}")
    if K[0, 1] != 0:
        raise ValueError(f"{name}: K[0, 1] = {float(K[0, 1])!r} is a skew, but the stereo model has none "
                         "(K = [[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]], rectified images); rectify or set it to 0")
    if K[1, 0] != 0 or np.any(K[2] != [0.0, 0.0, 1.0]):
        raise ValueError(f"{name}: K must be [[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]], got {K.tolist()}")
    b = float(b)
    if not np.isfinite(b) or b <= 0:
        raise ValueError(f"{name}: baseline b must be a positive number, got {b}")
    return K, b


def stereo_matrix(K, b):
    """The 4x4 stereo calibration matrix ``Ks`` from left intrinsics ``K`` and baseline ``b``.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Left camera intrinsics ``[[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]``.
    b : float
        Stereo baseline in metres (right camera at ``+b`` along the left camera's x axis).

    Returns
    -------
    ndarray, shape (4, 4)
    """
    K, b = check_calibration(K, b, "stereo_matrix")
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.array(
        [
            [fsu, 0.0, cu, 0.0],
            [0.0, fsv, cv, 0.0],
            [fsu, 0.0, cu, -fsu * b],
            [0.0, fsv, cv, 0.0],
        ]
    )
