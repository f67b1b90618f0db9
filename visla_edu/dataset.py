"""The in-memory dataset every part of visla-edu works on (one class for all formats).

Observations are stored sparse and frame-major (compressed sparse rows over frames): frame ``t`` owns
entries ``frame_ptr[t]:frame_ptr[t + 1]`` of ``obs_ids`` (landmark indices, increasing within a frame)
and ``obs_z`` (pixels ``[uL, vL, uR, vR]``). :func:`frame_major_order` builds the layout.
"""

from dataclasses import dataclass, field

import numpy as np

from visla_edu import lie
from visla_edu.camera import StereoCamera
from visla_edu.camera import disparity as camera_disparity

__all__ = ["Dataset", "GroundTruth", "frame_major_order", "repeated_frames", "stale_copies"]


@dataclass
class GroundTruth:
    """True poses of a drive, and for simulated drives its true landmarks and velocities.

    Attributes
    ----------
    world_T_imu : ndarray, shape (n, 4, 4)
        Frames ``0 .. n - 1``, ``world`` = the IMU frame at the first time stamp; ``n = T`` for simulated
        drives, ``n <= T`` for real ones (KITTI poses, :mod:`visla_edu.data._groundtruth`).
    landmarks : ndarray, shape (M, 3), or None
        In the world frame.
    linear_velocity, angular_velocity : ndarray, shape (T, 3), or None
        Noise-free body-frame velocities (m/s, rad/s) that generated the drive.
    outlier : ndarray of bool, shape (M,), or None
        Landmarks whose tracks were corrupted on purpose.
    source : str
        The poses' file, or ``""`` for a simulation.
    file_rows : int or None
        Poses in the source file (None for a simulation), of which rows ``0 .. num_frames - 1`` are used.
    """

    world_T_imu: np.ndarray
    landmarks: np.ndarray = None
    linear_velocity: np.ndarray = None
    angular_velocity: np.ndarray = None
    outlier: np.ndarray = None
    source: str = ""
    file_rows: int = None

    @property
    def rows_text(self):
        """Which rows of the source file are used, e.g. ``"rows 0-499 of 1101"``; ``""`` when all are."""
        if self.file_rows is None or self.file_rows == self.num_frames:
            return ""
        return f"rows 0-{self.num_frames - 1} of {self.file_rows}"

    @property
    def num_frames(self):
        """n, the number of frames the true poses cover (frames ``0 .. n - 1``)."""
        return len(self.world_T_imu)

    @property
    def simulated(self):
        """Whether the landmarks, velocities and outlier mask are known (a simulated drive)."""
        return self.landmarks is not None


@dataclass
class Dataset:
    """A stereo-inertial drive in visla-edu's time-major layout.

    Attributes
    ----------
    name, source, label : str
        Short name (``"03"``, ``"sim"``, ``"10-standin"``...); file path or description of the simulation;
        human-readable description (stand-ins say so here).
    time_stamps : ndarray, shape (T,)
        Seconds, strictly increasing.
    linear_velocity, angular_velocity : ndarray, shape (T, 3)
        IMU body-frame velocities (m/s, rad/s); twist at ``t`` is ``[v_t; w_t]``.
    K, K_right : ndarray, shape (3, 3)
        Left and right camera intrinsics; ``K_right`` None (the same as ``K``) unless a 2025+ file gives it.
    b : float
        Stereo baseline (m).
    imu_T_cam : ndarray, shape (4, 4)
        Pose of the left camera (optical frame) in the IMU frame.
    extrinsic_readings : tuple of visla_edu.camera.RigReading, or None
        A 2025+ file's four readings of its extrinsics (:mod:`visla_edu.data._format2025`); None otherwise.
    num_landmarks : int
        M, the number of landmark tracks.
    frame_ptr, obs_ids, obs_z : ndarray, shapes (T + 1,) int, (N,) int, (N, 4)
        Sparse observations, see the module docstring.
    ground_truth : GroundTruth or None
        Present for simulated drives, and for real drives whose KITTI poses were found.
    extra : dict
        Metadata, not written by :func:`visla_edu.data.save`: a course file's ``"sha256"``, ``"format"``,
        ``"known_file"`` (2025+: also ``"extrinsic_reading"``, ``"ignored_keys"``, ``"no_features"``: why, in
        words); a simulation's ``"preset"``, ``"seed"``, ``"config"`` (``"simulated_imu_T_cam"`` when the reported
        calibration differs from the simulated rig's); diagnostics' results (``"calibration"``, ``"visual_odometry"``).
    """

    name: str
    source: str
    time_stamps: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    K: np.ndarray
    b: float
    imu_T_cam: np.ndarray
    num_landmarks: int
    frame_ptr: np.ndarray
    obs_ids: np.ndarray
    obs_z: np.ndarray
    ground_truth: GroundTruth = None
    label: str = ""
    extra: dict = field(default_factory=dict)
    K_right: np.ndarray = None
    extrinsic_readings: tuple = None

    @property
    def num_frames(self):
        """T, the number of time stamps."""
        return len(self.time_stamps)

    @property
    def num_observations(self):
        """N, the number of valid stereo observations over all frames."""
        return len(self.obs_ids)

    @property
    def camera(self):
        """A :class:`~visla_edu.camera.StereoCamera` built from ``K``, ``b``, ``imu_T_cam`` and ``K_right``."""
        return self.stereo_camera()

    def stereo_camera(self, imu_T_cam=None):
        """The drive's :class:`~visla_edu.camera.StereoCamera`, with ``imu_T_cam`` (4, 4) replaced if given."""
        return StereoCamera(self.K, self.b, self.imu_T_cam if imu_T_cam is None else imu_T_cam, self.K_right)

    def disparity(self):
        """Disparity of every observation in the left camera's pixels (``uL - uR`` for one intrinsics), (N,)."""
        return camera_disparity(self.obs_z, self.K, self.K_right)

    @property
    def twists(self):
        """IMU twists ``u_t = [v_t; w_t]``, shape (T, 6)."""
        return np.concatenate([self.linear_velocity, self.angular_velocity], axis=1)

    @property
    def time_steps(self):
        """``tau_t = t_{t+1} - t_t``, shape (T - 1,)."""
        return np.diff(self.time_stamps)

    def observations(self, t):
        """Landmark ids (k,) and pixels ``[uL, vL, uR, vR]`` (k, 4) of frame ``0 <= t < T`` (else ``IndexError``).

        Both are views into the dataset: do not modify.
        """
        if not 0 <= t < self.num_frames:
            raise IndexError(f"{self.name}: frame {t} out of range [0, {self.num_frames})")
        lo, hi = self.frame_ptr[t], self.frame_ptr[t + 1]
        return self.obs_ids[lo:hi], self.obs_z[lo:hi]

    def observation_frames(self):
        """Frame index of every sparse observation, shape (N,)."""
        return np.repeat(np.arange(self.num_frames), np.diff(self.frame_ptr))

    def track_spans(self):
        """First and last frame each landmark is observed at, shape (M, 2); -1 if never."""
        frames = self.observation_frames()
        first = np.full(self.num_landmarks, np.iinfo(np.int64).max)
        last = np.full(self.num_landmarks, -1, dtype=np.int64)
        np.minimum.at(first, self.obs_ids, frames)
        np.maximum.at(last, self.obs_ids, frames)
        first[last < 0] = -1
        return np.stack([first, last], axis=1)

    def track_lengths(self):
        """Number of observations of each landmark, shape (M,)."""
        return np.bincount(self.obs_ids, minlength=self.num_landmarks)

    def segment(self, start, stop):
        """Frames ``start .. stop - 1`` as a drive of their own, its world at the segment's first pose.

        ``0 <= start``, ``start + 2 <= stop <= T`` (else ``ValueError``). The segment is named ``"<name>[start:stop]"``,
        has only the landmarks observed in it (renumbered in order) and ``extra`` empty. Ground truth that covers
        frame ``start`` moves to the segment's world, ``seg_world_T_imu[k] = inv(world_T_imu[start]) @
        world_T_imu[start + k]``, the landmarks likewise, and keeps only the poses it has (``None`` if it ends
        before ``start``).
        """
        start, stop = _segment_bounds(start, stop, self.num_frames, self.name)
        lo, hi = self.frame_ptr[start], self.frame_ptr[stop]
        kept, obs_ids = np.unique(self.obs_ids[lo:hi], return_inverse=True)
        return Dataset(
            name=f"{self.name}[{start}:{stop}]", source=self.source,
            time_stamps=self.time_stamps[start:stop].copy(),
            linear_velocity=self.linear_velocity[start:stop].copy(),
            angular_velocity=self.angular_velocity[start:stop].copy(),
            K=self.K.copy(), b=self.b, imu_T_cam=self.imu_T_cam.copy(), num_landmarks=len(kept),
            frame_ptr=self.frame_ptr[start:stop + 1] - lo, obs_ids=obs_ids.astype(np.int64).reshape(-1),
            obs_z=self.obs_z[lo:hi].copy(),
            ground_truth=_segment_ground_truth(self.ground_truth, start, stop, kept),
            label=f"frames {start}..{stop - 1} of {self.label or self.name}",
            K_right=None if self.K_right is None else self.K_right.copy(), extrinsic_readings=self.extrinsic_readings)

    def to_dense_features(self, frames=None, landmarks=None):
        """The course's dense layout ``(4, M', T')``, -1 where not observed, of ``frames`` and ``landmarks``.

        Each a slice or array of int (default all); dense arrays are large, so exercises should select a window.
        """
        frame_idx = np.arange(self.num_frames)[frames if frames is not None else slice(None)]
        lm_idx = np.arange(self.num_landmarks)[landmarks if landmarks is not None else slice(None)]
        lm_pos = np.full(self.num_landmarks, -1)
        lm_pos[lm_idx] = np.arange(len(lm_idx))
        dense = np.full((4, len(lm_idx), len(frame_idx)), -1.0)
        for col, t in enumerate(frame_idx):
            ids, z = self.observations(int(t))
            rows = lm_pos[ids]
            keep = rows >= 0
            dense[:, rows[keep], col] = z[keep].T
        return dense

    @classmethod
    def from_dense(cls, features, **fields):
        """Build a dataset from dense course features ``(4, M, T)``, ``features[0, m, t] != -1`` observed.

        ``**fields`` are the other :class:`Dataset` fields but the sparse ones and ``num_landmarks`` (``= M``); a
        missing, unknown or repeated one is a ``TypeError``. ``obs_z`` is float.
        """
        features = np.asarray(features, dtype=float)
        landmark_ids, frames = np.nonzero(features[0] != -1)
        order, frame_ptr = frame_major_order(landmark_ids, frames, features.shape[2])
        landmark_ids, frames = landmark_ids[order], frames[order]
        return cls(
            num_landmarks=features.shape[1],
            frame_ptr=frame_ptr,
            obs_ids=landmark_ids.astype(np.int64),
            obs_z=features[:, landmark_ids, frames].T.copy(),
            **fields,
        )


def _segment_bounds(start, stop, num_frames, name):
    """``(start, stop)`` as ints after checking ``0 <= start``, ``start + 2 <= stop <= num_frames``."""
    for label, value in (("start", start), ("stop", stop)):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"{name}: segment {label} must be an integer frame index, got {value!r}")
    if not (0 <= start and start + 2 <= stop <= num_frames):
        raise ValueError(f"{name}: segment [{start}:{stop}] must satisfy 0 <= start, start + 2 <= stop <= "
                         f"{num_frames} (the drive's frames); a segment needs at least 2 frames")
    return int(start), int(stop)


def _segment_ground_truth(truth, start, stop, kept):
    """``truth`` of frames ``start .. stop - 1`` in the segment's world, landmarks ``kept``; or None."""
    if truth is None or truth.num_frames <= start:
        return None
    seg_T_world = lie.se3_inv(truth.world_T_imu[start])
    landmarks = None if truth.landmarks is None else truth.landmarks[kept] @ seg_T_world[:3, :3].T + seg_T_world[:3, 3]
    frames = slice(start, stop)
    return GroundTruth(
        world_T_imu=seg_T_world @ truth.world_T_imu[frames],
        landmarks=landmarks,
        linear_velocity=None if truth.linear_velocity is None else truth.linear_velocity[frames].copy(),
        angular_velocity=None if truth.angular_velocity is None else truth.angular_velocity[frames].copy(),
        outlier=None if truth.outlier is None else truth.outlier[kept].copy(),
        source=truth.source)  # the file's rows are the whole drive's, not the segment's: no rows_text


def frame_major_order(obs_ids, obs_frames, num_frames):
    """The permutation to the frame-major sparse layout of :class:`Dataset` (by frame, then id), and ``frame_ptr``.

    Parameters
    ----------
    obs_ids, obs_frames : array_like of int, shape (N,)
        Each ``(frame, id)`` pair once, ``0 <= frame < num_frames`` (else ``ValueError``).
    num_frames : int

    Returns
    -------
    order : ndarray of int, shape (N,)
        Sorts ``obs_ids``, ``obs_frames`` and any per-observation array.
    frame_ptr : ndarray of int64, shape (T + 1,)
        The prefix sum of the per-frame counts.
    """
    obs_ids, obs_frames = np.asarray(obs_ids), np.asarray(obs_frames)
    if obs_ids.shape != obs_frames.shape or obs_ids.ndim != 1:
        raise ValueError(f"frame_major_order: obs_ids and obs_frames must have the same shape (N,), "
                         f"got {obs_ids.shape} and {obs_frames.shape}")
    if obs_frames.size and not 0 <= obs_frames.min() <= obs_frames.max() < num_frames:
        raise ValueError(f"frame_major_order: frames must lie in [0, {num_frames}), got "
                         f"{obs_frames.min()}..{obs_frames.max()}")
    order = np.lexsort((obs_ids, obs_frames))
    frame_ptr = np.zeros(num_frames + 1, dtype=np.int64)
    np.cumsum(np.bincount(obs_frames, minlength=num_frames), out=frame_ptr[1:])
    return order, frame_ptr


def repeated_frames(dataset):
    """Frames ``t >= 1`` (list of int) whose observations repeat frame ``t - 1``'s exactly (ids and pixels).

    Usually a duplicated camera frame while the IMU kept going: the landmarks seem to move with the vehicle.
    """
    counts = np.diff(dataset.frame_ptr)
    candidates = np.flatnonzero((counts[1:] == counts[:-1]) & (counts[1:] > 0)) + 1
    repeats = []
    for t in candidates:
        ids_prev, z_prev = dataset.observations(int(t) - 1)
        ids, z = dataset.observations(int(t))
        if np.array_equal(ids, ids_prev) and np.array_equal(z, z_prev):
            repeats.append(int(t))
    return repeats


def stale_copies(dataset):
    """Observations whose four pixels repeat their landmark's at the frame before, bit for bit; bool, shape (N,).

    In the dataset's observation order, True for the copy at frame ``t`` (frame ``t - 1``'s is kept). Course
    files have frames where every continuing track copies the previous frame's pixels: on a moving vehicle the
    copies are errors of the whole step (real pixels of a moving camera are never bit-identical).
    """
    frames = dataset.observation_frames()
    order = np.lexsort((frames, dataset.obs_ids))
    ids, frames, z = dataset.obs_ids[order], frames[order], dataset.obs_z[order]
    copy = (ids[1:] == ids[:-1]) & (frames[1:] == frames[:-1] + 1) & np.all(z[1:] == z[:-1], axis=1)
    stale = np.zeros(len(ids), dtype=bool)
    stale[order[1:][copy]] = True
    return stale
