"""Load, check, save and summarise the course data files.

Where the files are
-------------------
The data directory is, in this order: the ``data_dir`` argument, the environment
variable ``VISLA_EDU_DATA``, or ``./data`` under the current working directory.
Course files are never copied into the project: point ``VISLA_EDU_DATA`` at them.

    >>> from visla_edu import data
    >>> ds = data.load("03")                # <data dir>/03.npz
    >>> print(data.format_summary(ds))      # what ``visla-edu info 03`` prints
    >>> sim = data.load("sim")              # a simulated drive with ground truth

The two course formats
----------------------
Both store ``time_stamps`` (1, T), ``features`` (4, M, T) with ``[uL, vL, uR, vR]``
pixels (all four -1 where landmark i is not seen at frame t), ``linear_velocity``
(3, T), ``K`` (3, 3) and ``b`` (). The 2021+ format adds ``angular_velocity`` (3, T)
and ``imu_T_cam`` (4, 4); the 2019/2020 format has ``rotational_velocity`` (3, T)
and ``cam_T_imu`` (4, 4), the inverse transform. :func:`load` converts both to the
time-major :class:`~visla_edu.dataset.Dataset` once, and keeps the features sparse:
the dense array is streamed from the file in chunks of landmark rows (dataset 10's
is 1.3 GB), never held in memory as a whole.

Every problem with a file is reported as a ``FileNotFoundError`` or ``ValueError``
whose message names the file, the key, and the expected and actual shape or value.
"""

import hashlib
import io
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from visla_edu import lie
from visla_edu.dataset import Dataset, GroundTruth, repeated_frames

__all__ = [
    "ENV_VAR",
    "FORMAT_2021",
    "FORMAT_2019",
    "REGISTRY",
    "SIMULATED",
    "GROUND_TRUTH_KEYS",
    "data_dir",
    "load",
    "save",
    "available",
    "repeated_frames",
    "summarize",
    "format_summary",
]

#: Environment variable naming the folder with the course files.
ENV_VAR = "VISLA_EDU_DATA"
FORMAT_2021 = "2021+"
FORMAT_2019 = "2019/2020"

#: Keys each course format must have (and, with the extras below, the only ones allowed).
FORMAT_KEYS = {
    FORMAT_2021: ("time_stamps", "features", "linear_velocity", "angular_velocity", "K", "b", "imu_T_cam"),
    FORMAT_2019: ("time_stamps", "features", "linear_velocity", "rotational_velocity", "K", "b", "cam_T_imu"),
}
#: The angular-velocity key and the extrinsics key of each format.
_FORMAT_SPECIFIC_KEYS = {FORMAT_2021: ("angular_velocity", "imu_T_cam"), FORMAT_2019: ("rotational_velocity", "cam_T_imu")}
#: Extra keys written by :func:`save` for drives with ground truth.
GROUND_TRUTH_KEYS = (
    "ground_truth_world_T_imu",
    "ground_truth_landmarks",
    "ground_truth_linear_velocity",
    "ground_truth_angular_velocity",
    "ground_truth_outlier",
)
#: Extra string keys written by :func:`save`.
TEXT_KEYS = ("name", "label")

#: Names that :func:`load` answers with a simulated drive, and their preset.
SIMULATED = {"sim": "course", "sim-small": "small", "sim-tiny": "tiny"}

#: Known course files: name -> sha256, format and a description (used as ``Dataset.label``).
REGISTRY = {
    "03": {
        "sha256": "fdfd30237cb0a5697625af7392acc2a241c2be299a7d5cf2d0e189fa95a1f0c9",
        "format": FORMAT_2021,
        "description": "dataset 3: KITTI-360 drive 2013_05_28_drive_0003, "
        "10 Hz stereo feature tracks + IMU velocities",
    },
    "10": {
        "sha256": None,  # no public copy of the full file was available to hash
        "format": FORMAT_2021,
        "description": "dataset 10: KITTI-360 drive 2013_05_28_drive_0010, "
        "10 Hz stereo feature tracks + IMU velocities",
    },
    "0022": {
        "sha256": "f190bd587bb8178185cae90113b51601caf66b81a6173032dbd5a450ca0e8c8b",
        "format": FORMAT_2019,
        "description": "KITTI raw 2011_09_26_drive_0022 (2019/2020 course format), "
        "10 Hz stereo feature tracks + IMU velocities",
    },
    "10_imu_only": {
        "sha256": "5543a9f404a80564b1ea382b7c2101652f3ef0829aa53fe16f0bbd93257018aa",
        "format": "2021+ (IMU only)",
        "description": "dataset 10: KITTI-360 drive 2013_05_28_drive_0010, IMU velocities only "
        "(no features); the input of the stand-in load('10')",
    },
}
_COURSE_NAMES = ("03", "10", "0022")
_STANDIN_INPUTS = ("10_imu_only.npz", "03.npz")

#: Bytes of the dense features decoded at a time (tests shrink it to exercise chunking).
_CHUNK_BYTES = 8 * 2**20
#: Tolerance on ``R^T R = I`` for the camera extrinsics.
RIGID_TOL = 1e-6
_PLANES = ("uL", "vL", "uR", "vR")


# --------------------------------------------------------------------------- data directory


def _resolve_dir(path=None):
    """The data directory and a phrase saying where it came from."""
    if path is not None:
        return Path(path).expanduser().resolve(), "the data_dir argument"
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return Path(env).expanduser().resolve(), f"{ENV_VAR}={env}"
    return (Path.cwd() / "data").resolve(), f"the default ./data ({ENV_VAR} is not set)"


def data_dir(path=None):
    """The folder with the course files, as an absolute path.

    Parameters
    ----------
    path : str or os.PathLike, optional
        Use this folder. Otherwise the environment variable ``VISLA_EDU_DATA``, and if
        that is unset or empty, ``./data`` under the current working directory.

    Returns
    -------
    pathlib.Path
        Absolute; it is not checked to exist.
    """
    return _resolve_dir(path)[0]


def available(data_dir=None):
    """Names :func:`load` can answer right now, for menus in the CLI and widgets.

    Parameters
    ----------
    data_dir : str or os.PathLike, optional
        See :func:`data_dir`.

    Returns
    -------
    list of str
        Course names whose files exist (``"10"`` also when only the stand-in inputs
        ``10_imu_only.npz`` and ``03.npz`` exist), then ``"sim"``.
    """
    directory, _ = _resolve_dir(data_dir)
    names = []
    for name in _COURSE_NAMES:
        if (directory / f"{name}.npz").is_file() or (name == "10" and _has_standin_inputs(directory)):
            names.append(name)
    return names + ["sim"]


def _has_standin_inputs(directory):
    return all((directory / f).is_file() for f in _STANDIN_INPUTS)


# --------------------------------------------------------------------------- load


def load(name_or_path, data_dir=None):
    """Load a course file or a simulated drive as a :class:`~visla_edu.dataset.Dataset`.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A course name (``"03"``, ``"0022"``, ``"10"``: the file ``<data dir>/<name>.npz``),
        ``"sim"``, ``"sim-small"`` or ``"sim-tiny"`` (simulated with seed 0), or a path to
        an ``.npz`` file in either course format or written by :func:`save`.
        ``"10"`` falls back to a stand-in when ``10.npz`` is absent: simulated stereo
        tracks on dataset 10's real IMU drive (``10_imu_only.npz`` + ``03.npz``'s rig).
    data_dir : str or os.PathLike, optional
        Folder of the course files, see :func:`data_dir`.

    Returns
    -------
    Dataset
        Time-major arrays, sparse observations; ``source`` is the absolute file path and
        ``label`` describes known files (recognised by sha256).

    Raises
    ------
    FileNotFoundError
        The file is not there (the message says where it looked).
    ValueError
        The file is not a valid course file (the message names key, expected and actual).
    """
    if isinstance(name_or_path, os.PathLike) or _looks_like_path(name_or_path):
        return _load_npz(_find_file(name_or_path, data_dir))
    name = _check_name(name_or_path)
    if name in SIMULATED:
        from visla_edu import simulate  # lazy: simulation is optional for loading files

        return simulate.simulate_drive(preset=SIMULATED[name], seed=0)
    directory, how = _resolve_dir(data_dir)
    if name == "10":
        return _load_dataset10(directory, how)
    path = directory / f"{name}.npz"
    if not path.is_file():
        raise FileNotFoundError(_not_found_message(f"{name}.npz", directory, how))
    return _load_npz(path)


def _looks_like_path(value):
    return isinstance(value, str) and (value.endswith(".npz") or "/" in value or os.sep in value)


def _check_name(value):
    if not isinstance(value, str):
        raise TypeError(f"load: expected a dataset name or a path, got {type(value).__name__} {value!r}")
    if not value.strip():
        raise ValueError("load: empty dataset name; use e.g. '03', '0022', '10' or 'sim'")
    return value.strip()


def _not_found_message(filename, directory, how):
    known = ", ".join(repr(n) for n in (*_COURSE_NAMES, *SIMULATED))
    return (
        f"course file {filename} not found in {directory} (the data directory from {how}). "
        f"Set {ENV_VAR} to the folder with the course files or pass data_dir=...; "
        f"known names: {known}."
    )


def _find_file(path, data_dir):
    """An existing file given as a path: as given, else relative to the data directory."""
    given = Path(path).expanduser()
    if given.is_file():
        return given.resolve()
    directory, how = _resolve_dir(data_dir)
    if not given.is_absolute() and (directory / given).is_file():
        return (directory / given).resolve()
    where = f"{given.resolve()}" if given.is_absolute() else f"{given.resolve()} nor in {directory} ({how})"
    raise FileNotFoundError(
        f"no data file {str(path)!r}: not found at {where}. "
        f"Set {ENV_VAR} to the folder with the course files or pass an existing path."
    )


def _standin_dataset10(directory):
    """The stand-in for dataset 10, with the same calibration quirk as the course files.

    Dataset 3 comes from the same vehicle. Its file's ``imu_T_cam`` has axes that disagree
    with its IMU (found by :func:`visla_edu.diagnostics.check_extrinsics`), and the real
    ``10.npz`` carries the same calibration. So the stand-in's cameras are simulated with the
    corrected extrinsic (the physical rig), and the dataset reports the file's uncorrected
    one, exactly as a user holding the real ``10.npz`` would see it.
    """
    from visla_edu import diagnostics, simulate

    calibration = _load_npz(directory / "03.npz")
    physical_imu_T_cam, _ = diagnostics.resolve_extrinsics(calibration, "auto")
    dataset = simulate.standin_dataset10(directory / "10_imu_only.npz", directory / "03.npz",
                                         imu_T_cam=physical_imu_T_cam)
    dataset.imu_T_cam = calibration.imu_T_cam.copy()
    dataset.extra["simulated_imu_T_cam"] = physical_imu_T_cam
    return dataset


def _load_dataset10(directory, how):
    """The real ``10.npz`` if present, else the stand-in built from its IMU drive."""
    full = directory / "10.npz"
    if full.is_file():
        return _load_npz(full)
    if _has_standin_inputs(directory):
        return _standin_dataset10(directory)
    missing = [f for f in _STANDIN_INPUTS if not (directory / f).is_file()]
    raise FileNotFoundError(
        f"dataset 10: the course file 10.npz is not in {directory} (the data directory from {how}), "
        f"and the stand-in (simulated stereo tracks on dataset 10's real IMU drive) needs "
        f"10_imu_only.npz and 03.npz there, but {' and '.join(missing)} "
        f"{'is' if len(missing) == 1 else 'are'} missing. Set {ENV_VAR} to the folder with the course files."
    )


def _load_npz(path):
    """Read, check and convert one ``.npz`` file (see :func:`load`)."""
    path = Path(path).resolve()
    sha = _sha256(path)
    try:
        with zipfile.ZipFile(path) as zf:
            fmt, arrays, sparse = _read_contents(zf, path)
    except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
        raise ValueError(_corrupt_message(path, exc)) from None
    name, label, known = _identity(path, sha, arrays)
    extra = {"sha256": sha, "format": fmt, "known_file": known}
    return _build_dataset(fmt, arrays, sparse, path, name, label, extra)


def _sha256(path, block=2**20):
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(block):
            digest.update(chunk)
    return digest.hexdigest()


def _corrupt_message(path, exc):
    with open(path, "rb") as f:
        start = f.read(6)
    hint = " It is a single .npy array, not an .npz archive." if start == b"\x93NUMPY" else ""
    return (
        f"{path}: not a valid .npz (zip) archive: the file is truncated, corrupt, or not an .npz "
        f"file ({type(exc).__name__}: {exc}).{hint} Re-download the course file."
    )


def _read_contents(zf, path):
    """Format, checked small arrays, and sparse features ``(frame_ptr, ids, z, M)``."""
    members = _member_keys(zf)
    fmt = _detect_format(members, path)
    _reject_unexpected(members, fmt, path)
    arrays = {key: _read_small(zf, member, key, path) for key, member in members.items() if key != "features"}
    T = _check_course_arrays(arrays, fmt, path)
    sparse = _features_streamed(zf, members["features"], arrays, T, path)
    if sparse is None:  # fortran order or an unusual .npy version: read it whole
        sparse = _features_in_memory(zf, members["features"], arrays, T, path)
    return fmt, arrays, sparse


def _features_streamed(zf, member, arrays, T, path):
    """Sparse features ``(frame_ptr, ids, z, M)`` decoded chunk by chunk; None if not C-order."""
    with zf.open(member) as fp:
        header = _read_npy_header(fp, path)
        if header is None or header[1]:
            return None
        M = _check_features_header(header[0], header[2], T, path)
        _check_extras(arrays, T, M, path)
        try:
            sparse = _collect_observations(_stream_chunks(fp, header[2], M, T, path), T, path)
        except ValueError:
            _drain(fp)  # a damaged archive shows only at the end (CRC): report that instead
            raise
        if fp.read(1):
            raise ValueError(f"{path}: key 'features' has extra bytes after its {header[0]} array data")
    return sparse + (M,)


def _drain(fp, block=2**22):
    """Read a zip member to its end, so zipfile checks its CRC (raises BadZipFile)."""
    while fp.read(block):
        pass


def _features_in_memory(zf, member, arrays, T, path):
    """Like :func:`_features_streamed`, reading the whole dense array first."""
    dense = _read_small(zf, member, "features", path)
    M = _check_features_header(dense.shape, dense.dtype, T, path)
    _check_extras(arrays, T, M, path)
    return _collect_observations(_array_chunks(dense, M, T), T, path) + (M,)


def _member_keys(zf):
    """Key -> zip member name (``np.savez`` stores key ``k`` as ``k.npy``)."""
    return {(n[:-4] if n.endswith(".npy") else n): n for n in zf.namelist() if not n.endswith("/")}


def _detect_format(members, path):
    present = set(members)
    for fmt, required in FORMAT_KEYS.items():
        if set(required) <= present:
            return fmt
    markers = {FORMAT_2021: {"angular_velocity", "imu_T_cam"}, FORMAT_2019: {"rotational_velocity", "cam_T_imu"}}
    candidates = [fmt for fmt, keys in markers.items() if keys & present]
    found = f"found keys {sorted(present)}"
    if len(candidates) == 1:
        fmt = candidates[0]
        missing = [k for k in FORMAT_KEYS[fmt] if k not in present]
        hint = ""
        if path.stem == "10_imu_only":
            hint = " This is dataset 10's IMU-only file: load('10') builds the stand-in from it."
        raise ValueError(f"{path}: looks like the {fmt} course format but is missing key(s) {missing}; {found}.{hint}")
    needs = "; ".join(
        f"{fmt} needs {list(req)} (missing {[k for k in req if k not in present]})" for fmt, req in FORMAT_KEYS.items()
    )
    raise ValueError(f"{path}: matches neither course format: {needs}; {found}.")


def _reject_unexpected(members, fmt, path):
    allowed = set(FORMAT_KEYS[fmt]) | set(GROUND_TRUTH_KEYS) | set(TEXT_KEYS)
    extra = sorted(k for k in members if k not in allowed)
    if extra:
        raise ValueError(
            f"{path}: unexpected key(s) {extra} in a {fmt} course file; allowed are {list(FORMAT_KEYS[fmt])} "
            f"and, for files written by visla_edu.data.save, {list(GROUND_TRUTH_KEYS + TEXT_KEYS)}."
        )


def _read_small(zf, member, key, path):
    """One whole member as an array (CRC-checked by ``zf.read``)."""
    raw = zf.read(member)
    try:
        return np.lib.format.read_array(io.BytesIO(raw), allow_pickle=False)
    except (ValueError, TypeError, EOFError, OSError, UnicodeError) as exc:
        raise ValueError(f"{path}: key '{key}' is not a readable numpy array ({exc})") from None


# --------------------------------------------------------------------------- checks of the small arrays


def _check_course_arrays(arrays, fmt, path):
    """Check dtypes, shapes, finiteness and meaning of the non-feature keys; return T."""
    velocity_key, pose_key = _FORMAT_SPECIFIC_KEYS[fmt]
    keys = ("time_stamps", "linear_velocity", velocity_key, "K", "b", pose_key)
    for key in keys:
        _check_numeric(arrays[key], key, path)
    T = _frame_count(arrays["time_stamps"], path)
    for key in ("linear_velocity", velocity_key):
        _check_shape(arrays[key], (3, T), key, path, T)
    for key, shape in (("K", (3, 3)), ("b", ()), (pose_key, (4, 4))):
        _check_shape(arrays[key], shape, key, path)
    for key in keys:
        _check_finite(arrays[key], key, path)
    _check_increasing(arrays["time_stamps"][0], path)
    _check_intrinsics(arrays["K"], path)
    _check_baseline(arrays["b"], path)
    _check_rigid(arrays[pose_key], pose_key, path)
    return T


def _check_numeric(arr, key, path, kinds="fiu"):
    if arr.dtype.kind not in kinds:
        want = "boolean" if kinds == "b" else "real numbers"
        raise ValueError(f"{path}: key '{key}' must hold {want}, got dtype {arr.dtype}")


def _frame_count(time_stamps, path):
    if time_stamps.ndim != 2 or time_stamps.shape[0] != 1 or time_stamps.shape[1] < 1:
        raise ValueError(f"{path}: key 'time_stamps' expected shape (1, T) with T >= 1, got {time_stamps.shape}")
    return time_stamps.shape[1]


def _check_shape(arr, expected, key, path, T=None):
    if arr.shape != tuple(expected):
        note = f" (T = {T} from time_stamps)" if T is not None else ""
        raise ValueError(f"{path}: key '{key}' expected shape {tuple(expected)}{note}, got {arr.shape}")


def _check_finite(arr, key, path):
    bad = ~np.isfinite(arr)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{path}: key '{key}' has a non-finite value {arr[index]} at index {index}")


def _check_increasing(stamps, path):
    bad = np.flatnonzero(np.diff(stamps) <= 0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{path}: key 'time_stamps' must be strictly increasing, but time_stamps[0, {i + 1}] = "
            f"{stamps[i + 1]!r} is not after time_stamps[0, {i}] = {stamps[i]!r}"
        )


def _check_intrinsics(K, path):
    lower = K[np.tril_indices(3, -1)]
    if np.any(lower != 0) or K[2, 2] != 1:
        raise ValueError(
            f"{path}: key 'K' must be upper triangular with K[2, 2] = 1 "
            f"([[fsu, s, cu], [0, fsv, cv], [0, 0, 1]]), got {K.tolist()}"
        )
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{path}: key 'K' needs positive focal lengths, got fsu = {K[0, 0]}, fsv = {K[1, 1]}")


def _check_baseline(b, path):
    if not b > 0:
        raise ValueError(f"{path}: key 'b' (stereo baseline, metres) must be positive, got {b.item()!r}")


def _check_rigid(T, key, path):
    R = T[:3, :3]
    orth = float(np.abs(R.T @ R - np.eye(3)).max())
    if orth > RIGID_TOL:
        raise ValueError(
            f"{path}: key '{key}' is not a rigid transform: max |R^T R - I| = {orth:.3g} > {RIGID_TOL:g}"
        )
    det = float(np.linalg.det(R))
    if abs(det - 1) > 10 * RIGID_TOL:
        raise ValueError(
            f"{path}: key '{key}' is not a rigid transform: det(R) = {det:.6g}, expected +1 (a reflection?)"
        )
    if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(
            f"{path}: key '{key}' is not a rigid transform: last row is {T[3].tolist()}, expected [0, 0, 0, 1]"
        )


def _check_extras(arrays, T, M, path):
    """Check ground-truth and text keys written by :func:`save`."""
    present = [k for k in GROUND_TRUTH_KEYS if k in arrays]
    if present and len(present) < len(GROUND_TRUTH_KEYS):
        missing = [k for k in GROUND_TRUTH_KEYS if k not in arrays]
        raise ValueError(f"{path}: has ground-truth key(s) {present} but is missing {missing}")
    if present:
        shapes = dict(zip(GROUND_TRUTH_KEYS, [(T, 4, 4), (M, 3), (T, 3), (T, 3), (M,)]))
        for key, shape in shapes.items():
            _check_numeric(arrays[key], key, path, kinds="b" if key.endswith("outlier") else "fiu")
            _check_shape(arrays[key], shape, key, path)
            _check_finite(arrays[key], key, path)
    for key in TEXT_KEYS:
        if key in arrays and (arrays[key].dtype.kind != "U" or arrays[key].shape != ()):
            raise ValueError(
                f"{path}: key '{key}' must be a single string, got dtype {arrays[key].dtype} "
                f"shape {arrays[key].shape}"
            )


# --------------------------------------------------------------------------- features, streamed


def _read_npy_header(fp, path):
    """``(shape, fortran_order, dtype)`` of an ``.npy`` stream, or None for versions 3+."""
    try:
        version = np.lib.format.read_magic(fp)
        if version == (1, 0):
            return np.lib.format.read_array_header_1_0(fp)
        if version == (2, 0):
            return np.lib.format.read_array_header_2_0(fp)
        return None
    except (ValueError, TypeError, EOFError, OSError, UnicodeError) as exc:
        raise ValueError(f"{path}: key 'features' is not a readable numpy array ({exc})") from None


def _check_features_header(shape, dtype, T, path):
    """Check the shape and dtype of ``features``; return M."""
    if len(shape) != 3 or shape[0] != 4 or shape[2] != T:
        raise ValueError(f"{path}: key 'features' expected shape (4, M, T) with T = {T} from time_stamps, got {shape}")
    if dtype.kind not in "fiu":
        raise ValueError(f"{path}: key 'features' must hold real numbers, got dtype {dtype}")
    return shape[1]


def _rows_per_chunk(T, itemsize):
    return max(1, _CHUNK_BYTES // max(1, T * itemsize))


def _stream_chunks(fp, dtype, M, T, path):
    """Yield ``(plane, first_row, block)`` with block (rows, T) of ``features[plane]``, in file order."""
    step = _rows_per_chunk(T, dtype.itemsize)
    for plane in range(4):
        for first in range(0, M, step):
            rows = min(step, M - first)
            raw = _read_exact(fp, rows * T * dtype.itemsize, path)
            yield plane, first, np.frombuffer(raw, dtype=dtype).reshape(rows, T)


def _array_chunks(features, M, T):
    """Like :func:`_stream_chunks` for an array already in memory."""
    step = _rows_per_chunk(T, features.dtype.itemsize)
    for plane in range(4):
        for first in range(0, M, step):
            yield plane, first, features[plane, first:first + step]


def _read_exact(fp, size, path):
    parts, remaining = [], size
    while remaining:
        part = fp.read(remaining)
        if not part:
            raise ValueError(f"{path}: key 'features' is truncated: its array data ends {remaining} bytes early")
        parts.append(part)
        remaining -= len(part)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def _collect_observations(chunks, T, path):
    """Sparse frame-major observations ``(frame_ptr, obs_ids, obs_z)`` from feature blocks.

    Plane 0 (``uL``) decides which entries are observations; planes 1-3 must be -1
    exactly where ``uL`` is -1, and their values are taken at the observed entries.
    """
    found, z = [], None
    for plane, first, block in chunks:
        _check_finite_block(block, plane, first, path)
        if plane == 0:
            rows, frames = np.nonzero(block != -1)
            found.append((rows + first, frames, block[rows, frames]))
            continue
        if z is None:
            ids, frames, z = _start_observations(found)
        lo, hi = np.searchsorted(ids, [first, first + len(block)])
        values = block[ids[lo:hi] - first, frames[lo:hi]]
        _check_complete(block, plane, first, ids[lo:hi], frames[lo:hi], values, path)
        z[lo:hi, plane] = values
    if z is None:
        ids, frames, z = _start_observations(found)
    return _frame_major(ids, frames, z, T)


def _start_observations(found):
    """Concatenate plane-0 findings: landmark ids (sorted), frames, and z with uL filled."""
    ids = np.concatenate([f[0] for f in found]) if found else np.zeros(0, dtype=np.int64)
    frames = np.concatenate([f[1] for f in found]) if found else np.zeros(0, dtype=np.int64)
    z = np.empty((len(ids), 4))
    z[:, 0] = np.concatenate([f[2] for f in found]) if found else 0.0
    return ids.astype(np.int64), frames.astype(np.int64), z


def _check_finite_block(block, plane, first, path):
    bad = ~np.isfinite(block)
    if bad.any():
        row, frame = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"{path}: key 'features' has a non-finite value {block[row, frame]} at index "
            f"({plane}, {first + row}, {frame}) ({_PLANES[plane]} of landmark {first + row} at frame {frame})"
        )


def _check_complete(block, plane, first, ids, frames, values, path):
    """Each observation has all four pixels or none (all -1)."""
    if np.count_nonzero(block == -1) == block.size - len(values) and not np.any(values == -1):
        return
    observed = np.zeros(block.shape, dtype=bool)
    observed[ids - first, frames] = True
    row, frame = (int(i) for i in np.argwhere((block == -1) == observed)[0])
    landmark = first + row
    state = "observed (uL != -1)" if observed[row, frame] else "not observed (uL = -1)"
    raise ValueError(
        f"{path}: key 'features': landmark {landmark} at frame {frame} is partly observed: it is {state} "
        f"but {_PLANES[plane]} = features[{plane}, {landmark}, {frame}] = {block[row, frame]}; "
        f"all four of [uL, vL, uR, vR] must be -1 (not observed) or none of them"
    )


def _frame_major(ids, frames, z, T):
    """Reorder landmark-major entries into the CSR-over-frames layout of :class:`Dataset`."""
    order = np.lexsort((ids, frames))
    frame_ptr = np.zeros(T + 1, dtype=np.int64)
    np.cumsum(np.bincount(frames, minlength=T), out=frame_ptr[1:])
    return frame_ptr, ids[order], z[order]


# --------------------------------------------------------------------------- building the Dataset


def _identity(path, sha, arrays):
    """``(name, label, known_registry_name_or_None)`` of a loaded file."""
    known = next((n for n, entry in REGISTRY.items() if entry["sha256"] == sha), None)
    if known is not None:
        return known, REGISTRY[known]["description"], known
    name = str(arrays["name"]) if "name" in arrays else path.stem
    if "label" in arrays:
        return name, str(arrays["label"]), None
    entry = REGISTRY.get(path.stem)
    if entry is None:
        return name, f"{path.name} (not a known course file)", None
    if entry["sha256"] is None:
        return name, f"{entry['description']} (sha256 {sha} not on record)", None
    return name, f"{entry['description']} -- but this copy's sha256 differs from the known file (modified?)", None


def _time_major(arr):
    """``(k, T)`` file layout -> ``(T, k)`` float64, C-contiguous."""
    return np.ascontiguousarray(arr.T, dtype=float)


def _build_dataset(fmt, arrays, sparse, path, name, label, extra):
    frame_ptr, obs_ids, obs_z, M = sparse
    if fmt == FORMAT_2021:
        angular, imu_T_cam = arrays["angular_velocity"], np.array(arrays["imu_T_cam"], dtype=float)
    else:
        angular, imu_T_cam = arrays["rotational_velocity"], lie.se3_inv(arrays["cam_T_imu"])
    return Dataset(
        name=name,
        source=str(path),
        time_stamps=np.array(arrays["time_stamps"][0], dtype=float),
        linear_velocity=_time_major(arrays["linear_velocity"]),
        angular_velocity=_time_major(angular),
        K=np.array(arrays["K"], dtype=float),
        b=float(arrays["b"]),
        imu_T_cam=imu_T_cam,
        num_landmarks=int(M),
        frame_ptr=frame_ptr,
        obs_ids=obs_ids,
        obs_z=obs_z,
        ground_truth=_ground_truth(arrays),
        label=label,
        extra=extra,
    )


def _ground_truth(arrays):
    if GROUND_TRUTH_KEYS[0] not in arrays:
        return None
    world_T_imu, landmarks, linear, angular, outlier = (arrays[k] for k in GROUND_TRUTH_KEYS)
    return GroundTruth(
        world_T_imu=np.array(world_T_imu, dtype=float),
        landmarks=np.array(landmarks, dtype=float),
        linear_velocity=np.array(linear, dtype=float),
        angular_velocity=np.array(angular, dtype=float),
        outlier=np.array(outlier, dtype=bool),
    )


# --------------------------------------------------------------------------- save


def save(dataset, path):
    """Write a dataset as a 2021+ course file (plus ground truth and its name and label).

    Parameters
    ----------
    dataset : Dataset
    path : str or os.PathLike
        Target file; ``.npz`` is appended if missing. Written atomically (temporary
        file, then rename). The dense features ``(4, M, T)`` are built in memory.

    Returns
    -------
    pathlib.Path
        The absolute path written. :func:`load` on it gives back identical arrays.
    """
    path = Path(path).expanduser()
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    arrays = _course_arrays(dataset)
    if dataset.ground_truth is not None:
        arrays.update(_ground_truth_arrays(dataset.ground_truth))
    arrays["name"] = np.array(str(dataset.name))
    arrays["label"] = np.array(str(dataset.label))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path.resolve()


def _course_arrays(dataset):
    """The 2021+ keys in the course layout: ``(k, T)`` rows and dense ``(4, M, T)`` features."""
    return {
        "time_stamps": np.asarray(dataset.time_stamps, dtype=float)[None, :],
        "features": dataset.to_dense_features(),
        "linear_velocity": np.asarray(dataset.linear_velocity, dtype=float).T,
        "angular_velocity": np.asarray(dataset.angular_velocity, dtype=float).T,
        "K": np.asarray(dataset.K, dtype=float),
        "b": np.array(float(dataset.b)),
        "imu_T_cam": np.asarray(dataset.imu_T_cam, dtype=float),
    }


def _ground_truth_arrays(gt):
    return {
        "ground_truth_world_T_imu": np.asarray(gt.world_T_imu, dtype=float),
        "ground_truth_landmarks": np.asarray(gt.landmarks, dtype=float),
        "ground_truth_linear_velocity": np.asarray(gt.linear_velocity, dtype=float),
        "ground_truth_angular_velocity": np.asarray(gt.angular_velocity, dtype=float),
        "ground_truth_outlier": np.asarray(gt.outlier, dtype=bool),
    }


# --------------------------------------------------------------------------- summary


def _stats(values):
    """``{"min", "median", "max"}`` of an array (None entries when empty)."""
    values = np.asarray(values)
    if values.size == 0:
        return {"min": None, "median": None, "max": None}
    cast = int if values.dtype.kind in "iu" else float
    return {"min": cast(values.min()), "median": float(np.median(values)), "max": cast(values.max())}


def summarize(dataset):
    """Facts about a dataset a student should know before running a filter on it.

    Parameters
    ----------
    dataset : Dataset

    Returns
    -------
    dict
        Keys: ``name, label, source, frames, duration_s, time_step_s`` (mean/min/max),
        ``landmarks, landmarks_never_observed, observations, observations_per_frame``
        (min/median/max), ``frames_without_observations, track_length_frames``
        (min/median/max over observed landmarks), ``landmarks_seen_once,
        nonpositive_disparity, nonpositive_disparity_share, tiny_disparity,
        tiny_disparity_depth_m, repeated_frames, tracks_contiguous,
        noncontiguous_landmarks, speed_m_s`` (mean/min/max), ``distance_m, ground_truth``.
    """
    ds = dataset
    steps = ds.time_steps
    per_frame = np.diff(ds.frame_ptr)
    lengths = ds.track_lengths()
    observed = lengths > 0
    spans = ds.track_spans()
    gaps = (spans[:, 1] - spans[:, 0] + 1 != lengths) & observed
    disparity = ds.obs_z[:, 0] - ds.obs_z[:, 2]
    nonpositive = int(np.count_nonzero(disparity <= 0))
    speed = np.linalg.norm(ds.linear_velocity, axis=1)
    return {
        "name": ds.name,
        "label": ds.label,
        "source": ds.source,
        "frames": ds.num_frames,
        "duration_s": float(ds.time_stamps[-1] - ds.time_stamps[0]),
        "time_step_s": _mean_min_max(steps),
        "landmarks": ds.num_landmarks,
        "landmarks_never_observed": int(np.count_nonzero(~observed)),
        "observations": ds.num_observations,
        "observations_per_frame": _stats(per_frame),
        "frames_without_observations": int(np.count_nonzero(per_frame == 0)),
        "track_length_frames": _stats(lengths[observed]),
        "landmarks_seen_once": int(np.count_nonzero(lengths == 1)),
        "nonpositive_disparity": nonpositive,
        "nonpositive_disparity_share": nonpositive / max(1, ds.num_observations),
        "tiny_disparity": int(np.count_nonzero((disparity > 0) & (disparity < 1))),
        "tiny_disparity_depth_m": float(ds.K[0, 0] * ds.b),
        "repeated_frames": repeated_frames(ds),
        "tracks_contiguous": not gaps.any(),
        "noncontiguous_landmarks": int(np.count_nonzero(gaps)),
        "speed_m_s": _mean_min_max(speed),
        "distance_m": float(np.sum(speed[:-1] * steps)),
        "ground_truth": ds.ground_truth is not None,
    }


def _mean_min_max(values):
    if len(values) == 0:
        return {"mean": None, "min": None, "max": None}
    return {"mean": float(np.mean(values)), "min": float(np.min(values)), "max": float(np.max(values))}


def _shorten(text, limit=160):
    """``text`` cut to ``limit`` characters (a simulated drive's source lists its whole config)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def format_summary(dataset):
    """The readable text of :func:`summarize` (what ``visla-edu info DATASET`` prints).

    Parameters
    ----------
    dataset : Dataset

    Returns
    -------
    str
    """
    s = summarize(dataset)
    lines = [f"{s['name']}: {s['label']}" if s["label"] else s["name"], f"  source        {_shorten(s['source'])}"]
    lines += _time_lines(s) + _observation_lines(s) + _track_lines(s) + _disparity_lines(s)
    lines += _motion_lines(s)
    return "\n".join(lines)


def _fmt_stats(stats, unit=""):
    def num(x):
        return f"{x:g}" if isinstance(x, float) else str(x)

    return f"min {num(stats['min'])} / median {num(stats['median'])} / max {num(stats['max'])}{unit}"


def _time_lines(s):
    step = s["time_step_s"]
    if step["mean"] is None:
        return [f"  frames        {s['frames']} (a single time stamp)"]
    return [
        f"  frames        {s['frames']} over {s['duration_s']:.1f} s; time step mean {step['mean']:.4f} s "
        f"(min {step['min']:.4f}, max {step['max']:.4f}): use each step's own tau, not a constant"
    ]


def _observation_lines(s):
    never = s["landmarks_never_observed"]
    lines = [f"  landmarks     {s['landmarks']}" + (f" ({never} never observed)" if never else " (every one observed)")]
    lines.append(f"  observations  {s['observations']} in total; per frame {_fmt_stats(s['observations_per_frame'])}")
    if s["frames_without_observations"]:
        count = s["frames_without_observations"]
        lines.append(f"                {count} frames have no observations (prediction only)")
    return lines


def _track_lines(s):
    lines = [
        f"  tracks        length {_fmt_stats(s['track_length_frames'], ' frames')}; "
        f"{s['landmarks_seen_once']} landmarks seen only once"
    ]
    if s["tracks_contiguous"]:
        lines.append("                every track is one contiguous run of frames: a landmark can leave the "
                     "filter after its last observation")
    else:
        lines.append(f"                {s['noncontiguous_landmarks']} tracks have gaps (landmark seen again after "
                     "missing frames): keep them in the filter until their last observation")
    for t in s["repeated_frames"]:
        lines.append(f"  repeated      frame {t} repeats the features of frame {t - 1} exactly "
                     "(duplicated camera frame; the IMU keeps moving)")
    return lines


def _disparity_lines(s):
    return [
        f"  disparity     {s['nonpositive_disparity']} observations ({100 * s['nonpositive_disparity_share']:.2f}%) "
        "have uL - uR <= 0: no depth, skip them when initialising landmarks",
        f"                {s['tiny_disparity']} observations have 0 < uL - uR < 1 px: depth beyond "
        f"{s['tiny_disparity_depth_m']:.0f} m, very uncertain",
    ]


def _motion_lines(s):
    speed = s["speed_m_s"]
    lines = [
        f"  speed         mean {speed['mean']:.2f} m/s (min {speed['min']:.2f}, max {speed['max']:.2f}); "
        f"about {s['distance_m']:.0f} m driven"
    ]
    truth = "yes (poses, landmarks, velocities, outliers)" if s["ground_truth"] else "none (real data)"
    return lines + [f"  ground truth  {truth}"]
