"""The calibrated stereo rig mounted on the IMU: :class:`StereoCamera`."""

import numpy as np

from visla_edu import lie
from visla_edu.camera._extrinsics import rectified_baseline
from visla_edu.camera._intrinsics import disparity, same_intrinsics, stereo_matrix, stereo_rows
from visla_edu.camera._projection import projection, stereo_projection
from visla_edu.camera._triangulation import triangulate_bearing, triangulate_disparity, triangulation_jacobian

__all__ = ["StereoCamera"]


def _check_points(p_world, name):
    p_world = np.asarray(p_world, dtype=float)
    if p_world.ndim != 2 or p_world.shape[1] != 3:
        raise ValueError(f"{name}: landmarks must have shape (M, 3) in world coordinates, got {p_world.shape}")
    return p_world


class StereoCamera:
    """A calibrated stereo rig mounted on the IMU (a rectified pair, one or two intrinsics).

    The methods' ``world_T_imu`` (4, 4) is the pose mean ``mu`` (the IMU in the world) and
    ``p_world`` (M, 3) the landmark positions ``m`` (world frame, m); other shapes raise a
    ``ValueError``. The model and the Jacobians' formulas: :mod:`visla_edu.camera`.

    Parameters
    ----------
    K, K_right : array_like, shape (3, 3)
        Left and right camera intrinsics (``K_right`` default: ``K``).
    b : float
        Baseline (m).
    imu_T_cam : array_like, shape (4, 4)
        The left camera (optical frame).

    Attributes
    ----------
    Ks : ndarray, shape (4, 4)
        :func:`~visla_edu.camera.stereo_matrix`.
    cam_T_imu : ndarray, shape (4, 4)
        ``inv(imu_T_cam)``, written ``o_T_i`` in the course.
    K_right : ndarray, shape (3, 3)
        ``K`` itself (a copy) for a single-intrinsics rig.
    same_intrinsics : bool
        ``K_right == K``: every computation is the single-intrinsics one, bit for bit.
    stereo_rows : ndarray, shape (3, 4)
        :func:`~visla_edu.camera.stereo_rows` of ``Ks``.
    fsu_b : float
        ``fsu b``: a landmark at depth ``d`` has :meth:`disparity` ``fsu b / d`` (px).
    """

    def __init__(self, K, b, imu_T_cam, K_right=None):
        self.K = np.array(K, dtype=float)
        self.b = float(b)
        self.Ks = stereo_matrix(self.K, self.b, K_right)
        self.same_intrinsics = same_intrinsics(self.K, K_right)
        self.K_right = self.K.copy() if self.same_intrinsics else np.array(K_right, dtype=float)
        self.stereo_rows = stereo_rows(self.Ks)
        self.fsu_b = self.K[0, 0] * self.b
        self.imu_T_cam = np.array(imu_T_cam, dtype=float)
        if self.imu_T_cam.shape != (4, 4):
            raise ValueError(f"StereoCamera: imu_T_cam must have shape (4, 4), got {self.imu_T_cam.shape}")
        self.cam_T_imu = lie.se3_inv(self.imu_T_cam)

    @classmethod
    def from_extrinsics(cls, K, K_right, imu_T_left, imu_T_right):
        """The rig of two cameras given by their poses, the baseline derived (a rectified pair only).

        ``K``, ``K_right`` (3, 3); ``imu_T_left``, ``imu_T_right`` (4, 4): both cameras' optical frames.
        ``b = |inv(imu_T_left) imu_T_right|`` (:func:`~visla_edu.camera.rectified_baseline`, which
        raises the ``ValueError`` of a pair that is not rectified).
        """
        return cls(K, rectified_baseline(imu_T_left, imu_T_right), imu_T_left, K_right)

    def __repr__(self):
        right = "" if self.same_intrinsics else f", right fsu={self.K_right[0, 0]:.2f}, fsv={self.K_right[1, 1]:.2f}"
        return f"StereoCamera(fsu={self.K[0, 0]:.2f}, fsv={self.K[1, 1]:.2f}{right}, b={self.b:.4f} m)"

    def disparity(self, z):
        """Disparity ``uL - uR`` in the left camera's pixels, (..., 4) -> (...): :func:`~visla_edu.camera.disparity`."""
        return disparity(z, self.K, self._right())

    def points_in_camera(self, world_T_imu, p_world):
        """Homogeneous landmark coordinates in the left camera, ``q = cam_T_imu inv(T) m``, shape (M, 4)."""
        cam_T_world = self.cam_T_imu @ lie.se3_inv(world_T_imu)
        p_world = _check_points(p_world, "points_in_camera")
        return p_world @ cam_T_world[:, :3].T + cam_T_world[:, 3]

    def predict(self, world_T_imu, p_world):
        """Stereo pixels ``z = Ks pi(cam_T_imu inv(world_T_imu) m)``, (M, 4); ``pi`` of :meth:`points_in_camera`."""
        return projection(self.points_in_camera(world_T_imu, p_world)) @ self.Ks.T

    def predict_with_jacobians(self, world_T_imu, p_world):
        """Predicted pixels and both observation Jacobians (:func:`~visla_edu.camera.stereo_projection`).

        Returns
        -------
        z : ndarray, shape (M, 4)
        J_z_landmark : ndarray, shape (M, 4, 3)
            Pixels per metre of ``m``.
        J_z_pose : ndarray, shape (M, 4, 6)
            For the right perturbation of ``world_T_imu``; columns 0-2 for ``v``, 3-5 for ``w``.
        """
        p_world = _check_points(p_world, "predict_with_jacobians")
        z, _, J_z_landmark, J_z_pose = stereo_projection(self.Ks, self.cam_T_imu, np.asarray(world_T_imu, float),
                                                         p_world)
        return z, J_z_landmark, J_z_pose

    def jacobian_landmark(self, world_T_imu, p_world):
        """``J_z_landmark = Ks dpi/dq(q) cam_T_imu inv(mu) P^T``, (M, 4, 3), of :meth:`predict_with_jacobians`."""
        return self.predict_with_jacobians(world_T_imu, p_world)[1]

    def jacobian_pose(self, world_T_imu, p_world):
        """``J_z_pose = -Ks dpi/dq(q) cam_T_imu odot(inv(mu) m)``, (M, 4, 6), of :meth:`predict_with_jacobians`."""
        return self.predict_with_jacobians(world_T_imu, p_world)[2]

    def triangulate(self, z, world_T_imu=None, method="disparity"):
        """Landmark positions (M, 3) from stereo pixels ``z`` (M, 4) (:mod:`visla_edu.camera._triangulation`).

        In the world frame if ``world_T_imu`` is given, else in the left camera frame; NaN rows where the
        disparity is not positive. ``method``: ``"disparity"`` or ``"bearing"``.
        """
        if method not in ("disparity", "bearing"):
            raise ValueError(f"triangulate: method must be 'disparity' or 'bearing', got {method!r}")
        triangulate = triangulate_disparity if method == "disparity" else triangulate_bearing
        p_cam = triangulate(z, self.K, self.b, self._right())
        if world_T_imu is None:
            return p_cam
        world_T_cam = np.asarray(world_T_imu, dtype=float) @ self.imu_T_cam
        return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]

    def triangulation_jacobian(self, z):
        """:func:`~visla_edu.camera.triangulation_jacobian` of the rig's disparity triangulation, (..., 3, 4)."""
        return triangulation_jacobian(z, self.K, self.b, self._right())

    def triangulation_covariance(self, z, noise_var, world_T_imu=None):
        """Covariance ``J (noise_var I4) J^T`` (M, 3, 3) of triangulated points, ``J``: :meth:`triangulation_jacobian`.

        ``noise_var``: pixel noise variance (px^2). With a pose it is rotated into the world frame:
        ``R Sigma_cam R^T``, ``R`` the rotation of ``world_T_imu @ imu_T_cam``.
        """
        J = self.triangulation_jacobian(z)
        cov = noise_var * J @ np.swapaxes(J, -1, -2)
        if world_T_imu is None:
            return cov
        R = (np.asarray(world_T_imu, dtype=float) @ self.imu_T_cam)[:3, :3]
        return R @ cov @ R.T

    def _right(self):
        """``K_right`` for the triangulation functions (None for one intrinsics: their bit-identical path)."""
        return None if self.same_intrinsics else self.K_right
