"""Dead reckoning and the two modes over a map of independent landmarks: mapping and VIO.

Mapping and VIO share :class:`_LandmarkMap`: the dead-reckoning pose plus landmarks with a
mean and a 3x3 covariance each (no correlation between them or with the pose), the gate
for their observations and their initialisation. Each class says its model.
"""

import abc

import numpy as np

from visla_edu import ekf, lie, motion
from visla_edu.filters._base import FilterBase

__all__ = ["DeadReckoning", "LandmarkMapping", "VisualInertialOdometry"]


class DeadReckoning(FilterBase):
    """IMU prediction only: ``mu <- mu exp(tau u)``, ``Sigma <- F Sigma F^T + W``.

    Its pose, with a 6x6 covariance of its own (:attr:`pose_cov`, right perturbation ``[v; w]``,
    ``initial_pose_sigma^2 I`` at the start), is also the pose of mapping and VIO. Arguments,
    attributes and ``ValueError`` as :class:`~visla_edu.filters.FilterBase`.
    """

    def __init__(self, dataset, camera, config):
        super().__init__(dataset, camera, config)
        self._pose_cov = config.initial_pose_sigma**2 * np.eye(6)

    @property
    def pose_cov(self):
        """The pose covariance, (6, 6)."""
        return self._pose_cov

    @pose_cov.setter
    def pose_cov(self, value):
        self._pose_cov = value

    def _predict_covariance(self, F, W):
        self._pose_cov = motion.predict_pose_covariance(self._pose_cov, F, W)

    def _update(self, ids, z, status, z_pred):
        return np.nan, 0

    def _active(self):
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3, 3))

    def landmark_estimates(self):
        """Landmark means (M, 3) and covariances (M, 3, 3) (copies); NaN if never initialised."""
        return self.landmarks.copy(), self.landmark_cov.copy()


class _LandmarkMap(DeadReckoning):
    """The dead-reckoning pose and independent landmarks (mean, 3x3 covariance); modes fill :meth:`_pose_noise`."""

    def __init__(self, dataset, camera, config):
        super().__init__(dataset, camera, config)
        self.init_frame = np.full(dataset.num_landmarks, -1)  # frame of each landmark's first sighting

    @abc.abstractmethod
    def _pose_noise(self, lm, J_pose):
        """Noise (k, 4, 4) the pose's uncertainty adds to the observations of ``lm``; ``J_pose`` (k, 4, 6)."""

    def _active(self):
        active = np.nonzero(np.isfinite(self.landmarks[:, 0]) & (self.last_frame >= self.t))[0]
        return active, self.landmark_cov[active].copy()

    def _gate_mapped(self, ids, z, status, z_pred, known):
        """Predict and gate the observations of mapped landmarks (``known`` mask); fills ``z_pred`` and ``status``.

        Returns ``accepted`` (k,) bool, ``nis`` (sum of their squared Mahalanobis distances; NaN when
        none was predicted), ``dof`` (4 per accepted) and ``pose_noise`` (k_accepted, 4, 4) or None.
        """
        accepted = np.zeros(len(ids), dtype=bool)
        if not np.any(known):
            return accepted, np.nan, 0, None
        lm = ids[known]
        pred, J_landmark, J_pose = self.camera.predict_with_jacobians(self.world_T_imu, self.landmarks[lm])
        z_pred[known] = pred
        pose_noise = self._pose_noise(lm, J_pose)
        S = ekf.innovation_covariances(None, J_landmark, None, None, self.landmark_cov[lm], self.noise_var)
        inside, d2 = self._gate(S + pose_noise, z[known] - pred, pred)
        self._mark_gated(status, known, inside)
        accepted[np.nonzero(known)[0][inside]] = True
        return accepted, float(d2[inside].sum()), 4 * int(inside.sum()), pose_noise[inside]

    def _update_landmarks(self, lm, z, extra_noise=None):
        """One 3x3 EKF update per landmark of ``lm`` with the pose held fixed (``ekf.landmark_update``)."""
        self.landmarks[lm], self.landmark_cov[lm] = ekf.landmark_update(
            self.landmarks[lm], self.landmark_cov[lm], z, self.world_T_imu, self.camera, self.noise_var,
            extra_noise=extra_noise)

    def _add_new(self, ids, z, status, candidates, Sigma_pose=None):
        """Initialise new landmarks; with an uncertain pose ``Sigma_pose``, ``G Sigma_pose G^T`` is added."""
        new, G_pose, C_new = self._new_landmarks(ids, z, status, candidates)
        if Sigma_pose is not None:
            C_new = C_new + G_pose @ Sigma_pose @ np.swapaxes(G_pose, 1, 2)
        self.landmark_cov[ids[new]] = C_new
        self.init_frame[ids[new]] = self.t


class LandmarkMapping(_LandmarkMap):
    """Poses from dead reckoning, landmarks by independent 3x3 EKF updates.

    The poses are held fixed, but they are not exact: between a landmark's first sighting at
    ``t0`` and frame ``t`` the dead-reckoned motion accumulates the process noise
    ``Q = Sigma_t - Phi Sigma_t0 Phi^T`` with ``Phi = Ad(inv(T_t) T_t0)`` (the part of the pose
    covariance not shared with the pose the landmark was placed from). Each observation's noise
    becomes ``R + J_pose Q J_pose^T``, in the gate and in the update
    (``FilterConfig.mapping_motion_noise``; off, the poses count as exact).

    Attributes
    ----------
    landmark_cov, init_frame : ndarray, shapes (M, 3, 3) and (M,) of int
        Covariances of :attr:`landmarks`, independent of each other and of the pose, and the frame of
        each landmark's first sighting, -1 before it.
    pose_history, pose_cov_history : ndarray, shapes (T, 4, 4) and (T, 6, 6)
        Pose mean and covariance at every frame processed so far (later rows not set), for ``Q``.
    """

    def __init__(self, dataset, camera, config):
        super().__init__(dataset, camera, config)
        T = dataset.num_frames
        self.pose_history = np.empty((T, 4, 4))
        self.pose_cov_history = np.empty((T, 6, 6))

    def _update(self, ids, z, status, z_pred):
        self.pose_history[self.t] = self.world_T_imu
        self.pose_cov_history[self.t] = self.pose_cov
        usable = self._usable(ids, z, status)
        known = self._known(ids, usable)
        accepted, nis, dof, pose_noise = self._gate_mapped(ids, z, status, z_pred, known)
        if np.any(accepted):
            self._update_landmarks(ids[accepted], z[accepted], extra_noise=pose_noise)
        self._add_new(ids, z, status, usable & ~known)
        return nis, dof

    def _pose_noise(self, lm, J_pose):
        """``J_pose Q J_pose^T`` per observation, Q the motion noise since each landmark's first sighting."""
        if not self.config.mapping_motion_noise:
            return np.zeros((len(lm), 4, 4))
        t0 = self.init_frame[lm]
        Phi = lie.adjoint(lie.se3_inv(self.world_T_imu) @ self.pose_history[t0])
        Q = self.pose_cov - Phi @ self.pose_cov_history[t0] @ np.swapaxes(Phi, 1, 2)
        return J_pose @ Q @ np.swapaxes(J_pose, 1, 2)


class VisualInertialOdometry(_LandmarkMap):
    """Pose EKF against landmarks fixed where they were first triangulated.

    A landmark is placed once, from its first observation and the pose then (its covariance includes
    that pose's uncertainty, ``G_pose Sigma_pose G_pose^T``); later observations update the pose
    alone (:attr:`pose_cov`), with ``R_i = sigma^2 I + J_landmark Sigma_i J_landmark^T``. Updating the
    landmarks too would count each observation twice (``FilterConfig.vio_refine_landmarks`` does it
    for comparison); :class:`~visla_edu.filters.JointSlam` refines both consistently.
    ``landmark_cov`` and ``init_frame`` as :class:`LandmarkMapping`'s.
    """

    def _update(self, ids, z, status, z_pred):
        usable = self._usable(ids, z, status)
        known = self._known(ids, usable)
        accepted, nis, dof, _ = self._gate_mapped(ids, z, status, z_pred, known)
        if np.any(accepted):
            lm = ids[accepted]
            try:
                self.world_T_imu, self.pose_cov, _ = ekf.pose_update(
                    self.world_T_imu, self.pose_cov, self.landmarks[lm], z[accepted], self.camera,
                    self.noise_var, Sigma_landmark=self.landmark_cov[lm])
            except np.linalg.LinAlgError as err:
                raise self._diverged(err) from err
            if self.config.vio_refine_landmarks:
                self._update_landmarks(lm, z[accepted])
        self._add_new(ids, z, status, usable & ~known, Sigma_pose=self.pose_cov)
        return nis, dof

    def _pose_noise(self, lm, J_pose):
        """The gate sees the current pose uncertainty ``J_pose Sigma_pose J_pose^T``."""
        return J_pose @ self.pose_cov @ np.swapaxes(J_pose, 1, 2)
