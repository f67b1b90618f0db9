"""Batch and sliding-window least squares on SE(3): the course report's objective (section 2), solved.

Over all poses ``world_T_imu[t]`` (the first held: it is the world frame) and landmarks ``m_j`` (world xyz)::

    sum_obs rho(|z_tj - h(T_t, m_j)|^2_V) + sum_t |log((T_t exp(tau_t u_t^))^{-1} T_{t+1})|^2_{W_t}

with ``h`` of :mod:`visla_edu.camera`, ``V = sigma_pixel^2 I4``, ``W_t = tau_t^2 diag(sigma_v^2 I3, sigma_w^2 I3)``
(:func:`visla_edu.motion.motion_noise`), ``u_t = [v; w]`` the twist of the step ``t -> t+1``
(:func:`visla_edu.motion.select_twists`), ``rho`` :func:`robust_loss`; Levenberg-Marquardt in the perturbations of
:mod:`visla_edu.lie`.

* :func:`smooth` -- batch over the whole drive from a trajectory (and optionally a map), with outlier rounds.
* :func:`smooth_window` -- the fixed-lag sliding window.
* :func:`normal_equations` -- the full sparse Gauss-Newton system at a state (teaching; the smoothers never form it).

The smoothers return a :class:`SmootherResult`; :class:`SmootherConfig` holds every setting. Private modules:
``_factors`` (motion residual, robust losses), ``_normal`` (linearisation, Schur step, marginals), ``_envelope``
(block envelope Cholesky), ``_problem``, ``_batch``, ``_window``, ``_config``, ``_result``. ``reprojection`` is
:func:`visla_edu.camera.stereo_projection`; the SE(3) right Jacobians are lie's (re-exported for notebooks 13-14).
"""

from visla_edu.smoother._batch import NormalEquations, normal_equations, smooth, start_cost
from visla_edu.smoother._config import (BATCH_ONLY, FILTER_SETTINGS, FROM_FILTER, LOSSES, OWN_SETTINGS, WINDOW_MODES,
                                        WINDOW_ONLY, SmootherConfig, check_own_settings)
from visla_edu.camera import stereo_projection as reprojection
from visla_edu.lie import se3_right_jacobian, se3_right_jacobian_inv
from visla_edu.smoother._factors import motion_residuals, robust_loss
from visla_edu.smoother._problem import triangulate_landmarks
from visla_edu.smoother._result import HISTORY_FIELDS, STOP_REASONS, SmootherResult
from visla_edu.smoother._window import smooth_window

__all__ = [
    "SmootherConfig",
    "SmootherResult",
    "LOSSES",
    "WINDOW_MODES",
    "FROM_FILTER",
    "OWN_SETTINGS",
    "FILTER_SETTINGS",
    "BATCH_ONLY",
    "WINDOW_ONLY",
    "check_own_settings",
    "HISTORY_FIELDS",
    "STOP_REASONS",
    "smooth",
    "start_cost",
    "smooth_window",
    "NormalEquations",
    "normal_equations",
    "triangulate_landmarks",
    "motion_residuals",
    "reprojection",
    "robust_loss",
    "se3_right_jacobian",
    "se3_right_jacobian_inv",
]
