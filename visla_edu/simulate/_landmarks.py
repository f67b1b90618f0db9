"""Landmarks placed along a true trajectory, and the scene change that paces the detector."""

import numpy as np

__all__ = ["place_landmarks", "scene_change", "default_time_stamps", "check_poses"]


def scene_change(world_T_imu, time_stamps, config):
    """Scene change per step over its mean, (T-1,), of poses (T, 4, 4) and stamps (T,):
    ``|p_{t+1} - p_t| + scene_speed_floor (t_{t+1} - t_t)``; all ones when every change is 0 (a car that never moves).
    """
    step_len = np.linalg.norm(np.diff(world_T_imu[:, :3, 3], axis=0), axis=1)
    change = step_len + config.scene_speed_floor * np.diff(time_stamps)
    return change / change.mean() if change.sum() > 0 else np.ones_like(change)


def default_time_stamps(time_stamps, T, config):
    """``time_stamps`` as floats checked to be (T,), or ``config.time_step * arange(T)`` (from 0) if None."""
    if time_stamps is None:
        return config.time_step * np.arange(T)
    stamps = np.asarray(time_stamps, dtype=float)
    if stamps.shape != (T,):
        raise ValueError(f"simulate: time_stamps must have shape ({T},), got {stamps.shape}")
    return stamps


def _anchor_frames(change, n, config, rng):
    """Appearance frames, drawn in proportion to the scene change, shape (n,)."""
    weight = change.copy()
    # The detector starts with a full image: about one mean lifetime of anchors at frame 0.
    weight[0] += 1.0 / config.track_loss_probability
    return rng.choice(len(weight), size=n, p=weight / weight.sum())


def _roadside_points(world_T_imu, arc, anchor, config, rng):
    """Points beside the road ahead of the anchor poses, shape (n, 3)."""
    n = len(anchor)
    s = arc[anchor] + rng.uniform(*config.ahead_range, n)
    k = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 1)
    side = rng.choice([-1.0, 1.0], n)
    offset = np.stack([
        s - arc[k],  # beyond the last pose the road continues straight
        side * rng.uniform(*config.lateral_range, n),
        rng.uniform(*config.height_range, n) - config.imu_height,
    ], axis=1)
    return np.einsum("nij,nj->ni", world_T_imu[k, :3, :3], offset) + world_T_imu[k, :3, 3]


def _far_points(world_T_imu, anchor, config, rng):
    """Far points in front of the anchor poses, shape (n, 3)."""
    n = len(anchor)
    distance = rng.uniform(*config.far_range, n)
    bearing = rng.uniform(-config.far_bearing, config.far_bearing, n)
    offset = np.stack([
        distance * np.cos(bearing),
        distance * np.sin(bearing),
        rng.uniform(*config.far_height_range, n) - config.imu_height,
    ], axis=1)
    return np.einsum("nij,nj->ni", world_T_imu[anchor, :3, :3], offset) + world_T_imu[anchor, :3, 3]


def place_landmarks(world_T_imu, num_landmarks, config, rng, time_stamps=None):
    """Place landmarks along a true trajectory, each anchored to a frame (the track model's step 1).

    A share ``1 - far_share`` stands beside the road ahead of its anchor pose, the rest are far points in front of it
    (the ranges of :class:`SimulationConfig`, in the anchor's body frame). ``world_T_imu`` (T, 4, 4); ``time_stamps``
    (T,) default to uniform steps of ``config.time_step``. Returns ``landmarks`` (num_landmarks, 3) and ``appear``
    (num_landmarks,) int, the anchor frames: a landmark's track may start at this frame or a few later.
    """
    world_T_imu = check_poses(world_T_imu, "place_landmarks")
    time_stamps = default_time_stamps(time_stamps, len(world_T_imu), config)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(world_T_imu[:, :3, 3], axis=0), axis=1))])
    change = scene_change(world_T_imu, time_stamps, config)
    anchor = _anchor_frames(change, num_landmarks, config, rng)
    far = rng.random(num_landmarks) < config.far_share
    landmarks = np.empty((num_landmarks, 3))
    landmarks[~far] = _roadside_points(world_T_imu, arc, anchor[~far], config, rng)
    landmarks[far] = _far_points(world_T_imu, anchor[far], config, rng)
    return landmarks, anchor.astype(np.int64)


def check_poses(world_T_imu, where):
    """``world_T_imu`` as floats, shape (T, 4, 4) with T >= 2 (only the shape is checked), else a ValueError."""
    poses = np.asarray(world_T_imu, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) < 2:
        raise ValueError(f"{where}: world_T_imu must have shape (T, 4, 4) with T >= 2, got {poses.shape}")
    return poses
