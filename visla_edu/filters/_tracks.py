"""Multi-frame track updates of the joint filter: the MSCKF null-space update and delayed entry.

A landmark not in the joint state keeps its observations in a :class:`TrackBuffer` while the
frames they were made from are *cloned* in the state (:meth:`visla_edu.filters.ActiveSet.clone_pose`);
:mod:`visla_edu.filters._clones` decides when they are used. Then, all at once (Mourikis and
Roumeliotis 2007; OpenVINS):

1. **Triangulation** (:func:`triangulate_tracks`): Gauss-Newton on the inverse depth
   ``(x/z, y/z, 1/z)`` in the camera of the observation with the largest disparity, Huber
   weights, so a far point (disparity below a pixel) is as well posed as a near one.
2. **Linearisation** (:func:`track_systems`): the stacked residual ``r`` (4 rows per observation)
   of ``z = h(T_k, m)`` with Jacobians ``H_x`` on the clones (the error form's
   ``clone_jacobian``) and ``H_m`` on the point.
3. **Null space** (:func:`project_out_point`): with ``H_m = [Q1 Q2] [R1; 0]`` (QR), ``Q2^T r =
   Q2^T H_x x + Q2^T n`` no longer involves the point: an EKF update of the clones (and so of
   everything correlated with them) with ``4 n - 3`` rows and a whole-track chi-square gate
   (:func:`gate_tracks`: a moving car or a mismatch is refused as a whole).
4. **Delayed entry** of a long track as a SLAM landmark: the ``Q1`` rows give its covariance and
   its correlation with the state (:func:`delayed_entry`), the ``Q2`` rows update the state as in 3.

Shared arrays, over the ``N`` observations of a frame's tracks: ``world_T_imu`` (N, 4, 4) the clone
mean each was made from, ``z`` (N, 4) its stereo pixels (disparity positive), ``owner`` (N,) its
track, ``0 .. count - 1``, sorted.
"""

import numpy as np

from visla_edu.camera import stereo_projection
from visla_edu.metrics import chi2_quantile

__all__ = ["TrackBuffer", "triangulate_tracks", "track_systems", "project_out_point", "gate_tracks", "delayed_entry",
           "segment_sum", "MIN_TRACK_OBSERVATIONS", "TRIANGULATION_ITERATIONS", "HUBER_SIGMAS"]

#: A track with fewer observations than this in the clone window is not used (3 observations
#: give ``4 * 3 - 3 = 9`` rows about the clones).
MIN_TRACK_OBSERVATIONS = 3
#: Gauss-Newton iterations of the triangulation.
TRIANGULATION_ITERATIONS = 5
#: Residuals beyond this many pixel sigmas get Huber's weight ``c / |r|`` in the triangulation.
HUBER_SIGMAS = 3.0
#: Smallest inverse depth (1/m) of a triangulated point: 10 km.
MIN_INVERSE_DEPTH = 1e-4
#: A triangulated point closer than this (m) to a camera that saw it is not used.
MIN_POINT_DEPTH = 0.1


class TrackBuffer:
    """Observations ``(frame, z)`` of the landmarks outside the state: ``frames[lm]`` and ``pixels[lm]`` (4,) lists."""

    def __init__(self):
        self.frames, self.pixels = {}, {}

    def __len__(self):
        return len(self.frames)

    def __contains__(self, lm):
        return lm in self.frames

    def add(self, ids, z, t):
        """Append frame ``t``'s observations ``z`` (k, 4) of landmarks ``ids`` (k,)."""
        for lm, zz in zip(ids.tolist(), z):
            self.frames.setdefault(lm, []).append(t)
            self.pixels.setdefault(lm, []).append(zz)

    def landmarks(self):
        """The landmarks with buffered observations, ndarray of int."""
        return np.fromiter(self.frames, dtype=np.int64, count=len(self.frames))

    def first_frame(self, lms):
        """Frame of the oldest buffered observation of each landmark of ``lms``."""
        return np.array([self.frames[lm][0] for lm in lms.tolist()], dtype=np.int64)

    def pop(self, lms):
        """Remove ``lms`` and return their observations: frames (N,), z (N, 4), owner (N,) (index into lms)."""
        frames, pixels, owner = [], [], []
        for i, lm in enumerate(lms.tolist()):
            frames += self.frames.pop(lm)
            pixels += self.pixels.pop(lm)
            owner += [i] * (len(frames) - len(owner))
        return (np.array(frames, dtype=np.int64), np.array(pixels, dtype=float).reshape(-1, 4),
                np.array(owner, dtype=np.int64))

    def forget_before(self, frame):
        """Drop observations made before ``frame`` (their clone left the state)."""
        for lm in list(self.frames):
            frames = self.frames[lm]
            if frames[0] >= frame:
                continue
            keep = next((i for i, f in enumerate(frames) if f >= frame), len(frames))
            del frames[:keep], self.pixels[lm][:keep]
            if not frames:
                del self.frames[lm], self.pixels[lm]


def _project(camera, world_T_imu, p_world):
    """:func:`visla_edu.camera.stereo_projection` of points ``p_world`` (N, 3) from poses ``world_T_imu`` (N, 4, 4)."""
    return stereo_projection(camera.Ks, camera.cam_T_imu, world_T_imu, p_world)


def segment_sum(values, owner, count):
    """Sum of ``values`` (N, ...) over the observations of each track (``owner`` sorted), (count, ...)."""
    starts = np.searchsorted(owner, np.arange(count))
    return np.add.reduceat(values, starts, axis=0)


def _from_inverse_depth(world_T_cam, psi):
    """World points of inverse-depth parameters ``psi`` (B, 3) in cameras ``world_T_cam`` (B, 4, 4), and ``dp/dpsi``."""
    a, b, rho = psi[:, 0], psi[:, 1], psi[:, 2]
    p_cam = np.stack([a, b, np.ones_like(a)], axis=1) / rho[:, None]
    dp_cam = np.zeros((len(psi), 3, 3))
    dp_cam[:, 0, 0] = dp_cam[:, 1, 1] = 1 / rho
    dp_cam[:, :, 2] = -p_cam / rho[:, None]
    R = world_T_cam[:, :3, :3]
    return np.einsum("bij,bj->bi", R, p_cam) + world_T_cam[:, :3, 3], R @ dp_cam


def triangulate_tracks(camera, world_T_imu, z, owner, count, sigma_pixel):
    """Least-squares points ``p_world`` (count, 3) of ``count`` tracks, and ``ok`` (count,) bool.

    Every track is observed at least once; ``sigma_pixel`` scales the Huber weights
    (:data:`HUBER_SIGMAS`). ``ok``: finite, and at least :data:`MIN_POINT_DEPTH` in front of every
    camera that saw it.
    """
    disparity = camera.disparity(z)
    anchor = np.zeros(count, dtype=np.int64)
    best = np.full(count, -np.inf)
    np.maximum.at(best, owner, disparity)
    anchor[owner[::-1]] = np.arange(len(owner))[::-1]  # any observation of the track ...
    is_best = disparity == best[owner]
    anchor[owner[is_best][::-1]] = np.nonzero(is_best)[0][::-1]  # ... the one with the largest disparity
    world_T_cam = world_T_imu[anchor] @ camera.imu_T_cam
    p_cam = camera.triangulate(z[anchor])
    psi = np.column_stack([p_cam[:, 0] / p_cam[:, 2], p_cam[:, 1] / p_cam[:, 2], 1 / p_cam[:, 2]])
    c = HUBER_SIGMAS * sigma_pixel
    for _ in range(TRIANGULATION_ITERATIONS):
        p_world, dp_dpsi = _from_inverse_depth(world_T_cam, psi)
        z_pred, _, J_z_landmark, _ = _project(camera, world_T_imu, p_world[owner])
        r = z - z_pred
        weight = np.minimum(1.0, c / np.maximum(np.abs(r), 1e-12))
        H = J_z_landmark @ dp_dpsi[owner]  # (N, 4, 3)
        WH = H * weight[:, :, None]
        normal = segment_sum(np.swapaxes(WH, 1, 2) @ H, owner, count) + 1e-9 * np.eye(3)
        gradient = segment_sum(np.einsum("nij,ni->nj", WH, r), owner, count)
        psi = psi + np.linalg.solve(normal, gradient[..., None])[..., 0]
        psi[:, 2] = np.maximum(psi[:, 2], MIN_INVERSE_DEPTH)
    p_world, _ = _from_inverse_depth(world_T_cam, psi)
    _, depth, _, _ = _project(camera, world_T_imu, p_world[owner])
    ok = np.isfinite(p_world).all(axis=1)
    ok &= segment_sum((depth >= MIN_POINT_DEPTH).astype(np.int64), owner, count) == np.bincount(owner, minlength=count)
    return p_world, ok


def track_systems(camera, form, world_T_imu, z, owner, p_world):
    """Residuals ``r`` (N, 4) and Jacobians ``H_clone`` (N, 4, 6), ``H_point`` (N, 4, 3) of every track observation.

    ``H_clone`` is with respect to the error of the clone the observation was made from (the
    error form's ``clone_jacobian``), ``H_point`` with respect to the world point ``m``.
    """
    z_pred, _, J_z_landmark, J_z_pose = _project(camera, world_T_imu, p_world[owner])
    return z - z_pred, form.clone_jacobian(J_z_landmark, J_z_pose, p_world[owner]), J_z_landmark


def project_out_point(r, H_point):
    """The null-space rows of ``B`` tracks of ``n`` observations each: ``Q2^T``, and ``(Q1^T, R1)`` of the point.

    ``r`` (B, n, 4), ``H_point`` (B, n, 4, 3); returns ``Q2T`` (B, 4n - 3, 4n) with
    ``Q2T @ H_point.reshape(B, 4n, 3) = 0``, ``Q1T`` (B, 3, 4n) and ``R1`` (B, 3, 3), upper
    triangular, ``Q1T @ H_point = R1``.
    """
    B, n = r.shape[:2]
    Q, R = np.linalg.qr(H_point.reshape(B, 4 * n, 3), mode="complete")
    QT = np.swapaxes(Q, 1, 2)
    return QT[:, 3:], QT[:, :3], R[:, :3]


def gate_tracks(r_o, H_o, Sigma_sub, noise_var, probability):
    """Whole-track chi-square gate: mask (B,) of tracks whose null-space residual is plausible.

    ``d2 = r_o^T (H_o Sigma_sub H_o^T + noise_var I)^-1 r_o <= chi2_{4n-3}(probability)``.
    """
    m = r_o.shape[1]
    S = H_o @ Sigma_sub @ np.swapaxes(H_o, 1, 2) + noise_var * np.eye(m)
    d2 = np.einsum("bi,bi->b", r_o, np.linalg.solve(S, r_o[..., None])[..., 0])
    return d2 <= chi2_quantile(probability, m), d2


def delayed_entry(r1, R1, H1_Sigma, H1_Sigma_H1T, noise_var):
    """Mean correction, cross-covariance and covariance of a point entering the state from its track.

    From the point's rows ``Q1^T r = H1 x + R1 e + Q1^T n`` (``e`` the point's error, ``x`` the
    state's), to first order ``e = R1^-1 (Q1^T r - H1 x - Q1^T n)``, so::

        mean    R1^-1 Q1^T r                                  (3,)
        cross   Sigma_e,x = -R1^-1 H1 Sigma                   (3, D)
        block   R1^-1 (H1 Sigma H1^T + noise_var I) R1^-T     (3, 3)

    from ``r1 = Q1^T r`` (3,), ``R1`` (3, 3), ``H1_Sigma`` (3, D) over every state column and
    ``H1_Sigma_H1T`` (3, 3).
    """
    R1_inv = np.linalg.inv(R1)
    block = R1_inv @ (H1_Sigma_H1T + noise_var * np.eye(3)) @ R1_inv.T
    return R1_inv @ r1, -R1_inv @ H1_Sigma, block
