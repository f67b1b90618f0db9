"""Calibrate a drive from its own data, without ground truth, and say why.

:func:`calibrate` (``_calibration``) decides the :class:`Calibration` the filter's ``"auto"``
settings use, from track reprojection (``_tracks``, ``_bootstrap``), residual correlation along
tracks (``_correlation``), visual odometry against the IMU (:mod:`.odometry`, ``_vo``, ``_motion``)
and the velocities' noise (``_noise``), after a 2025+ file's reading of its extrinsics
(:func:`choose_reading`, ``_readings``); ``_report`` prints it, ``_checks`` has the single checks.

Parameters shared by the whole package: ``dataset`` is a :class:`visla_edu.dataset.Dataset`;
``imu_T_cam`` (4, 4) is the left camera (optical frame) in the IMU frame; with ``lag`` the step
``t -> t+1`` uses the velocity sample ``u[t + lag]`` (:data:`LAGS`); twists are ``[v; w]`` (m/s,
rad/s).
"""

from visla_edu.diagnostics._calibration import (
    CACHED_ARRAYS,
    CALIBRATION_VERSION,
    Calibration,
    VoEvidence,
    cache_path,
    calibrate,
    outlier_indicators,
)
from visla_edu.diagnostics._correlation import track_correlation
from visla_edu.diagnostics._checks import check_time_alignment, diagnose, imu_noise_and_bias, resolve_extrinsics
from visla_edu.diagnostics._motion import gyro_bias, velocity_scale
from visla_edu.diagnostics._noise import (MIN_NOISE_SAMPLES, MIN_SIGMA_ANGULAR, MIN_SIGMA_LINEAR, UNMEASURED_SIGMA_ANGULAR,
                                          UNMEASURED_SIGMA_LINEAR, imu_noise)
from visla_edu.diagnostics._readings import ReadingEvidence, choose_reading
from visla_edu.diagnostics._tracks import TrackChoice, TrackEvidence, TrackScorer, track_pairs
from visla_edu.diagnostics._vo import (
    CORRECTIONS,
    LAGS,
    MIN_SIGNIFICANCE,
    MIN_SLOPE,
    ExtrinsicCheck,
    check_extrinsics,
)
from visla_edu.diagnostics.odometry import VisualOdometry, visual_odometry

__all__ = [
    "CORRECTIONS",
    "LAGS",
    "MIN_SLOPE",
    "MIN_SIGNIFICANCE",
    "MIN_SIGMA_LINEAR",
    "MIN_SIGMA_ANGULAR",
    "MIN_NOISE_SAMPLES",
    "UNMEASURED_SIGMA_LINEAR",
    "UNMEASURED_SIGMA_ANGULAR",
    "CALIBRATION_VERSION",
    "CACHED_ARRAYS",
    "Calibration",
    "VoEvidence",
    "ReadingEvidence",
    "TrackEvidence",
    "TrackChoice",
    "TrackScorer",
    "VisualOdometry",
    "ExtrinsicCheck",
    "calibrate",
    "choose_reading",
    "cache_path",
    "visual_odometry",
    "check_extrinsics",
    "resolve_extrinsics",
    "check_time_alignment",
    "imu_noise_and_bias",
    "imu_noise",
    "gyro_bias",
    "velocity_scale",
    "track_pairs",
    "track_correlation",
    "outlier_indicators",
    "diagnose",
]
