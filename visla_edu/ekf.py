"""EKF update steps for visual-inertial SLAM: mapping, visual-inertial odometry, joint SLAM.

Every update here is the textbook EKF update written with a Cholesky factor
``S = L L^T`` of the innovation covariance instead of an inverse::

    S     = H Sigma H^T + R
    A     = L^{-1} H Sigma              (solve, never invert)
    delta = A^T L^{-1} r                (= K r with K = Sigma H^T S^{-1})
    Sigma = Sigma - A^T A               (= (I - K H) Sigma)

The observation of landmark ``m`` from pose ``T`` is ``z = Ks pi(cam_T_imu T^{-1} m)`` (see
:mod:`visla_edu.camera`); noise ``R = sigma_pixel^2 I4`` per observation. Pose corrections are
applied on the right, ``mu <- mu @ se3_exp(delta_pose)``; landmark corrections are added.
"""

from dataclasses import asdict, dataclass

import numpy as np
from scipy import linalg

from visla_edu import lie

__all__ = [
    "FilterConfig",
    "FilterDivergedError",
    "cholesky_update",
    "innovation_covariances",
    "mahalanobis_squared",
    "initialize_landmarks",
    "landmark_update",
    "pose_update",
    "joint_update",
]


class FilterDivergedError(RuntimeError):
    """The filter produced a non-finite state or a covariance that is not positive definite."""


@dataclass
class FilterConfig:
    """Noise, initialisation and gating parameters of every filter mode.

    The defaults work without per-dataset tuning on the simulated drives, datasets 03 and
    0022 and the dataset-10 stand-in. They were chosen from evidence, not guessed (notebook 07
    recomputes each figure):

    * ``visla-edu info`` measures the IMU noise from second differences of the velocities:
      up to 0.5 m/s and 0.05 rad/s (dataset 0022, the noisiest file), so those are the
      velocity noise settings. With 0.02 rad/s instead, 03 and 0022 gate about twice as many
      observations (15.7% and 14.9%, against 8.0% and 4.5%), and the 03 trajectory ends 36 m
      below its start height after 1.3 km (4 m with 0.05 rad/s).
    * The gated share grows with a track's age (tracker drift: roughly 10% after ten frames
      on 03), and the distances are heavy-tailed (about 1% of them above 100 for a
      chi-square(4) variable), so gating stays on.
    * ``sigma_pixel`` 1.5 gives accepted observations a NIS per degree of freedom of 0.9 on
      03 (1.5 at 1 px): slightly conservative, as it should be with drifting tracks.
    * ``min_init_disparity`` 3 px (depth up to ``fsu b / 3``, 110 m on dataset 03's rig): a
      far landmark triangulated from a 2 px disparity is a poor Gaussian in x, y, z that makes
      joint SLAM overconfident and less accurate, while fixed far landmarks help VIO hold its
      orientation. Against 2 px, SLAM's error on the dataset-10 stand-in drops from 24 m to
      15 m and the NEES on 300-frame drives falls by a third; 5 px helps SLAM a little more
      but makes VIO worse than dead reckoning on some simulated drives. 03 and 0022 gate
      8.0% and 4.5% of their observations (7.5% and 4.4% at 2 px).
    * The extrinsic check finds dataset 03's ``imu_T_cam`` axes flipped (rotation slope -0.78,
      +0.83 after the ``flip_yz`` correction), hence ``extrinsic_correction="auto"``.
    * The time-alignment check prefers ``imu_lag=+1`` by only 0.2% (03) and 1% (0022) of
      the rotation residual: too weak to leave the course's convention ``u[t]`` for ``t->t+1``.

    Attributes
    ----------
    sigma_pixel : float
        Standard deviation of each stereo pixel coordinate (px); ``R = sigma_pixel^2 I4``.
    sigma_linear_velocity : float
        White noise on each linear-velocity sample (m/s); ``W`` scales it by the time step.
    sigma_angular_velocity : float
        White noise on each angular-velocity sample (rad/s).
    landmark_prior_inflation : float
        A landmark enters the state at its first observation (which it consumes) with its mean
        at the stereo triangulation and the covariance ``inflation^2 C_tri + sigma^2 I`` from
        the pixels, plus, in SLAM, the pose's uncertainty and correlation carried through the
        triangulation (see :func:`initialize_landmarks`). ``C_tri`` is long along the viewing
        ray and grows with depth squared; the inflation allows for the linearisation error of
        far points.
    landmark_prior_sigma : float
        Isotropic part of a new landmark's covariance (m).
    initial_pose_sigma : float
        Standard deviation of the first pose; 0 because ``world`` is the first IMU frame.
    gate_probability : float
        Observations whose Mahalanobis distance exceeds the chi-square quantile with 4 degrees
        of freedom at this probability are rejected as outliers (1.0 disables gating).
    min_init_disparity : float
        Minimum disparity ``uL - uR`` (px) to triangulate a new landmark; smaller disparities
        give depths beyond ``fsu b / min_init_disparity``. Observations with non-positive
        disparity are never used.
    imu_lag : int
        Which velocity sample drives the step ``t -> t+1``: ``u[t + imu_lag]``.
    extrinsic_correction : str
        ``"auto"`` applies the correction that :func:`visla_edu.diagnostics.check_extrinsics`
        finds with strong evidence; ``"none"`` uses the file's ``imu_T_cam`` as is; or the name
        of a correction (``"flip_yz"``, ...), see :data:`visla_edu.diagnostics.CORRECTIONS`.
    landmark_cross_covariance : bool
        Joint SLAM: a new landmark enters correlated with the state (``G_pose Sigma_pose,x``).
        False is the textbook shortcut (pixel covariance only, no correlation), which makes
        the filter overconfident; kept for comparison.
    mapping_motion_noise : bool
        Mapping: widen each observation's noise by the dead-reckoning motion noise since the
        landmark's first sighting. False takes the dead-reckoned poses as exact.
    vio_refine_landmarks : bool
        VIO: also update the landmarks with the observations that just corrected the pose.
        This counts each observation twice (kept for comparison; off by default).
    skip_repeated_frames : bool
        Make no update at frames whose observations exactly repeat the previous frame's
        (a duplicated camera frame while the IMU moved on; dataset 03 has one at 1008).
    landmark_stride : int
        Use only landmarks whose index is a multiple of this (the textbook workaround for the
        dense filter's memory; 1 = every landmark).
    blas_threads : int or None
        BLAS threads while the filter runs (the per-step matrices are small, so 1 is fastest);
        None leaves numpy's setting alone.
    """

    sigma_pixel: float = 1.5
    sigma_linear_velocity: float = 0.5
    sigma_angular_velocity: float = 0.05
    landmark_prior_inflation: float = 1.0
    landmark_prior_sigma: float = 0.1
    initial_pose_sigma: float = 0.0
    gate_probability: float = 0.999
    min_init_disparity: float = 3.0
    imu_lag: int = 0
    extrinsic_correction: str = "auto"
    landmark_cross_covariance: bool = True
    mapping_motion_noise: bool = True
    vio_refine_landmarks: bool = False
    skip_repeated_frames: bool = True
    landmark_stride: int = 1
    blas_threads: int = 1

    def __post_init__(self):
        positive = ["sigma_pixel", "landmark_prior_sigma"]
        non_negative = ["landmark_prior_inflation", "sigma_linear_velocity", "sigma_angular_velocity", "initial_pose_sigma",
                        "min_init_disparity"]
        for name in positive:
            if not np.isfinite(getattr(self, name)) or getattr(self, name) <= 0:
                raise ValueError(f"FilterConfig.{name} must be a positive number, got {getattr(self, name)!r}")
        for name in non_negative:
            if not np.isfinite(getattr(self, name)) or getattr(self, name) < 0:
                raise ValueError(f"FilterConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 < self.gate_probability <= 1:
            raise ValueError(f"FilterConfig.gate_probability must be in (0, 1], got {self.gate_probability!r}")
        if int(self.landmark_stride) != self.landmark_stride or self.landmark_stride < 1:
            raise ValueError(f"FilterConfig.landmark_stride must be a positive integer, got {self.landmark_stride!r}")
        if int(self.imu_lag) != self.imu_lag:
            raise ValueError(f"FilterConfig.imu_lag must be an integer, got {self.imu_lag!r}")

    @property
    def pixel_variance(self):
        """``sigma_pixel^2``."""
        return self.sigma_pixel**2

    @property
    def gate_threshold(self):
        """Chi-square (4 dof) quantile at ``gate_probability``; ``inf`` when gating is off."""
        if self.gate_probability >= 1:
            return np.inf
        from scipy.stats import chi2

        return float(chi2.ppf(self.gate_probability, 4))

    def to_dict(self):
        """Plain dict of the settings (for saving with results)."""
        return asdict(self)


def cholesky_update(Sigma, H, cols, innovation, R):
    """One EKF update on the state columns ``cols`` of ``Sigma``, in place.

    Parameters
    ----------
    Sigma : ndarray, shape (D, D)
        Full state covariance; overwritten with the posterior.
    H : ndarray, shape (m, c)
        Observation Jacobian restricted to the columns ``cols`` (all other columns are zero).
    cols : ndarray of int, shape (c,)
    innovation : ndarray, shape (m,)
        ``z - h(mu)``.
    R : ndarray, shape (m, m)
        Observation noise covariance.

    Returns
    -------
    delta : ndarray, shape (D,)
        State correction ``K r``.
    nis : float
        Normalised innovation squared ``r^T S^{-1} r`` (chi-square with m dof if consistent).

    Raises
    ------
    numpy.linalg.LinAlgError
        If the innovation covariance is not positive definite.
    """
    Sigma_Ht = Sigma[:, cols] @ H.T  # (D, m)
    return _gain_update(Sigma, Sigma_Ht, H @ Sigma_Ht[cols] + R, innovation)


def _gain_update(Sigma, Sigma_Ht, S, innovation):
    """``Sigma -= A^T A`` and ``delta = A^T L^{-1} r`` with ``S = L L^T``, ``A = L^{-1} H Sigma``.

    ``A.T @ A`` is computed as a symmetric rank-m product, so a symmetric ``Sigma`` stays
    exactly symmetric.
    """
    L = linalg.cholesky(S, lower=True, check_finite=False)
    A = linalg.solve_triangular(L, Sigma_Ht.T, lower=True, check_finite=False)  # (m, D)
    white = linalg.solve_triangular(L, innovation, lower=True, check_finite=False)
    Sigma -= A.T @ A
    return A.T @ white, float(white @ white)


def innovation_covariances(J_pose, J_landmark, Sigma_pose, Sigma_pose_landmark, Sigma_landmark, noise_var):
    """Per-observation innovation covariances ``S_i = H_i Sigma H_i^T + R`` (batched).

    ``H_i = [J_pose_i, J_landmark_i]`` acts on the pose and on landmark i only, so::

        S_i = Jp Spp Jp^T + Jp Spl_i Jl^T + Jl Spl_i^T Jp^T + Jl Sll_i Jl^T + noise_var I

    Any of the Sigma terms may be None (treated as zero).

    Parameters
    ----------
    J_pose : ndarray, shape (k, 4, 6) or None
    J_landmark : ndarray, shape (k, 4, 3) or None
    Sigma_pose : ndarray, shape (6, 6) or None
    Sigma_pose_landmark : ndarray, shape (k, 6, 3) or None
    Sigma_landmark : ndarray, shape (k, 3, 3) or None
    noise_var : float

    Returns
    -------
    ndarray, shape (k, 4, 4)
    """
    k = len(J_pose) if J_pose is not None else len(J_landmark)
    S = np.broadcast_to(noise_var * np.eye(4), (k, 4, 4)).copy()
    if Sigma_pose is not None:
        S += J_pose @ Sigma_pose @ np.swapaxes(J_pose, 1, 2)
    if Sigma_pose_landmark is not None:
        cross = J_pose @ Sigma_pose_landmark @ np.swapaxes(J_landmark, 1, 2)
        S += cross + np.swapaxes(cross, 1, 2)
    if Sigma_landmark is not None:
        S += J_landmark @ Sigma_landmark @ np.swapaxes(J_landmark, 1, 2)
    return S


def mahalanobis_squared(innovation, S):
    """``r_i^T S_i^{-1} r_i`` for each observation; innovation (k, 4), S (k, 4, 4) -> (k,)."""
    return np.einsum("ki,ki->k", innovation, np.linalg.solve(S, innovation[..., None])[..., 0])


def initialize_landmarks(world_T_imu, z, camera, noise_var):
    """Triangulate new landmarks and linearise the triangulation for their covariance.

    ``m = world_T_imu exp(hat(delta)) imu_T_cam p_cam(z)`` with ``p_cam`` the disparity
    triangulation, so to first order::

        m ~ m0 + G_pose delta + G_z dz,   G_pose = R [I, -hat(p_imu)],   G_z = R R_ic J_tri

    with ``R`` the rotation of ``world_T_imu``, ``R_ic`` that of ``imu_T_cam`` and ``p_imu`` the
    point in the IMU frame. In joint SLAM the new block is ``G_pose Sigma_pp G_pose^T + C_tri``
    and its correlation with every other state entry ``x`` is ``G_pose Sigma_px``: a landmark
    placed from an uncertain pose inherits that uncertainty. Dropping this correlation (the
    textbook shortcut) makes the filter overconfident.

    Parameters
    ----------
    world_T_imu : ndarray, shape (4, 4)
    z : ndarray, shape (k, 4)
    camera : visla_edu.camera.StereoCamera
    noise_var : float
        Pixel noise variance.

    Returns
    -------
    p_world : ndarray, shape (k, 3)
    G_pose : ndarray, shape (k, 3, 6)
    C_tri : ndarray, shape (k, 3, 3)
        Triangulation covariance in the world frame, ``noise_var G_z G_z^T``.
    """
    p_cam = camera.triangulate(z)
    p_imu = p_cam @ camera.imu_T_cam[:3, :3].T + camera.imu_T_cam[:3, 3]
    R = world_T_imu[:3, :3]
    p_world = p_imu @ R.T + world_T_imu[:3, 3]
    G_pose = np.concatenate([np.broadcast_to(R, (len(z), 3, 3)), -R @ lie.hat(p_imu)], axis=2)
    return p_world, G_pose, camera.triangulation_covariance(z, noise_var, world_T_imu)


def landmark_update(p_world, Sigma_landmark, z, world_T_imu, camera, noise_var, extra_noise=None):
    """Landmark-mapping update with the pose held fixed, one 3x3 EKF per landmark (batched).

    With the pose known, observations of different landmarks are independent, so the joint
    (3M x 3M) update is block diagonal and each landmark updates on its own::

        H_i = Ks dpi/dq(q_i) cam_T_imu T^{-1} P^T          (4 x 3)
        K_i = Sigma_i H_i^T (H_i Sigma_i H_i^T + R)^{-1}
        m_i <- m_i + K_i (z_i - Ks pi(q_i)),   Sigma_i <- (I - K_i H_i) Sigma_i

    Parameters
    ----------
    p_world : ndarray, shape (k, 3)
    Sigma_landmark : ndarray, shape (k, 3, 3)
    z : ndarray, shape (k, 4)
    world_T_imu : ndarray, shape (4, 4)
    camera : visla_edu.camera.StereoCamera
    noise_var : float
    extra_noise : ndarray, shape (k, 4, 4), optional
        Added to each ``R`` (e.g. the pose's own uncertainty seen through ``J_pose``).

    Returns
    -------
    p_new : ndarray, shape (k, 3)
    Sigma_new : ndarray, shape (k, 3, 3)
    """
    z_pred, J_landmark, _ = camera.predict_with_jacobians(world_T_imu, p_world)
    S = innovation_covariances(None, J_landmark, None, None, Sigma_landmark, noise_var)
    if extra_noise is not None:
        S = S + extra_noise
    PHt = Sigma_landmark @ np.swapaxes(J_landmark, 1, 2)  # (k, 3, 4)
    gain = np.swapaxes(np.linalg.solve(S, np.swapaxes(PHt, 1, 2)), 1, 2)  # (k, 3, 4)
    p_new = p_world + np.einsum("kij,kj->ki", gain, z - z_pred)
    Sigma_new = Sigma_landmark - gain @ np.swapaxes(PHt, 1, 2)
    return p_new, 0.5 * (Sigma_new + np.swapaxes(Sigma_new, 1, 2))


def pose_update(world_T_imu, Sigma_pose, p_world, z, camera, noise_var, Sigma_landmark=None):
    """Visual-inertial update of the pose alone, landmarks treated as known.

    ``H_i = -Ks dpi/dq(q_i) cam_T_imu odot(T^{-1} m_i)`` stacked over the observations;
    with landmark covariances given, each observation's noise becomes
    ``R_i = noise_var I + J_landmark_i Sigma_landmark_i J_landmark_i^T``.
    The correction is applied on the right: ``T <- T @ se3_exp(delta)``.

    Parameters
    ----------
    world_T_imu : ndarray, shape (4, 4)
    Sigma_pose : ndarray, shape (6, 6)
    p_world : ndarray, shape (k, 3)
    z : ndarray, shape (k, 4)
    camera : visla_edu.camera.StereoCamera
    noise_var : float
    Sigma_landmark : ndarray, shape (k, 3, 3), optional

    Returns
    -------
    world_T_imu_new : ndarray, shape (4, 4)
    Sigma_pose_new : ndarray, shape (6, 6)
    nis : float
    """
    z_pred, J_landmark, J_pose = camera.predict_with_jacobians(world_T_imu, p_world)
    k = len(z)
    R_blocks = innovation_covariances(None, J_landmark, None, None, Sigma_landmark, noise_var)
    R = linalg.block_diag(*R_blocks) if k else np.zeros((0, 0))
    Sigma = np.array(Sigma_pose, dtype=float)
    delta, nis = cholesky_update(Sigma, J_pose.reshape(4 * k, 6), np.arange(6), (z - z_pred).ravel(), R)
    return world_T_imu @ lie.se3_exp(delta), 0.5 * (Sigma + Sigma.T), nis


#: Stereo rows ``[uL, vL, uR, vR]`` -> ``[uL, (vL + vR)/sqrt(2), uR]``. Rows 2 and 4 of ``Ks``
#: are equal, so ``vL`` and ``vR`` have the same prediction and Jacobian: with noise
#: ``sigma^2 I`` their difference carries no information about the state. Rotating the pair
#: orthonormally and dropping the difference row is an exact reduction from 4 to 3 rows.
STEREO_ROWS = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)], [0.0, 0.0, 1.0, 0.0]])


def joint_update(Sigma, world_T_imu, p_active, obs_slots, z, camera, noise_var, prediction=None):
    """Joint EKF update of the pose and all landmarks in the state, covariance in place.

    The state is ``[pose perturbation (6); landmark slot 0 (3); slot 1 (3); ...]``. The
    observation of the landmark in slot s touches the pose columns and that slot's columns::

        H_i = [J_pose_i (4x6), 0, ..., J_landmark_i (4x3) at columns 6+3s.., ..., 0]

    so ``Sigma H^T`` and ``H Sigma H^T`` are assembled block by block instead of with the
    mostly-zero ``H``, and each observation's rows are reduced exactly from 4 to 3
    (:data:`STEREO_ROWS`). Every landmark in the state moves (unobserved ones through their
    correlation with the pose), so the whole ``p_active`` is corrected.

    Parameters
    ----------
    Sigma : ndarray, shape (D, D), D = 6 + 3 n
        Joint covariance, overwritten with the posterior.
    world_T_imu : ndarray, shape (4, 4)
        Pose mean.
    p_active : ndarray, shape (n, 3)
        Means of all landmarks in the state, in slot order.
    obs_slots : ndarray of int, shape (k,)
        Slot of each observed landmark.
    z : ndarray, shape (k, 4)
        Its stereo pixels.
    camera : visla_edu.camera.StereoCamera
    noise_var : float

    prediction : tuple of ndarray, optional
        ``camera.predict_with_jacobians(world_T_imu, p_active[obs_slots])`` if already computed
        (the filter has it from gating).

    Returns
    -------
    world_T_imu_new : ndarray, shape (4, 4)
    p_active_new : ndarray, shape (n, 3)
    nis : float
        ``r^T S^{-1} r`` of the full 4-row observations (``4 k`` degrees of freedom).
    """
    k = len(obs_slots)
    if prediction is None:
        prediction = camera.predict_with_jacobians(world_T_imu, p_active[obs_slots])
    z_pred, J_landmark, J_pose = prediction
    r4 = z - z_pred
    J_pose3 = (STEREO_ROWS @ J_pose).reshape(3 * k, 6)  # (m, 6), m = 3k
    J_lm3 = STEREO_ROWS @ J_landmark  # (k, 3, 3)
    lm_cols = (6 + 3 * np.asarray(obs_slots)[:, None] + np.arange(3)).ravel()
    D = Sigma.shape[0]
    Sigma_lm = Sigma[:, lm_cols].reshape(D, k, 3)
    # per observation i: Sigma[:, cols_i] @ J_lm3_i^T, batched as matmuls (einsum is 10x slower here)
    lm_part = (Sigma_lm.transpose(1, 0, 2) @ J_lm3.transpose(0, 2, 1)).transpose(1, 0, 2)
    Sigma_Ht = Sigma[:, :6] @ J_pose3.T + lm_part.reshape(D, 3 * k)
    S = J_pose3 @ Sigma_Ht[:6] + (J_lm3 @ Sigma_Ht[lm_cols].reshape(k, 3, 3 * k)).reshape(3 * k, 3 * k)
    S[np.diag_indices(3 * k)] += noise_var
    delta, nis = _gain_update(Sigma, Sigma_Ht, S, (r4 @ STEREO_ROWS.T).ravel())
    nis += float(np.sum((r4[:, 1] - r4[:, 3]) ** 2)) / (2 * noise_var)
    p_new = p_active + delta[6:].reshape(-1, 3)
    return world_T_imu @ lie.se3_exp(delta[:6]), p_new, nis
