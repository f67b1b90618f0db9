"""The course file format: its keys, and the checks of every array but the features.

Keys and shapes: :mod:`visla_edu.data`. :func:`check_course_headers` runs on the ``.npy`` headers alone
(:class:`~visla_edu.data._zip.NpyHeader`, which works wherever only ``dtype`` and ``shape`` are read), before
any data is read, and bounds the cost of reading (:data:`MAX_FRAMES`, :data:`MAX_FEATURES_BYTES`);
:func:`check_course_arrays` then checks the small arrays' values and plausibility. Every check raises
``ValueError`` at the first failure, naming ``path`` and ``key`` (:mod:`visla_edu.data`).
"""

import numpy as np

from visla_edu._files import format_bytes
from visla_edu.data._plausible import check_ground_truth_reach, check_time_stamps, check_velocities
from visla_edu.validation import (check_baseline, check_intrinsics, check_plausible_calibration, check_rigid,
                                  check_rigid_poses)

__all__ = [
    "FORMAT_2021",
    "FORMAT_2019",
    "FORMAT_KEYS",
    "FORMAT_SPECIFIC_KEYS",
    "GROUND_TRUTH_KEYS",
    "GROUND_TRUTH_FIELDS",
    "TEXT_KEYS",
    "MAX_FRAMES",
    "MAX_FEATURES_BYTES",
    "check_course_headers",
    "check_course_arrays",
    "check_features_header",
    "check_numeric",
    "check_shape",
    "check_finite",
    "check_increasing",
    "check_calibration_keys",
    "check_extras",
]

FORMAT_2021 = "2021+"
FORMAT_2019 = "2019/2020"

#: Keys each course format must have (and, with the extras below, the only ones allowed).
FORMAT_KEYS = {
    FORMAT_2021: ("time_stamps", "features", "linear_velocity", "angular_velocity", "K", "b", "imu_T_cam"),
    FORMAT_2019: ("time_stamps", "features", "linear_velocity", "rotational_velocity", "K", "b", "cam_T_imu"),
}
#: The angular-velocity key and the extrinsics key of each format.
FORMAT_SPECIFIC_KEYS = {
    FORMAT_2021: ("angular_velocity", "imu_T_cam"),
    FORMAT_2019: ("rotational_velocity", "cam_T_imu"),
}
#: Extra keys written by :func:`~visla_edu.data.save` for drives with ground truth.
GROUND_TRUTH_KEYS = (
    "ground_truth_world_T_imu",
    "ground_truth_landmarks",
    "ground_truth_linear_velocity",
    "ground_truth_angular_velocity",
    "ground_truth_outlier",
)
#: The :class:`~visla_edu.dataset.GroundTruth` field and dtype of each ground-truth key.
GROUND_TRUTH_FIELDS = {key: (key.removeprefix("ground_truth_"), bool if key.endswith("outlier") else float)
                       for key in GROUND_TRUTH_KEYS}
#: Extra string keys written by :func:`~visla_edu.data.save`.
TEXT_KEYS = ("name", "label")
#: Most frames a course file may have: 28 hours at 10 Hz. Every per-frame array (and the
#: filter's per-frame results, about 400 bytes a frame) is bounded by it before it is read.
MAX_FRAMES = 1_000_000
#: Largest dense ``features`` array read (4 GiB, three times dataset 10's 1.3 GB). It is
#: streamed in chunks, so this bounds the time of a load (about 25 s), not its memory.
MAX_FEATURES_BYTES = 4 * 2**30
#: Longest ``name``/``label`` string (characters).
_MAX_TEXT = 10_000


def check_course_headers(headers, fmt, path):
    """Check every key's dtype and shape from its ``.npy`` header (key -> NpyHeader); return ``(T, M)``."""
    T = _check_layout(headers, fmt, path)
    M = check_features_header(headers["features"], T, path)
    _check_extras_layout(headers, T, M, path)
    return T, M


def check_course_arrays(arrays, fmt, path):
    """Check dtypes, shapes, finiteness, meaning and plausibility of the non-feature keys; return T.

    Shapes as in :mod:`visla_edu.data` (``T <=`` :data:`MAX_FRAMES`); time stamps increasing at a
    camera's rate, plausible velocities (:mod:`~._plausible`), :func:`check_calibration_keys`.
    """
    velocity_key, pose_key = FORMAT_SPECIFIC_KEYS[fmt]
    T = _check_layout(arrays, fmt, path)
    for key in ("time_stamps", "linear_velocity", velocity_key, "K", "b", pose_key):
        check_finite(arrays[key], key, path)
    check_increasing(arrays["time_stamps"][0], path)
    check_time_stamps(arrays["time_stamps"][0], path)
    check_velocities(arrays["linear_velocity"], arrays[velocity_key], ("linear_velocity", velocity_key), path)
    check_calibration_keys(arrays, path, pose_key)
    return T


def _check_layout(items, fmt, path):
    """Dtypes and shapes of the keys but ``features`` in ``items`` (arrays or headers); return T."""
    velocity_key, pose_key = FORMAT_SPECIFIC_KEYS[fmt]
    for key in ("time_stamps", "linear_velocity", velocity_key, "K", "b", pose_key):
        check_numeric(items[key], key, path)
    T = _frame_count(items["time_stamps"], path)
    for key in ("linear_velocity", velocity_key):
        check_shape(items[key], (3, T), key, path, T)
    for key, shape in (("K", (3, 3)), ("b", ()), (pose_key, (4, 4))):
        check_shape(items[key], shape, key, path)
    return T


def check_calibration_keys(arrays, path, pose_key=None):
    """``K`` (3, 3), ``b`` () and, unless ``pose_key`` is None, the extrinsics (4, 4): valid, then plausible.

    :mod:`visla_edu.validation`'s checks; the arrays are finite (checked before).
    """
    check_intrinsics(arrays["K"], f"{path}: key 'K'")
    check_baseline(arrays["b"], f"{path}: key 'b'")
    pose = None if pose_key is None else arrays[pose_key]
    if pose is not None:
        check_rigid(pose, f"{path}: key '{pose_key}'")
    check_plausible_calibration(arrays["K"], float(arrays["b"]), path, pose, pose_key or "imu_T_cam")


def check_features_header(header, T, path, stamps_key="time_stamps"):
    """Shape ``(4, M, T)``, a dtype that can hold -1 and pixels, at most :data:`MAX_FEATURES_BYTES`; return M.

    T comes from the key ``stamps_key``; a ``(4, T, M)`` shape gets a transpose hint in the message.
    """
    shape, dtype = header.shape, header.dtype
    if len(shape) != 3 or shape[0] != 4 or shape[2] != T:
        swapped = len(shape) == 3 and shape[0] == 4 and shape[1] == T
        hint = (f"; its landmark and frame axes look swapped ((4, T, M) = {shape}): store it as (4, M, T), "
                "e.g. features.transpose(0, 2, 1)") if swapped else ""
        raise ValueError(f"{path}: key 'features' expected shape (4, M, T) with T = {T} from {stamps_key}, "
                         f"got {shape}{hint}")
    if dtype.kind in "ub":
        raise ValueError(f"{path}: key 'features' has dtype {dtype}, which cannot hold -1, the course's marker "
                         "for 'not observed' (every entry would count as an observation); store the features "
                         "as float (or signed integer) pixels")
    if dtype.kind not in "fi":
        raise ValueError(f"{path}: key 'features' must hold real numbers, got dtype {dtype}")
    if header.nbytes > MAX_FEATURES_BYTES:
        raise ValueError(f"{path}: key 'features' declares a {shape} {dtype} array of "
                         f"{format_bytes(header.nbytes)}, more than the {format_bytes(MAX_FEATURES_BYTES)} "
                         "visla-edu reads (three times the largest course file); nothing was read. "
                         "Is the header damaged, or M or T wrong?")
    return shape[1]


def check_numeric(arr, key, path, kinds="fiu"):
    """``arr`` (any shape) has a dtype kind in ``kinds`` (``"fiu"``: real numbers, ``"b"``: boolean)."""
    if arr.dtype.kind not in kinds:
        want = "boolean" if kinds == "b" else "real numbers"
        raise ValueError(f"{path}: key '{key}' must hold {want}, got dtype {arr.dtype}")


def _frame_count(time_stamps, path):
    """T of ``time_stamps``, which must have shape (1, T) with 1 <= T <= MAX_FRAMES."""
    if time_stamps.ndim != 2 or time_stamps.shape[0] != 1 or time_stamps.shape[1] < 1:
        raise ValueError(f"{path}: key 'time_stamps' expected shape (1, T) with T >= 1, got {time_stamps.shape}")
    if time_stamps.shape[1] > MAX_FRAMES:
        raise ValueError(f"{path}: key 'time_stamps' declares T = {time_stamps.shape[1]} frames, more than the "
                         f"{MAX_FRAMES} visla-edu reads (28 hours at 10 Hz); nothing was read. "
                         "Is the header damaged? Split a longer drive into parts.")
    return time_stamps.shape[1]


def check_shape(arr, expected, key, path, T=None):
    """``arr.shape == expected``; ``T`` (if given) is named in the message as coming from ``time_stamps``."""
    if arr.shape != tuple(expected):
        note = f" (T = {T} from time_stamps)" if T is not None else ""
        raise ValueError(f"{path}: key '{key}' expected shape {tuple(expected)}{note}, got {arr.shape}")


def check_finite(arr, key, path):
    """No NaN or inf in ``arr`` (any shape); the message gives the index of the first one."""
    bad = ~np.isfinite(arr)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{path}: key '{key}' has a non-finite value {arr[index]} at index {index}")


def check_increasing(stamps, path, key="time_stamps", index="[0, {}]"):
    """``stamps`` (T,) strictly increasing; the message names the first pair that is not.

    ``index`` writes entry ``i`` after ``key`` (``"[0, {}]"``: the file's (1, T) layout).
    """
    bad = np.flatnonzero(np.diff(stamps) <= 0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{path}: key '{key}' must be strictly increasing, but {key}{index.format(i + 1)} = "
            f"{float(stamps[i + 1])!r} is not after {key}{index.format(i)} = {float(stamps[i])!r}"
        )


def check_extras(arrays, T, M, path):
    """Check the ground-truth keys (all or none) and the text keys, as :func:`~visla_edu.data.save` writes them.

    Ground truth: numeric (``ground_truth_outlier`` boolean), the shapes of :class:`~visla_edu.dataset.GroundTruth`
    from T and M, finite, rigid poses within the drive's reach (:func:`~._plausible.check_ground_truth_reach`,
    which needs ``time_stamps``); ``name`` and ``label``: one string of at most 10,000 characters. Other keys
    are ignored.
    """
    _check_extras_layout(arrays, T, M, path)
    for key in GROUND_TRUTH_KEYS:
        if key in arrays:
            check_finite(arrays[key], key, path)
    poses_key = GROUND_TRUTH_KEYS[0]
    if poses_key in arrays:
        check_rigid_poses(arrays[poses_key], f"{path}: key '{poses_key}': the pose")
        check_ground_truth_reach(arrays[poses_key], arrays["time_stamps"][0], f"key '{poses_key}'", path)


def _check_extras_layout(items, T, M, path):
    """Dtypes and shapes of the ground-truth and text keys in ``items`` (arrays or headers)."""
    present = [k for k in GROUND_TRUTH_KEYS if k in items]
    if present and len(present) < len(GROUND_TRUTH_KEYS):
        missing = [k for k in GROUND_TRUTH_KEYS if k not in items]
        raise ValueError(f"{path}: has ground-truth key(s) {present} but is missing {missing}")
    if present:
        shapes = dict(zip(GROUND_TRUTH_KEYS, [(T, 4, 4), (M, 3), (T, 3), (T, 3), (M,)]))
        for key, shape in shapes.items():
            check_numeric(items[key], key, path, kinds="b" if key.endswith("outlier") else "fiu")
            check_shape(items[key], shape, key, path)
    for key in TEXT_KEYS:
        item = items.get(key)
        if item is not None and (item.dtype.kind != "U" or item.shape != () or item.dtype.itemsize > 4 * _MAX_TEXT):
            raise ValueError(
                f"{path}: key '{key}' must be a single string of at most {_MAX_TEXT} characters, got dtype "
                f"{item.dtype} shape {item.shape}"
            )

