"""Notebook 12's loop skeleton: VIO and joint SLAM assembled from functions passed in.

:class:`CapstoneFilter` (the library's step interface) runs the loop and calls :class:`Parts` (notebooks 01-09)
and :class:`Steps` (notebook 12). In the right perturbation (:mod:`visla_edu.lie`) a correct assembly reproduces
``FilterConfig(slam_error="right")``'s joint filter. The state is ``[pose (6); landmarks (3 each, in slot order)]``.
"""

from dataclasses import dataclass
from typing import Callable

import numpy as np

from visla_edu import camera as cam
from visla_edu import diagnostics, ekf, lie, motion, run
from visla_edu.codes import OBS_FAR, OBS_GATED, OBS_NEW, OBS_USED
from visla_edu.filters import FilterBase

__all__ = ["Parts", "Steps", "library_parts", "CapstoneFilter", "run_capstone", "POSE_DIM"]

#: Dimension of the pose perturbation ``[v; w]``.
POSE_DIM = 6


@dataclass(frozen=True)
class Parts:
    """The exercise functions of notebooks 01-09, with the notebooks' signatures (notebook in brackets).

    ``se3_exp(u (6,)) -> (4, 4)`` (01); ``project(Ks, cam_T_imu, world_T_imu, p_world (M, 3)) -> z (M, 4)`` (02);
    ``pose_jacobian(Ks, cam_T_imu, mu, m (3,)) -> (4, 6)`` (03); ``odot(s (4,)) -> (4, 6)`` (03);
    ``landmark_jacobian(Ks, cam_T_imu, world_T_imu, m (3,)) -> (4, 3)`` (05);
    ``init_landmark(z (4,), K, b, imu_T_cam, world_T_imu) -> m (3,)`` (05);
    ``pose_transition(u (6,), tau) -> F (6, 6)`` (06);
    ``pose_update(mu, Sigma (6, 6), z (k, 4), p_world (k, 3), Ks, cam_T_imu, noise_var) -> (mu, Sigma)`` (07);
    ``slam_jacobian(J_pose (k, 4, 6), J_landmark (k, 4, 3), slots (k,), n) -> H (4k, 6 + 3n)`` (08);
    ``marginalize(Sigma, keep) -> Sigma[keep][:, keep]`` (09).
    """

    se3_exp: Callable
    pose_transition: Callable
    project: Callable
    pose_jacobian: Callable
    landmark_jacobian: Callable
    init_landmark: Callable
    odot: Callable
    pose_update: Callable
    slam_jacobian: Callable
    marginalize: Callable


@dataclass(frozen=True)
class Steps:
    """The three assembly functions of notebook 12, each taking :class:`Parts` first.

    ``predict(parts, world_T_imu, Sigma (D, D), u (6,), tau, W (6, 6)) -> (world_T_imu, Sigma)``, VIO and SLAM;
    ``add_landmarks(parts, world_T_imu, Sigma, z (k, 4), K, b, imu_T_cam, C_pixels (k, 3, 3))
    -> (p_new (k, 3), Sigma (D + 3k, D + 3k))``, SLAM only (VIO uses ``parts.init_landmark``);
    ``slam_update(parts, world_T_imu, Sigma, p_active (n, 3), slots (k,), z (k, 4), Ks, cam_T_imu, noise_var)
    -> (world_T_imu, Sigma, p_active)``, SLAM only (VIO uses ``parts.pose_update``).
    """

    predict: Callable
    add_landmarks: Callable
    slam_update: Callable


# ---------------------------------------------------------------- the library's parts
# The projection and its Jacobians are the camera's (visla_edu.camera.stereo_projection), in the
# exercises' signatures.
def _project(Ks, cam_T_imu, world_T_imu, p_world):
    return cam.stereo_projection(Ks, cam_T_imu, world_T_imu, np.asarray(p_world, dtype=float), jacobians=False)[0]


def _pose_jacobian(Ks, cam_T_imu, mu, m):
    return cam.stereo_projection(Ks, cam_T_imu, mu, np.asarray(m, dtype=float)[None])[3][0]


def _landmark_jacobian(Ks, cam_T_imu, world_T_imu, m):
    return cam.stereo_projection(Ks, cam_T_imu, world_T_imu, np.asarray(m, dtype=float)[None])[2][0]


def _init_landmark(z, K, b, imu_T_cam, world_T_imu):
    p_cam = cam.triangulate_disparity(np.asarray(z, dtype=float)[None], K, b)[0]
    return (world_T_imu @ imu_T_cam @ np.concatenate((p_cam, [1.0])))[:3]


def _pose_update(mu, Sigma, z, p_world, Ks, cam_T_imu, noise_var):
    z_pred, _, _, J_pose = cam.stereo_projection(Ks, cam_T_imu, mu, np.asarray(p_world, dtype=float))
    H = J_pose.reshape(-1, POSE_DIM)
    S = H @ Sigma @ H.T + noise_var * np.eye(len(H))
    gain = np.linalg.solve(S, H @ Sigma).T
    Sigma_new = (np.eye(POSE_DIM) - gain @ H) @ Sigma
    r = (np.asarray(z) - z_pred).ravel()
    return mu @ lie.se3_exp(gain @ r), 0.5 * (Sigma_new + Sigma_new.T)


def _slam_jacobian(J_pose, J_landmark, slots, n_landmarks):
    k = len(slots)
    H = np.zeros((k, 4, POSE_DIM + 3 * n_landmarks))
    H[:, :, :POSE_DIM] = J_pose
    for i, s in enumerate(slots):
        H[i, :, POSE_DIM + 3 * s: POSE_DIM + 3 * s + 3] = J_landmark[i]
    return H.reshape(4 * k, -1)


def _marginalize(Sigma, keep):
    return Sigma[np.ix_(keep, keep)]


def library_parts():
    """The library's versions of the notebooks' exercises, as :class:`Parts`.

    Swap in your own with ``dataclasses.replace(library_parts(), pose_update=my_pose_update)``.
    """
    return Parts(se3_exp=lie.se3_exp, pose_transition=motion.pose_transition, project=_project,
                 pose_jacobian=_pose_jacobian, landmark_jacobian=_landmark_jacobian,
                 init_landmark=_init_landmark, odot=lie.odot, pose_update=_pose_update,
                 slam_jacobian=_slam_jacobian, marginalize=_marginalize)


# ---------------------------------------------------------------- the loop skeleton
class CapstoneFilter(FilterBase):
    """VIO or joint SLAM whose mathematics are the functions passed in; the loop is provided.

    Each ``step()`` predicts with ``steps.predict``, then, with the frame's observations:

    1. (SLAM) retires the landmarks whose track has ended (``parts.marginalize``);
    2. gates the observations of placed landmarks (chi-square test with ``S_i`` computed here from the state);
    3. updates with those inside the gate: VIO ``parts.pose_update`` (landmarks taken as exact), SLAM
       ``steps.slam_update`` (pose and every active landmark);
    4. (SLAM) places again a never-used landmark whose observation was gated (``reinit_gated_landmarks``);
    5. places new landmarks (enough disparity): VIO ``parts.init_landmark``, SLAM ``steps.add_landmarks``
       (with their cross-covariance); ``C_pixels`` is computed here.

    ``config`` is resolved (:func:`visla_edu.run.resolve_config`); its ``slam_error`` is ignored (the skeleton
    is the right-perturbation form). ``joint``: True for SLAM, False for VIO. ``Sigma``: shape (6 + 3n, 6 + 3n)
    (VIO: 6 x 6); ``slots``: landmark ids in the state, shape (n,), in slot order.
    """

    def __init__(self, dataset, config, parts, steps, joint=True):
        if not isinstance(parts, Parts) or not isinstance(steps, Steps):
            raise TypeError("CapstoneFilter: parts must be a capstone.Parts and steps a capstone.Steps, got "
                            f"{type(parts).__name__} and {type(steps).__name__}")
        if not cam.same_intrinsics(dataset.K, dataset.K_right):
            raise ValueError(f"CapstoneFilter: {dataset.name}'s stereo rig has two intrinsics (K_l != K_r), but the "
                             "notebooks' functions take one K and a baseline b; run the library's filters on it "
                             "(run.run_filter), or the capstone on a drive with one K")
        imu_T_cam, _ = diagnostics.resolve_extrinsics(dataset, config.extrinsic_correction)
        super().__init__(dataset, dataset.stereo_camera(imu_T_cam), config)
        self.parts, self.steps, self.joint = parts, steps, bool(joint)
        self.Sigma = config.initial_pose_sigma**2 * np.eye(POSE_DIM)
        M = dataset.num_landmarks
        self.slots = np.zeros(0, dtype=np.int64)
        self.slot_of = np.full(M, -1)
        self.updates = np.zeros(M, dtype=np.int64)

    @property
    def pose_cov(self):
        """Covariance (6, 6) of the pose's right perturbation ``[v; w]``."""
        return self.Sigma[:POSE_DIM, :POSE_DIM]

    def _predict(self, u, tau):
        """``steps.predict`` moves the mean and the covariance (the motion noise W is given)."""
        W = motion.motion_noise(tau, self.config.sigma_linear_velocity, self.config.sigma_angular_velocity)
        mu, Sigma = self.steps.predict(self.parts, self.world_T_imu, self.Sigma, u, tau, W)
        self.world_T_imu = self._checked("predict", mu, (4, 4), "world_T_imu")
        self.Sigma = self._checked("predict", Sigma, self.Sigma.shape, "Sigma")

    def _predict_covariance(self, F, W):
        raise NotImplementedError("CapstoneFilter predicts through steps.predict (see _predict)")

    def _checked(self, fn, value, shape, what):
        """``value`` as a float array of ``shape``, or a ValueError naming the function and frame."""
        value = np.asarray(value, dtype=float)
        if value.shape != tuple(shape):
            raise ValueError(f"{fn} returned {what} of shape {value.shape} at frame {self.t}, expected {tuple(shape)}")
        return value

    # ------------------------------------------------------------ the update
    def _update(self, ids, z, status, z_pred):
        if self.joint:
            self._retire(self.slots[self.last_frame[self.slots] < self.t], keep_covariance=True)
        usable = self._usable(ids, z, status)
        known = self._known(ids, usable)
        d2 = self._gate_known(ids, z, status, z_pred, known)
        use = status == OBS_USED
        nis = float(d2[use[known]].sum()) if np.any(use) else np.nan
        if np.any(use):
            self._correct(ids[use], z[use])
        again = np.zeros(len(ids), dtype=bool)
        if self.joint and self.config.reinit_gated_landmarks:
            again = (status == OBS_GATED) & (self.updates[ids] == 0)
            self._retire(ids[again], keep_covariance=False)
            self.landmarks[ids[again]] = np.nan
        self._add(ids, z, status, (usable & ~known) | again)
        return nis, 4 * int(use.sum())

    def _gate_known(self, ids, z, status, z_pred, known):
        """Gate the observations of placed landmarks; their squared Mahalanobis distances (k_known,)."""
        if not np.any(known):
            return np.zeros(0)
        lm = ids[known]
        pred, J_landmark, J_pose = self.camera.predict_with_jacobians(self.world_T_imu, self.landmarks[lm])
        z_pred[known] = pred
        if self.joint:
            cols = POSE_DIM + 3 * self.slot_of[lm][:, None] + np.arange(3)  # (k, 3)
            cross = self.Sigma[:POSE_DIM][:, cols].transpose(1, 0, 2)  # (k, 6, 3)
            S = ekf.innovation_covariances(J_pose, J_landmark, self.pose_cov, cross,
                                           self.Sigma[cols[:, :, None], cols[:, None, :]], self.noise_var)
        else:  # VIO: the landmarks count as exact, as in pose_update
            S = ekf.innovation_covariances(J_pose, None, self.pose_cov, None, None, self.noise_var)
        inside, d2 = self._gate(S, z[known] - pred, pred)
        self._mark_gated(status, known, inside)
        return d2

    def _correct(self, lm, z):
        """The EKF update with the gated observations ``z`` (k, 4) of landmarks ``lm``."""
        cam_ = self.camera
        try:
            if not self.joint:
                mu, Sigma = self.parts.pose_update(self.world_T_imu, self.Sigma, z, self.landmarks[lm], cam_.Ks,
                                                   cam_.cam_T_imu, self.noise_var)
                self.world_T_imu = self._checked("pose_update", mu, (4, 4), "mu")
                self.Sigma = self._checked("pose_update", Sigma, (POSE_DIM, POSE_DIM), "Sigma")
                return
            mu, Sigma, p_active = self.steps.slam_update(
                self.parts, self.world_T_imu, self.Sigma, self.landmarks[self.slots], self.slot_of[lm], z,
                cam_.Ks, cam_.cam_T_imu, self.noise_var)
        except np.linalg.LinAlgError as err:
            raise self._diverged(err, f" ({len(lm)} observations)") from err
        self.world_T_imu = self._checked("slam_update", mu, (4, 4), "world_T_imu")
        self.Sigma = self._checked("slam_update", Sigma, self.Sigma.shape, "Sigma")
        self.landmarks[self.slots] = self._checked("slam_update", p_active, (len(self.slots), 3), "p_active")
        self.updates[lm] += 1

    def _retire(self, lm, keep_covariance):
        """Marginalise landmarks ``lm`` out of the state with ``parts.marginalize``."""
        if len(lm) == 0:
            return
        if keep_covariance:
            self.landmark_cov[lm] = self._marginals(lm)
        leaving = np.isin(self.slots, lm)
        keep_slots = np.nonzero(~leaving)[0]
        keep = np.r_[np.arange(POSE_DIM), (POSE_DIM + 3 * keep_slots[:, None] + np.arange(3)).ravel()]
        D = len(keep)
        self.Sigma = self._checked("marginalize", self.parts.marginalize(self.Sigma, keep), (D, D), "Sigma")
        self.slot_of[self.slots[leaving]] = -1
        self.slots = self.slots[keep_slots]
        self.slot_of[self.slots] = np.arange(len(self.slots))

    def _add(self, ids, z, status, candidates):
        """Place new landmarks (first observation with enough disparity)."""
        cfg = self.config
        new = candidates & (z[:, 0] - z[:, 2] >= cfg.min_init_disparity)
        status[candidates & ~new] = OBS_FAR
        status[new] = OBS_NEW
        if not np.any(new):
            return
        lm, c = ids[new], self.camera
        _, G_pose, C_tri = ekf.initialize_landmarks(self.world_T_imu, z[new], c, self.noise_var)
        C_pixels = cfg.landmark_prior_inflation**2 * C_tri + cfg.landmark_prior_sigma**2 * np.eye(3)
        if self.joint:
            p_new, Sigma = self.steps.add_landmarks(self.parts, self.world_T_imu, self.Sigma, z[new], c.K, c.b,
                                                    c.imu_T_cam, C_pixels)
            D = len(self.Sigma) + 3 * len(lm)
            self.Sigma = self._checked("add_landmarks", Sigma, (D, D), "Sigma")
            self.slot_of[lm] = len(self.slots) + np.arange(len(lm))
            self.slots = np.r_[self.slots, lm]
            self.updates[lm] = 0
        else:
            p_new = [self.parts.init_landmark(zi, c.K, c.b, c.imu_T_cam, self.world_T_imu) for zi in z[new]]
            self.landmark_cov[lm] = C_pixels + G_pose @ self.pose_cov @ np.swapaxes(G_pose, 1, 2)
        self.landmarks[lm] = self._checked("add_landmarks" if self.joint else "init_landmark", p_new,
                                           (len(lm), 3), "landmark means")

    # ------------------------------------------------------------ what the record shows
    def _marginals(self, lm):
        cols = POSE_DIM + 3 * self.slot_of[lm][:, None] + np.arange(3)
        return self.Sigma[cols[:, :, None], cols[:, None, :]]

    def _active(self):
        if self.joint:
            ids = self.slots[self.last_frame[self.slots] >= self.t]
            return ids, self._marginals(ids)
        ids = np.nonzero(np.isfinite(self.landmarks[:, 0]) & (self.last_frame >= self.t))[0]
        return ids, self.landmark_cov[ids].copy()

    def landmark_estimates(self):
        """Landmark means (M, 3) and marginal covariances (M, 3, 3); NaN if never placed."""
        cov = self.landmark_cov.copy()
        if self.joint and len(self.slots):
            cov[self.slots] = self._marginals(self.slots)
        return self.landmarks.copy(), cov


def run_capstone(dataset, config, parts, steps, joint=True):
    """Run :class:`CapstoneFilter` over the whole drive (one BLAS thread, as the library's driver).

    Parameters as :class:`CapstoneFilter`. Returns ``world_T_imu`` (T, 4, 4), ``pose_cov`` (T, 6, 6) and the
    final landmark means (M, 3), NaN where never placed.
    """
    flt = CapstoneFilter(dataset, config, parts, steps, joint=joint)
    flt.record_landmarks = False  # a whole run keeps no per-frame landmarks
    with run.limit_blas_threads(1):
        records = [flt.step() for _ in range(dataset.num_frames)]
    return (np.array([r.world_T_imu for r in records]), np.array([r.pose_cov for r in records]),
            flt.landmark_estimates()[0])
