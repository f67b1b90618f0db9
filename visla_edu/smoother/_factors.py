"""The smoother's motion residual and its analytic Jacobians, vectorised over factors; robust losses.

Reprojection residual and Jacobians: :func:`visla_edu.camera.stereo_projection`. Motion, one per step ``t -> t+1``::

    E_t = exp(-tau_t u_t^) T_t^{-1} T_{t+1},      e_t = log(E_t)

Right-perturbing ``T_t`` by ``a`` and ``T_{t+1}`` by ``b`` (:mod:`visla_edu.lie`) gives, to first order,
``E_t <- E_t exp((b - Ad(T_{t+1}^{-1} T_t) a)^)``, so::

    J_e_next = J_r(e_t)^{-1},      J_e_prev = -J_r(e_t)^{-1} Ad(T_{t+1}^{-1} T_t)
"""

import numpy as np

from visla_edu import lie

__all__ = ["motion_steps", "motion_residuals", "robust_loss"]


def motion_steps(time_stamps, twists, lag):
    """``exp(-tau_t u_t^)`` (T-1, 4, 4) and ``tau_t`` (T-1,) of twists (T, 6); ``lag``: ``select_twists``."""
    from visla_edu.motion import select_twists

    tau = np.diff(np.asarray(time_stamps, dtype=float))
    return lie.se3_exp(-tau[:, None] * select_twists(twists, lag)), tau


def motion_residuals(world_T_imu, step_inv, jacobians=True):
    """Motion residuals ``e_t = log(exp(-tau u^) T_t^{-1} T_{t+1})``, (K, 6), and their Jacobians.

    ``world_T_imu`` (K + 1, 4, 4): consecutive poses ``T_0 .. T_K``; ``step_inv`` (K, 4, 4): ``exp(-tau_t u_t^)`` of
    each step (:func:`motion_steps`). Returns ``e``, or ``(e, J_e_prev, J_e_next)``, (K, 6, 6) each, if ``jacobians``.
    """
    next_T_prev = lie.se3_inv(world_T_imu[1:]) @ world_T_imu[:-1]
    E = step_inv @ lie.se3_inv(next_T_prev)
    e = lie.se3_log(E)
    if not jacobians:
        return e
    J_e_next = lie.se3_right_jacobian_inv(e)
    J_e_prev = -J_e_next @ lie.adjoint(next_T_prev)
    return e, J_e_prev, J_e_next


def robust_loss(s, loss, scale):
    """Robust loss ``rho(s)`` of squared whitened errors ``s = |r|^2 / sigma^2`` (N,) and its IRLS weight ``rho'(s)``.

    Cauchy: ``rho = k^2 log(1 + s / k^2)``, ``rho' = 1 / (1 + s / k^2)``.
    Huber: ``rho = s`` for ``s <= k^2``, else ``2 k sqrt(s) - k^2``; ``rho' = min(1, k / sqrt(s))``.
    None: ``rho = s``, ``rho' = 1``. ``loss`` is "cauchy", "huber" or "none" (else ValueError); ``scale`` is ``k``, in
    units of ``sqrt(s)``. Returns ``rho, weight``, (N,) each.
    """
    k2 = scale**2
    if loss == "cauchy":
        return k2 * np.log1p(s / k2), 1.0 / (1.0 + s / k2)
    if loss == "huber":
        root = np.sqrt(s)
        inlier = root <= scale
        return np.where(inlier, s, 2 * scale * root - k2), np.where(inlier, 1.0, scale / np.maximum(root, scale))
    if loss == "none":
        return s, np.ones_like(s)
    raise ValueError(f"robust_loss: loss must be 'cauchy', 'huber' or 'none', got {loss!r}")
