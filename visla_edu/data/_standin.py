"""The STAND-IN for course dataset 10: its real IMU drive with simulated stereo tracks.

The real feature file ``10.npz`` is not available, only ``10_imu_only.npz`` (its time
stamps and IMU velocities). :func:`standin_dataset10` takes that drive as the true motion
and simulates landmarks, stereo tracks and IMU noise along it
(:func:`visla_edu.simulate.simulate_along_drive`) with the rig of dataset 3, which comes from
the same vehicle. Both input files are read with the package's one ``.npz`` reader and checked
like course files. :func:`load_dataset10` is what ``load("10")`` does.
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
    """The real ``10.npz`` if present, else the stand-in built from its IMU drive.

    Parameters
    ----------
    directory : pathlib.Path
        The data directory.
    how : str
        Where the directory came from (for the error message).

    Returns
    -------
    Dataset

    Raises
    ------
    FileNotFoundError
        Neither ``10.npz`` nor both stand-in inputs are in ``directory``.
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
    """The dataset-10 stand-in as ``load("10")`` builds it, with its seed and simulation changed.

    ``load("10")`` (without ``10.npz``) returns ``course_standin10(seed=0)``. Other seeds and
    :class:`~visla_edu.simulate.SimulationConfig` fields give harder or easier full-size
    drives with the course file's calibration quirk, e.g. 5% gross outlier tracks and
    dataset 3's IMU lag::

        course_standin10(outlier_share=0.05, imu_lag=1)

    Dataset 3 comes from the same vehicle. Its file's ``imu_T_cam`` has axes that disagree
    with its IMU (found by :func:`visla_edu.diagnostics.check_extrinsics`), and the real
    ``10.npz`` carries the same calibration. So the stand-in's cameras are simulated with the
    corrected extrinsic (the physical rig), and the dataset reports the file's uncorrected
    one, exactly as a user holding the real ``10.npz`` would see it.

    Parameters
    ----------
    data_dir : str or os.PathLike, optional
        The folder with ``10_imu_only.npz`` and ``03.npz`` (see :func:`visla_edu.data.data_dir`).
    seed : int
    **overrides
        :class:`~visla_edu.simulate.SimulationConfig` fields, as in :func:`standin_dataset10`
        (``imu_T_cam`` is the physical rig's and cannot be overridden here).

    Returns
    -------
    Dataset
        As :func:`standin_dataset10`; ``extra["simulated_imu_T_cam"]`` is the extrinsic the
        tracks were simulated with.

    Raises
    ------
    FileNotFoundError
        ``10_imu_only.npz`` or ``03.npz`` is not in the data directory.
    ValueError
        A file is unreadable or wrong, or an override is unknown or out of range.
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

    The real feature file ``10.npz`` is not available. The measured velocities of
    ``10_imu_only.npz`` define the true drive, landmarks are placed along that path and
    tracked as in :func:`visla_edu.simulate.simulate_drive` (about
    :data:`STANDIN_NUM_LANDMARKS` landmarks), and the measured IMU is the real velocities plus
    the simulation noise.

    The real gyro has biases of about 0.01 rad/s: integrating it as it is would make the
    "true" car climb over a kilometre and roll over. The true angular velocity is therefore
    the real one minus its mean roll and pitch rates (a car ends about as level as it
    started); that mean is kept in the measurement as a constant gyro bias
    (``config.gyro_bias``, also in ``extra["level_gyro_bias"]``), so the measured velocities
    are still the real ones plus noise.

    Parameters
    ----------
    imu_only_path : str or Path
        ``10_imu_only.npz``: ``time_stamps`` (1, T) or (T,), ``linear_velocity`` (3, T),
        ``angular_velocity`` (3, T).
    calibration_path : str or Path
        A 2021+ course file of the same rig (``03.npz``): ``K`` (3, 3), ``b``, ``imu_T_cam``.
    seed : int
    imu_T_cam : array_like, shape (4, 4), optional
        Use this extrinsic instead of the file's (e.g. a corrected one).
    extrinsic_note : str, optional
        What the source line says of ``imu_T_cam`` (default: "imu_T_cam given by the caller").
    **overrides
        :class:`~visla_edu.simulate.SimulationConfig` fields (``K``, ``b`` too); the motion
        fields and ``num_frames`` do not apply (the file decides).

    Returns
    -------
    Dataset
        Named ``"10-standin"``, labelled :data:`STANDIN_LABEL`, time stamps identical to
        the file's, with ``ground_truth``.

    Raises
    ------
    FileNotFoundError
        A file does not exist.
    ValueError
        A file is not a readable ``.npz``, or a key is missing or has a wrong shape or value.
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
