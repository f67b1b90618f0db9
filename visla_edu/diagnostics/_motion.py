"""Visual-odometry evidence on the IMU's own errors: gyro bias and velocity scale.

Both compare the odometry's motion in the IMU frame with the IMU's over the usable frame pairs
(:func:`~visla_edu.diagnostics._vo.vo_pairs`) by :func:`robust_location`, and are reported with a
verdict, not applied: on a sparse drive the odometry's own biases are as large as the effects.
"""

import numpy as np

from visla_edu import lie
from visla_edu.diagnostics._vo import MIN_VO_PAIRS, odometry_of, vo_motion_in_imu_frame, vo_pairs
from visla_edu.motion import select_twists

__all__ = ["robust_location", "gyro_bias", "velocity_scale", "MIN_STEP", "SIGNIFICANCE"]

#: Frame steps shorter than this (m, by the IMU) are left out of the velocity scale.
MIN_STEP = 0.2
#: An effect is reported as present when it is this many standard errors from its null value.
SIGNIFICANCE = 3.0
#: Standard error of a median over that of a mean, for normal samples (sqrt(pi / 2)).
_MEDIAN_EFFICIENCY = 1.2533
#: MAD to standard deviation, for normal samples.
_MAD_TO_SIGMA = 1.4826
NOT_ENOUGH = "not enough evidence"


def robust_location(samples):
    """Median of each column of ``samples`` (n,) or (n, k), and its standard error; NaN and inf if n = 0.

    The standard error of a median from the MAD: ``1.2533 * 1.4826 MAD / sqrt(n)``.
    """
    samples = np.asarray(samples, dtype=float)
    if len(samples) == 0:
        shape = samples.shape[1:]
        return np.full(shape, np.nan), np.full(shape, np.inf)
    location = np.median(samples, axis=0)
    mad = np.median(np.abs(samples - location), axis=0)
    return location, _MEDIAN_EFFICIENCY * _MAD_TO_SIGMA * mad / np.sqrt(len(samples))


def _used_motion(dataset, imu_T_cam, lag):
    """Odometry motions in the IMU frame (P, 4, 4), velocities (P, 6), time steps (P,) of the usable pairs."""
    vo = odometry_of(dataset)
    used = vo_pairs(vo)
    return (vo_motion_in_imu_frame(vo, imu_T_cam)[used], select_twists(dataset.twists, lag)[used],
            dataset.time_steps[used])


def _evidence(key, value, stderr, pairs, verdict):
    """``{key: value, "stderr", "pairs", "verdict"}``: floats or lists, None without pairs; "not enough evidence"
    replaces the verdict with fewer than ``MIN_VO_PAIRS`` pairs."""
    known = pairs > 0
    return {key: value.tolist() if known else None, "stderr": stderr.tolist() if known else None, "pairs": pairs,
            "verdict": NOT_ENOUGH if pairs < MIN_VO_PAIRS else verdict}


def gyro_bias(dataset, imu_T_cam, lag=0):
    """Gyro bias: the robust mean of ``w_imu[t + lag] - log(R_vo) / tau_t`` over the usable pairs.

    Returns
    -------
    dict
        ``bias`` (3,) rad/s and ``stderr`` (3,) (None without pairs), ``pairs``, and ``verdict``:
        "not enough evidence" (fewer than ``MIN_VO_PAIRS`` pairs), "consistent with zero" or
        "nonzero" (some axis :data:`SIGNIFICANCE` standard errors from zero).
    """
    vo_motion, imu_twist, tau = _used_motion(dataset, imu_T_cam, lag)
    w_vo = lie.so3_log(vo_motion[:, :3, :3]) / tau[:, None]
    bias, stderr = robust_location(imu_twist[:, 3:] - w_vo)
    consistent = np.all(np.abs(bias) < SIGNIFICANCE * stderr)
    return _evidence("bias", bias, stderr, len(tau), "consistent with zero" if consistent else "nonzero")


def velocity_scale(dataset, imu_T_cam, lag=0):
    """Velocity scale: the median of ``|t_vo| / |tau v_imu[t + lag]|`` over the usable pairs.

    Steps shorter than :data:`MIN_STEP` by the IMU are left out.

    Returns
    -------
    dict
        ``scale`` and ``stderr`` (None without pairs), ``pairs``, and ``verdict``: "not enough
        evidence", "consistent with 1", or "differs from 1 by x%" (as :func:`gyro_bias`).
    """
    vo_motion, imu_twist, tau = _used_motion(dataset, imu_T_cam, lag)
    step = tau * np.linalg.norm(imu_twist[:, :3], axis=1)
    moving = step > MIN_STEP
    ratio = np.linalg.norm(vo_motion[moving, :3, 3], axis=1) / step[moving]
    scale, stderr = robust_location(ratio)
    consistent = abs(scale - 1) < SIGNIFICANCE * stderr
    return _evidence("scale", scale, stderr, int(moving.sum()),
                     "consistent with 1" if consistent else f"differs from 1 by {100 * (scale - 1):+.1f}%")
