"""The batch smoother: Levenberg-Marquardt over all poses and landmarks, with outlier rounds.

One round is Levenberg-Marquardt on the robust cost (IRLS weights refreshed at every accepted step, damping
``H + lambda diag(H)`` adapted by the gain ratio, Nielsen's rule). A landmark that a step would bring behind a
camera observing it is dropped on the spot: kept, it would force the damping up and shrink every step. After a
round, outliers are rejected (:func:`reject_outliers`), landmarks dropped (:func:`drop_landmarks`), and the next
round starts from the current estimate; rounds followed by a rejection are rough (:data:`ROUGH`).

The helpers take a :class:`~._problem.Problem`, ``world_T_imu`` (T, 4, 4) by dataset frame and ``landmarks``
(L, 3), the problem's, in its local order.
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
from visla_edu.smoother._result import (CONVERGED, HISTORY_FIELDS, ITERATION_CAP, NO_DESCENT, SmootherResult,
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
    """``1 / (tau_t sigma)``, the diagonal of ``W_t^{-1/2}`` (linear axes first), (K, 6), for ``tau`` (K,) s."""
    return 1.0 / (np.asarray(tau)[:, None] * config.velocity_sigmas)


def _state_norm(problem, world_T_imu, landmarks):
    p = world_T_imu[problem.first_var:problem.last_frame + 1, :3, 3]
    m = landmarks[problem.landmark_active]
    return float(np.sqrt(np.sum(p * p) + np.sum(m * m)))


def levenberg_marquardt(problem, world_T_imu, landmarks, config, history, round_index=0, max_iterations=None,
                        function_tolerance=None, final_linearization=True, stops=None):
    """One round: minimise the robust cost of ``problem`` from the given state.

    Appends a record per iteration to ``history`` (:data:`~._result.HISTORY_FIELDS`) and why it stopped to ``stops``
    (:data:`~._result.STOP_REASONS`); ``max_iterations``, ``function_tolerance`` default to the config's. Returns
    ``(world_T_imu, landmarks, lin, factor)``: the estimate, its :class:`~._normal.Linearization` (without
    ``final_linearization``, maybe from before a step accepted in the last iteration), the last step's factor or None.
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


def _record(history, *values):
    """Append one iteration's ``values``, in the order of :data:`~._result.HISTORY_FIELDS`."""
    for key, value in zip(HISTORY_FIELDS, values):
        history[key].append(value)


def reject_outliers(problem, world_T_imu, landmarks, probability):
    """Clear ``problem.active`` where ``s > chi2.ppf(probability, 4)`` (not if ``probability >= 1``): (N,) bool."""
    bad = np.zeros(len(problem.active), dtype=bool)
    if probability < 1:
        s, _ = _normal.observation_errors(problem, world_T_imu, landmarks)
        bad = problem.active & (s > chi2_quantile(probability, 4))
        problem.active[bad] = False
    return bad


def drop_landmarks(problem, world_T_imu, landmarks, min_observations):
    """Drop active landmarks behind a camera, too far, or with too few active observations, in place.

    Checked in that order, each landmark counted once: an active observation with a depth below ``problem.min_depth``
    (or not finite); a largest predicted disparity ``fsu b / depth`` below ``problem.min_disparity / 2``; fewer than
    ``min_observations``. Clears ``problem.landmark_active`` and ``problem.active``; returns the counts
    ``landmarks_behind_camera``, ``landmarks_too_far``, ``landmarks_too_few``.
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
                "ignored": int(np.sum(status == OBS_IGNORED)),
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
    """Batch smoother: the course objective (:mod:`visla_edu.smoother`) over all poses and landmarks.

    ``config.rejection_rounds + 1`` rounds of Levenberg-Marquardt, outlier rejection in between, then the marginals.

    Parameters
    ----------
    world_T_imu : array_like, shape (T, 4, 4)
        Initial trajectory, e.g. ``RunResult.world_T_imu`` or dead reckoning; the first pose is held.
    landmarks : array_like, shape (M, 3), optional
        Initial map (e.g. ``RunResult.landmarks``); NaN rows or None: :func:`triangulate_landmarks`; inf: ValueError.
    imu_T_cam : array_like, shape (4, 4), optional
        Calibration (e.g. ``RunResult.imu_T_cam``, extrinsic corrected); default the dataset's.
    config : SmootherConfig, optional
        Anything else (e.g. a ``FilterConfig``) is a TypeError.
    blas_threads : int or None
        BLAS threads while it runs (:func:`visla_edu._blas.limit_blas_threads`, None: numpy's); 1: the blocks are small.

    Returns
    -------
    SmootherResult
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
        rejected.update({k: rejected[k] + v for k, v in dropped.items()})
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
    """The batch smoother's Gauss-Newton system ``H [dp; dm] = -g`` at one state, whose robust cost is ``cost``.

    Attributes
    ----------
    H, g : scipy.sparse.csr_matrix, shape (6 n + 3 L, 6 n + 3 L); ndarray, shape (6 n + 3 L,)
        ``J^T W J`` and ``J^T W r``: the pose variables (frames ``1 .. n``, ``n = num_poses = T - 1``, 6 columns each,
        right perturbations; frame 0 is held), then the landmarks (3 columns each, in :attr:`landmark_ids` order). A
        landmark left out (:attr:`landmark_active` False) has an identity block and no coupling.
    landmark_ids, landmark_active : ndarray of int, bool, shape (L,)
        Dataset id of each landmark block; whether it is in the problem.
    """

    H: sparse.csr_matrix
    g: np.ndarray
    num_poses: int
    landmark_ids: np.ndarray
    landmark_active: np.ndarray
    cost: float


def normal_equations(dataset, world_T_imu, landmarks=None, imu_T_cam=None, config=None):
    """The full sparse normal equations (:class:`NormalEquations`) of the batch problem at a state, for teaching.

    The problem :func:`smooth` builds, linearised at the state (poses ``world_T_imu``) with the IRLS weights there.
    Arguments as in :func:`smooth` (and refused as there).
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
    """The batch objective (float) at a candidate start, what the start cannot explain counted as outliers.

    The problem is the one :func:`smooth` would build from this start (arguments as there), with its drops. Starts
    drop different landmarks, so each observation a start leaves out is charged an outlier's cost at the rejection
    threshold, ``rho(chi2_4(rejection_probability))``: the costs of different starts compare the same observations.
    ``inf`` when the start puts an observation behind a camera.
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
