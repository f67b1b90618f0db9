"""Whole simulated drives with ground truth (the pipeline: :mod:`visla_edu.simulate`)."""

import math

import numpy as np

from visla_edu.camera import StereoCamera
from visla_edu.dataset import Dataset, GroundTruth
from visla_edu.motion import dead_reckon
from visla_edu.simulate._config import PRESET_NAMES, default_rig, make_config
from visla_edu.simulate._landmarks import place_landmarks
from visla_edu.simulate._motion import add_imu_noise, simulate_motion
from visla_edu.simulate._tracks import simulate_tracks

__all__ = ["simulate_drive", "simulate_along_drive"]


def _streams(seed):
    """Independent generators for motion, landmarks, tracks and IMU noise (the same for the same seed)."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]


def _rig(config, default):
    """Calibration from the config where given, else from ``default`` = (K, b, imu_T_cam)."""
    K = default[0] if config.K is None else np.asarray(config.K, dtype=float)
    b = default[1] if config.b is None else float(config.b)
    imu_T_cam = default[2] if config.imu_T_cam is None else np.asarray(config.imu_T_cam, dtype=float)
    StereoCamera(K, b, imu_T_cam, config.K_right)  # validates shapes, the baseline and K_right
    return K, b, imu_T_cam


def _build(time_stamps, true_v, true_w, rig, config, rngs, **fields):
    """Poses, landmarks, tracks and IMU noise assembled into a Dataset."""
    _, rng_landmarks, rng_tracks, rng_imu = rngs
    K, b, imu_T_cam = rig
    poses = dead_reckon(time_stamps, np.concatenate([true_v, true_w], axis=1))
    n_candidates = int(math.ceil(config.candidate_factor * config.num_landmarks))
    landmarks, appear = place_landmarks(poses, n_candidates, config, rng_landmarks, time_stamps)
    tracks = simulate_tracks(poses, landmarks, K, b, imu_T_cam, config, rng_tracks, appear=appear,
                             max_landmarks=config.num_landmarks, time_stamps=time_stamps)
    meas_v, meas_w = add_imu_noise(true_v, true_w, config, rng_imu)
    truth = GroundTruth(world_T_imu=poses, landmarks=tracks.landmarks, linear_velocity=true_v,
                        angular_velocity=true_w, outlier=tracks.outlier)
    reported = imu_T_cam
    if config.reported_imu_T_cam is not None:  # the file's calibration differs from the rig's
        reported = np.array(config.reported_imu_T_cam, dtype=float)
        fields["extra"] = {**fields.get("extra", {}), "simulated_imu_T_cam": imu_T_cam}
    K_right = None if config.K_right is None else np.array(config.K_right, dtype=float)
    return Dataset(time_stamps=time_stamps, linear_velocity=meas_v, angular_velocity=meas_w,
                   K=K, b=b, imu_T_cam=reported, num_landmarks=len(tracks.landmarks),
                   frame_ptr=tracks.frame_ptr, obs_ids=tracks.obs_ids, obs_z=tracks.obs_z,
                   ground_truth=truth, K_right=K_right, **fields)


def simulate_drive(preset="course", seed=0, **overrides):
    """A seeded, deterministic simulated drive with ground truth, a :class:`~visla_edu.dataset.Dataset`.

    ``preset``: the scale (:func:`make_config`); ``overrides``: :class:`SimulationConfig` fields. Motion, landmarks,
    tracks and IMU noise draw from separate streams of ``seed``, so e.g. changing ``pixel_sigma`` keeps the drive and
    the map. Named ``"sim"`` (``"sim-small"``, ``"sim-tiny"``); ``extra = {"preset", "seed", "config"}``.
    """
    config = make_config(preset, **overrides)
    time_stamps, true_v, true_w = simulate_motion(config, _streams(seed)[0])
    args = ", ".join([f"preset={preset!r}", f"seed={seed!r}"] + [f"{k}=..." for k in sorted(overrides)])
    return simulate_along_drive(
        time_stamps, true_v, true_w, config, default_rig(), seed,
        name=PRESET_NAMES[preset],
        source=f"visla_edu.simulate.simulate_drive({args}); {config.describe()}",
        label=f"simulated drive (preset {preset}, seed {seed}) with ground truth",
        extra={"preset": preset, "seed": seed, "config": config},
    )


def simulate_along_drive(time_stamps, linear_velocity, angular_velocity, config, calibration, seed=0,
                         **fields):
    """A drive with ground truth (a Dataset) simulated along given true body velocities (dead-reckoned poses).

    ``time_stamps`` (T,), strictly increasing, T >= 2, and ``linear_velocity``, ``angular_velocity`` (T, 3), finite
    (else ValueError), are kept as given; the step ``t -> t+1`` uses sample ``t``. ``config``'s motion fields and
    ``num_frames`` are unused; ``calibration = (K (3, 3), b, imu_T_cam (4, 4))`` is used where the config's is None.
    Landmarks, tracks and IMU noise draw from the streams of :func:`simulate_drive`'s ``seed``; ``fields`` are Dataset
    fields: ``name``, ``source``, optionally ``label``, ``extra``.
    """
    time_stamps, true_v, true_w = _check_drive(time_stamps, linear_velocity, angular_velocity)
    rig = _rig(config, calibration)
    return _build(time_stamps, true_v, true_w, rig, config, _streams(seed), **fields)


def _check_drive(time_stamps, linear_velocity, angular_velocity):
    """The true drive as float arrays ``(T,), (T, 3), (T, 3)``, or a ``ValueError`` naming the problem."""
    stamps = np.asarray(time_stamps, dtype=float)
    if stamps.ndim != 1 or len(stamps) < 2 or not np.all(np.diff(stamps) > 0):
        raise ValueError(f"simulate_along_drive: time_stamps must be strictly increasing with shape (T,), "
                         f"T >= 2; got shape {stamps.shape}")
    velocities = []
    for name, value in (("linear_velocity", linear_velocity), ("angular_velocity", angular_velocity)):
        value = np.asarray(value, dtype=float)
        if value.shape != (len(stamps), 3) or not np.all(np.isfinite(value)):
            raise ValueError(f"simulate_along_drive: {name} must be finite with shape ({len(stamps)}, 3) "
                             f"(T from time_stamps), got shape {value.shape}")
        velocities.append(value)
    return stamps, velocities[0], velocities[1]
