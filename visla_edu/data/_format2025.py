"""The 2025+ course format (its keys: :mod:`visla_edu.data`): ``datasetNN.npy`` checked and converted.

The file is read without unpickling anything but plain arrays (:mod:`visla_edu.data._pickle`).
Two things the format leaves open are decided from evidence, not assumed:

* **The velocity layout**: (T, 3) and (3, T) differ unless T = 3, which is refused.
* **The extrinsics**: the course's loader documents them once as "left camera regular frame ->
  IMU frame" and once as "from IMU frame to left camera frame", and its "regular" camera frame is
  x forward, y left, z up. Each of the four readings (:func:`visla_edu.camera.extrinsic_readings`)
  gives a rig; under the right one the right camera is the left one moved along the left
  camera's x axis. The loader keeps every reading (``Dataset.extrinsic_readings``) and starts
  from the first rectified one in :data:`READING_ORDER` (a file rectified under none is refused
  with the reason); :func:`visla_edu.diagnostics.calibrate` then decides with the motion.
"""

import numpy as np

from visla_edu.camera import extrinsic_readings
from visla_edu.data._features import features_in_memory
from visla_edu.data._format import (MAX_FRAMES, check_features_header, check_finite, check_increasing, check_numeric,
                                    check_shape)
from visla_edu.data._npz import file_sha256
from visla_edu.data._pickle import read_pickled_dict
from visla_edu.data._plausible import check_observations, check_time_stamps, check_track_layout, check_velocities
from visla_edu.dataset import Dataset
from visla_edu.validation import check_intrinsics, check_plausible_calibration, check_rigid

__all__ = ["FORMAT_2025", "KEYS_2025", "READING_ORDER", "NO_FEATURES", "load_course2025"]

FORMAT_2025 = "2025+"
#: The keys a 2025+ file must have (``features`` may also be absent or None).
KEYS_2025 = ("timestamps", "v_t", "w_t", "K_l", "K_r", "extL_T_imu", "extR_T_imu")
#: The reading the loader starts from when several are rectified: the course loader's
#: "left camera regular frame -> IMU frame" first.
READING_ORDER = ("camera->IMU, regular", "IMU->camera, regular", "camera->IMU, optical", "IMU->camera, optical")
#: ``Dataset.extra`` key of the reason a drive has no feature tracks.
NO_FEATURES = "no_features"
_BASELINE_KEY = "extL_T_imu, extR_T_imu (the baseline between them)"


def load_course2025(path):
    """Read, check and convert one existing 2025+ ``.npy`` course file (str or path-like) to a Dataset.

    ``K`` = ``K_l``, ``K_right`` = ``K_r``, ``b`` from the extrinsics, ``imu_T_cam`` the loader's reading,
    ``extrinsic_readings`` all four, ``extra`` as listed for a 2025+ file in :class:`~visla_edu.dataset.Dataset`.
    """
    path, contents = read_pickled_dict(path)
    _check_keys(contents, path)
    stamps = _time_stamps(contents["timestamps"], path)
    T = len(stamps)
    linear, angular = (_velocity(contents[key], key, T, path) for key in ("v_t", "w_t"))
    check_velocities(linear.T, angular.T, ("v_t", "w_t"), path)
    K_left, K_right = (_intrinsics(contents[key], key, path) for key in ("K_l", "K_r"))
    readings, chosen = _readings(contents, path)
    b = float(np.linalg.norm(chosen.offset))
    check_plausible_calibration(K_left, b, path, chosen.imu_T_left, "extL_T_imu", K_key="K_l", b_key=_BASELINE_KEY)
    check_plausible_calibration(K_right, b, path, K_key="K_r", b_key=_BASELINE_KEY)
    sparse, missing = _features(contents.get("features"), T, K_left, K_right, path)
    frame_ptr, obs_ids, obs_z, M = sparse
    extra = {"sha256": file_sha256(path), "format": FORMAT_2025, "known_file": None, "extrinsic_reading": chosen.name,
             "ignored_keys": sorted(set(contents) - set(KEYS_2025) - {"features"})}
    if missing:
        extra[NO_FEATURES] = missing
    return Dataset(
        name=path.stem, source=str(path), time_stamps=stamps, linear_velocity=linear, angular_velocity=angular,
        K=K_left, b=b, imu_T_cam=chosen.imu_T_left.copy(), num_landmarks=M, frame_ptr=frame_ptr, obs_ids=obs_ids,
        obs_z=obs_z, label=f"{path.name} (2025+ course format, not a registered file)", extra=extra,
        K_right=K_right, extrinsic_readings=readings)


def _check_keys(contents, path):
    missing = [k for k in KEYS_2025 if k not in contents]
    if missing:
        raise ValueError(f"{path}: a 2025+ course file needs key(s) {missing}; found keys {sorted(contents)}")
    for key in KEYS_2025 + (("features",) if contents.get("features") is not None else ()):
        value = contents[key]
        if not isinstance(value, np.ndarray):
            raise ValueError(f"{path}: key '{key}' must be a numpy array, got {type(value).__name__}")
        check_numeric(value, key, path)


def _time_stamps(value, path):
    """``timestamps`` as (T,) float seconds: (T,), (1, T) or (T, 1), finite, increasing at a camera's rate."""
    if value.ndim == 2 and 1 in value.shape:
        value = value.reshape(-1)
    if value.ndim != 1 or len(value) < 1:
        raise ValueError(f"{path}: key 'timestamps' expected shape (T,) with T >= 1 (UNIX seconds), got {value.shape}")
    if len(value) > MAX_FRAMES:
        raise ValueError(f"{path}: key 'timestamps' has T = {len(value)} frames, more than the {MAX_FRAMES} visla-edu "
                         "reads (28 hours at 10 Hz); split the drive into parts")
    stamps = np.array(value, dtype=float)
    check_finite(stamps, "timestamps", path)
    check_increasing(stamps, path, "timestamps", "[{}]")
    check_time_stamps(stamps, path, "timestamps", "[{}]")
    return stamps


def _velocity(value, key, T, path):
    """``v_t`` or ``w_t`` as (T, 3): stored (T, 3) or (3, T); T = 3 is ambiguous and refused."""
    if value.shape == (3, 3) and T == 3:
        raise ValueError(f"{path}: key '{key}' has shape (3, 3) with T = 3 frames from timestamps: it cannot say "
                         "whether rows or columns are the frames; a drive of 3 frames is too short to filter anyway")
    if value.shape not in ((T, 3), (3, T)):
        raise ValueError(f"{path}: key '{key}' expected shape ({T}, 3) or (3, {T}) (T = {T} from timestamps), "
                         f"got {value.shape}")
    check_finite(value, key, path)
    return np.ascontiguousarray(value if value.shape == (T, 3) else value.T, dtype=float)


def _intrinsics(value, key, path):
    check_shape(value, (3, 3), key, path)
    check_finite(value, key, path)
    K = np.array(value, dtype=float)
    check_intrinsics(K, f"{path}: key '{key}'", key)
    return K


def _readings(contents, path):
    """All four readings of the extrinsics and the loader's (the first rectified one of :data:`READING_ORDER`)."""
    for key in ("extL_T_imu", "extR_T_imu"):
        check_shape(contents[key], (4, 4), key, path)
        check_finite(contents[key], key, path)
        check_rigid(np.asarray(contents[key], dtype=float), f"{path}: key '{key}'")
    readings = extrinsic_readings(np.asarray(contents["extL_T_imu"], float), np.asarray(contents["extR_T_imu"], float))
    by_name = {r.name: r for r in readings}
    rectified = [by_name[name] for name in READING_ORDER if by_name[name].rectified]
    if not rectified:
        why = "; ".join(f"read as {r.name}: {r.problem}" for r in readings)
        raise ValueError(f"{path}: keys 'extL_T_imu', 'extR_T_imu' are a rectified stereo pair under no reading "
                         f"(either direction, optical or regular camera frame): {why}. visla-edu's stereo model needs "
                         "the right camera translated along the left camera's x axis, with the same orientation")
    return readings, rectified[0]


def _features(value, T, K_left, K_right, path):
    """Sparse observations ``(frame_ptr, obs_ids, obs_z, M)`` and the reason there are none (``""`` if any)."""
    if value is None:
        empty = (np.zeros(T + 1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 4)), 0)
        return empty, (f"{path.name} has no feature tracks (its key 'features' is absent or None: a dataset shipped "
                       f"with images, {path.stem}_imgs.npy, whose features you track yourself)")
    M = check_features_header(value, T, path, "timestamps")
    frame_ptr, obs_ids, obs_z = features_in_memory(value, path)
    check_observations(K_left, obs_z, path, K_right, K_key="K_l")
    check_track_layout(frame_ptr, obs_ids, M, path)
    return (frame_ptr, obs_ids, obs_z, M), ""
