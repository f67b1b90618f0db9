"""EKF update steps for visual-inertial SLAM: mapping, visual-inertial odometry, joint SLAM.

Every update here is the textbook EKF update written with a Cholesky factor
``S = L L^T`` of the innovation covariance instead of an inverse::

    S     = H Sigma H^T + R
    A     = L^{-1} H Sigma              (solve, never invert)
    delta = A^T L^{-1} r                (= K r with K = Sigma H^T S^{-1})
    Sigma = Sigma - A^T A               (= (I - K H) Sigma)

Parameters shared by the functions below: ``world_T_imu`` (4, 4) is the pose mean ``mu`` (the
IMU in the world); ``z`` (k, 4) the stereo pixels ``[uL, vL, uR, vR]`` of k observations,
``z = Ks pi(cam_T_imu T^{-1} m)`` for landmark ``m``, predicted with their Jacobians by
``camera``, a :class:`visla_edu.camera.StereoCamera`; ``noise_var`` the pixel noise variance
(px^2), ``R = noise_var I4`` per observation; ``Sigma`` (D, D) a covariance overwritten with
the posterior. Pose corrections are applied on the right, ``mu <- mu @ se3_exp(delta_pose)``
(right perturbation, see :mod:`visla_edu.lie`); landmark corrections are added.
"""

import numpy as np
from scipy import linalg

from visla_edu import camera, lie

__all__ = [
    "POSE_DIM",
    "slot_columns",
    "cholesky_update",
    "gain_update",
    "innovation_covariances",
    "mahalanobis_squared",
    "initialize_landmarks",
    "landmark_update",
    "pose_update",
    "joint_update",
    "joint_correction",
    "invariant_pose_jacobian",
    "invariant_retract",
]

#: Dimension of the pose perturbation ``[v; w]``: the first columns of the joint state.
POSE_DIM = 6


def slot_columns(slots):
    """Columns ``6 + 3 s + [0, 1, 2]`` of landmark slots ``s`` in the joint state ``[pose (6); slot 0 (3); ...]``.

    Parameters
    ----------
    slots : array_like of int, shape (k,)

    Returns
    -------
    ndarray of int, shape (k, 3)
    """
    return POSE_DIM + 3 * np.asarray(slots, dtype=np.int64)[:, None] + np.arange(3)


def cholesky_update(Sigma, H, cols, innovation, R):
    """One EKF update, in place, with an observation Jacobian ``H`` on the columns ``cols`` (zero elsewhere).

    Parameters
    ----------
    Sigma : ndarray, shape (D, D)
    H : ndarray, shape (m, c)
    cols : ndarray of int, shape (c,)
    innovation : ndarray, shape (m,)
        ``z - h(mu)``.
    R : ndarray, shape (m, m)

    Returns
    -------
    delta : ndarray, shape (D,)
    nis : float
        As :func:`gain_update`, which raises ``numpy.linalg.LinAlgError`` if ``S`` is not
        positive definite.
    """
    Sigma_Ht = Sigma[:, cols] @ H.T  # (D, m)
    return gain_update(Sigma, Sigma_Ht, H @ Sigma_Ht[cols] + R, innovation)


def gain_update(Sigma, Sigma_Ht, S, innovation):
    """The EKF gain step in place: ``Sigma -= A^T A``, ``delta = A^T L^{-1} r`` (module docstring).

    ``A.T @ A`` is a symmetric rank-m product: a symmetric ``Sigma`` stays exactly symmetric.

    Parameters
    ----------
    Sigma : ndarray, shape (D, D)
    Sigma_Ht : ndarray, shape (D, m)
        ``Sigma H^T``.
    S : ndarray, shape (m, m)
        ``H Sigma H^T + R``.
    innovation : ndarray, shape (m,)

    Returns
    -------
    delta : ndarray, shape (D,)
        State correction ``K r``.
    nis : float
        ``r^T S^{-1} r`` (chi-square with m dof if consistent).

    Raises
    ------
    numpy.linalg.LinAlgError
        ``S`` is not positive definite.
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
    """``r_i^T S_i^{-1} r_i`` per observation, by a linear solve (never an inverse); empty for ``k = 0``.

    Parameters
    ----------
    innovation : ndarray, shape (k, 4)
        Residuals ``z_i - h_i(mu)`` (px).
    S : ndarray, shape (k, 4, 4)
        Innovation covariances (px^2), e.g. from :func:`innovation_covariances`.

    Returns
    -------
    ndarray, shape (k,)
        Chi-square with 4 dof if consistent.
    """
    return np.einsum("ki,ki->k", innovation, np.linalg.solve(S, innovation[..., None])[..., 0])


def initialize_landmarks(world_T_imu, z, camera, noise_var):
    """Triangulate new landmarks and linearise the triangulation for their covariance.

    ``m = world_T_imu exp(hat(delta)) imu_T_cam p_cam(z)`` with ``p_cam`` the disparity
    triangulation, so to first order::

        m ~ m0 + G_pose delta + G_z dz,   G_pose = R [I, -hat(p_imu)],   G_z = R R_ic J_tri

    with ``R``, ``R_ic`` the rotations of ``world_T_imu``, ``imu_T_cam`` and ``p_imu`` the point in
    the IMU frame. In joint SLAM the new block is ``G_pose Sigma_pp G_pose^T + C_tri`` and its
    correlation with every other state entry ``x`` is ``G_pose Sigma_px``; dropping it (the
    textbook shortcut) makes the filter overconfident.

    Parameters
    ----------
    world_T_imu : ndarray, shape (4, 4)
    z : ndarray, shape (k, 4)
    camera : visla_edu.camera.StereoCamera
    noise_var : float

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

    With the pose known the joint (3M x 3M) update is block diagonal::

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

    ``H_i = -Ks dpi/dq(q_i) cam_T_imu odot(T^{-1} m_i)`` stacked over the observations; with
    landmark covariances given, ``R_i = noise_var I + J_landmark_i Sigma_landmark_i J_landmark_i^T``.

    Parameters
    ----------
    world_T_imu : ndarray, shape (4, 4)
    Sigma_pose : ndarray, shape (6, 6)
        Not modified.
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


#: :data:`visla_edu.camera.STEREO_ROWS`: the exact reduction of the stereo rows from 4 to 3 for a rig
#: with one intrinsics (why it is exact, and a rig with two: :func:`visla_edu.camera.stereo_rows`).
STEREO_ROWS = camera.STEREO_ROWS


def joint_update(Sigma, world_T_imu, p_active, obs_slots, z, camera, noise_var, prediction=None):
    """Joint EKF update of the pose and all landmarks in the state, ``Sigma`` in place.

    The observation of the landmark in slot s touches the pose columns and that slot's columns
    (:func:`slot_columns`)::

        H_i = [J_pose_i (4x6), 0, ..., J_landmark_i (4x3) at columns 6+3s.., ..., 0]

    so :func:`joint_correction` assembles ``Sigma H^T`` and ``H Sigma H^T`` block by block. Every
    landmark in the state moves (unobserved ones through their correlation with the pose), so the
    whole ``p_active`` is corrected.

    Parameters
    ----------
    Sigma : ndarray, shape (D, D), D = 6 + 3 n
    world_T_imu : ndarray, shape (4, 4)
    p_active : ndarray, shape (n, 3)
        Means of all landmarks in the state, in slot order.
    obs_slots : ndarray of int, shape (k,)
        Slot of each observed landmark.
    z : ndarray, shape (k, 4)
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
        As :func:`joint_correction`.
    """
    if prediction is None:
        prediction = camera.predict_with_jacobians(world_T_imu, p_active[obs_slots])
    delta, nis = joint_correction(Sigma, obs_slots, z, noise_var, prediction, camera.stereo_rows)
    p_new = p_active + delta[POSE_DIM:].reshape(-1, 3)
    return world_T_imu @ lie.se3_exp(delta[:POSE_DIM]), p_new, nis


def joint_correction(Sigma, obs_slots, z, noise_var, prediction, rows=STEREO_ROWS):
    """The gain step of :func:`joint_update`: the state correction ``K r``, ``Sigma`` in place.

    Shared by both error forms of the joint filter (:mod:`visla_edu.filters._forms`): they differ
    only in the Jacobians in ``prediction`` and in how ``delta`` is applied (:func:`joint_update`,
    :func:`invariant_retract`). Each observation's rows are reduced exactly from 4 to 3 by ``rows``.

    Parameters
    ----------
    Sigma : ndarray, shape (D, D)
    obs_slots : ndarray of int, shape (k,)
    z : ndarray, shape (k, 4)
    noise_var : float
    prediction : tuple of ndarray
        ``(z_pred (k, 4), J_landmark (k, 4, 3), J_pose (k, 4, 6))``.
    rows : ndarray, shape (3, 4)
        The rig's exact reduction of the stereo rows (``camera.stereo_rows``); the default
        :data:`STEREO_ROWS` is that of a rig with one intrinsics.

    Returns
    -------
    delta : ndarray, shape (D,)
    nis : float
        ``r^T S^{-1} r`` of the full 4-row observations (``4 k`` degrees of freedom): the reduced
        rows' part plus the dropped row's ``|r - rows^T rows r|^2 / noise_var``.
    """
    k = len(obs_slots)
    z_pred, J_landmark, J_pose = prediction
    r4 = z - z_pred
    J_pose3 = (rows @ J_pose).reshape(3 * k, 6)  # (m, 6), m = 3k
    J_lm3 = rows @ J_landmark  # (k, 3, 3)
    lm_cols = slot_columns(obs_slots).ravel()
    D = Sigma.shape[0]
    Sigma_lm = Sigma[:, lm_cols].reshape(D, k, 3)
    # per observation i: Sigma[:, cols_i] @ J_lm3_i^T, batched as matmuls (einsum is 10x slower here)
    lm_part = (Sigma_lm.transpose(1, 0, 2) @ J_lm3.transpose(0, 2, 1)).transpose(1, 0, 2)
    Sigma_Ht = Sigma[:, :6] @ J_pose3.T + lm_part.reshape(D, 3 * k)
    S = J_pose3 @ Sigma_Ht[:6] + (J_lm3 @ Sigma_Ht[lm_cols].reshape(k, 3, 3 * k)).reshape(3 * k, 3 * k)
    S[np.diag_indices(3 * k)] += noise_var
    r3 = r4 @ rows.T
    delta, nis = gain_update(Sigma, Sigma_Ht, S, r3.ravel())
    if rows is STEREO_ROWS:  # the dropped row is (vL - vR) / sqrt(2)
        nis += float(np.sum((r4[:, 1] - r4[:, 3]) ** 2)) / (2 * noise_var)
    else:
        nis += float(np.sum((r4 - r3 @ rows) ** 2)) / noise_var
    return delta, nis


def invariant_pose_jacobian(J_landmark):
    """Pose Jacobian of the invariant form (:mod:`visla_edu.filters._forms`), ``[-J_landmark, 0]``.

    With ``T = exp(hat(xi)) mu``, ``xi = [p; theta]``, the point seen by the camera is
    ``inv(T) m_j ~ inv(mu) (mu_j + e_j - p)`` to first order: it depends on the pose error only
    through ``p`` and not at all on ``theta``, so moving the whole world changes nothing, whatever
    the estimate (what keeps the invariant filter consistent).

    Parameters
    ----------
    J_landmark : ndarray, shape (k, 4, 3)
        ``J_z_landmark`` of :meth:`visla_edu.camera.StereoCamera.predict_with_jacobians`.

    Returns
    -------
    ndarray, shape (k, 4, 6)
        Columns 0-2 for ``p``, columns 3-5 (zero) for ``theta``.
    """
    return np.concatenate([-J_landmark, np.zeros_like(J_landmark)], axis=-1)


def invariant_retract(world_T_imu, p_active, delta):
    """Apply an invariant correction: ``mu <- exp(hat(xi)) mu``, ``mu_j <- R_xi mu_j + J_l(theta) e_j``.

    ``R_xi`` is the rotation of ``exp(hat(xi))``, ``J_l`` :func:`visla_edu.lie.so3_left_jacobian`.

    Parameters
    ----------
    world_T_imu : ndarray, shape (4, 4)
    p_active : ndarray, shape (n, 3)
    delta : ndarray, shape (6 + 3 n,)
        ``[xi (6); e_0 (3); e_1 (3); ...]``.

    Returns
    -------
    world_T_imu_new : ndarray, shape (4, 4)
    p_active_new : ndarray, shape (n, 3)
    """
    step = lie.se3_exp(delta[:POSE_DIM])
    J_l = lie.so3_left_jacobian(delta[3:POSE_DIM])
    e = delta[POSE_DIM:].reshape(-1, 3)
    return step @ world_T_imu, p_active @ step[:3, :3].T + e @ J_l.T
