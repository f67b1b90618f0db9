"""How long a track's pixel errors persist: the residual correlation along tracks.

Each track of at least :data:`MIN_TRACK` observations is triangulated from a trajectory; its
left-image residuals ``r_t = uL_t - u(p, t)``, less their mean, enter one pooled lag-1
autocorrelation over consecutive frames::

    rho = sum_tracks sum_t r_t r_(t+1) / sum_tracks sum_t r_t^2

A track of ``L`` observations is then worth about ``L (1 - rho) / (1 + rho)`` independent ones;
removing the mean biases ``rho`` down by about ``(1 + 4 rho) / L``. The trajectory's own errors
persist too: ``rho`` describes the camera only where the trajectory is locally accurate (the gyro
regime of :func:`visla_edu.filters.pixel_noise_inflation`).
"""

import numpy as np

from visla_edu import lie
from visla_edu.camera import project_points

__all__ = ["MIN_TRACK", "MAX_RESIDUAL", "track_correlation"]

#: Shortest track that enters (a shorter one leaves little after its mean is removed).
MIN_TRACK = 6
#: A track with a residual over this (px) is an outlier track and left out.
MAX_RESIDUAL = 20.0


def _triangulate(Ks, cam_T_world, z):
    """The homogeneous world point (4,) best fitting ``z`` (L, 4) seen from ``cam_T_world`` (L, 4, 4), or None.

    Each pixel row ``k`` gives ``(z_k e3 - Ks[k]) cam_T_world p = 0``; the last right singular
    vector solves all.
    """
    rows = (z[:, :, None] * cam_T_world[:, None, 2, :] - np.einsum("kj,ljc->lkc", Ks, cam_T_world)).reshape(-1, 4)
    _, _, Vt = np.linalg.svd(rows)
    return Vt[-1] / Vt[-1, 3] if abs(Vt[-1, 3]) > 1e-12 else None


def _left_u_residuals(Ks, cam_T_world, z):
    """Left-image ``u`` residuals (L,) of one track at its triangulated point, or None (behind a camera, outlier)."""
    p = _triangulate(Ks, cam_T_world, z)
    if p is None:
        return None
    z_pred, q = project_points(Ks, cam_T_world, np.broadcast_to(p[:3], (len(z), 1, 3)), jacobians=False)
    if np.any(q[:, 0, 2] <= 0):
        return None
    r = z[:, 0] - z_pred[:, 0, 0]
    return r if np.max(np.abs(r)) <= MAX_RESIDUAL else None


def track_correlation(dataset, world_T_imu, imu_T_cam):
    """Pooled lag-1 autocorrelation ``rho`` of the left-image residuals along the tracks (module docstring).

    Parameters
    ----------
    world_T_imu : ndarray, shape (T, 4, 4)
        One IMU pose per frame (ValueError otherwise).

    Returns
    -------
    rho, tracks : float, int
        ``rho`` in ``[-1, 1]`` (0 when no track qualifies), over ``tracks`` tracks.
    """
    world_T_imu = np.asarray(world_T_imu, dtype=float)
    if world_T_imu.shape != (dataset.num_frames, 4, 4):
        raise ValueError(f"track_correlation: {dataset.name}: world_T_imu must have shape ({dataset.num_frames}, 4, 4), "
                         f"one pose per frame, got {world_T_imu.shape}")
    cam_T_world = lie.se3_inv(imu_T_cam) @ lie.se3_inv(world_T_imu)
    Ks = dataset.stereo_camera(imu_T_cam).Ks
    frames = dataset.observation_frames()
    order = np.lexsort((frames, dataset.obs_ids))
    ids, frames, z = dataset.obs_ids[order], frames[order], dataset.obs_z[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    lagged = total = 0.0
    tracks = 0
    for lo, hi in zip(starts, np.r_[starts[1:], len(ids)]):
        if hi - lo < MIN_TRACK:
            continue
        r = _left_u_residuals(Ks, cam_T_world[frames[lo:hi]], z[lo:hi])
        if r is None:
            continue
        r = r - r.mean()
        consecutive = np.diff(frames[lo:hi]) == 1
        lagged += float(np.sum((r[1:] * r[:-1])[consecutive]))
        total += float(np.sum(r ** 2))
        tracks += 1
    return (float(np.clip(lagged / total, -1.0, 1.0)) if total > 0 else 0.0), tracks
