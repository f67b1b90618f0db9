"""The batch smoother: Levenberg-Marquardt over all poses and landmarks, with outlier rounds.

One round is Levenberg-Marquardt on the robust cost (IRLS weights refreshed at every
accepted step, damping ``H + lambda diag(H)`` adapted by the gain ratio, Nielsen's rule).
A landmark that a step would bring behind a camera observing it (no finite cost) is dropped
on the spot: kept, it would force the damping up and shrink every step. After a round,
observations whose squared whitened error exceeds the chi-square (4 dof) quantile are
rejected, landmarks left with too few observations, too close to a camera or too far are
dropped, and the next round starts from the current estimate. Rounds followed by a rejection
are rough (100 times the function tolerance, half the iterations): they only have to
separate outliers from inliers. The first pose is held: it defines the world frame.

Measured on simulated drives (preset "small", 5% outlier tracks, seeds 0-4, from the EKF):
one rejection round gives the same ATE as two (0.078/0.199/0.094/0.518/0.172 m against
0.078/0.193/0.095/0.532/0.168 m) with fewer iterations; capping the rough round at half the
iterations costs nothing on four seeds and 0.17 -> 0.25 m on seed 4, and saves a quarter of
dataset 03's time (its 20 s whole-process budget).
"""

import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from visla_edu.smoother import _normal
from visla_edu._blas import limit_blas_threads
from visla_edu.codes import OBS_DROPPED, OBS_GATED, OBS_IGNORED, OBS_NO_DEPTH, OBS_USED
from visla_edu.metrics import chi2_quantile
from visla_edu.smoother._config import as_smoother_config
from visla_edu.smoother._factors import motion_steps, robust_loss
from visla_edu.smoother._problem import (build_problem, far_landmarks, observation_status, rig_camera,
                                         triangulate_landmarks)
from visla_edu.smoother._result import (CONVERGED, ITERATION_CAP, NO_DESCENT, SmootherResult,
                                        check_landmarks, check_trajectory, empty_history, finish_history)

__all__ = ["smooth", "levenberg_marquardt", "reject_outliers", "drop_landmarks", "motion_information",
           "NormalEquations", "normal_equations", "start_cost"]

#: Damping beyond which a round gives up (no step lowers the cost).
MAX_DAMPING = 1e12
#: Rounds followed by outlier rejection stop at ``ROUGH`` times the function tolerance: their
#: estimate only has to separate outliers from inliers, and the last round refines.
ROUGH = 100
#: ... and get ``max_iterations // ROUGH_ITERATIONS`` iterations (the last round gets all).
ROUGH_ITERATIONS = 2


def motion_information(tau, config):
    """Diagonal of ``W_t^{-1/2}`` for each step: ``1 / (tau_t sigma)``, shape (K, 6).

    With ``W_t = tau_t^2 diag(sigma_v^2, sigma_w^2)`` (:func:`visla_edu.motion.motion_noise`),
    the whitened motion residual is ``W_t^{-1/2} e_t``.

    Parameters
    ----------
    tau : array_like, shape (K,)
        The steps' durations (s).
    config : SmootherConfig
        Its :attr:`~SmootherConfig.velocity_sigmas` ``[sigma_v (3); sigma_w (3)]``.

    Returns
    -------
    ndarray, shape (K, 6)
        ``1 / (tau_t sigma_i)``, linear axes first.
    """
    return 1.0 / (np.asarray(tau)[:, None] * config.velocity_sigmas)


def _state_norm(problem, world_T_imu, landmarks):
    p = world_T_imu[problem.first_var:problem.last_frame + 1, :3, 3]
    m = landmarks[problem.landmark_active]
    return float(np.sqrt(np.sum(p * p) + np.sum(m * m)))


def levenberg_marquardt(problem, world_T_imu, landmarks, config, history, round_index=0, max_iterations=None,
                        function_tolerance=None, final_linearization=True, stops=None):
    """Minimise the robust cost of ``problem`` from the given state.

    Parameters
    ----------
    problem : Problem
    world_T_imu : ndarray, shape (T, 4, 4)
    landmarks : ndarray, shape (L, 3)
        The problem's landmarks (local order).
    config : SmootherConfig
        Stopping rules and the first damping.
    history : dict of list
        Appended to, one record per iteration (see ``HISTORY_FIELDS``).
    round_index : int
    max_iterations : int, optional
        Default ``config.max_iterations``.
    function_tolerance : float, optional
        Default ``config.function_tolerance``.
    final_linearization : bool
        Relinearise after a step accepted in the last allowed iteration (for covariances);
        without it the returned ``lin`` may be from the state before that step.
    stops : list of str, optional
        Appended to: why the iterations stopped, one of :data:`~._result.STOP_REASONS`.

    Returns
    -------
    world_T_imu, landmarks : ndarray
        The estimate.
    lin : Linearization
        At the estimate (for covariances).
    factor : EnvelopeFactor or None
        Of the last step solved (None if none was).
    """
    lin = _normal.linearize(problem, world_T_imu, landmarks)
    damping, nu = config.initial_damping, 2.0
    iterations = max_iterations or config.max_iterations
    factor, reason = None, ITERATION_CAP
    for iteration in range(iterations):
        try:
            step = _normal.solve_step(problem, lin, damping)
            factor = step.factor
        except np.linalg.LinAlgError:
            damping, nu = damping * nu, nu * 2
            continue
        new_T, new_m, too_close, errors = _normal.apply_step(problem, world_T_imu, landmarks, step)
        step_norm = float(np.sqrt(np.sum(step.d_pose**2) + np.sum(step.d_landmark**2)))
        if too_close.any():  # the step sends them behind a camera: inconsistent, drop them
            problem.landmark_active[too_close] = False
            problem.active &= problem.landmark_active[problem.obs_landmark]
            problem.dropped_in_steps += int(too_close.sum())
            lin = _normal.linearize(problem, world_T_imu, landmarks)
            _record(history, round_index, lin.cost, step_norm, False, damping)
            continue
        new_cost = _normal.evaluate(problem, new_T, new_m, errors)
        small_step = step_norm < config.step_tolerance * (1 + _state_norm(problem, world_T_imu, landmarks))
        accepted = bool(np.isfinite(new_cost) and new_cost < lin.cost)
        _record(history, round_index, new_cost if accepted else lin.cost, step_norm, accepted, damping)
        if not accepted:
            damping, nu = damping * nu, nu * 2
            if small_step or damping > MAX_DAMPING:
                reason = NO_DESCENT
                break
            continue
        gain = (lin.cost - new_cost) / max(step.predicted, 1e-300)
        damping, nu = damping * max(1 / 3, 1 - (2 * gain - 1) ** 3), 2.0
        relative = (lin.cost - new_cost) / max(lin.cost, 1e-300)
        world_T_imu, landmarks = new_T, new_m
        if final_linearization or iteration + 1 < iterations:
            lin = _normal.linearize(problem, world_T_imu, landmarks)
        if small_step or relative < (function_tolerance or config.function_tolerance):
            reason = CONVERGED
            break
    if stops is not None:
        stops.append(reason)
    return world_T_imu, landmarks, lin, factor


def _record(history, round_index, cost, step_norm, accepted, damping):
    for key, value in zip(("round", "cost", "step_norm", "accepted", "damping"),
                          (round_index, cost, step_norm, accepted, damping)):
        history[key].append(value)


def reject_outliers(problem, world_T_imu, landmarks, probability):
    """Deactivate observations with ``s > chi2.ppf(probability, 4)``.

    ``s = |h - z|^2 / sigma^2`` (:func:`~._normal.observation_errors`); ``problem.active`` is
    cleared in place for the rejected ones.

    Parameters
    ----------
    problem : Problem
        Modified in place.
    world_T_imu : ndarray, shape (T, 4, 4)
        IMU poses in the world frame.
    landmarks : ndarray, shape (L, 3)
        The problem's landmarks (local order).
    probability : float
        Chi-square (4 dof) quantile of the threshold; 1 or more rejects nothing.

    Returns
    -------
    ndarray of bool, shape (N,)
        The observations rejected now.
    """
    bad = np.zeros(len(problem.active), dtype=bool)
    if probability < 1:
        s, _ = _normal.observation_errors(problem, world_T_imu, landmarks)
        bad = problem.active & (s > chi2_quantile(probability, 4))
        problem.active[bad] = False
    return bad


def drop_landmarks(problem, world_T_imu, landmarks, min_observations):
    """Drop active landmarks with too few active observations, too close to a camera, or too far.

    Too far: the largest predicted disparity ``fsu b / depth`` over its active observations is
    below ``min_disparity / 2``.

    Too close: an active observation with depth below ``problem.min_depth`` (or not finite).
    Each landmark counts once, checked in that order: behind the camera, too far, too few.
    ``problem.landmark_active`` and ``problem.active`` are cleared in place.

    Parameters
    ----------
    problem : Problem
        Modified in place; ``min_depth`` and ``min_disparity`` come from it.
    world_T_imu : ndarray, shape (T, 4, 4)
        IMU poses in the world frame.
    landmarks : ndarray, shape (L, 3)
        The problem's landmarks (local order).
    min_observations : int
        Fewest active observations an active landmark keeps.

    Returns
    -------
    dict of int
        Landmarks dropped: ``landmarks_too_few``, ``landmarks_behind_camera``, ``landmarks_too_far``.
    """
    if problem.num_landmarks == 0:
        return _drop_counts(0, 0, 0)
    _, depth = _normal.observation_errors(problem, world_T_imu, landmarks)
    starts = problem.landmark_start[:-1]
    count = np.add.reduceat(problem.active.astype(np.int64), starts)
    close = np.add.reduceat((problem.active & ~(depth >= problem.min_depth)).astype(np.int64), starts) > 0
    disparity = np.where(problem.active, problem.fsu_b / np.where(depth > 0, depth, np.inf), -np.inf)
    far = np.maximum.reduceat(disparity, starts) < problem.min_disparity / 2
    behind = problem.landmark_active & close
    too_far = problem.landmark_active & ~behind & far & (count > 0)
    too_few = problem.landmark_active & ~behind & ~too_far & (count < min_observations)
    problem.landmark_active[behind | too_far | too_few] = False
    problem.active &= problem.landmark_active[problem.obs_landmark]
    return _drop_counts(int(too_few.sum()), int(behind.sum()), int(too_far.sum()))


def _setup(dataset, world_T_imu, landmarks, camera, config):
    """The batch problem, its initial landmarks, the observation status and drop counts."""
    status = observation_status(dataset, config)
    initial = triangulate_landmarks(dataset, camera, world_T_imu, status == OBS_USED, landmarks)
    far = far_landmarks(dataset, status == OBS_USED, config.min_disparity)
    known = np.all(np.isfinite(initial), axis=1)
    use = (status == OBS_USED) & (known & ~far)[dataset.obs_ids]
    rejected = {"nonpositive_disparity": int(np.sum(status == OBS_NO_DEPTH)),
                "repeated_frame": int(np.sum(status == OBS_IGNORED)),
                "landmarks_no_position": int(np.sum(~known & (np.bincount(dataset.obs_ids, status == OBS_USED,
                                                                          dataset.num_landmarks) > 0))),
                "landmarks_too_far": int(far.sum())}
    status[(status == OBS_USED) & ~use] = OBS_DROPPED
    step_inv, tau = motion_steps(dataset.time_stamps, dataset.twists, config.imu_lag)
    idx = np.flatnonzero(use)
    problem = build_problem(dataset.observation_frames()[idx], dataset.obs_ids[idx], dataset.obs_z[idx], idx,
                            camera=camera, config=config, frames=(0, 1, dataset.num_frames - 1),
                            motion=(0, step_inv, motion_information(tau, config)))
    return problem, initial[problem.landmark_ids], status, rejected


def smooth(dataset, world_T_imu, landmarks=None, imu_T_cam=None, config=None, blas_threads=1):
    """Batch smoother: the course objective over all poses and landmarks.

    Minimises ``sum_obs rho(|z - h(T_t, m_j)|^2_V) + sum_t |log((T_t exp(tau_t u_t^))^{-1} T_{t+1})|^2_{W_t}``
    by Levenberg-Marquardt on SE(3) with the landmark Schur complement, in
    ``config.rejection_rounds + 1`` rounds with outlier rejection in between (see the
    module docstring), then computes the marginal covariances.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    world_T_imu : array_like, shape (T, 4, 4)
        Initial trajectory, e.g. the EKF's (``RunResult.world_T_imu``) or dead reckoning.
        Its first pose is held.
    landmarks : array_like, shape (M, 3), optional
        Initial map (e.g. ``RunResult.landmarks``); NaN rows and a missing map are
        triangulated from each landmark's largest-disparity observation (an infinite entry is
        a ValueError).
    imu_T_cam : array_like, shape (4, 4), optional
        Calibration to use (e.g. ``RunResult.imu_T_cam``, after the extrinsic correction);
        default the dataset's.
    config : SmootherConfig, optional
    blas_threads : int or None
        BLAS threads while it runs (:func:`visla_edu._blas.limit_blas_threads`): its dense blocks
        are small (6x6 to a few hundred rows), where a second thread costs far more in
        synchronisation than it saves (the 60-frame simulated drive: 0.46 s with one thread,
        12 s with two on a busy 2-core machine); None leaves numpy's setting alone.

    Returns
    -------
    SmootherResult

    Raises
    ------
    ValueError
        A bad initial trajectory, map or calibration.
    TypeError
        ``config`` is not a :class:`SmootherConfig` (e.g. a ``FilterConfig``).
    """
    config = as_smoother_config(config, "smooth")
    with limit_blas_threads(blas_threads):
        return _smooth(dataset, world_T_imu, landmarks, imu_T_cam, config)


def _smooth(dataset, world_T_imu, landmarks, imu_T_cam, config):
    """:func:`smooth` with the BLAS thread limit in place."""
    start = time.perf_counter()
    world_T_imu = check_trajectory(world_T_imu, dataset.num_frames, dataset.name)
    landmarks = check_landmarks(landmarks, dataset.num_landmarks, dataset.name)
    camera = rig_camera(dataset, imu_T_cam)
    problem, m, status, rejected = _setup(dataset, world_T_imu, landmarks, camera, config)
    dropped = drop_landmarks(problem, world_T_imu, m, config.min_observations)
    rejected.update({k: rejected.get(k, 0) + v for k, v in dropped.items()})
    outlier = np.zeros(len(problem.active), dtype=bool)
    history, stops = empty_history(), []
    timing = {"setup": time.perf_counter() - start}
    round_index, final = 0, config.rejection_rounds == 0
    while True:
        tolerance = config.function_tolerance * (1 if final else ROUGH)
        iterations = config.max_iterations if final else max(1, config.max_iterations // ROUGH_ITERATIONS)
        world_T_imu, m, lin, _ = levenberg_marquardt(problem, world_T_imu, m, config, history, round_index,
                                                     max_iterations=iterations, function_tolerance=tolerance,
                                                     stops=stops)
        if final:
            break
        newly = reject_outliers(problem, world_T_imu, m, config.rejection_probability)
        outlier |= newly
        dropped = drop_landmarks(problem, world_T_imu, m, config.min_observations)
        for key, value in dropped.items():
            rejected[key] += value
        round_index += 1
        final = round_index == config.rejection_rounds or not (newly.any() or any(dropped.values()))
    rejected["outliers"] = int(outlier.sum())
    rejected["landmarks_behind_camera"] += problem.dropped_in_steps
    timing["solve"] = time.perf_counter() - start - timing["setup"]
    status[problem.obs_source[~problem.active]] = OBS_DROPPED
    status[problem.obs_source[outlier]] = OBS_GATED
    result = _result(dataset, problem, world_T_imu, m, lin, status, rejected, history, timing, camera, config, start)
    result.stop_reasons = stops
    return result


@dataclass
class NormalEquations:
    """The batch smoother's Gauss-Newton system ``H [dp; dm] = -g`` at one state.

    Attributes
    ----------
    H : scipy.sparse.csr_matrix, shape (6 n + 3 L, 6 n + 3 L)
        ``J^T W J``: the pose variables first (frames ``1 .. n``, 6 columns each, right
        perturbations ``T <- T exp(delta^)``; frame 0 is held), then the landmarks (3 columns
        each, in the order of :attr:`landmark_ids`). A landmark left out of the problem
        (:attr:`landmark_active` False) has an identity block and no coupling.
    g : ndarray, shape (6 n + 3 L,)
        ``J^T W r``.
    num_poses : int
        ``n``, the pose variables (``T - 1``).
    landmark_ids : ndarray of int, shape (L,)
        Dataset id of each landmark block.
    landmark_active : ndarray of bool, shape (L,)
    cost : float
        The robust cost at the state.
    """

    H: sparse.csr_matrix
    g: np.ndarray
    num_poses: int
    landmark_ids: np.ndarray
    landmark_active: np.ndarray
    cost: float


def normal_equations(dataset, world_T_imu, landmarks=None, imu_T_cam=None, config=None):
    """The full sparse normal equations of the batch problem at a state, for teaching and checks.

    The problem is the one :func:`smooth` builds (the same observations, landmarks and
    checks) linearised at ``world_T_imu`` and ``landmarks``, with the robust loss's IRLS
    weights at that state. :func:`smooth` itself never forms this matrix: it eliminates the
    landmarks block by block (the Schur complement).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    world_T_imu : array_like, shape (T, 4, 4)
        The state's poses (e.g. the EKF's trajectory, or the ground truth).
    landmarks, imu_T_cam, config
        As in :func:`smooth` (missing landmarks are triangulated).

    Returns
    -------
    NormalEquations

    Raises
    ------
    ValueError
        ``world_T_imu`` is not (T, 4, 4) or not finite, ``landmarks`` is not (M, 3) or has
        infinite entries, or ``imu_T_cam`` is not (4, 4).
    TypeError
        ``config`` is not a :class:`SmootherConfig` (e.g. a ``FilterConfig``).
    """
    config = as_smoother_config(config, "normal_equations")
    world_T_imu = check_trajectory(world_T_imu, dataset.num_frames, dataset.name)
    landmarks = check_landmarks(landmarks, dataset.num_landmarks, dataset.name)
    problem, m, _, _ = _setup(dataset, world_T_imu, landmarks, rig_camera(dataset, imu_T_cam), config)
    drop_landmarks(problem, world_T_imu, m, config.min_observations)
    lin = _normal.linearize(problem, world_T_imu, m)
    H, g = _normal.normal_equations(problem, lin)
    return NormalEquations(H, g, problem.num_vars, problem.landmark_ids.copy(), problem.landmark_active.copy(),
                           lin.cost)


def start_cost(dataset, world_T_imu, landmarks=None, imu_T_cam=None, config=None):
    """The batch objective at a candidate start, with what the start cannot explain counted as outliers.

    The problem is the one :func:`smooth` would build from this start (its landmarks, missing
    ones triangulated, and its drops: landmarks behind a camera or too far). Starts drop
    different landmarks, so each observation a start leaves out is charged what an outlier at
    the rejection threshold costs, ``rho(chi2_4(rejection_probability))``: the costs of
    different starts compare the same observations.

    Parameters
    ----------
    dataset, world_T_imu, landmarks, imu_T_cam, config
        As in :func:`smooth`.

    Returns
    -------
    float
        The robust cost plus the charge for the observations left out; ``inf`` when the start
        puts an observation behind a camera.
    """
    config = as_smoother_config(config, "start_cost")
    world_T_imu = check_trajectory(world_T_imu, dataset.num_frames, dataset.name)
    landmarks = check_landmarks(landmarks, dataset.num_landmarks, dataset.name)
    problem, m, status, _ = _setup(dataset, world_T_imu, landmarks, rig_camera(dataset, imu_T_cam), config)
    drop_landmarks(problem, world_T_imu, m, config.min_observations)
    cost = _normal.evaluate(problem, world_T_imu, m)
    usable = int(np.sum(status == OBS_USED)) + int(np.sum(status == OBS_DROPPED))
    outlier = robust_loss(np.array([chi2_quantile(config.rejection_probability, 4)]), config.loss,
                          config.loss_scale)[0][0]
    return float(cost + (usable - int(problem.active.sum())) * outlier)


def _drop_counts(too_few, behind, too_far):
    return {"landmarks_too_few": too_few, "landmarks_behind_camera": behind, "landmarks_too_far": too_far}


def _result(dataset, problem, world_T_imu, m, lin, status, rejected, history, timing, camera, config, start):
    """Marginal covariances and the :class:`SmootherResult`."""
    T, M = dataset.num_frames, dataset.num_landmarks
    cov_start = time.perf_counter()
    pose_cov = np.full((T, 6, 6), np.nan)
    landmark_cov = np.full((M, 3, 3), np.nan)
    if config.pose_covariance or config.landmark_covariance:
        poses, lms = _normal.marginals(problem, lin, config.landmark_covariance)
        pose_cov[0] = 0.0
        if config.pose_covariance:
            pose_cov[1:] = poses
        if lms is not None:
            landmark_cov[problem.landmark_ids] = lms
    landmarks = np.full((M, 3), np.nan)
    keep = problem.landmark_active
    landmarks[problem.landmark_ids[keep]] = m[keep]
    timing["covariance"] = time.perf_counter() - cov_start
    timing["total"] = time.perf_counter() - start
    return SmootherResult(
        name=dataset.name, mode="smooth", time_stamps=dataset.time_stamps.copy(), world_T_imu=world_T_imu,
        landmarks=landmarks, pose_cov=pose_cov, landmark_cov=landmark_cov, history=finish_history(history),
        rejected=rejected, obs_status=status, timing=timing, config=config.to_dict(),
        imu_T_cam=camera.imu_T_cam.copy(),
    )
