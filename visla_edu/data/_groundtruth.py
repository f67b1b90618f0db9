"""Ground truth of real drives: KITTI odometry poses, checked and converted to ``world_T_imu``.

The KITTI odometry benchmark gives, per sequence, ``poses/NN.txt`` (row ``i``: the 3x4 pose
``P_i`` of the left camera at frame ``i`` in the left camera frame of frame 0, 12 numbers,
row-major; a 13-column variant puts the time first) and ``sequences/NN/times.txt`` (seconds
since frame 0, one per row). visla-edu's convention is the IMU pose with ``world`` = the IMU
frame at frame 0, so with the drive's calibration ``imu_T_cam`` (as loaded from the course
file: ``cam_T_imu = inv(imu_T_cam)``)

    world_T_imu[i] = inv(cam_T_imu) @ P_i @ cam_T_imu = imu_T_cam @ P_i @ inv(imu_T_cam).

Rows are frames: row ``i`` is the dataset's frame ``i``. The poses may cover fewer frames
than the dataset (``0020.npz`` has 1104 frames, its poses 1101) or more: a course file that
is the first part of a KITTI sequence (``0042.npz``, the first 500 of sequence 01's 1101
frames) uses the first rows, and says which (:attr:`~visla_edu.dataset.GroundTruth.rows_text`).
The times, when given, must equal the dataset's ``time_stamps - time_stamps[0]`` to
:data:`TIME_TOLERANCE` on every frame they share with it; they are what tells a longer
sequence that starts with this drive from another drive's poses.
"""

import dataclasses
from pathlib import Path

import numpy as np

from visla_edu._files import expand_user
from visla_edu.data._plausible import check_ground_truth_reach
from visla_edu.data._registry import ground_truth_files
from visla_edu.dataset import Dataset, GroundTruth
from visla_edu.trajectory import read_kitti, read_table

__all__ = [
    "TIME_TOLERANCE",
    "read_kitti_times",
    "imu_poses_from_kitti",
    "kitti_poses_from_imu",
    "check_times",
    "load_ground_truth",
    "attach_ground_truth",
    "attach_registered_ground_truth",
]

#: Largest difference (s) allowed between a times file and the dataset's relative time stamps.
TIME_TOLERANCE = 1e-3
#: Fewest ground-truth poses accepted: the SE(3) alignment of the aligned ATE needs three.
MIN_POSES = 3


def read_kitti_times(path):
    """Read a KITTI ``times.txt``: one number per row, seconds since frame 0.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    FileNotFoundError, ValueError
        Missing, empty, not one finite number per row (the message names file, line, value).
    """
    table, _ = read_table(path, (1,), "KITTI times: one number per row, seconds since frame 0")
    return table[:, 0]


def imu_poses_from_kitti(cam0_T_cam, imu_T_cam):
    """KITTI left-camera poses to IMU poses: ``world_T_imu[i] = imu_T_cam @ P_i @ inv(imu_T_cam)``.

    Parameters
    ----------
    cam0_T_cam : array_like, shape (n, 4, 4)
        ``P_i``: the left camera at frame ``i`` in the left camera frame of frame 0.
    imu_T_cam : array_like, shape (4, 4)
        The left camera in the IMU frame.

    Returns
    -------
    ndarray, shape (n, 4, 4)
        ``world_T_imu``, ``world`` = the IMU frame at frame 0 when ``P_0`` is the identity.

    Notes
    -----
    ``inv`` is the matrix inverse, not the rigid-transform formula: a course file's rotation
    is orthonormal only to about 1e-7, and with the exact inverse ``P_0 = I`` still maps to
    ``world_T_imu[0] = I`` (to rounding), and this function and :func:`kitti_poses_from_imu`
    invert each other.
    """
    imu_T_cam = np.asarray(imu_T_cam, dtype=float)
    return imu_T_cam @ np.asarray(cam0_T_cam, dtype=float) @ np.linalg.inv(imu_T_cam)


def kitti_poses_from_imu(world_T_imu, imu_T_cam):
    """IMU poses to KITTI left-camera poses: ``P_i = inv(imu_T_cam) @ world_T_imu[i] @ imu_T_cam``.

    The inverse of :func:`imu_poses_from_kitti`; write the result with
    :func:`visla_edu.trajectory.write_kitti` to compare with KITTI's tools and files.

    Parameters
    ----------
    world_T_imu : array_like, shape (n, 4, 4)
    imu_T_cam : array_like, shape (4, 4)

    Returns
    -------
    ndarray, shape (n, 4, 4)
    """
    imu_T_cam = np.asarray(imu_T_cam, dtype=float)
    return np.linalg.inv(imu_T_cam) @ np.asarray(world_T_imu, dtype=float) @ imu_T_cam


def check_times(times, time_stamps, path, tolerance=TIME_TOLERANCE, allow_longer=False):
    """Check ground-truth times against the dataset's ``time_stamps - time_stamps[0]``.

    Parameters
    ----------
    times : ndarray, shape (n,)
        Seconds since frame 0, row ``i`` for frame ``i``.
    time_stamps : ndarray, shape (T,)
        The dataset's time stamps, ``T >= n`` unless ``allow_longer``.
    path : str or os.PathLike
        The file the times came from, for the message.
    tolerance : float
        Seconds.
    allow_longer : bool
        Accept more times than frames (a sequence longer than the drive) and check the first
        ``T``.

    Raises
    ------
    ValueError
        The first row whose time differs by more than ``tolerance``, with both values; more
        times than frames (unless ``allow_longer``); a ``tolerance`` that is not a finite
        number >= 0.
    """
    times = np.asarray(times, dtype=float).ravel()
    time_stamps = np.asarray(time_stamps, dtype=float).ravel()
    if len(times) > len(time_stamps) and not allow_longer:
        raise ValueError(f"{path}: {len(times)} times but the dataset has only {len(time_stamps)} frames "
                         "(one time per frame: is this the ground truth of another drive?)")
    times = times[: len(time_stamps)]
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"check_times: tolerance must be a finite number of seconds >= 0, got {tolerance!r}")
    relative = time_stamps[: len(times)] - time_stamps[0]
    error = np.abs(np.asarray(times, dtype=float) - relative)
    bad = np.flatnonzero(error > tolerance)
    if len(bad) and np.all(np.abs(times - times[0] - relative) <= tolerance):
        raise ValueError(f"{path}: the times start at {times[0]:.6f} s, not 0, and match the dataset's after "
                         "subtracting that: KITTI's times count seconds from frame 0 (subtract the first time)")
    if len(bad):
        i = bad[0]
        raise ValueError(f"{path}: row {i} (frame {i}) has time {times[i]:.6f} s but the dataset's time_stamps[{i}] - "
                         f"time_stamps[0] is {relative[i]:.6f} s (differ by {error[i]:.3g} s > {tolerance:g} s); "
                         "is this the ground truth of another drive?")


def _read_checked_poses(dataset, poses_path, times_path, tolerance):
    """KITTI poses of ``dataset``'s first frames, their times checked: ``P`` (n, 4, 4), and the file's rows.

    A file with more poses than the drive has frames is the sequence the drive begins
    (``0042.npz``): its first ``T`` rows are the drive's frames, and the times, when given,
    are checked on those rows.
    """
    cam0_T_cam, inline_times = read_kitti(poses_path)
    n, T = len(cam0_T_cam), dataset.num_frames
    if n < MIN_POSES:
        raise ValueError(f"{poses_path}: {n} pose(s); an ATE against ground truth needs at least {MIN_POSES} "
                         "(the SE(3) alignment is undetermined with fewer)")
    if inline_times is not None:
        check_times(inline_times, dataset.time_stamps, poses_path, tolerance, allow_longer=True)
    if times_path is not None:
        times = read_kitti_times(times_path)
        if len(times) != n:
            raise ValueError(f"{times_path}: {len(times)} times but {poses_path} has {n} poses (one time per pose)")
        check_times(times, dataset.time_stamps, times_path, tolerance, allow_longer=True)
    return cam0_T_cam[:T], n


def load_ground_truth(dataset, poses_path, times_path=None, tolerance=TIME_TOLERANCE):
    """Read a KITTI odometry ground truth for ``dataset`` as its :class:`~visla_edu.dataset.GroundTruth`.

    Parameters
    ----------
    dataset : Dataset
        The drive; its ``imu_T_cam`` (the course file's calibration) converts the camera poses
        and its ``time_stamps`` check the times.
    poses_path : str or os.PathLike
        KITTI ``poses/NN.txt`` (12 columns, or 13 with the time first), row ``i`` = frame ``i``.
    times_path : str or os.PathLike, optional
        KITTI ``times.txt``, one row per pose.
    tolerance : float
        Seconds allowed between the times and ``time_stamps - time_stamps[0]``.

    Returns
    -------
    GroundTruth
        ``world_T_imu`` (n, 4, 4) for frames ``0 .. n - 1`` (``n <= T``: a longer file gives its
        first ``T`` rows, and ``file_rows`` says how many it has), ``world`` = the IMU at
        frame 0: ``imu_T_cam @ inv(P_0) @ P_i @ inv(imu_T_cam)`` (KITTI's ``P_0`` is the identity,
        so this is the formula of the module docstring); no landmarks or velocities.

    Raises
    ------
    FileNotFoundError
        A file is missing.
    ValueError
        A bad file (see :func:`visla_edu.trajectory.read_kitti`), fewer than
        :data:`MIN_POSES` poses, times not one per pose or not matching the dataset's on the
        frames they share, a pose farther from the first than the drive can go in its time
        (:func:`~visla_edu.data._plausible.check_ground_truth_reach`: another unit, another drive).
    TypeError
        ``dataset`` is not a :class:`~visla_edu.dataset.Dataset`.
    """
    if not isinstance(dataset, Dataset):
        raise TypeError(f"load_ground_truth: expected a visla_edu.dataset.Dataset, got {type(dataset).__name__}")
    cam0_T_cam, file_rows = _read_checked_poses(dataset, poses_path, times_path, tolerance)
    cam0_T_cam = np.linalg.inv(cam0_T_cam[0]) @ cam0_T_cam
    world_T_imu = imu_poses_from_kitti(cam0_T_cam, dataset.imu_T_cam)
    check_ground_truth_reach(world_T_imu, dataset.time_stamps, "KITTI poses", poses_path)
    source = str(expand_user(poses_path).resolve())
    return GroundTruth(world_T_imu=world_T_imu, source=source, file_rows=file_rows)


def attach_ground_truth(dataset, poses_path, times_path=None, tolerance=TIME_TOLERANCE):
    """A copy of ``dataset`` whose ``ground_truth`` is read from KITTI files (:func:`load_ground_truth`).

    Replaces any ground truth the dataset had. The arrays are shared with ``dataset``, not copied.

    Parameters
    ----------
    dataset : Dataset
        The drive; not modified.
    poses_path : str or os.PathLike
        KITTI ``poses/NN.txt`` (12 columns, or 13 with the time first), row ``i`` = frame ``i``.
    times_path : str or os.PathLike, optional
        KITTI ``times.txt``, one row per pose.
    tolerance : float
        Seconds allowed between the times and ``time_stamps - time_stamps[0]``.

    Returns
    -------
    Dataset
        ``ground_truth.world_T_imu`` (n, 4, 4) for frames ``0 .. n - 1``, ``n <= T``.

    Raises
    ------
    FileNotFoundError, ValueError, TypeError
        As :func:`load_ground_truth`.
    """
    truth = load_ground_truth(dataset, poses_path, times_path, tolerance)
    return dataclasses.replace(dataset, ground_truth=truth)


def attach_registered_ground_truth(dataset):
    """``dataset`` with the ground truth the registry names for it, when its files are beside the npz.

    A drive of :data:`~visla_edu.data.REGISTRY` with a ``"ground_truth"`` entry (e.g. ``"0020"``:
    ``kitti_odometry_06_poses.txt`` and ``kitti_odometry_06_times.txt``) gets its poses when the
    poses file is in the folder of ``dataset.source`` (times checked when that file is there
    too). Datasets that already have ground truth, or none registered, come back unchanged.

    Parameters
    ----------
    dataset : Dataset
        A loaded drive: its ``name`` picks the registry entry and ``source`` (the npz path) the
        folder to look in. Not modified; one without a ``source`` (e.g. simulated) is returned as is.

    Returns
    -------
    Dataset
        ``dataset`` itself, or a copy with ``ground_truth`` (:func:`attach_ground_truth`).

    Raises
    ------
    PermissionError, ValueError
        The registered files are there but not readable, or do not fit the drive (as
        :func:`load_ground_truth`).
    """
    if dataset.ground_truth is not None or not dataset.source:
        return dataset
    files = ground_truth_files(dataset.name, Path(dataset.source).parent)
    if files is None:
        return dataset
    return attach_ground_truth(dataset, *files)
