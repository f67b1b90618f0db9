"""Stereo feature tracks of known landmarks seen from known poses (see :mod:`visla_edu.simulate`)."""

from dataclasses import dataclass

import numpy as np

from visla_edu import lie
from visla_edu.camera import StereoCamera, left_in_right_u, projection, single_intrinsics
from visla_edu.dataset import frame_major_order
from visla_edu.simulate._landmarks import check_poses, default_time_stamps, scene_change

__all__ = ["SimulatedTracks", "simulate_tracks"]


@dataclass
class SimulatedTracks:
    """Stereo tracks in the sparse layout (``frame_ptr``, ``obs_ids``) of :class:`~visla_edu.dataset.Dataset`.

    Attributes
    ----------
    landmarks, source_index : ndarray, shape (M, 3), (M,)
        True positions of the tracked landmarks, in id order (by first observation frame); the row of each in the
        ``landmarks`` given to :func:`simulate_tracks`.
    obs_z : ndarray, shape (N, 4)
        Measured pixels, frame-major, ids increasing within a frame.
    outlier : ndarray of bool, shape (M,)
        Tracks corrupted on purpose.
    """

    landmarks: np.ndarray
    source_index: np.ndarray
    frame_ptr: np.ndarray
    obs_ids: np.ndarray
    obs_z: np.ndarray
    outlier: np.ndarray


def _visible(q, Ks, config):
    """Depth within ``depth_range`` and pixels inside both images, shape (n,)."""
    depth = q[:, 2]
    near, far = config.depth_range
    ok = (depth >= near) & (depth <= far)
    safe = np.where(ok, depth, 1.0)
    uL = Ks[0, 0] * q[:, 0] / safe + Ks[0, 2]
    vL = Ks[1, 1] * q[:, 1] / safe + Ks[1, 2]
    width, height = config.image_size
    if single_intrinsics(Ks):
        uR, vR = uL + Ks[2, 3] / safe, vL
    else:
        uR = Ks[2, 0] * q[:, 0] / safe + Ks[2, 2] + Ks[2, 3] / safe
        vR = Ks[3, 1] * q[:, 1] / safe + Ks[3, 2]
    return (ok & (uR >= 0) & (uL < width) & (uL >= 0) & (uR < width) & (vL >= 0) & (vL < height)
            & (vR >= 0) & (vR < height))


def _march(cam_T_world, landmarks, appear, clock, budget, Ks, config):
    """Follow every landmark from its appearance frame until its track ends (not visible, or the detector
    ``clock`` (T,) advanced by its ``budget`` (n,) after ``min_track_length`` frames): the observations
    ``(landmark row, frame, q)``, shapes (N,), (N,), (N, 3).
    """
    T = len(cam_T_world)
    start = np.full(len(landmarks), -1)
    length = np.zeros(len(landmarks), dtype=np.int64)
    alive = np.flatnonzero(appear < T)
    rows, frames, points = [], [], []
    age = 0
    while alive.size:
        t = appear[alive] + age
        alive, t = alive[t < T], t[t < T]
        q = np.einsum("nij,nj->ni", cam_T_world[t, :3, :3], landmarks[alive]) + cam_T_world[t, :3, 3]
        vis = _visible(q, Ks, config)
        waiting = start[alive] < 0
        start[alive[waiting & vis]] = t[waiting & vis]
        lost = (length[alive] >= config.min_track_length) & (
            clock[t] - clock[np.maximum(start[alive], 0)] >= budget[alive])
        seen = vis & (start[alive] >= 0) & ~lost
        rows.append(alive[seen])
        frames.append(t[seen])
        points.append(q[seen])
        length[alive[seen]] += 1
        stop = (~waiting & ~seen) | (waiting & ~vis & (age >= config.max_start_delay))
        alive = alive[~stop]
        age += 1
    if not rows:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    return np.concatenate(rows), np.concatenate(frames), np.concatenate(points)


def _longest_runs(rows, frames, keep, min_length):
    """Keep each landmark's longest run of consecutive kept frames if long enough, shape (N,)."""
    if len(rows) == 0:
        return keep.copy()
    order = np.lexsort((frames, rows))
    r, f, k = rows[order], frames[order], keep[order]
    follows = np.r_[False, (r[1:] == r[:-1]) & (f[1:] == f[:-1] + 1) & k[:-1]]
    new_run = k & ~follows
    run_id = np.cumsum(new_run) - 1
    run_len = np.bincount(run_id[k], minlength=new_run.sum())
    run_row = r[new_run]
    by_row = np.lexsort((-run_len, run_row))
    first = np.r_[True, run_row[by_row][1:] != run_row[by_row][:-1]]
    best = np.zeros(len(run_len), dtype=bool)
    best[by_row[first]] = True
    best &= run_len >= min_length
    result = np.zeros(len(rows), dtype=bool)
    result[order] = k & best[np.maximum(run_id, 0)]
    return result


def _cap_per_frame(rows, frames, depth, config):
    """Drop the farthest observations of crowded frames, keeping tracks contiguous, shape (N,)."""
    order = np.lexsort((depth, frames))
    f_sorted = frames[order]
    rank = np.arange(len(order)) - np.searchsorted(f_sorted, f_sorted, side="left")
    keep = np.empty(len(order), dtype=bool)
    keep[order] = rank < config.max_observations_per_frame
    return _longest_runs(rows, frames, keep, config.min_track_length)


def _select_tracks(rows, frames, q, n_candidates, max_landmarks, config, rng):
    """Drop short tracks, keep at most ``max_landmarks``, apply the per-frame cap, shape (N,)."""
    length = np.bincount(rows, minlength=n_candidates)
    survivors = np.flatnonzero(length >= config.min_track_length)
    if max_landmarks is not None and len(survivors) > max_landmarks:
        survivors = rng.choice(survivors, size=max_landmarks, replace=False)
    chosen = np.zeros(n_candidates, dtype=bool)
    chosen[survivors] = True
    keep = chosen[rows]
    keep[keep] = _cap_per_frame(rows[keep], frames[keep], q[keep, 2], config)
    return keep


def _outlier_offsets(num_landmarks, config, rng):
    """``offsets`` (M, 4), zero for inliers, and ``outlier`` (M,) bool: wrong features, wrong matches."""
    outlier = np.zeros(num_landmarks, dtype=bool)
    n_out = int(round(config.outlier_share * num_landmarks))
    outlier[rng.choice(num_landmarks, size=n_out, replace=False)] = True
    size = rng.uniform(*config.outlier_offset_range, num_landmarks)
    angle = rng.uniform(0.0, 2 * np.pi, num_landmarks)
    wrong_match = rng.random(num_landmarks) < 0.5
    du, dv = size * np.cos(angle), size * np.sin(angle)
    zero = np.zeros(num_landmarks)
    offsets = np.where(wrong_match[:, None],
                       np.stack([zero, zero, np.copysign(size, du), zero], axis=1),
                       np.stack([du, dv, du, dv], axis=1))
    return np.where(outlier[:, None], offsets, 0.0), outlier


def _force_nonpositive_disparity(z, true_disparity, inlier, camera, config, rng):
    """In place, top up non-positive disparities (``camera.disparity``) to the configured share on the farthest
    inliers: ``uR = uL + U(0, 1)`` px in the left camera's pixels (then mapped into the right camera's).
    """
    target = int(round(config.nonpositive_disparity_share * len(z)))
    disparity = camera.disparity(z)
    need = target - int(np.count_nonzero(disparity <= 0))
    candidates = np.flatnonzero(inlier & (disparity > 0))
    if need <= 0 or candidates.size == 0:
        return
    pool = candidates[np.argsort(true_disparity[candidates], kind="stable")[: 5 * need]]
    chosen = rng.choice(pool, size=min(need, len(pool)), replace=False)
    z[chosen, 2] = left_in_right_u(z[chosen, 0] + rng.uniform(0.0, 1.0, len(chosen)), camera.K, camera.K_right)


def _uniform_pixels(count, camera, config, rng):
    """Random stereo pixels ``[uL, vL, uR, vR]`` in the image, ``uL > uR``, ``vR = vL`` + noise, (count, 4); two
    intrinsics: ``uR``, ``vR`` drawn in the left camera's pixels, then mapped into the right camera's.
    """
    width, height = config.image_size
    u = np.sort(rng.uniform(0.0, width, (count, 2)), axis=1)
    v = rng.uniform(0.0, height, count)
    z = np.stack([u[:, 1], v, u[:, 0], v + config.pixel_sigma * rng.standard_normal(count)], axis=1)
    if not camera.same_intrinsics:
        K, R = camera.K, camera.K_right
        z[:, 2] = left_in_right_u(z[:, 2], K, R)
        z[:, 3] = R[1, 2] + R[1, 1] * (z[:, 3] - K[1, 2]) / K[1, 1]
    return z


def _measure(q, ids, num_landmarks, camera, config, rng):
    """Noisy pixels with outliers and non-positive disparities, shapes (N, 4), (M,)."""
    q_h = np.concatenate([q, np.ones((len(q), 1))], axis=1)
    z_true = projection(q_h) @ camera.Ks.T
    z = z_true + config.pixel_sigma * rng.standard_normal(z_true.shape)
    offsets, outlier = _outlier_offsets(num_landmarks, config, rng)
    z += offsets[ids]
    if config.outlier_kind == "uniform":
        hit = outlier[ids]
        z[hit] = _uniform_pixels(int(hit.sum()), camera, config, rng)
    _force_nonpositive_disparity(z, camera.disparity(z_true), ~outlier[ids], camera, config, rng)
    return z, outlier


def _renumber(rows, frames, n_candidates):
    """Ids by first observation frame: ``(source rows in id order, id of each observation)``."""
    first = np.full(n_candidates, np.iinfo(np.int64).max)
    np.minimum.at(first, rows, frames)
    used = np.unique(rows)
    source = used[np.lexsort((used, first[used]))]
    new_id = np.full(n_candidates, -1, dtype=np.int64)
    new_id[source] = np.arange(len(source))
    return source, new_id[rows]


def simulate_tracks(world_T_imu, landmarks, K, b, imu_T_cam, config, rng, appear=None,
                    max_landmarks=None, time_stamps=None):
    """Stereo feature tracks of known landmarks seen from known poses, by the track model: :class:`SimulatedTracks`.

    ``world_T_imu`` (T, 4, 4); ``landmarks`` (n, 3): candidate world positions (M <= n are tracked, N observations); the
    rig ``K`` (3, 3), ``b``, ``imu_T_cam`` (4, 4) as in :class:`visla_edu.camera.StereoCamera`, with ``config.K_right``;
    ``appear`` (n,) int: the frame from which each landmark may be detected (default 0; another shape: ValueError);
    ``max_landmarks``: keep a random subset of at most this many tracks; ``time_stamps`` (T,) default to uniform steps
    of ``config.time_step``.
    """
    world_T_imu = check_poses(world_T_imu, "simulate_tracks")
    landmarks = np.asarray(landmarks, dtype=float).reshape(-1, 3)
    n, T = len(landmarks), len(world_T_imu)
    appear = np.zeros(n, dtype=np.int64) if appear is None else np.asarray(appear, dtype=np.int64)
    if appear.shape != (n,):
        raise ValueError(f"simulate_tracks: appear must have shape ({n},), got {appear.shape}")
    camera = StereoCamera(K, b, imu_T_cam, config.K_right)
    cam_T_world = camera.cam_T_imu @ lie.se3_inv(world_T_imu)
    change = scene_change(world_T_imu, default_time_stamps(time_stamps, T, config), config)
    clock = np.concatenate([[0.0], np.cumsum(change)])
    budget = rng.exponential(1.0 / config.track_loss_probability, n)
    rows, frames, q = _march(cam_T_world, landmarks, appear, clock, budget, camera.Ks, config)
    keep = _select_tracks(rows, frames, q, n, max_landmarks, config, rng)
    rows, frames, q = rows[keep], frames[keep], q[keep]
    source, ids = _renumber(rows, frames, n)
    order, frame_ptr = frame_major_order(ids, frames, T)
    z, outlier = _measure(q[order], ids[order], len(source), camera, config, rng)
    return SimulatedTracks(landmarks[source], source, frame_ptr, ids[order], z, outlier)
