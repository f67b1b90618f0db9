"""Ground truth of real drives: KITTI odometry poses, checked and converted to ``world_T_imu``.

KITTI odometry gives, per sequence, ``poses/NN.txt`` (row ``i``: the 3x4 pose ``P_i`` of the left camera at
frame ``i`` in the left camera frame of frame 0, 12 numbers, row-major; a 13-column variant puts the time
first) and ``sequences/NN/times.txt`` (seconds since frame 0, one per row). visla-edu's ``world`` is the IMU
frame at frame 0, so with the drive's ``imu_T_cam`` (``cam_T_imu = inv(imu_T_cam)``)

    world_T_imu[i] = inv(cam_T_imu) @ P_i @ cam_T_imu = imu_T_cam @ P_i @ inv(imu_T_cam).

Row ``i`` is the dataset's frame ``i``. The poses may cover fewer frames than the dataset or more (a course
file that is the first part of a KITTI sequence, ``0042.npz``: the first rows are used, as
:attr:`~visla_edu.dataset.GroundTruth.rows_text` says). The times, when given, must equal
``time_stamps - time_stamps[0]`` to :data:`TIME_TOLERANCE` on every frame they share.
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
    """Read a KITTI ``times.txt`` (str or path-like) as shape (n,): one number per row, seconds since frame 0."""
    table, _ = read_table(path, (1,), "KITTI times: one number per row, seconds since frame 0")
    return table[:, 0]


def imu_poses_from_kitti(cam0_T_cam, imu_T_cam):
    """KITTI left-camera poses to IMU poses: ``world_T_imu[i] = imu_T_cam @ P_i @ inv(imu_T_cam)``, (n, 4, 4).

    ``cam0_T_cam`` (n, 4, 4) holds the ``P_i``; ``world`` is the IMU frame at frame 0 when ``P_0`` is the identity.
    ``inv`` is the matrix inverse (a course file's rotation is orthonormal only to about 1e-7): so ``P_0 = I`` maps
    to ``I`` and :func:`kitti_poses_from_imu` inverts this to rounding.
    """
    imu_T_cam = np.asarray(imu_T_cam, dtype=float)
    return imu_T_cam @ np.asarray(cam0_T_cam, dtype=float) @ np.linalg.inv(imu_T_cam)


def kitti_poses_from_imu(world_T_imu, imu_T_cam):
    """IMU poses to KITTI left-camera poses: ``P_i = inv(imu_T_cam) @ world_T_imu[i] @ imu_T_cam``, (n, 4, 4).

    The inverse of :func:`imu_poses_from_kitti`; :func:`visla_edu.trajectory.write_kitti` writes it.
    """
    imu_T_cam = np.asarray(imu_T_cam, dtype=float)
    return np.linalg.inv(imu_T_cam) @ np.asarray(world_T_imu, dtype=float) @ imu_T_cam


def check_times(times, time_stamps, path, tolerance=TIME_TOLERANCE, allow_longer=False):
    """Check ground-truth ``times`` (n,), seconds since frame 0, against the dataset's ``time_stamps - time_stamps[0]``.

    ``tolerance`` in seconds, finite and >= 0; ``allow_longer`` accepts ``n > T`` (a sequence longer than the
    drive) and checks the first ``T``.
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
    error = np.abs(times - relative)
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
    """KITTI poses ``P`` (n, 4, 4) of ``dataset``'s first ``n <= T`` frames, times checked, and the file's row count."""
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

    ``poses_path`` is ``poses/NN.txt`` (12 columns, or 13 with the time first; row ``i`` = frame ``i``),
    ``times_path`` ``times.txt`` (one row per pose), ``tolerance`` (s) as in :func:`check_times`. The dataset's
    ``imu_T_cam`` converts the poses, its ``time_stamps`` check the times. The result's ``world_T_imu``
    (n, 4, 4), ``n <= T``, is ``imu_T_cam @ inv(P_0) @ P_i @ inv(imu_T_cam)`` (``world`` = the IMU at frame 0);
    ``file_rows`` counts the file's rows.

    ``ValueError`` also for fewer than :data:`MIN_POSES` poses, times that are not the dataset's, or a pose out
    of reach (:func:`~._plausible.check_ground_truth_reach`).
    """
    if not isinstance(dataset, Dataset):
        raise TypeError(f"load_ground_truth: expected a visla_edu.dataset.Dataset, got {type(dataset).__name__}")
    cam0_T_cam, file_rows = _read_checked_poses(dataset, poses_path, times_path, tolerance)
    cam0_T_cam = np.linalg.inv(cam0_T_cam[0]) @ cam0_T_cam
    world_T_imu = imu_poses_from_kitti(cam0_T_cam, dataset.imu_T_cam)
    check_ground_truth_reach(world_T_imu, dataset.time_stamps, "KITTI poses", poses_path)
    return GroundTruth(world_T_imu=world_T_imu, source=str(expand_user(poses_path).resolve()), file_rows=file_rows)


def attach_ground_truth(dataset, poses_path, times_path=None, tolerance=TIME_TOLERANCE):
    """A copy of ``dataset`` whose ``ground_truth`` is read from KITTI files (:func:`load_ground_truth`).

    Replaces any ground truth; ``dataset`` is not modified, and its arrays are shared with the copy, not copied.
    """
    return dataclasses.replace(dataset, ground_truth=load_ground_truth(dataset, poses_path, times_path, tolerance))


def attach_registered_ground_truth(dataset):
    """``dataset`` with the ground truth :data:`~visla_edu.data.REGISTRY` names for its ``name``, beside ``source``.

    ``dataset`` itself (not modified) if it has ground truth or no ``source``, or the registered poses file is
    absent (its times file is optional); else a copy (:func:`attach_ground_truth`).
    """
    if dataset.ground_truth is not None or not dataset.source:
        return dataset
    files = ground_truth_files(dataset.name, Path(dataset.source).parent)
    if files is None:
        return dataset
    return attach_ground_truth(dataset, *files)
