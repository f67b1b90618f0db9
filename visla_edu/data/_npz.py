"""The one reader of ``.npz`` files in visla-edu: course files, and named arrays of any archive.

:func:`load_npz` reads a course file into a :class:`~visla_edu.dataset.Dataset`; :func:`read_arrays` reads
named arrays of any archive (the dataset-10 stand-in's inputs). Both read the zip members themselves
(``allow_pickle=False``), so a damaged, truncated or foreign file is a ``ValueError`` naming the file.

Reading goes in passes, each bounded before the next starts: the zip directory and every member's ``.npy``
header (:mod:`visla_edu.data._zip`), the dtypes and shapes, the small arrays' values and plausibility, then
the features, streamed, and the checks that need the observations.
"""

import hashlib
import zipfile
from pathlib import Path

import numpy as np

from visla_edu import lie
from visla_edu.data._features import features_streamed
from visla_edu.data._format import (
    FORMAT_2019,
    FORMAT_2021,
    FORMAT_KEYS,
    FORMAT_SPECIFIC_KEYS,
    GROUND_TRUTH_FIELDS,
    GROUND_TRUTH_KEYS,
    TEXT_KEYS,
    check_course_arrays,
    check_course_headers,
    check_extras,
)
from visla_edu.data._plausible import check_observations, check_track_layout
from visla_edu.data._registry import identify
from visla_edu._files import check_input_file, format_bytes
from visla_edu.data._zip import ZIP_ERRORS, member_infos, read_header, read_member
from visla_edu.dataset import Dataset, GroundTruth

__all__ = ["load_npz", "read_arrays", "file_sha256", "time_major", "MAX_ARRAY_BYTES"]

#: Largest member :func:`read_arrays` reads whole (it does not know the shapes to expect).
MAX_ARRAY_BYTES = 2**30


def load_npz(path):
    """Read, check and convert one course ``.npz`` file (see :func:`visla_edu.data.load`) to a Dataset.

    ``source`` is the absolute path, ``name`` and ``label`` come from
    :func:`~visla_edu.data._registry.identify`, ``extra = {"sha256", "format", "known_file"}``.
    """
    path = check_input_file(path, "course file")
    sha = file_sha256(path)
    try:
        with zipfile.ZipFile(path) as zf:
            fmt, arrays, sparse = _read_course_members(zf, path)
    except ZIP_ERRORS as exc:
        raise ValueError(_corrupt_message(path, exc)) from None
    stored_name = str(arrays["name"]) if "name" in arrays else None
    stored_label = str(arrays["label"]) if "label" in arrays else None
    name, label, known = identify(path, sha, stored_name, stored_label)
    extra = {"sha256": sha, "format": fmt, "known_file": known}
    return _build_dataset(fmt, arrays, sparse, path, name, label, extra)


def read_arrays(path, keys):
    """The arrays of ``keys`` (each present once, at most :data:`MAX_ARRAY_BYTES`) of an ``.npz``, read whole.

    No pickles; other keys are ignored; dtype and shape are the caller's to check.
    """
    path = check_input_file(path)
    try:
        with zipfile.ZipFile(path) as zf:
            members = member_infos(zf, path)
            missing = [k for k in keys if k not in members]
            if missing:
                raise ValueError(f"{path}: missing key(s) {missing}; keys present: {sorted(members)}")
            headers = {key: read_header(zf, members[key], key, path) for key in keys}
            for key, header in headers.items():
                if header.nbytes > MAX_ARRAY_BYTES:
                    raise ValueError(f"{path}: key '{key}' declares a {header.shape} {header.dtype} array of "
                                     f"{format_bytes(header.nbytes)}, more than the {format_bytes(MAX_ARRAY_BYTES)} "
                                     "read whole; nothing was read")
            return {key: read_member(zf, members[key], key, path) for key in keys}
    except ZIP_ERRORS as exc:
        raise ValueError(_corrupt_message(path, exc)) from None


def file_sha256(path, block=2**20):
    """Hex sha256 (64 lowercase digits) of a file, read ``block`` bytes at a time (bounded memory)."""
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


def _read_course_members(zf, path):
    """Format, checked small arrays, and sparse features ``(frame_ptr, ids, z, M)``, read last, streamed."""
    members = member_infos(zf, path)
    fmt = _detect_format(members, path)
    _reject_unexpected(members, fmt, path)
    headers = {key: read_header(zf, info, key, path) for key, info in members.items()}
    T, M = check_course_headers(headers, fmt, path)
    arrays = {key: read_member(zf, info, key, path) for key, info in members.items() if key != "features"}
    check_course_arrays(arrays, fmt, path)
    check_extras(arrays, T, M, path)
    with zf.open(members["features"]) as fp:
        fp.read(headers["features"].data_offset)
        frame_ptr, obs_ids, obs_z = features_streamed(fp, headers["features"], path)
    check_observations(arrays["K"], obs_z, path)
    check_track_layout(frame_ptr, obs_ids, M, path)
    return fmt, arrays, (frame_ptr, obs_ids, obs_z, M)


def _detect_format(members, path):
    """The course format whose keys are all present, else a ``ValueError`` saying what is missing."""
    present = set(members)
    for fmt, required in FORMAT_KEYS.items():
        if set(required) <= present:
            return fmt
    if {"world_T_imu", "mode"} <= present and "features" not in present:
        raise ValueError(f"{path}: is a result file of 'visla-edu run --out' (keys world_T_imu, landmarks, mode, "
                         "...), not a course file; give the course file the run read, or read this one with "
                         "visla_edu.run.load_result")
    candidates = [fmt for fmt, keys in FORMAT_SPECIFIC_KEYS.items() if present.intersection(keys)]
    found = f"found keys {sorted(present)}"
    if len(candidates) == 1:
        fmt = candidates[0]
        missing = [k for k in FORMAT_KEYS[fmt] if k not in present]
        hint = " This is dataset 10's IMU-only file: load('10') builds the stand-in from it." \
            if path.stem == "10_imu_only" else ""
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


def time_major(arr):
    """``(k, T)`` file layout -> ``(T, k)`` float64, C-contiguous (a copy unless ``arr.T`` already is)."""
    return np.ascontiguousarray(arr.T, dtype=float)


def _build_dataset(fmt, arrays, sparse, path, name, label, extra):
    """The :class:`Dataset` of checked arrays: time-major, ``imu_T_cam`` whatever the format."""
    frame_ptr, obs_ids, obs_z, M = sparse
    if fmt == FORMAT_2021:
        angular, imu_T_cam = arrays["angular_velocity"], np.array(arrays["imu_T_cam"], dtype=float)
    else:
        angular, imu_T_cam = arrays["rotational_velocity"], lie.se3_inv(arrays["cam_T_imu"])
    return Dataset(
        name=name,
        source=str(path),
        time_stamps=np.array(arrays["time_stamps"][0], dtype=float),
        linear_velocity=time_major(arrays["linear_velocity"]),
        angular_velocity=time_major(angular),
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
    """The :class:`GroundTruth` of a file written by :func:`~visla_edu.data.save`, or None."""
    if GROUND_TRUTH_KEYS[0] not in arrays:
        return None
    fields = {field: np.array(arrays[key], dtype=dtype) for key, (field, dtype) in GROUND_TRUTH_FIELDS.items()}
    return GroundTruth(**fields)
