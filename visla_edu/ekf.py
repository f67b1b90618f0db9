"""EKF update steps for visual-inertial SLAM: mapping, visual-inertial odometry, joint SLAM.

Every update is the textbook EKF update with a Cholesky factor ``S = L L^T`` of the innovation
covariance instead of an inverse::

    S     = H Sigma H^T + R
    A     = L^{-1} H Sigma              (solve, never invert)
    delta = A^T L^{-1} r                (= K r with K = Sigma H^T S^{-1})
    Sigma = Sigma - A^T A               (= (I - K H) Sigma)

Shared parameters: ``world_T_imu`` (4, 4) the pose mean ``mu``; ``z`` (k, 4) the stereo pixels
``[uL, vL, uR, vR]``, ``z = Ks pi(cam_T_imu T^{-1} m)`` for landmark ``m``, predicted with their
Jacobians by ``camera`` (:class:`visla_edu.camera.StereoCamera`); ``noise_var`` the pixel noise
variance (px^2), ``R = noise_var I4`` per observation; ``Sigma`` (D, D) a covariance overwritten
with the posterior. Pose corrections are applied on the right, ``mu <- mu @ se3_exp(delta_pose)``
(right perturbation, :mod:`visla_edu.lie`); landmark corrections are added.
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

    ``slots`` (k,) int; returns (k, 3) int.
    """
    return POSE_DIM + 3 * np.asarray(slots, dtype=np.int64)[:, None] + np.arange(3)


def cholesky_update(Sigma, H, cols, innovation, R):
    """One EKF update, in place, with an observation Jacobian ``H`` on the columns ``cols`` (zero elsewhere).

    ``H`` (m, c), ``cols`` (c,) int, ``innovation`` (m,) ``z - h(mu)``, ``R`` (m, m). Returns
    ``delta`` (D,) and ``nis`` as :func:`gain_update`, which raises ``numpy.linalg.LinAlgError`` if
    ``S`` is not positive definite.
    """
    Sigma_Ht = Sigma[:, cols] @ H.T  # (D, m)
    return gain_update(Sigma, Sigma_Ht, H @ Sigma_Ht[cols] + R, innovation)


def gain_update(Sigma, Sigma_Ht, S, innovation):
    """The EKF gain step in place: ``Sigma -= A^T A``, ``delta = A^T L^{-1} r`` (module docstring).

    ``Sigma_Ht`` (D, m) is ``Sigma H^T``, ``S`` (m, m) ``H Sigma H^T + R``, ``innovation`` (m,).
    ``A.T @ A`` is a symmetric rank-m product: a symmetric ``Sigma`` stays exactly symmetric.
    Returns ``delta`` (D,), the correction ``K r``, and ``nis = r^T S^{-1} r`` (chi-square with m
    dof if consistent). Raises ``numpy.linalg.LinAlgError`` if ``S`` is not positive definite.
    """
    L = linalg.cholesky(S, lower=True, check_finite=False)
    A = linalg.solve_triangular(L, Sigma_Ht.T, lower=True, check_finite=False)  # (m, D)
    white = linalg.solve_triangular(L, innovation, lower=True, check_finite=False)
    Sigma -= A.T @ A
    return A.T @ white, float(white @ white)


def innovation_covariances(J_pose, J_landmark, Sigma_pose, Sigma_pose_landmark, Sigma_landmark, noise_var):
    """Per-observation innovation covariances ``S_i = H_i Sigma H_i^T + R`` (batched), (k, 4, 4).

    ``H_i = [J_pose_i, J_landmark_i]`` acts on the pose and on landmark i only, so::

        S_i = Jp Spp Jp^T + Jp Spl_i Jl^T + Jl Spl_i^T Jp^T + Jl Sll_i Jl^T + noise_var I

    Shapes: ``J_pose`` (k, 4, 6), ``J_landmark`` (k, 4, 3), ``Sigma_pose`` (6, 6),
    ``Sigma_pose_landmark`` (k, 6, 3), ``Sigma_landmark`` (k, 3, 3); any of them may be None (a None
    Sigma term is zero).
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

    ``innovation`` (k, 4) the residuals ``z_i - h_i(mu)`` (px), ``S`` (k, 4, 4) their covariances
    (px^2, e.g. :func:`innovation_covariances`). Returns (k,), chi-square with 4 dof if consistent.
    """
    return np.einsum("ki,ki->k", innovation, np.linalg.solve(S, innovation[..., None])[..., 0])


def initialize_landmarks(world_T_imu, z, camera, noise_var):
    """Triangulate new landmarks and linearise the triangulation for their covariance.

    ``m = world_T_imu exp(hat(delta)) imu_T_cam p_cam(z)`` with ``p_cam`` the disparity
    triangulation, so to first order::

        m ~ m0 + G_pose delta + G_z dz,   G_pose = R [I, -hat(p_imu)],   G_z = R R_ic J_tri

    with ``R``, ``R_ic`` the rotations of ``world_T_imu``, ``imu_T_cam`` and ``p_imu`` the point in
    the IMU frame. Joint SLAM correlates the new landmark with the state through ``G_pose``
    (:meth:`visla_edu.filters.ActiveSet.augment`); dropping that makes the filter overconfident.

    Returns ``p_world`` (k, 3), ``G_pose`` (k, 3, 6) and ``C_tri`` (k, 3, 3), the triangulation
    covariance in the world frame, ``noise_var G_z G_z^T``.
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

    ``p_world`` (k, 3), ``Sigma_landmark`` (k, 3, 3); ``extra_noise`` (k, 4, 4), optional, is added to
    each ``R`` (e.g. the pose's own uncertainty seen through ``J_pose``). Returns ``p_new`` (k, 3) and
    ``Sigma_new`` (k, 3, 3).
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

    ``Sigma_pose`` (6, 6) is not modified; ``p_world`` (k, 3), ``Sigma_landmark`` (k, 3, 3), optional.
    Returns ``world_T_imu_new`` (4, 4), ``Sigma_pose_new`` (6, 6) and ``nis``.
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

    ``Sigma`` (D, D), D = 6 + 3 n; ``p_active`` (n, 3) the means of all landmarks in the state, in
    slot order; ``obs_slots`` (k,) int the slot of each observed landmark; ``prediction``, optional,
    ``camera.predict_with_jacobians(world_T_imu, p_active[obs_slots])`` if already computed (the
    filter has it from gating). Returns ``world_T_imu_new`` (4, 4), ``p_active_new`` (n, 3) and
    ``nis`` as :func:`joint_correction`.
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
    :func:`invariant_retract`). Each observation's rows are reduced exactly from 4 to 3 by ``rows``
    (3, 4), the rig's ``camera.stereo_rows`` (the default :data:`STEREO_ROWS` is that of a rig with
    one intrinsics). ``obs_slots`` (k,) int; ``prediction`` is
    ``(z_pred (k, 4), J_landmark (k, 4, 3), J_pose (k, 4, 6))``.

    Returns ``delta`` (D,) and ``nis``, the ``r^T S^{-1} r`` of the full 4-row observations (``4 k``
    degrees of freedom): the reduced rows' part plus the dropped row's
    ``|r - rows^T rows r|^2 / noise_var``.
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
    """Pose Jacobian of the invariant form (:mod:`visla_edu.filters._forms`), ``[-J_landmark, 0]``, (k, 4, 6).

    With ``T = exp(hat(xi)) mu``, ``xi = [p; theta]``, the point seen by the camera is
    ``inv(T) m_j ~ inv(mu) (mu_j + e_j - p)`` to first order: it depends on the pose error only
    through ``p`` (columns 0-2) and not at all on ``theta`` (columns 3-5, zero), so moving the whole
    world changes nothing, whatever the estimate (what keeps the invariant filter consistent).
    ``J_landmark`` (k, 4, 3) is ``J_z_landmark`` of
    :meth:`visla_edu.camera.StereoCamera.predict_with_jacobians`.
    """
    return np.concatenate([-J_landmark, np.zeros_like(J_landmark)], axis=-1)


def invariant_retract(world_T_imu, p_active, delta):
    """Apply an invariant correction: ``mu <- exp(hat(xi)) mu``, ``mu_j <- R_xi mu_j + J_l(theta) e_j``.

    ``R_xi`` is the rotation of ``exp(hat(xi))``, ``J_l`` :func:`visla_edu.lie.so3_left_jacobian`.
    ``p_active`` (n, 3), ``delta`` (6 + 3 n,) ``[xi (6); e_0 (3); e_1 (3); ...]``. Returns
    ``world_T_imu_new`` (4, 4) and ``p_active_new`` (n, 3).
    """
    step = lie.se3_exp(delta[:POSE_DIM])
    J_l = lie.so3_left_jacobian(delta[3:POSE_DIM])
    e = delta[POSE_DIM:].reshape(-1, 3)
    return step @ world_T_imu, p_active @ step[:3, :3].T + e @ J_l.T
