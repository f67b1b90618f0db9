"""The STAND-IN for course dataset 10: its real IMU drive with simulated stereo tracks.

``10.npz`` is not available, only ``10_imu_only.npz`` (its time stamps and IMU velocities).
:func:`standin_dataset10` simulates landmarks, stereo tracks and IMU noise along that drive
with the rig of dataset 3 (the same vehicle), both inputs read and checked like course files;
:func:`load_dataset10` is what ``load("10")`` does.
"""

import os

import numpy as np

from visla_edu.data._format import check_calibration_keys, check_finite, check_increasing, check_numeric, check_shape
from visla_edu.data._npz import load_npz, read_arrays, time_major
from visla_edu.data._plausible import check_time_stamps, check_velocities
from visla_edu.data._registry import ENV_VAR, STANDIN_INPUTS, missing_standin_inputs, resolve_dir

__all__ = ["STANDIN_LABEL", "STANDIN_NUM_LANDMARKS", "standin_dataset10", "course_standin10", "load_dataset10"]

#: Label of the dataset-10 stand-in (shown wherever the dataset is named).
STANDIN_LABEL = (
    "STAND-IN for dataset 10: real IMU drive of dataset 10, simulated stereo tracks "
    "(the real 10.npz features are not available)"
)
#: Default number of landmarks of the stand-in, about the size of the real dataset 10.
STANDIN_NUM_LANDMARKS = 13_000

_IMU_KEYS = ("time_stamps", "linear_velocity", "angular_velocity")


def load_dataset10(directory, how):
    """The real ``10.npz`` in ``directory`` if there, else the stand-in (:func:`course_standin10`, seed 0).

    ``how`` (where the directory came from) goes into the ``FileNotFoundError`` when neither is there.
    """
    full = directory / "10.npz"
    if os.path.lexists(full):
        return load_npz(full)
    missing = missing_standin_inputs(directory)
    if not missing:
        return course_standin10(directory, seed=0)
    raise FileNotFoundError(
        f"dataset 10: the course file 10.npz is not in {directory} (the data directory from {how}), "
        f"and the stand-in (simulated stereo tracks on dataset 10's real IMU drive) needs "
        f"10_imu_only.npz and 03.npz there, but {' and '.join(missing)} "
        f"{'is' if len(missing) == 1 else 'are'} missing. Set {ENV_VAR} to the folder with the course files."
    )


def course_standin10(data_dir=None, seed=0, **overrides):
    """The dataset-10 stand-in as ``load("10")`` builds it (seed 0), with its seed and simulation changed.

    E.g. 5% gross outlier tracks and dataset 3's IMU lag: ``course_standin10(outlier_share=0.05, imu_lag=1)``.
    Dataset 3's ``imu_T_cam`` disagrees with its IMU (:func:`visla_edu.diagnostics.check_extrinsics`) and the
    real ``10.npz`` has the same one, so the tracks are simulated with the corrected extrinsic (the physical rig,
    ``extra["simulated_imu_T_cam"]``) and the dataset reports the file's, as the real ``10.npz`` would.

    ``data_dir`` is the folder with the stand-in inputs (:func:`visla_edu.data.data_dir`); ``**overrides`` as in
    :func:`standin_dataset10` but not ``imu_T_cam`` (``ValueError`` also for one unknown or out of range).
    """
    from visla_edu import diagnostics  # lazy: only the stand-in needs it

    if "imu_T_cam" in overrides:
        raise ValueError("course_standin10: imu_T_cam is the physical rig's (dataset 3's corrected extrinsic); "
                         "call standin_dataset10 to simulate with another one")
    directory, how = resolve_dir(data_dir)
    missing = missing_standin_inputs(directory)
    if missing:
        raise FileNotFoundError(
            f"course_standin10: {' and '.join(missing)} not in {directory} (the data directory from {how}); "
            f"the stand-in needs {' and '.join(STANDIN_INPUTS)}. Set {ENV_VAR} to the folder with the course files.")
    calibration = load_npz(directory / "03.npz")
    physical_imu_T_cam, _ = diagnostics.resolve_extrinsics(calibration, "auto")
    dataset = standin_dataset10(directory / "10_imu_only.npz", directory / "03.npz", seed=seed,
                                imu_T_cam=physical_imu_T_cam, extrinsic_note=PHYSICAL_RIG_NOTE, **overrides)
    dataset.imu_T_cam = calibration.imu_T_cam.copy()
    dataset.extra["simulated_imu_T_cam"] = physical_imu_T_cam
    return dataset


#: How the stand-in's source line names the extrinsic its tracks were simulated with.
PHYSICAL_RIG_NOTE = ("tracks simulated with 03's corrected imu_T_cam (the physical rig; the file's uncorrected "
                     "one is reported, as 03.npz does)")


def standin_dataset10(imu_only_path, calibration_path, seed=0, imu_T_cam=None, extrinsic_note=None, **overrides):
    """The STAND-IN for course dataset 10: its real IMU drive with simulated stereo tracks.

    The velocities of ``10_imu_only.npz`` define the true drive; landmarks along it are tracked as in
    :func:`visla_edu.simulate.simulate_drive`, and the measured IMU is the real velocities plus the simulation
    noise. The real gyro's biases would make the "true" car climb and roll over, so the true angular velocity
    is the real one minus its mean roll and pitch rates, which the measurement keeps as a constant gyro bias
    (``config.gyro_bias``, ``extra["level_gyro_bias"]``).

    ``imu_only_path`` holds ``time_stamps`` (1, T) or (T,), ``linear_velocity`` and ``angular_velocity`` (3, T);
    ``calibration_path`` is a 2021+ course file of the same rig (``03.npz``: ``K``, ``b``, ``imu_T_cam``);
    ``imu_T_cam`` (4, 4) replaces the file's, ``extrinsic_note`` then saying what it is in the source line;
    ``**overrides`` are :class:`~visla_edu.simulate.SimulationConfig` fields (``K``, ``b`` too; ``num_landmarks``
    defaults to :data:`STANDIN_NUM_LANDMARKS`); the file decides the motion and ``num_frames``. The Dataset is
    named ``"10-standin"``, labelled :data:`STANDIN_LABEL`, with the file's time stamps and ``ground_truth``.
    """
    from visla_edu import simulate  # lazy: loading course files needs no simulation (nor scipy.ndimage)

    time_stamps, true_v, real_w = _read_imu_drive(imu_only_path)
    if "num_frames" in overrides:
        raise ValueError("standin_dataset10: num_frames comes from the IMU file and cannot be overridden")
    overrides.setdefault("num_landmarks", STANDIN_NUM_LANDMARKS)
    level_bias = (float(real_w[:, 0].mean()), float(real_w[:, 1].mean()), 0.0)
    true_w = real_w - np.array(level_bias)
    overrides.setdefault("gyro_bias", level_bias)
    if imu_T_cam is not None:
        overrides["imu_T_cam"] = imu_T_cam
    config = simulate.make_config("course", num_frames=len(time_stamps), **overrides)
    calibration = _read_calibration(calibration_path, need_extrinsic=imu_T_cam is None)
    extrinsic = (extrinsic_note or "imu_T_cam given by the caller") if imu_T_cam is not None \
        else f"imu_T_cam from {calibration_path}"
    return simulate.simulate_along_drive(
        time_stamps, true_v, true_w, config, calibration, seed,
        name="10-standin",
        source=(f"visla_edu.data.standin_dataset10: IMU drive from {imu_only_path}, K and b from "
                f"{calibration_path}, {extrinsic}, seed={seed!r}; {config.describe()}"),
        label=STANDIN_LABEL,
        extra={"preset": "standin", "seed": seed, "config": config, "level_gyro_bias": level_bias},
    )


def _read_imu_drive(path):
    """``time_stamps`` (T,), ``linear_velocity`` and ``angular_velocity`` (T, 3) of an IMU-only file."""
    arrays = read_arrays(path, _IMU_KEYS)
    for key in _IMU_KEYS:
        check_numeric(arrays[key], key, path)
    stamps = arrays["time_stamps"]
    if stamps.ndim not in (1, 2) or stamps.size != stamps.shape[-1] or stamps.size < 2:
        raise ValueError(f"{path}: key 'time_stamps' must have shape (1, T) or (T,) with T >= 2, "
                         f"got {stamps.shape}")
    T = stamps.size
    for key in ("linear_velocity", "angular_velocity"):
        check_shape(arrays[key], (3, T), key, path, T)
    for key in _IMU_KEYS:
        check_finite(arrays[key], key, path)
    stamps = np.array(stamps.reshape(T), dtype=float)
    check_increasing(stamps, path)
    check_time_stamps(stamps, path)
    check_velocities(arrays["linear_velocity"], arrays["angular_velocity"], _IMU_KEYS[1:], path)
    return stamps, time_major(arrays["linear_velocity"]), time_major(arrays["angular_velocity"])


def _read_calibration(path, need_extrinsic):
    """``K`` (3, 3), ``b`` and (if needed, else None) ``imu_T_cam`` (4, 4) of a 2021+ course file."""
    shapes = {"K": (3, 3), "b": (), "imu_T_cam": (4, 4)} if need_extrinsic else {"K": (3, 3), "b": ()}
    arrays = read_arrays(path, tuple(shapes))
    if arrays["b"].size == 1:  # a scalar stored as shape (1,) is accepted too
        arrays["b"] = arrays["b"].reshape(())
    for key, shape in shapes.items():
        check_numeric(arrays[key], key, path)
        check_shape(arrays[key], shape, key, path)
        check_finite(arrays[key], key, path)
    check_calibration_keys(arrays, path, "imu_T_cam" if need_extrinsic else None)
    imu_T_cam = np.array(arrays["imu_T_cam"], dtype=float) if need_extrinsic else None
    return np.array(arrays["K"], dtype=float), float(arrays["b"]), imu_T_cam
