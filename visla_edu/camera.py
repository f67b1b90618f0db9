"""Calibrated stereo camera: the stereo matrix Ks, projection, Jacobians, triangulation.

Model (rectified stereo pair, left camera optical frame ``o``: x right, y down, z forward)::

    q = cam_T_imu @ inv(world_T_imu) @ m          # homogeneous point in the left camera
    z = Ks @ pi(q) = [uL, vL, uR, vR]             # pixels, left then right image

    Ks = [[fsu, 0,   cu, 0       ],
          [0,   fsv, cv, 0       ],
          [fsu, 0,   cu, -fsu * b],
          [0,   fsv, cv, 0       ]]
    pi(q) = q / q3

The right perturbation ``world_T_imu = mu @ exp(twist_hat(delta))`` gives the pose Jacobian
``J_z_pose = -Ks dpi/dq(q) cam_T_imu odot(inv(mu) m)``; the landmark Jacobian is
``J_z_landmark = Ks dpi/dq(q) cam_T_imu inv(mu) P^T`` with ``P = [I 0]``.
"""

import numpy as np

from visla_edu import lie

__all__ = [
    "stereo_matrix",
    "projection",
    "projection_jacobian",
    "triangulate_disparity",
    "triangulate_bearing",
    "triangulation_jacobian",
    "StereoCamera",
]


def _check_calibration(K, b, name):
    """Return ``K`` as a (3, 3) float array and ``b`` as a positive float, or raise ValueError.

    ``K`` must be ``[[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]`` with finite entries and positive
    focal lengths: the stereo model has no skew, so a skew ``K[0, 1]`` is refused, not ignored.
    """
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3):
        raise ValueError(f"{name}: K must have shape (3, 3), got {K.shape}")
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{name}: K needs finite entries and positive focal lengths, got {K.tolist()}")
    if K[0, 1] != 0:
        raise ValueError(f"{name}: K[0, 1] = {float(K[0, 1])!r} is a skew, but the stereo model has none "
                         "(K = [[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]], rectified images); rectify or set it to 0")
    if K[1, 0] != 0 or np.any(K[2] != [0.0, 0.0, 1.0]):
        raise ValueError(f"{name}: K must be [[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]], got {K.tolist()}")
    b = float(b)
    if not np.isfinite(b) or b <= 0:
        raise ValueError(f"{name}: baseline b must be a positive number, got {b}")
    return K, b


def stereo_matrix(K, b):
    """The 4x4 stereo calibration matrix ``Ks`` from left intrinsics ``K`` and baseline ``b``.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Left camera intrinsics ``[[fsu, 0, cu], [0, fsv, cv], [0, 0, 1]]``.
    b : float
        Stereo baseline in metres (right camera at ``+b`` along the left camera's x axis).

    Returns
    -------
    ndarray, shape (4, 4)
    """
    K, b = _check_calibration(K, b, "stereo_matrix")
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.array(
        [
            [fsu, 0.0, cu, 0.0],
            [0.0, fsv, cv, 0.0],
            [fsu, 0.0, cu, -fsu * b],
            [0.0, fsv, cv, 0.0],
        ]
    )


def projection(q):
    """Perspective division ``pi(q) = q / q3`` of homogeneous camera points.

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"projection: expected shape (..., 4), got {q.shape}")
    return q / q[..., 2:3]


def projection_jacobian(q):
    """Jacobian ``dpi/dq`` of :func:`projection`.

    ``dpi/dq = (1/q3) [[1, 0, -q1/q3, 0], [0, 1, -q2/q3, 0], [0, 0, 0, 0], [0, 0, -q4/q3, 1]]``

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    ndarray, shape (..., 4, 4)
    """
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"projection_jacobian: expected shape (..., 4), got {q.shape}")
    inv_q3 = 1.0 / q[..., 2]
    J = np.zeros(q.shape[:-1] + (4, 4))
    J[..., 0, 0] = inv_q3
    J[..., 1, 1] = inv_q3
    J[..., 3, 3] = inv_q3
    J[..., 0, 2] = -q[..., 0] * inv_q3**2
    J[..., 1, 2] = -q[..., 1] * inv_q3**2
    J[..., 3, 2] = -q[..., 3] * inv_q3**2
    return J


def _check_pixels(z, name):
    z = np.asarray(z, dtype=float)
    if z.ndim == 0 or z.shape[-1] != 4:
        raise ValueError(f"{name}: pixels must have shape (..., 4) as [uL, vL, uR, vR], got {z.shape}")
    return z


def triangulate_disparity(z, K, b):
    """Points in the left camera frame from stereo pixels, by disparity.

    ``depth = fsu b / (uL - uR)``, ``x = (uL - cu) depth / fsu``, ``y = (vL - cv) depth / fsv``.
    Pixels with non-positive disparity have no finite depth: their rows are NaN.
    Raises ValueError unless ``K`` is 3x3 and ``b`` is positive.

    Parameters
    ----------
    z : array_like, shape (..., 4)
        ``[uL, vL, uR, vR]``.
    K : array_like, shape (3, 3)
    b : float

    Returns
    -------
    ndarray, shape (..., 3)
    """
    z = _check_pixels(z, "triangulate_disparity")
    K, b = _check_calibration(K, b, "triangulate_disparity")
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    disparity = z[..., 0] - z[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(disparity > 0, fsu * b / disparity, np.nan)
    x = (z[..., 0] - cu) * depth / fsu
    y = (z[..., 1] - cv) * depth / fsv
    return np.stack([x, y, depth], axis=-1)


def triangulate_bearing(z, K, b):
    """Points in the left camera frame by the course's bearing triangulation.

    With normalised bearings ``z1 = K^-1 [uL, vL, 1]`` and ``z2 = K^-1 [uR, vR, 1]``,
    the right camera at ``p = [b, 0, 0]`` and ``R = I`` in the left frame,
    ``lambda1 z1 = m`` and ``lambda2 z2 = R^T (m - p)`` give in least squares
    ``lambda1 = a^T c / a^T a`` with ``a = R^T z1 - (e3^T R^T z1) z2`` and
    ``c = R^T p - (e3^T R^T p) z2``; then ``m = lambda1 z1``.
    On noise-free rectified pixels it equals :func:`triangulate_disparity`.
    Rows with non-positive ``lambda1`` are NaN. Raises ValueError unless ``K`` is 3x3 and
    ``b`` is positive.

    Parameters
    ----------
    z : array_like, shape (..., 4)
    K : array_like, shape (3, 3)
    b : float

    Returns
    -------
    ndarray, shape (..., 3)
    """
    z = _check_pixels(z, "triangulate_bearing")
    K, b = _check_calibration(K, b, "triangulate_bearing")
    K_inv = np.linalg.inv(K)
    ones = np.ones(z.shape[:-1] + (1,))
    z1 = np.concatenate([z[..., 0:2], ones], axis=-1) @ K_inv.T
    z2 = np.concatenate([z[..., 2:4], ones], axis=-1) @ K_inv.T
    p = np.array([b, 0.0, 0.0])
    a = z1 - z1[..., 2:3] * z2  # R = I
    c = p - p[2] * z2
    with np.errstate(divide="ignore", invalid="ignore"):
        lam1 = np.einsum("...i,...i->...", a, c) / np.einsum("...i,...i->...", a, a)
    lam1 = np.where(lam1 > 0, lam1, np.nan)
    return lam1[..., None] * z1


def triangulation_jacobian(z, K, b):
    """Jacobian of :func:`triangulate_disparity` with respect to ``[uL, vL, uR, vR]``.

    With disparity ``d = uL - uR`` and ``p = [X, Y, Z]``::

        dZ/duL = -Z/d              dZ/duR = Z/d
        dX/duL = Z/fsu - X/d       dX/duR = X/d
        dY/duL = -Y/d              dY/duR = Y/d        dY/dvL = Z/fsv

    (``vR`` is not used by the disparity form.) Propagating pixel noise gives the
    triangulation covariance ``J (sigma^2 I) J^T``, which grows with depth squared.

    Parameters
    ----------
    z : array_like, shape (..., 4)
    K : array_like, shape (3, 3)
    b : float

    Returns
    -------
    ndarray, shape (..., 3, 4)
        Where the disparity is not positive, every entry that depends on the depth is NaN
        (the entries that are always zero, such as the ``vR`` column, stay 0), so the
        covariance ``J J^T`` is NaN throughout.
    """
    z = _check_pixels(z, "triangulation_jacobian")
    K = np.asarray(K, dtype=float)
    p = triangulate_disparity(z, K, b)
    X, Y, Z = p[..., 0], p[..., 1], p[..., 2]
    d = z[..., 0] - z[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        J = np.zeros(z.shape[:-1] + (3, 4))
        J[..., 0, 0] = Z / K[0, 0] - X / d
        J[..., 0, 2] = X / d
        J[..., 1, 0] = -Y / d
        J[..., 1, 1] = Z / K[1, 1]
        J[..., 1, 2] = Y / d
        J[..., 2, 0] = -Z / d
        J[..., 2, 2] = Z / d
    return J


def _check_points(p_world, name):
    p_world = np.asarray(p_world, dtype=float)
    if p_world.ndim != 2 or p_world.shape[1] != 3:
        raise ValueError(f"{name}: landmarks must have shape (M, 3) in world coordinates, got {p_world.shape}")
    return p_world


class StereoCamera:
    """A calibrated stereo rig mounted on the IMU.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Left camera intrinsics.
    b : float
        Baseline in metres.
    imu_T_cam : array_like, shape (4, 4)
        Pose of the left camera (optical frame) in the IMU frame.

    Attributes
    ----------
    Ks : ndarray, shape (4, 4)
        Stereo matrix, see :func:`stereo_matrix`.
    cam_T_imu : ndarray, shape (4, 4)
        ``inv(imu_T_cam)``, written ``o_T_i`` in the course.
    """

    def __init__(self, K, b, imu_T_cam):
        self.K = np.array(K, dtype=float)
        self.b = float(b)
        self.Ks = stereo_matrix(self.K, self.b)
        self.imu_T_cam = np.array(imu_T_cam, dtype=float)
        if self.imu_T_cam.shape != (4, 4):
            raise ValueError(f"StereoCamera: imu_T_cam must have shape (4, 4), got {self.imu_T_cam.shape}")
        self.cam_T_imu = lie.se3_inv(self.imu_T_cam)

    def __repr__(self):
        return f"StereoCamera(fsu={self.K[0, 0]:.2f}, fsv={self.K[1, 1]:.2f}, b={self.b:.4f} m)"

    def points_in_camera(self, world_T_imu, p_world):
        """Homogeneous landmark coordinates in the left camera, ``q = cam_T_imu inv(T) m``.

        Parameters
        ----------
        world_T_imu : array_like, shape (4, 4)
        p_world : array_like, shape (M, 3)

        Returns
        -------
        ndarray, shape (M, 4)
        """
        cam_T_world = self.cam_T_imu @ lie.se3_inv(world_T_imu)
        p_world = _check_points(p_world, "points_in_camera")
        return p_world @ cam_T_world[:, :3].T + cam_T_world[:, 3]

    def predict(self, world_T_imu, p_world):
        """Predicted stereo pixels ``z = Ks pi(cam_T_imu inv(world_T_imu) m)``.

        Parameters
        ----------
        world_T_imu : array_like, shape (4, 4)
        p_world : array_like, shape (M, 3)

        Returns
        -------
        ndarray, shape (M, 4)
        """
        q = self.points_in_camera(world_T_imu, p_world)
        return projection(q) @ self.Ks.T

    def predict_with_jacobians(self, world_T_imu, p_world):
        """Predicted pixels and both observation Jacobians, sharing one projection.

        Parameters
        ----------
        world_T_imu : array_like, shape (4, 4)
            Pose mean ``mu``.
        p_world : array_like, shape (M, 3)

        Returns
        -------
        z : ndarray, shape (M, 4)
        J_z_landmark : ndarray, shape (M, 4, 3)
            ``Ks dpi/dq(q) cam_T_imu inv(mu) P^T``.
        J_z_pose : ndarray, shape (M, 4, 6)
            ``-Ks dpi/dq(q) cam_T_imu odot(inv(mu) m)`` for the right perturbation.
        """
        imu_T_world = lie.se3_inv(world_T_imu)
        p_world = _check_points(p_world, "predict_with_jacobians")
        p_imu = p_world @ imu_T_world[:3, :3].T + imu_T_world[:3, 3]
        q = p_imu @ self.cam_T_imu[:, :3].T + self.cam_T_imu[:, 3]
        z = projection(q) @ self.Ks.T
        Ks_dpi = self.Ks @ projection_jacobian(q)  # (M, 4, 4)
        J_z_q3 = Ks_dpi @ self.cam_T_imu[:, :3]  # (M, 4, 3): derivative w.r.t. the IMU-frame point
        J_z_landmark = J_z_q3 @ imu_T_world[:3, :3]
        # odot(s) = [[I, -hat(s)], [0, 0]] for s = [p_imu; 1], so its top rows suffice.
        J_z_pose = np.concatenate([-J_z_q3, J_z_q3 @ lie.hat(p_imu)], axis=-1)
        return z, J_z_landmark, J_z_pose

    def jacobian_landmark(self, world_T_imu, p_world):
        """``J_z_landmark`` of :meth:`predict_with_jacobians`, shape (M, 4, 3).

        ``J_z_landmark = Ks dpi/dq(q) cam_T_imu inv(mu) P^T`` with ``P = [I 0]``: the derivative of
        the predicted pixels with respect to each landmark's world position.

        Parameters
        ----------
        world_T_imu : array_like, shape (4, 4)
            Pose mean ``mu``, the IMU in the world frame.
        p_world : array_like, shape (M, 3)
            Landmark positions ``m`` in the world frame, in metres.

        Returns
        -------
        ndarray, shape (M, 4, 3)
            One 4x3 block per landmark, pixels per metre.

        Raises
        ------
        ValueError
            ``world_T_imu`` is not (4, 4) or ``p_world`` is not (M, 3).
        """
        return self.predict_with_jacobians(world_T_imu, p_world)[1]

    def jacobian_pose(self, world_T_imu, p_world):
        """``J_z_pose`` of :meth:`predict_with_jacobians`, shape (M, 4, 6).

        ``J_z_pose = -Ks dpi/dq(q) cam_T_imu odot(inv(mu) m)``: the derivative of the predicted
        pixels with respect to the right perturbation ``world_T_imu = mu exp(delta^)``,
        ``delta = [v; w]`` (linear first).

        Parameters
        ----------
        world_T_imu : array_like, shape (4, 4)
            Pose mean ``mu``, the IMU in the world frame.
        p_world : array_like, shape (M, 3)
            Landmark positions ``m`` in the world frame, in metres.

        Returns
        -------
        ndarray, shape (M, 4, 6)
            One 4x6 block per landmark; columns 0-2 for ``v``, 3-5 for ``w``.

        Raises
        ------
        ValueError
            ``world_T_imu`` is not (4, 4) or ``p_world`` is not (M, 3).
        """
        return self.predict_with_jacobians(world_T_imu, p_world)[2]

    def triangulate(self, z, world_T_imu=None, method="disparity"):
        """Landmark positions from stereo pixels.

        Parameters
        ----------
        z : array_like, shape (M, 4)
        world_T_imu : array_like, shape (4, 4), optional
            If given, points are returned in the world frame, else in the left camera frame.
        method : {"disparity", "bearing"}

        Returns
        -------
        ndarray, shape (M, 3)
            NaN rows where the disparity is not positive.
        """
        if method == "disparity":
            p_cam = triangulate_disparity(z, self.K, self.b)
        elif method == "bearing":
            p_cam = triangulate_bearing(z, self.K, self.b)
        else:
            raise ValueError(f"triangulate: method must be 'disparity' or 'bearing', got {method!r}")
        if world_T_imu is None:
            return p_cam
        world_T_cam = np.asarray(world_T_imu, dtype=float) @ self.imu_T_cam
        return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]

    def triangulation_covariance(self, z, noise_var, world_T_imu=None):
        """Covariance of triangulated points from pixel noise ``noise_var I4``.

        ``J (noise_var I) J^T`` with ``J`` from :func:`triangulation_jacobian`, rotated into the
        world frame (``R Sigma_cam R^T`` with ``R`` the rotation of ``world_T_imu @ imu_T_cam``)
        when a pose is given.

        Parameters
        ----------
        z : array_like, shape (M, 4)
        noise_var : float
        world_T_imu : array_like, shape (4, 4), optional

        Returns
        -------
        ndarray, shape (M, 3, 3)
        """
        J = triangulation_jacobian(z, self.K, self.b)
        cov = noise_var * J @ np.swapaxes(J, -1, -2)
        if world_T_imu is None:
            return cov
        R = (np.asarray(world_T_imu, dtype=float) @ self.imu_T_cam)[:3, :3]
        return R @ cov @ R.T
