"""IMU motion model on SE(3): dead reckoning and the EKF prediction step.

Motion model (twist ``u_t = [v_t; w_t]`` in the body frame, ``tau_t = t_{t+1} - t_t``)::

    world_T_imu[t+1] = world_T_imu[t] @ exp(tau_t * twist_hat(u_t))

The right perturbation ``delta`` (:mod:`visla_edu.lie`) evolves as
``delta_{t+1} = F_t delta_t + n_t`` with the closed form (no ``expm`` needed)::

    F_t = exp(-tau_t curly_hat(u_t)) = adjoint(exp(-tau_t twist_hat(u_t)))

and ``n_t ~ N(0, W_t)``, ``W_t = tau_t^2 diag(sigma_v^2, sigma_w^2)`` for white noise on each
velocity sample (:func:`motion_noise`).

Shared parameters: ``u`` (6,) the step's body twist ``[v; w]`` (m/s, rad/s), ``tau`` the step's
duration (s), ``world_T_imu`` (4, 4) the pose mean ``mu``, ``W`` (6, 6) the step's noise covariance
(:func:`motion_noise`), ``sigma_linear, sigma_angular`` as in :func:`motion_noise`.

The invariant joint filter measures the pose error in the world frame instead,
``T = exp(hat(xi)) mu`` (:mod:`visla_edu.filters._forms`; :func:`predict_invariant_covariance`).
"""

import numpy as np

from visla_edu import lie

__all__ = [
    "select_twists",
    "dead_reckon",
    "motion_noise",
    "pose_transition",
    "imu_step",
    "predict_pose",
    "predict_pose_covariance",
    "predict_joint_covariance",
    "invariant_noise_factor",
    "predict_invariant_covariance",
]


def select_twists(twists, lag=0):
    """The twist used for the step ``t -> t+1``: ``u[t + lag]`` (clipped at the ends), (T - 1, 6).

    ``twists`` (T, 6) holds one ``[v; w]`` sample per time stamp; ``lag`` 0 uses the sample at the
    start of the interval (the course's convention), 1 the sample at its end.
    """
    twists = np.asarray(twists, dtype=float)
    if twists.ndim != 2 or twists.shape[1] != 6:
        raise ValueError(f"select_twists: twists must have shape (T, 6), got {twists.shape}")
    idx = np.clip(np.arange(len(twists) - 1) + int(lag), 0, len(twists) - 1)
    return twists[idx]


def dead_reckon(time_stamps, twists, world_T_imu0=None, lag=0):
    """Integrate IMU twists into a trajectory (T, 4, 4): ``world_T_imu[t+1] = world_T_imu[t] @ se3_exp(tau_t u_t)``.

    ``time_stamps`` (T,), ``twists`` (T, 6), ``lag`` as in :func:`select_twists`; ``world_T_imu0``
    (4, 4) defaults to the identity (world = IMU frame at the first time stamp). The prediction
    step's mean, nothing else.
    """
    time_stamps = np.asarray(time_stamps, dtype=float)
    steps = lie.se3_exp(np.diff(time_stamps)[:, None] * select_twists(twists, lag))
    poses = np.empty((len(time_stamps), 4, 4))
    poses[0] = np.eye(4) if world_T_imu0 is None else world_T_imu0
    for t, step in enumerate(steps):
        poses[t + 1] = poses[t] @ step
    return poses


def _noise_sigmas(sigma_linear, sigma_angular):
    """``[sigma_v (3); sigma_w (3)]`` from scalars (every axis) or per-axis triples."""
    parts = []
    for name, sigma in (("sigma_linear", sigma_linear), ("sigma_angular", sigma_angular)):
        sigma = np.asarray(sigma, dtype=float)
        if sigma.shape not in ((), (3,)):
            raise ValueError(f"motion_noise: {name} must be a number or 3 numbers (x, y, z), got shape {sigma.shape}")
        parts.append(np.broadcast_to(sigma, (3,)))
    return np.concatenate(parts)


def motion_noise(tau, sigma_linear, sigma_angular):
    """Per-step motion noise covariance ``W = tau^2 diag(sigma_v^2, sigma_w^2)`` of a twist ``[v; w]``, (6, 6).

    ``sigma_linear``, ``sigma_angular`` are ``sigma_v`` (m/s) and ``sigma_w`` (rad/s): one number
    for every axis, or a triple ``(x, y, z)`` in the body frame. ``W`` is diagonal.
    """
    return np.diag((tau * _noise_sigmas(sigma_linear, sigma_angular)) ** 2)


def pose_transition(u, tau):
    """Perturbation transition ``F = adjoint(se3_exp(-tau u))`` (= ``expm(-tau curly_hat(u))``), (6, 6)."""
    return lie.adjoint(lie.se3_exp(-tau * np.asarray(u, dtype=float)))


def imu_step(u, tau, sigma_linear, sigma_angular):
    """Everything one prediction step needs, with a single exponential.

    Returns ``step = se3_exp(tau u)`` (4, 4), the mean moving as ``mu <- mu @ step``;
    ``F = adjoint(inv(step))`` (6, 6), the same as :func:`pose_transition`; and ``W`` (6, 6) of
    :func:`motion_noise`.
    """
    step = lie.se3_exp(tau * np.asarray(u, dtype=float))
    return step, lie.adjoint(lie.se3_inv(step)), motion_noise(tau, sigma_linear, sigma_angular)


def predict_pose(world_T_imu, u, tau):
    """Mean prediction ``mu @ se3_exp(tau u)`` (4, 4): the pose after the step from ``world_T_imu`` before it."""
    return world_T_imu @ lie.se3_exp(tau * np.asarray(u, dtype=float))


def predict_pose_covariance(Sigma_pose, F, W):
    """Covariance prediction ``F Sigma F^T + W`` for the pose alone, a new (6, 6) array (not symmetrised).

    ``Sigma_pose`` (6, 6), the pose's right-perturbation covariance, is not modified; ``F`` is
    :func:`pose_transition` (or the ``F`` of :func:`imu_step`).
    """
    return F @ Sigma_pose @ F.T + W


def predict_joint_covariance(Sigma, F, W):
    """Covariance prediction of the joint state ``[pose (6); landmarks]``, in place; returns ``Sigma`` itself.

    Landmarks are static, so only the pose rows and columns change (``F``, ``W`` (6, 6))::

        Sigma_pp <- F Sigma_pp F^T + W,   Sigma_pl <- F Sigma_pl,   Sigma_lp <- Sigma_lp F^T
    """
    Sigma[:6, 6:] = F @ Sigma[:6, 6:]
    Sigma[6:, :6] = Sigma[:6, 6:].T
    Sigma_pp = F @ Sigma[:6, :6] @ F.T + W
    Sigma[:6, :6] = 0.5 * (Sigma_pp + Sigma_pp.T)  # keep the joint covariance exactly symmetric
    return Sigma


def invariant_noise_factor(world_T_imu, p_landmarks, W):
    """``B`` with ``B B^T`` the noise one IMU step adds to the invariant errors, (6 + 3n, 6).

    The errors are ``xi = [p; theta]`` of the pose and ``e_j = m_j - exp(hat(theta)) mu_j`` of each
    landmark (to first order; :func:`visla_edu.ekf.invariant_retract` applies the group
    exponential). A noise ``n ~ N(0, W)`` on the step's twist (body frame) moves them by
    ``Ad(mu) n`` and ``hat(mu_j) R n_w`` (``R`` the rotation of ``mu``, ``n_w`` the angular part), so::

        B = [[Ad(mu) L]; [hat(mu_j) R L_w] for each landmark],   W = L L^T, L_w = L[3:]

    ``world_T_imu`` is the pose mean after the step; ``p_landmarks`` (n, 3) the landmark means in
    state order (non-finite rows, the dense filter's placeholders, get zero rows: their covariance
    is written at their first observation).
    """
    L = np.linalg.cholesky(W) if np.any(W != np.diag(np.diag(W))) else np.diag(np.sqrt(np.diag(W)))
    R = world_T_imu[:3, :3]
    m = np.where(np.isfinite(p_landmarks), p_landmarks, 0.0)
    B = np.empty((6 + 3 * len(m), 6))
    B[:6] = lie.adjoint(world_T_imu) @ L
    B[6:] = (lie.hat(m) @ (R @ L[3:])).reshape(-1, 6)
    return B


def predict_invariant_covariance(Sigma, world_T_imu, p_landmarks, W):
    """Invariant covariance prediction, in place: ``Sigma <- Sigma + B B^T`` (:func:`invariant_noise_factor`).

    The invariant errors do not change along a noise-free step (the transition is the identity),
    so only the step's noise is added, through ``Ad(mu)``: the unobservable directions (the same
    translation in ``p`` and every ``e_j``, and a rotation ``theta``) do not depend on the estimate
    (:mod:`visla_edu.filters._forms`). ``Sigma`` (6 + 3 n, 6 + 3 n); the other arguments as
    :func:`invariant_noise_factor`. Returns ``Sigma`` itself.
    """
    B = invariant_noise_factor(world_T_imu, p_landmarks, W)
    Sigma += B @ B.T
    return Sigma
