"""Calibrate a drive from its own data, without ground truth, and say why.

Course files carry quirks a student cannot see by eye: the axes of the stated extrinsic
flipped (dataset 03), velocity samples one frame ahead of the motion they describe (the KITTI
raw drives), velocity noise from nearly none to 0.5 m/s, gross outlier tracks, stale copies of
frames. Two kinds of evidence measure them:

* **track reprojection** (:mod:`._tracks`): each landmark's first observation, triangulated
  and moved by the IMU's dead-reckoned motion with a candidate lag and extrinsic correction,
  must land on its later observations 1-5 frames on; the median pixel error scores the
  candidate, and a bootstrap over landmarks says whether the best one is better than every
  other with 95% confidence. It works on sparse drives too.
* **residual correlation along tracks** (:mod:`._correlation`): how long a track's pixel errors
  persist, along the dead-reckoned poses; ``pixel_noise_inflation="auto"`` reads it.
* **visual odometry** (:mod:`._vo`, :mod:`._motion`): the robust RANSAC stereo odometry
  (:func:`visla_edu.diagnostics.odometry.visual_odometry`) against the IMU: slopes of the extrinsic check,
  rotation residual per lag, gyro bias and velocity scale, each with a standard error and a
  verdict.

:func:`calibrate` turns them into one decision, a :class:`Calibration` (what the filter's
``"auto"`` settings use: extrinsic correction, IMU lag, per-axis velocity noise from the
velocities, :mod:`._noise`), with a readable :meth:`Calibration.report` (``visla-edu info``),
cached per dataset content in the user cache folder. The single checks stay available:
:func:`check_extrinsics`, :func:`resolve_extrinsics`, :func:`check_time_alignment`,
:func:`imu_noise_and_bias`, :func:`outlier_indicators`, :func:`diagnose`.

A 2025+ file's extrinsics may be read four ways (camera->IMU or IMU->camera, optical or
"regular" camera frame): :func:`choose_reading` (module ``_readings``) decides from the rig
geometry and the same two kinds of evidence, before the axis flips, and the
:class:`Calibration` keeps its :class:`ReadingEvidence`.

Modules: ``_vo`` (odometry access, corrections, extrinsic check, time alignment), ``_motion``
(gyro bias, velocity scale), ``_noise`` (white and hold noise), ``_bootstrap`` (cluster
bootstrap of medians), ``_tracks`` (track reprojection), ``_correlation`` (residual correlation
along tracks), ``_readings`` (the reading of a 2025+ file's extrinsics), ``_calibration`` (the decision and the cache), ``_report`` (its text),
``_checks`` (the single checks with calibrated defaults).
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
