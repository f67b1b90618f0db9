"""Trajectory files in the KITTI and TUM formats: readers and (atomic) writers.

KITTI (the odometry benchmark's ``poses/NN.txt``)
    One row per frame: the 12 numbers of the top 3x4 block ``[R | t]`` of a 4x4 pose,
    row-major, separated by spaces. A 13-column variant puts the time (s) first.
TUM (``t x y z qx qy qz qw``)
    One row per pose: time (s), position, and the rotation as a unit quaternion with the
    scalar last (scipy's order); lines starting with ``#`` are comments.

visla-edu writes ``world_T_imu`` (the IMU pose, ``world`` = the IMU frame at the first time
stamp) with :func:`write_trajectory`: atomically (a temporary file in the same folder, then
renamed; nothing for a non-finite pose), every float exactly (shortest round-trip repr), returning
the absolute path; :func:`read_trajectory` reads it back. Every ``path`` is a str or os.PathLike.
KITTI's own ground truth holds poses of the left *camera* in the first camera frame
(:func:`~visla_edu.data.kitti_poses_from_imu` converts).

Every problem with a file is a one-line error naming the file, the line and the value: a
``FileNotFoundError`` (no such file, or a folder), a ``PermissionError`` (not readable) or a
``ValueError`` (a FIFO or device, larger than :data:`MAX_TEXT_BYTES`, empty, not text, a row
with another column count, a value that is not a finite number, a rotation not orthonormal
to :data:`ORTHONORMAL_TOL` or with determinant -1, a TUM quaternion whose norm is not 1 to
that tolerance, times not strictly increasing, an unknown suffix).
"""

import os
from pathlib import Path

import numpy as np

from visla_edu._files import atomic_write, expand_user, file_kind, format_bytes
from visla_edu.validation import POSE_RIGID_TOL, nonrigid_frames

__all__ = ["FORMATS", "ORTHONORMAL_TOL", "trajectory_format", "read_table", "read_kitti", "write_kitti", "read_tum",
           "write_tum", "read_trajectory", "write_trajectory"]

#: File suffix -> format name.
FORMATS = {".kitti": "kitti", ".txt": "kitti", ".tum": "tum"}
#: Largest trajectory or times file read (a million frames of TUM rows take about 200 MB).
MAX_TEXT_BYTES = 512 * 2**20
#: Largest ``|R^T R - I|`` entry (and ``| |q| - 1 |`` of a TUM quaternion) a read pose may have:
#: :data:`visla_edu.validation.POSE_RIGID_TOL`.
ORTHONORMAL_TOL = POSE_RIGID_TOL


def trajectory_format(path):
    """The format of a trajectory file from its suffix (:data:`FORMATS`), else a ValueError.

    Returns
    -------
    {"kitti", "tum"}
    """
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"{path}: unknown trajectory format {suffix or '(no suffix)'!r}; use .kitti or .txt "
                         f"(KITTI: 12 numbers per row) or .tum (TUM: t x y z qx qy qz qw)")
    return FORMATS[suffix]


# ----------------------------------------------------------------------------- reading


def read_table(path, allowed_columns, what):
    """The numbers of a whitespace-separated text file, checked (the parser of every reader here).

    Blank lines and lines starting with ``#`` are skipped; every row must have the same
    number of columns, one of ``allowed_columns``, and only finite numbers.

    Parameters
    ----------
    allowed_columns : tuple of int
    what : str
        What the file should hold, for the error messages (e.g. ``"KITTI times: one number per row"``).

    Returns
    -------
    table : ndarray, shape (n, c)
    line_numbers : ndarray of int, shape (n,)
        The file line (from 1) of each row.
    """
    path = expand_user(path)
    _check_text_file(path, what)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (expected {what}: rows of numbers)") from None
    numbered = [(i + 1, line.split()) for i, line in enumerate(lines)
                if line.strip() and not line.lstrip().startswith("#")]
    if not numbered:
        raise ValueError(f"{path}: no rows: the file is empty (expected {what})")
    first_line, first_tokens = numbered[0]
    columns = len(first_tokens)
    for line_no, tokens in numbered:
        if len(tokens) not in allowed_columns or len(tokens) != columns:
            expected = f"{columns} like line {first_line}"
            if line_no == first_line:
                expected = " or ".join(map(str, allowed_columns))
            hint = "; separated by commas? use spaces" if "," in " ".join(tokens) else ""
            raise ValueError(f"{path}: line {line_no} has {len(tokens)} numbers, expected {expected} ({what}){hint}")
    return _parse_numbers(path, numbered), np.array([n for n, _ in numbered])


def _check_text_file(path, what):
    """A readable regular file of bounded size, else a one-line error (a FIFO would block a reader)."""
    kind = file_kind(path)
    if kind in ("missing", "a broken symbolic link", "a directory"):
        where = {"missing": "not found", "a directory": "is a folder, not a file"}.get(kind, "is a broken symbolic link")
        raise FileNotFoundError(f"{path}: {what} file {where}")
    if kind != "a regular file":
        raise ValueError(f"{path}: {what} file is {kind}, not a regular file; save it to a file on disk")
    if not os.access(path, os.R_OK):
        raise PermissionError(f"{path}: {what} file is not readable by this user (permission denied)")
    if path.stat().st_size > MAX_TEXT_BYTES:
        raise ValueError(f"{path}: {format_bytes(path.stat().st_size)}, more than the {format_bytes(MAX_TEXT_BYTES)} "
                         f"of a trajectory of a million frames (expected {what}); nothing was read")


def _parse_numbers(path, numbered):
    """Float array of the tokens, or a ``ValueError`` naming the first bad token and its line."""
    try:
        table = np.array([tokens for _, tokens in numbered], dtype=float)
    except ValueError:
        for line_no, tokens in numbered:
            for column, token in enumerate(tokens, start=1):
                try:
                    float(token)
                except ValueError:
                    raise ValueError(f"{path}: line {line_no}, column {column}: {token!r} is not a number") from None
        raise
    bad = np.argwhere(~np.isfinite(table))
    if len(bad):
        row, column = bad[0]
        raise ValueError(f"{path}: line {numbered[row][0]}, column {column + 1}: non-finite value {table[row, column]}")
    return table


def _check_rotations(path, poses, line_numbers):
    """Rotations of ``poses`` (n, 4, 4) orthonormal to :data:`ORTHONORMAL_TOL`, det +1, else a ValueError."""
    bad, deviation = nonrigid_frames(poses, ORTHONORMAL_TOL)
    if not bad.any():
        return
    i = int(np.argmax(bad))
    if deviation[i] > ORTHONORMAL_TOL:
        raise ValueError(f"{path}: line {line_numbers[i]}: rotation is not orthonormal (largest |R^T R - I| entry "
                         f"{deviation[i]:.3g} > {ORTHONORMAL_TOL:g}); is this a 3x4 pose, row-major?")
    raise ValueError(f"{path}: line {line_numbers[i]}: rotation has determinant -1 (a reflection, not a rotation)")


def _check_increasing(path, times, line_numbers):
    """Time stamps strictly increasing, else a ``ValueError`` naming both lines and values."""
    bad = np.flatnonzero(np.diff(times) <= 0)
    if len(bad):
        i = bad[0]
        raise ValueError(f"{path}: line {line_numbers[i + 1]}: time {float(times[i + 1])!r} does not increase "
                         f"(line {line_numbers[i]} has {float(times[i])!r})")


def _poses(rotations, translations):
    """``(n, 4, 4)`` poses from ``(n, 3, 3)`` rotations and ``(n, 3)`` translations."""
    poses = np.zeros((len(rotations), 4, 4))
    poses[:, :3, :3] = rotations
    poses[:, :3, 3] = translations
    poses[:, 3, 3] = 1.0
    return poses


def read_kitti(path):
    """Read a KITTI poses file (12 numbers per row, or 13 with the time first).

    Returns
    -------
    poses : ndarray, shape (n, 4, 4)
    times : ndarray, shape (n,), or None
        None for a 12-column file.
    """
    table, line_numbers = read_table(path, (12, 13), "KITTI poses: 12 numbers per row, row-major 3x4 [R | t]")
    times = table[:, 0].copy() if table.shape[1] == 13 else None
    blocks = table[:, -12:].reshape(-1, 3, 4)
    poses = _poses(blocks[:, :, :3], blocks[:, :, 3])
    _check_rotations(path, poses, line_numbers)
    if times is not None:
        _check_increasing(path, times, line_numbers)
    return poses, times


def read_tum(path):
    """Read a TUM trajectory file (``t x y z qx qy qz qw`` per row, the quaternion normalised, ``#`` comments).

    Returns
    -------
    times : ndarray, shape (n,)
    poses : ndarray, shape (n, 4, 4)
    """
    table, line_numbers = read_table(path, (8,), "TUM trajectory: t x y z qx qy qz qw")
    norms = np.linalg.norm(table[:, 4:], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1) > ORTHONORMAL_TOL)
    if len(bad):
        raise ValueError(f"{path}: line {line_numbers[bad[0]]}: quaternion (qx qy qz qw) has norm {norms[bad[0]]:.6g}, "
                         "expected a unit quaternion")
    _check_increasing(path, table[:, 0], line_numbers)
    from scipy.spatial.transform import Rotation  # lazy: scipy.spatial takes ~0.5 s to import

    return table[:, 0].copy(), _poses(Rotation.from_quat(table[:, 4:]).as_matrix(), table[:, 1:4])


def read_trajectory(path):
    """Read a trajectory in its suffix's format (:func:`trajectory_format`): :func:`read_tum` or :func:`read_kitti`.

    Returns
    -------
    times : ndarray, shape (n,), or None
        Seconds; None for a 12-column KITTI file. Always first.
    poses : ndarray, shape (n, 4, 4)
    """
    if trajectory_format(path) == "tum":
        return read_tum(path)
    poses, times = read_kitti(path)
    return times, poses


# ----------------------------------------------------------------------------- writing


def _check_poses(poses, time_stamps=None):
    """Poses ``(T, 4, 4)`` (and times ``(T,)``) as float arrays, finite, else a ``ValueError``."""
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
        raise ValueError(f"trajectory: poses must have shape (T, 4, 4) with T >= 1, got {poses.shape}")
    bad = np.flatnonzero(~np.isfinite(poses).all(axis=(1, 2)))
    if len(bad):
        raise ValueError(f"trajectory: pose of frame {bad[0]} is not finite; nothing written")
    if time_stamps is None:
        return poses, None
    times = np.asarray(time_stamps, dtype=float)
    if times.shape != (len(poses),) or not np.isfinite(times).all():
        raise ValueError(f"trajectory: time stamps must be {len(poses)} finite numbers (one per pose), "
                         f"got shape {times.shape}")
    return poses, times


def _write_rows(path, rows):
    """Write rows of floats, space-separated, each exactly (shortest round-trip repr)."""
    with atomic_write(path) as f:
        for row in rows.tolist():
            f.write(" ".join(map(repr, row)) + "\n")
    return expand_user(path).resolve()


def write_kitti(path, poses):
    """Write ``poses`` (T, 4, 4) as a KITTI poses file: 12 numbers per row, row-major 3x4 ``[R | t]``.

    Returns
    -------
    pathlib.Path
    """
    poses, _ = _check_poses(poses)
    return _write_rows(path, poses[:, :3, :].reshape(len(poses), 12))


def write_tum(path, time_stamps, poses):
    """Write ``time_stamps`` (T,) s and ``poses`` (T, 4, 4) as a TUM trajectory (scipy's quaternion, scalar last).

    Returns
    -------
    pathlib.Path
    """
    from scipy.spatial.transform import Rotation  # lazy, as in read_tum

    poses, times = _check_poses(poses, time_stamps)
    quaternions = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    return _write_rows(path, np.column_stack([times, poses[:, :3, 3], quaternions]))


def write_trajectory(path, time_stamps, poses):
    """Write ``time_stamps`` (T,), ``poses`` (T, 4, 4) by the suffix (:func:`trajectory_format`; KITTI drops the times).

    Returns
    -------
    pathlib.Path
    """
    if trajectory_format(path) == "tum":
        return write_tum(path, time_stamps, poses)
    return write_kitti(path, poses)
