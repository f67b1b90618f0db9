"""Batch and sliding-window least squares on SE(3): the course report's objective, solved.

The EKF linearises each observation once; the smoother minimises the whole objective of the
course report (section 2) over all poses ``world_T_imu[t]`` (the first held: it is the
world frame) and landmarks ``m_j`` (world xyz)::

    sum_obs rho(|z_tj - h(T_t, m_j)|^2_V) + sum_t |log((T_t exp(tau_t u_t^))^{-1} T_{t+1})|^2_{W_t}

with the stereo model ``h`` of :mod:`visla_edu.camera`, ``V = sigma_pixel^2 I4``,
``W_t = tau_t^2 diag(sigma_v^2 I3, sigma_w^2 I3)`` (:func:`visla_edu.motion.motion_noise`),
the twist ``u_t = [v; w]`` of the step ``t -> t+1`` (:func:`visla_edu.motion.select_twists`)
and a robust loss ``rho`` (:func:`robust_loss`). Levenberg-Marquardt in the perturbations of
:mod:`visla_edu.lie`; the landmarks are eliminated by the Schur complement and the reduced
pose system is solved by a block envelope Cholesky factor, which also gives the marginals.

* :func:`smooth` -- the batch smoother over the whole drive, started from a trajectory
  (the EKF's, or dead reckoning) and optionally a map; rounds of outlier rejection.
* :func:`smooth_window` -- the fixed-lag sliding window, the real-time middle ground
  between the filter and the batch.

Both return a :class:`SmootherResult`; :class:`SmootherConfig` holds every setting.
:func:`normal_equations` gives the full sparse Gauss-Newton system at a state (for teaching:
notebook 13's spy plot and Schur complement; the smoothers never form it).

    >>> from visla_edu import data, run, smoother
    >>> ds = data.load("sim-tiny")
    >>> ekf = run.run_filter(ds, "slam", progress=False)
    >>> result = smoother.smooth(ds, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam)
    >>> result.world_T_imu.shape == (ds.num_frames, 4, 4)
    True

Modules (private; the public names are re-exported here): ``_config``, ``_factors`` (motion
residual, robust losses), ``_problem``, ``_envelope`` (the block envelope Cholesky),
``_normal`` (linearisation, Schur step, marginals), ``_result``, ``_batch``, ``_window``. The
reprojection factor is the camera's (:func:`visla_edu.camera.stereo_projection`, re-exported
as ``reprojection``), the SE(3) right Jacobians lie's (re-exported for notebooks 13-14).
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
