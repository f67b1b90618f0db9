"""What every filter mode shares: the step record, the step loop and its declared hooks.

:meth:`FilterBase.step` is the same for every mode: predict from the previous frame, update with
this frame's observations, check the state, record. A mode fills in the hooks the step calls
(:attr:`~FilterBase.pose_cov`, :meth:`~FilterBase._predict_covariance`, :meth:`~FilterBase._update`,
:meth:`~FilterBase._active`, :meth:`~FilterBase.landmark_estimates`); they are abstract here, each
with its contract.
"""

import abc
from dataclasses import dataclass

import numpy as np

from visla_edu import ekf, motion
from visla_edu.codes import OBS_FAR, OBS_GATED, OBS_IGNORED, OBS_NEW, OBS_NO_DEPTH, OBS_USED
from visla_edu.dataset import repeated_frames, stale_copies

__all__ = ["FilterDivergedError", "StepRecord", "MAX_DISTANCE", "MIN_DEPTH"]

#: A pose farther than this from the start (m) has diverged (no course drive goes near it).
MAX_DISTANCE = 1e7

#: Landmark estimates closer to the camera than this (m) are not linearised (see ``_gate``).
MIN_DEPTH = 0.1


class FilterDivergedError(RuntimeError):
    """The filter produced a non-finite state or a covariance that is not positive definite.

    Raised by ``step()`` when, after the frame, the pose or its covariance is not finite, a pose
    variance is negative or the pose is more than :data:`MAX_DISTANCE` m from the origin, and when
    an update cannot factorise its innovation covariance (chained from the ``LinAlgError``).
    """


@dataclass
class StepRecord:
    """What one filter step produced (copies, safe to keep).

    Attributes
    ----------
    t : int
        Frame index.
    world_T_imu, pose_cov : ndarray, shapes (4, 4) and (6, 6)
        Pose mean and covariance (right perturbation ``[v; w]``) after the update.
    ids, z : ndarray, shapes (k,) of int and (k, 4)
        Landmarks observed at this frame and their stereo pixels.
    z_pred, status : ndarray, shapes (k, 4) and (k,) of int
        Predicted pixels before the update (NaN where the landmark was not in the state) and the
        ``OBS_*`` code of each observation (:mod:`visla_edu.codes`).
    nis, nis_dof : float and int
        Normalised innovation squared of the update (NaN without an update) and its degrees of
        freedom: 4 per used observation, and ``4 n - 3`` per track of ``n`` observations used in a
        null-space update (joint SLAM with clones).
    active_ids, active_means, active_covs : ndarray, shapes (n,) of int, (n, 3), (n, 3, 3)
        Landmarks currently in the state (the active set; mapped landmarks for mapping/VIO), their
        means and marginal covariances.
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


class FilterBase(abc.ABC):
    """Shared bookkeeping of every mode: time, twists, observations with their status, the landmark means.

    ``dataset`` (:class:`visla_edu.dataset.Dataset`) is the drive, ``camera``
    (:class:`visla_edu.camera.StereoCamera`) the calibration to use (after any extrinsic correction),
    ``config`` a resolved :class:`visla_edu.filters.FilterConfig` (no ``"auto"`` left, else
    ``ValueError``).

    Attributes
    ----------
    t : int
        Last frame processed (-1 before the first step).
    world_T_imu : ndarray, shape (4, 4)
        Pose mean.
    landmarks, landmark_cov : ndarray, shapes (M, 3) and (M, 3, 3)
        Landmark means in the world frame, NaN until a landmark is initialised, and the covariances
        of the modes that keep them per landmark (in SLAM: of retired landmarks only, see
        :meth:`landmark_estimates`).
    record_landmarks : bool
        Fill the active landmarks of each :class:`StepRecord` (else they are empty; the whole-run
        driver turns this off).
    """

    def __init__(self, dataset, camera, config):
        if not config.resolved:
            raise ValueError("a filter needs its 'auto' settings measured first: build it with "
                             "visla_edu.run.make_filter, or pass config=run.resolve_config(dataset, config)")
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
        self.stale = stale_copies(dataset) if config.skip_stale_copies else np.zeros(dataset.num_observations, bool)
        self._frame_stale = np.zeros(0, dtype=bool)
        self.record_landmarks = True

    # -- the hooks step() calls ---------------------------------------------------------
    @property
    @abc.abstractmethod
    def pose_cov(self):
        """Covariance of the pose perturbation ``[v; w]``, (6, 6), after the last step."""

    @abc.abstractmethod
    def _predict_covariance(self, F, W):
        """Propagate the covariance through one IMU step: ``Sigma_pose <- F Sigma_pose F^T + W``, F and W (6, 6).

        Called after the pose mean moved (:func:`visla_edu.motion.imu_step`); a joint state also
        carries the pose-landmark cross-covariance through ``F``.
        """

    @abc.abstractmethod
    def _update(self, ids, z, status, z_pred):
        """Use frame ``self.t``'s observations ``ids`` (k,), ``z`` (k, 4); return ``(nis, dof)`` as the StepRecord's.

        Fills in place ``status`` (k,), which starts as ``OBS_IGNORED``, and ``z_pred`` (k, 4),
        which starts as NaN, for the observations of landmarks already in the state.
        """

    @abc.abstractmethod
    def _active(self):
        """The landmarks to show as active at ``self.t``: ids (n,) and covariances (n, 3, 3) (copies)."""

    @abc.abstractmethod
    def landmark_estimates(self):
        """Landmark means (M, 3) and marginal covariances (M, 3, 3) now; NaN if never initialised."""

    # -- the step -------------------------------------------------------------------------
    @property
    def done(self):
        """True once the last frame has been processed."""
        return self.t >= self.dataset.num_frames - 1

    def step(self):
        """Process the next frame (predict from the previous one, then update); return its :class:`StepRecord`."""
        if self.done:
            raise StopIteration(f"{self.dataset.name}: all {self.dataset.num_frames} frames processed")
        self.t += 1
        if self.t > 0:
            self._predict(self.step_twists[self.t - 1], self.taus[self.t - 1])
        ids, z = self.dataset.observations(self.t)
        self._frame_stale = self.stale[self.dataset.frame_ptr[self.t]:self.dataset.frame_ptr[self.t + 1]]
        status = np.full(len(ids), OBS_IGNORED)
        z_pred = np.full((len(ids), 4), np.nan)
        nis, dof = (np.nan, 0) if self.t in self.skip_frames else self._update(ids, z, status, z_pred)
        self._check_finite()
        return self._record(ids, z, z_pred, status, nis, dof)

    # -- pieces the modes share -----------------------------------------------------------
    def _predict(self, u, tau):
        """IMU prediction: ``mu <- mu exp(tau u)``, covariance through ``F`` and ``W``."""
        step, F, W = motion.imu_step(u, tau, self.config.sigma_linear_velocity, self.config.sigma_angular_velocity)
        self.world_T_imu = self.world_T_imu @ step
        self._predict_covariance(F, W)

    def _usable(self, ids, z, status):
        """Mark no-depth observations; return the usable ones (in the stride, no stale copy, positive disparity)."""
        wanted = (ids % self.config.landmark_stride == 0) & ~self._frame_stale
        disparity = self.camera.disparity(z)
        status[wanted & (disparity <= 0)] = OBS_NO_DEPTH
        return wanted & (disparity > 0)

    def _known(self, ids, usable):
        """Mask of usable observations whose landmark has a mean already."""
        return usable & np.isfinite(self.landmarks[ids, 0])

    def _new_landmarks(self, ids, z, status, candidates):
        """Triangulate never-seen landmarks among ``candidates`` (mask) at the current pose, into :attr:`landmarks`.

        Their first observation is consumed (``OBS_NEW``; ``OBS_FAR`` below ``min_init_disparity``).
        Returns ``new`` (k,) bool, ``G_pose`` (k_new, 3, 6) and ``C_new`` (k_new, 3, 3), the pixels'
        covariance ``inflation^2 C_tri + sigma^2 I``, for the caller to store.
        """
        cfg = self.config
        disparity = self.camera.disparity(z)
        new = candidates & (disparity >= cfg.min_init_disparity)
        status[candidates & ~new] = OBS_FAR
        status[new] = OBS_NEW
        p_world, G_pose, C_tri = ekf.initialize_landmarks(self.world_T_imu, z[new], self.camera, self.noise_var)
        self.landmarks[ids[new]] = p_world
        return new, G_pose, cfg.landmark_prior_inflation**2 * C_tri + cfg.landmark_prior_sigma**2 * np.eye(3)

    def _gate(self, S, innovation, z_pred):
        """Chi-square gate mask and squared distances (``inf``: estimate behind the camera or within ``MIN_DEPTH``)."""
        fsu_b = self.camera.fsu_b
        disparity = self.camera.disparity(z_pred)
        valid = (disparity > 0) & (disparity < fsu_b / MIN_DEPTH) & np.isfinite(S).all(axis=(1, 2))
        d2 = np.full(len(S), np.inf)
        if np.any(valid):
            d2[valid] = ekf.mahalanobis_squared(innovation[valid], S[valid])
        return d2 <= self.gate, d2

    @staticmethod
    def _mark_gated(status, known, inside):
        """Status of the gated observations (``known`` mask, ``inside`` over them): used or gated."""
        where = np.nonzero(known)[0]
        status[where[inside]] = OBS_USED
        status[where[~inside]] = OBS_GATED

    def _diverged(self, err, what=""):
        """A :class:`FilterDivergedError` for a failed Cholesky factorisation at this frame."""
        return FilterDivergedError(
            f"{self.dataset.name}: innovation covariance not positive definite at frame {self.t}{what}: {err}")

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
        if self.record_landmarks:
            active_ids, active_covs = self._active()
        else:
            active_ids, active_covs = np.zeros(0, dtype=np.int64), np.zeros((0, 3, 3))
        return StepRecord(
            t=self.t, world_T_imu=self.world_T_imu.copy(), pose_cov=self.pose_cov.copy(),
            ids=ids.copy(), z=z.copy(), z_pred=z_pred, status=status, nis=nis, nis_dof=dof,
            active_ids=active_ids, active_means=self.landmarks[active_ids].copy(),
            active_covs=active_covs,
        )
