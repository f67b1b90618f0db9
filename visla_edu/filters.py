"""The four filter modes as small state machines that advance one frame per ``step()``.

* :class:`DeadReckoning` - IMU prediction only (mean and covariance).
* :class:`LandmarkMapping` - poses fixed to dead reckoning, one 3x3 EKF per landmark; each
  observation's noise includes the motion noise accumulated since the landmark's first
  sighting.
* :class:`VisualInertialOdometry` - pose EKF against landmarks fixed where they were first
  triangulated (their covariance includes the pose's uncertainty at that time); only the
  pose is updated.
* :class:`JointSlam` - the joint EKF over the pose and the landmarks. By default it keeps
  only the *active set* (landmarks being tracked): a landmark enters at its first usable
  observation, which it consumes (mean from stereo triangulation; covariance from the pixels
  and, through ``G_pose``, from the pose, with the matching cross-covariance to the rest of
  the state), and is marginalised (its rows and columns deleted) after its last one. With
  ``dense=True`` it is the textbook filter over all landmarks from the start. Both give the
  same trajectory: a landmark not yet observed is uncorrelated with everything (its rows are
  filled at its first observation exactly as the active set appends them), and marginalising
  a Gaussian in covariance form is deleting rows and columns. The maps differ in one way: in
  the dense filter a retired landmark keeps moving through its correlation with the pose, in
  the active set it keeps the estimate it had when it left.

Each ``step()`` returns a :class:`StepRecord` (what the widgets and metrics read).
"""

from dataclasses import dataclass

import numpy as np

from visla_edu import ekf, lie, motion
from visla_edu.dataset import repeated_frames
from visla_edu.ekf import FilterDivergedError

__all__ = [
    "StepRecord",
    "OBS_USED",
    "OBS_GATED",
    "OBS_NEW",
    "OBS_NO_DEPTH",
    "OBS_FAR",
    "OBS_IGNORED",
    "STATUS_NAMES",
    "DeadReckoning",
    "LandmarkMapping",
    "VisualInertialOdometry",
    "JointSlam",
]

OBS_USED = 0  #: used in the update
OBS_GATED = 1  #: rejected by the Mahalanobis gate (outlier)
OBS_NEW = 2  #: first observation: the landmark entered the state here
OBS_NO_DEPTH = 3  #: non-positive disparity: a broken stereo match, never used
OBS_FAR = 4  #: disparity too small to initialise the landmark (not yet in the state)
OBS_IGNORED = 5  #: not used by this mode (dead reckoning, landmark stride)
STATUS_NAMES = ("used", "gated", "new", "no depth", "too far", "ignored")

#: A pose farther than this from the start (m) has diverged (no course drive goes near it).
MAX_DISTANCE = 1e7

#: Landmark estimates closer to the camera than this (m) are not linearised (see ``_gate``).
MIN_DEPTH = 0.1

#: Variance on the diagonal of a landmark the dense filter has not observed yet (its mean is
#: not set either); replaced by the real prior at the first observation.
DENSE_PLACEHOLDER_VARIANCE = 1e6

#: The dense reference refuses covariances larger than this (bytes); use a landmark stride.
MAX_DENSE_BYTES = 4 * 2**30


@dataclass
class StepRecord:
    """What one filter step produced (copies, safe to keep).

    Attributes
    ----------
    t : int
        Frame index.
    world_T_imu : ndarray, shape (4, 4)
        Pose mean after the update.
    pose_cov : ndarray, shape (6, 6)
        Pose covariance (right perturbation ``[v; w]``).
    ids : ndarray of int, shape (k,)
        Landmarks observed at this frame.
    z : ndarray, shape (k, 4)
        Their stereo pixels.
    z_pred : ndarray, shape (k, 4)
        Predicted pixels before the update (NaN where the landmark was not in the state).
    status : ndarray of int, shape (k,)
        ``OBS_*`` code of each observation.
    nis : float
        Normalised innovation squared of the update (NaN without an update).
    nis_dof : int
        Its degrees of freedom (4 per used observation).
    active_ids : ndarray of int, shape (n,)
        Landmarks currently in the state (the active set; mapped landmarks for mapping/VIO).
    active_means : ndarray, shape (n, 3)
    active_covs : ndarray, shape (n, 3, 3)
        Marginal covariance of each active landmark.
    """

    t: int
    world_T_imu: np.ndarray
    pose_cov: np.ndarray
    ids: np.ndarray
    z: np.ndarray
    z_pred: np.ndarray
    status: np.ndarray
    nis: float
    nis_dof: int
    active_ids: np.ndarray
    active_means: np.ndarray
    active_covs: np.ndarray


class _Filter:
    """Shared bookkeeping: time, twists, observations with their status, the landmark map."""

    def __init__(self, dataset, camera, config):
        self.dataset = dataset
        self.camera = camera
        self.config = config
        self.noise_var = config.pixel_variance
        self.gate = config.gate_threshold
        self.taus = dataset.time_steps
        self.step_twists = motion.select_twists(dataset.twists, config.imu_lag)
        self.t = -1
        self.world_T_imu = np.eye(4)
        M = dataset.num_landmarks
        self.landmarks = np.full((M, 3), np.nan)
        self.landmark_cov = np.full((M, 3, 3), np.nan)
        self.last_frame = dataset.track_spans()[:, 1]
        self.skip_frames = set(repeated_frames(dataset)) if config.skip_repeated_frames else set()

    @property
    def done(self):
        """True once the last frame has been processed."""
        return self.t >= self.dataset.num_frames - 1

    def step(self):
        """Process the next frame (predict from the previous one, then update)."""
        if self.done:
            raise StopIteration(f"{self.dataset.name}: all {self.dataset.num_frames} frames processed")
        self.t += 1
        if self.t > 0:
            self._predict(self.step_twists[self.t - 1], self.taus[self.t - 1])
        ids, z = self.dataset.observations(self.t)
        status = np.full(len(ids), OBS_IGNORED)
        z_pred = np.full((len(ids), 4), np.nan)
        nis, dof = (np.nan, 0) if self.t in self.skip_frames else self._update(ids, z, status, z_pred)
        self._check_finite()
        return self._record(ids, z, z_pred, status, nis, dof)

    # -- pieces the modes share -------------------------------------------------------
    def _predict(self, u, tau):
        """IMU prediction: ``mu <- mu exp(tau u)``, covariance through ``F`` and ``W``."""
        step, F, W = motion.imu_step(u, tau, self.config.sigma_linear_velocity, self.config.sigma_angular_velocity)
        self.world_T_imu = self.world_T_imu @ step
        self._predict_covariance(F, W)

    def _usable(self, ids, z, status):
        """Mark stride-skipped and no-depth observations; return the mask of usable ones."""
        in_stride = ids % self.config.landmark_stride == 0
        disparity = z[:, 0] - z[:, 2]
        status[in_stride & (disparity <= 0)] = OBS_NO_DEPTH
        return in_stride & (disparity > 0)

    def _new_landmarks(self, ids, z, status, candidates):
        """Triangulate never-seen landmarks among ``candidates`` (mask) at the current pose.

        Their first observation is consumed by the initialisation (status ``OBS_NEW``).

        Returns
        -------
        new : ndarray of bool, shape (k,)
            Observations whose landmark was initialised now.
        G_pose : ndarray, shape (k_new, 3, 6)
            Sensitivity of the new landmarks to the pose perturbation.
        C_new : ndarray, shape (k_new, 3, 3)
            Their covariance from the pixels: ``inflation^2 C_tri + sigma^2 I``.
        """
        cfg = self.config
        disparity = z[:, 0] - z[:, 2]
        new = candidates & (disparity >= cfg.min_init_disparity)
        status[candidates & ~new] = OBS_FAR
        status[new] = OBS_NEW
        p_world, G_pose, C_tri = ekf.initialize_landmarks(self.world_T_imu, z[new], self.camera, self.noise_var)
        self.landmarks[ids[new]] = p_world
        return new, G_pose, cfg.landmark_prior_inflation**2 * C_tri + cfg.landmark_prior_sigma**2 * np.eye(3)

    def _gate(self, S, innovation, z_pred):
        """Mask of observations inside the chi-square gate, and their squared distances.

        A landmark whose estimate lies behind the camera or closer than ``MIN_DEPTH`` (its
        predicted disparity ``fsu b / depth`` is not in ``(0, fsu b / MIN_DEPTH)``) has no
        usable linearisation: its observation is rejected with distance ``inf``.
        """
        fsu_b = self.camera.K[0, 0] * self.camera.b
        disparity = z_pred[:, 0] - z_pred[:, 2]
        valid = (disparity > 0) & (disparity < fsu_b / MIN_DEPTH) & np.isfinite(S).all(axis=(1, 2))
        d2 = np.full(len(S), np.inf)
        if np.any(valid):
            d2[valid] = ekf.mahalanobis_squared(innovation[valid], S[valid])
        return d2 <= self.gate, d2

    def _check_finite(self):
        # The covariance too: a huge but finite velocity keeps the pose finite while
        # F Sigma F^T overflows, after which every observation is silently gated.
        for what, value in (("pose", self.world_T_imu), ("pose covariance", self.pose_cov)):
            if not np.all(np.isfinite(value)):
                raise FilterDivergedError(
                    f"{self.dataset.name}: {what} became non-finite at frame {self.t}; "
                    "check the noise settings and the input velocities")
        distance = float(np.linalg.norm(self.world_T_imu[:3, 3]))
        if distance > MAX_DISTANCE:
            raise FilterDivergedError(
                f"{self.dataset.name}: the pose diverged at frame {self.t} ({distance:.3g} m from the start)")
        variances = np.diag(self.pose_cov)
        if np.any(variances < 0):
            raise FilterDivergedError(
                f"{self.dataset.name}: pose covariance lost positive definiteness at frame {self.t} "
                f"(diagonal {np.array2string(variances, precision=3)})")

    def _record(self, ids, z, z_pred, status, nis, dof):
        active_ids, active_covs = self._active()
        return StepRecord(
            t=self.t, world_T_imu=self.world_T_imu.copy(), pose_cov=self.pose_cov.copy(),
            ids=ids.copy(), z=z.copy(), z_pred=z_pred, status=status, nis=nis, nis_dof=dof,
            active_ids=active_ids, active_means=self.landmarks[active_ids].copy(),
            active_covs=active_covs,
        )

    def _active(self):
        """Ids of the landmarks shown as active, and their covariances (copies)."""
        active = np.nonzero(np.isfinite(self.landmarks[:, 0]) & (self.last_frame >= self.t))[0]
        return active, self.landmark_cov[active].copy()


class DeadReckoning(_Filter):
    """IMU prediction only: ``mu <- mu exp(tau u)``, ``Sigma <- F Sigma F^T + W``."""

    def __init__(self, dataset, camera, config):
        super().__init__(dataset, camera, config)
        self.pose_cov = config.initial_pose_sigma**2 * np.eye(6)

    def _predict_covariance(self, F, W):
        self.pose_cov = motion.predict_pose_covariance(self.pose_cov, F, W)

    def _update(self, ids, z, status, z_pred):
        return np.nan, 0


class LandmarkMapping(DeadReckoning):
    """Poses from dead reckoning, landmarks by independent 3x3 EKF updates.

    The poses are held fixed, but they are not exact: between a landmark's first sighting at
    ``t0`` and frame ``t`` the dead-reckoned motion accumulates the process noise
    ``Q = Sigma_t - Phi Sigma_t0 Phi^T`` with ``Phi = Ad(inv(T_t) T_t0)`` (the part of the pose
    covariance that is not shared with the pose the landmark was placed from). Each
    observation's noise becomes ``R + J_pose Q J_pose^T``, in the gate and in the update, so
    a drifting IMU widens the gate instead of rejecting the observations.
    """

    def __init__(self, dataset, camera, config):
        super().__init__(dataset, camera, config)
        T = dataset.num_frames
        self.pose_history = np.empty((T, 4, 4))
        self.pose_cov_history = np.empty((T, 6, 6))
        self.init_frame = np.full(dataset.num_landmarks, -1)

    def _update(self, ids, z, status, z_pred):
        self.pose_history[self.t] = self.world_T_imu
        self.pose_cov_history[self.t] = self.pose_cov
        usable = self._usable(ids, z, status)
        known = usable & np.isfinite(self.landmarks[ids, 0])
        accepted, nis, dof = self._gate_mapped(ids, z, status, z_pred, known)
        if np.any(accepted):
            lm = ids[accepted]
            self.landmarks[lm], self.landmark_cov[lm] = ekf.landmark_update(
                self.landmarks[lm], self.landmark_cov[lm], z[accepted], self.world_T_imu, self.camera,
                self.noise_var, extra_noise=self._accepted_pose_noise)
        self._add_new(ids, z, status, usable & ~known)
        return nis, dof

    def _relative_motion_noise(self, lm, J_pose):
        """``J_pose Q J_pose^T`` per observation, Q the motion noise since each landmark's first sighting."""
        t0 = self.init_frame[lm]
        Phi = lie.adjoint(lie.se3_inv(self.world_T_imu) @ self.pose_history[t0])
        Q = self.pose_cov - Phi @ self.pose_cov_history[t0] @ np.swapaxes(Phi, 1, 2)
        return J_pose @ Q @ np.swapaxes(J_pose, 1, 2)

    def _gate_mapped(self, ids, z, status, z_pred, known):
        """Predict and gate the observations of mapped landmarks.

        Returns the accepted mask, the sum of their squared distances and its dof.
        """
        accepted = np.zeros(len(ids), dtype=bool)
        if not np.any(known):
            return accepted, np.nan, 0
        lm = ids[known]
        pred, J_landmark, J_pose = self.camera.predict_with_jacobians(self.world_T_imu, self.landmarks[lm])
        z_pred[known] = pred
        pose_noise = self._pose_noise(lm, J_pose)
        S = ekf.innovation_covariances(None, J_landmark, None, None, self.landmark_cov[lm], self.noise_var)
        inside, d2 = self._gate(S + pose_noise, z[known] - pred, pred)
        where = np.nonzero(known)[0]
        accepted[where[inside]] = True
        status[where[inside]] = OBS_USED
        status[where[~inside]] = OBS_GATED
        self._accepted_pose_noise = pose_noise[inside]
        return accepted, float(d2[inside].sum()), 4 * int(inside.sum())

    def _pose_noise(self, lm, J_pose):
        if not self.config.mapping_motion_noise:
            return np.zeros((len(lm), 4, 4))
        return self._relative_motion_noise(lm, J_pose)

    def _add_new(self, ids, z, status, candidates, Sigma_pose=None):
        """Initialise new landmarks; with an uncertain pose, its uncertainty is added."""
        new, G_pose, C_new = self._new_landmarks(ids, z, status, candidates)
        if Sigma_pose is not None:
            C_new = C_new + G_pose @ Sigma_pose @ np.swapaxes(G_pose, 1, 2)
        self.landmark_cov[ids[new]] = C_new
        self.init_frame[ids[new]] = self.t


class VisualInertialOdometry(LandmarkMapping):
    """Pose EKF against landmarks fixed where they were first triangulated.

    A landmark is placed once, from its first observation and the pose at that time (its
    covariance includes that pose's uncertainty, ``G_pose Sigma_pose G_pose^T``); later
    observations update the pose alone, with ``R_i = sigma^2 I + J_landmark Sigma_i
    J_landmark^T``. The landmarks are not re-estimated: updating them with the same
    observations that just corrected the pose would count each observation twice and drag
    pose and map along together (on the simulated drive that makes the trajectory error 60x
    larger). The joint filter (``JointSlam``) is the consistent way to refine both.
    """

    def _update(self, ids, z, status, z_pred):
        usable = self._usable(ids, z, status)
        known = usable & np.isfinite(self.landmarks[ids, 0])
        accepted, nis, dof = self._gate_mapped(ids, z, status, z_pred, known)
        if np.any(accepted):
            try:
                self.world_T_imu, self.pose_cov, _ = ekf.pose_update(
                    self.world_T_imu, self.pose_cov, self.landmarks[ids[accepted]], z[accepted], self.camera,
                    self.noise_var, Sigma_landmark=self.landmark_cov[ids[accepted]])
            except np.linalg.LinAlgError as err:
                raise FilterDivergedError(
                    f"{self.dataset.name}: innovation covariance not positive definite at frame {self.t}: {err}"
                ) from err
            if self.config.vio_refine_landmarks:
                lm = ids[accepted]
                self.landmarks[lm], self.landmark_cov[lm] = ekf.landmark_update(
                    self.landmarks[lm], self.landmark_cov[lm], z[accepted], self.world_T_imu, self.camera,
                    self.noise_var)
        self._add_new(ids, z, status, usable & ~known, Sigma_pose=self.pose_cov)
        return nis, dof

    def _pose_noise(self, lm, J_pose):
        """The gate sees the current pose uncertainty ``J_pose Sigma_pose J_pose^T``."""
        return J_pose @ self.pose_cov @ np.swapaxes(J_pose, 1, 2)


class JointSlam(_Filter):
    """Joint EKF over ``[pose; landmarks]``, active set by default, textbook form if ``dense``.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    camera : visla_edu.camera.StereoCamera
    config : visla_edu.ekf.FilterConfig
    dense : bool
        Keep every (strided) landmark in the state from the first frame.
    """

    def __init__(self, dataset, camera, config, dense=False):
        super().__init__(dataset, camera, config)
        self.dense = dense
        self.slot_of = np.full(dataset.num_landmarks, -1)
        if dense:
            self.active_ids = np.arange(0, dataset.num_landmarks, config.landmark_stride)
            D = 6 + 3 * len(self.active_ids)
            if D * D * 8 > MAX_DENSE_BYTES:
                raise ValueError(
                    f"dense SLAM on {dataset.name}: a {D}x{D} covariance needs {D * D * 8 / 2**30:.1f} GiB "
                    f"(limit {MAX_DENSE_BYTES / 2**30:.0f} GiB); use landmark_stride or the active set")
            self.slot_of[self.active_ids] = np.arange(len(self.active_ids))
            self.Sigma = np.zeros((D, D))
            idx = np.arange(6, D)
            self.Sigma[idx, idx] = DENSE_PLACEHOLDER_VARIANCE
        else:
            self.active_ids = np.zeros(0, dtype=np.int64)
            self.Sigma = np.zeros((6, 6))
        self.Sigma[:6, :6] = config.initial_pose_sigma**2 * np.eye(6)

    @property
    def pose_cov(self):
        """The pose block of the joint covariance, (6, 6) (a view)."""
        return self.Sigma[:6, :6]

    def _predict_covariance(self, F, W):
        motion.predict_joint_covariance(self.Sigma, F, W)

    def _update(self, ids, z, status, z_pred):
        if not self.dense:
            self._retire(self.last_frame[self.active_ids] < self.t)
        usable = self._usable(ids, z, status)
        known = usable & np.isfinite(self.landmarks[ids, 0])
        self._gate_known(ids, z, status, z_pred, known)
        use = status == OBS_USED
        nis = np.nan
        if np.any(use):
            try:
                self.world_T_imu, self.landmarks[self.active_ids], nis = ekf.joint_update(
                    self.Sigma, self.world_T_imu, self.landmarks[self.active_ids], self.slot_of[ids[use]],
                    z[use], self.camera, self.noise_var, prediction=self._prediction(known, use))
            except np.linalg.LinAlgError as err:
                raise FilterDivergedError(
                    f"{self.dataset.name}: innovation covariance not positive definite at frame {self.t} "
                    f"({int(use.sum())} observations): {err}") from err
        new, G_pose, C_new = self._new_landmarks(ids, z, status, usable & ~known)
        if np.any(new):
            if not self.dense:
                self._enter(ids[new])
            self._augment(ids[new], G_pose, C_new)
        return nis, 4 * int(use.sum())

    def _gate_known(self, ids, z, status, z_pred, known):
        """Predict and gate the observations of landmarks already in the state."""
        if not np.any(known):
            return
        lm = ids[known]
        cols = 6 + 3 * self.slot_of[lm][:, None] + np.arange(3)  # (k, 3)
        pred, J_landmark, J_pose = self.camera.predict_with_jacobians(self.world_T_imu, self.landmarks[lm])
        z_pred[known] = pred
        S = ekf.innovation_covariances(
            J_pose, J_landmark, self.Sigma[:6, :6],
            np.swapaxes(self.Sigma[:6][:, cols], 0, 1),
            self.Sigma[cols[:, :, None], cols[:, None, :]], self.noise_var)
        inside, _ = self._gate(S, z[known] - pred, pred)
        where = np.nonzero(known)[0]
        status[where[inside]] = OBS_USED
        status[where[~inside]] = OBS_GATED
        self._known_prediction = (pred, J_landmark, J_pose)

    def _prediction(self, known, use):
        """The gate's predictions and Jacobians restricted to the observations in use."""
        keep = use[known]
        return tuple(a[keep] for a in self._known_prediction)

    def _enter(self, new_ids):
        """Append slots for new landmarks (zero rows and columns, filled by :meth:`_augment`)."""
        n_old = len(self.active_ids)
        D_old = self.Sigma.shape[0]
        Sigma = np.zeros((D_old + 3 * len(new_ids),) * 2)
        Sigma[:D_old, :D_old] = self.Sigma
        self.Sigma = Sigma
        self.active_ids = np.concatenate([self.active_ids, new_ids])
        self.slot_of[new_ids] = n_old + np.arange(len(new_ids))

    def _augment(self, new_ids, G_pose, C_new):
        """Fill the covariance of newly initialised landmarks (see ``ekf.initialize_landmarks``).

        ``Sigma_new,x = G_pose Sigma_pose,x`` for every state entry x, and
        ``Sigma_new,new = G_pose Sigma_pp G_pose^T + C_new`` (C_new block diagonal). In the
        dense form their rows held the placeholder prior and no correlation (never observed),
        so overwriting them is the same as appending them now.
        """
        k = len(new_ids)
        cols = (6 + 3 * self.slot_of[new_ids][:, None] + np.arange(3)).ravel()
        if not self.config.landmark_cross_covariance:  # the textbook shortcut, for comparison
            G_pose = np.zeros_like(G_pose)
        G = G_pose.reshape(3 * k, 6)
        cross = G @ self.Sigma[:6]  # (3k, D)
        self.Sigma[cols] = cross
        self.Sigma[:, cols] = cross.T
        block = G @ self.Sigma[:6, :6] @ G.T
        block.reshape(k, 3, k, 3)[np.arange(k), :, np.arange(k), :] += C_new
        self.Sigma[np.ix_(cols, cols)] = block

    def _retire(self, leaving):
        """Marginalise the landmarks marked ``leaving`` (delete their rows and columns)."""
        if not np.any(leaving):
            return
        self.landmark_cov[self.active_ids[leaving]] = self._slot_covs(np.nonzero(leaving)[0])
        self.slot_of[self.active_ids[leaving]] = -1
        keep_slots = np.nonzero(~leaving)[0]
        keep = np.concatenate([np.arange(6), (6 + 3 * keep_slots[:, None] + np.arange(3)).ravel()])
        self.Sigma = self.Sigma.take(keep, axis=0).take(keep, axis=1)
        self.active_ids = self.active_ids[keep_slots]
        self.slot_of[self.active_ids] = np.arange(len(self.active_ids))

    def _slot_covs(self, slots):
        cols = 6 + 3 * np.asarray(slots)[:, None] + np.arange(3)
        return self.Sigma[cols[:, :, None], cols[:, None, :]]

    def _active(self):
        ids = self.active_ids
        active = ids[np.isfinite(self.landmarks[ids, 0]) & (self.last_frame[ids] >= self.t)]
        return active, self._slot_covs(self.slot_of[active])

    def landmark_estimates(self):
        """Final landmark means (M, 3) and marginal covariances (M, 3, 3); NaN if never initialised.

        Landmarks still in the state report their current estimate (in the dense form that
        is every initialised landmark, retired or not).
        """
        cov = self.landmark_cov.copy()
        in_state = self.active_ids[np.isfinite(self.landmarks[self.active_ids, 0])]
        cov[in_state] = self._slot_covs(self.slot_of[in_state])
        return self.landmarks.copy(), cov
