"""The fixed-lag sliding-window smoother: the batch objective over the last N frames, online.

At each new frame ``k`` the pose is predicted from the previous estimate and the IMU step, landmarks seen for the
first time are triangulated there, and a few Levenberg-Marquardt iterations (:func:`~._batch.levenberg_marquardt`)
optimise the poses of the window ``max(1, k - N + 1) .. k`` and the landmarks they observe. Observations whose
squared whitened error then exceeds the chi-square threshold are rejected for good. States leaving the window
(``SmootherConfig.window_mode``):

``"fix"`` (default)
    Older poses are held, so their observations are factors on the landmarks alone: a leaving frame's are folded
    into Gaussian landmark priors (:meth:`_WindowState.hold`), so landmarks keep what old frames saw while the
    problem stays small. The motion factor from the last held pose anchors the window.
``"marginalize"``
    Only observations inside the window are used; a leaving pose ``v``'s window marginal, propagated through the motion
    step, becomes a prior on the new oldest pose (information ``(F Sigma_v F^T + W)^{-1}``, mean ``T_v exp(tau u^)``),
    which counts the observations still in the window twice and loses the old ones of remaining landmarks.

The defaults are measured on simulated drives: ``"fix"`` had a lower ATE than ``"marginalize"`` on every seed at
the same time per frame (``python benchmarks/bench_smoother.py --cases sim``); 20 frames, one iteration, came close
to 30 frames' ATE at less time per frame (10 frames were worse, even with two iterations).
"""

import time

import numpy as np

from visla_edu import lie
from visla_edu.camera import stereo_projection
from visla_edu.smoother import _envelope, _normal
from visla_edu.smoother._batch import levenberg_marquardt, motion_information
from visla_edu._blas import limit_blas_threads
from visla_edu.codes import OBS_DROPPED, OBS_GATED, OBS_IGNORED, OBS_NO_DEPTH, OBS_USED
from visla_edu.metrics import chi2_quantile
from visla_edu.smoother._config import as_smoother_config
from visla_edu.smoother._factors import motion_steps, robust_loss
from visla_edu.smoother._problem import PosePrior, build_problem, observation_status, rig_camera
from visla_edu.smoother._result import SmootherResult, check_trajectory, empty_history, finish_history

__all__ = ["smooth_window"]

#: ``"fix"`` mode: observations of this many held frames before the window stay in the problem
#: (relinearised, and rejected if they turn out to be outliers) before they are folded into
#: landmark priors.
HELD_FRAMES = 10


class _WindowState:
    """Everything the window carries from frame to frame."""

    def __init__(self, dataset, world_T_imu0, camera, config):
        self.dataset, self.camera, self.config = dataset, camera, config
        T, M = dataset.num_frames, dataset.num_landmarks
        self.step_inv, tau = motion_steps(dataset.time_stamps, dataset.twists, config.imu_lag)
        self.sqrt_info = motion_information(tau, config)
        self.world_T_imu = np.empty((T, 4, 4))
        self.world_T_imu[0] = world_T_imu0
        self.online = self.world_T_imu.copy()
        self.landmarks = np.full((M, 3), np.nan)
        self.status = observation_status(dataset, config)
        self.frames = dataset.observation_frames()
        self.prior_info = np.zeros((M, 3, 3))  # "fix": observations from held poses, folded in
        self.prior_eta = np.zeros((M, 3))
        self.prior_const = np.zeros(M)
        self.held_count = np.zeros(M, dtype=np.int64)
        self.pose_cov = np.full((T, 6, 6), np.nan)
        self.pose_cov[0] = 0.0
        self.prior = None
        self.threshold = chi2_quantile(config.rejection_probability, 4) if config.rejection_probability < 1 \
            else np.inf
        self.dropped = {"landmarks_behind_camera": 0}

    def predict(self, k):
        """Predict pose ``k`` from pose ``k - 1``; triangulate there, as the EKF does, the landmarks first
        seen at ``k`` with a disparity of at least ``min_disparity`` (their earlier observations count too).
        """
        self.world_T_imu[k] = self.world_T_imu[k - 1] @ lie.se3_inv(self.step_inv[k - 1])
        idx = np.arange(self.dataset.frame_ptr[k], self.dataset.frame_ptr[k + 1])
        ids = self.dataset.obs_ids[idx]
        disparity = self.camera.disparity(self.dataset.obs_z[idx])
        new = idx[(self.status[idx] == OBS_USED) & np.isnan(self.landmarks[ids, 0])
                  & (disparity >= self.config.min_disparity)]
        if len(new):
            self.landmarks[self.dataset.obs_ids[new]] = self.camera.triangulate(
                self.dataset.obs_z[new], self.world_T_imu[k])

    def window_observations(self, k, v0):
        """Dataset indices of the observations of the window problem at frame ``k``: the usable ones of
        frames ``v0 .. k`` and, in ``"fix"`` mode, the held frames' (:meth:`held_from`) of the same
        landmarks, for landmarks with ``min_observations`` (counting those folded into priors).
        """
        ds = self.dataset
        idx = np.arange(ds.frame_ptr[v0], ds.frame_ptr[k + 1])
        idx = idx[(self.status[idx] == OBS_USED) & np.isfinite(self.landmarks[ds.obs_ids[idx], 0])]
        lo = self.held_from(v0)
        if lo < v0:
            old = np.arange(ds.frame_ptr[lo], ds.frame_ptr[v0])
            seen = np.zeros(ds.num_landmarks, dtype=bool)
            seen[ds.obs_ids[idx]] = True
            idx = np.concatenate([old[(self.status[old] == OBS_USED) & seen[ds.obs_ids[old]]], idx])
        count = np.bincount(ds.obs_ids[idx], minlength=ds.num_landmarks) + self.held_count
        return idx[count[ds.obs_ids[idx]] >= self.config.min_observations]

    def held_from(self, v0):
        """First held frame whose observations stay: ``"fix"``, :data:`HELD_FRAMES` before ``v0``;
        ``"marginalize"``, frame 0 until the first pose is marginalised, then none.
        """
        if self.config.window_mode == "marginalize":
            return 0 if v0 == 1 else v0
        return max(0, v0 - HELD_FRAMES)

    def problem(self, k, v0):
        """The window problem at frame ``k`` (pose variables ``v0 .. k``)."""
        ds, config = self.dataset, self.config
        idx = self.window_observations(k, v0)
        fix = config.window_mode == "fix"
        motion_from = v0 - 1 if fix or v0 == 1 else v0  # the prior replaces the link once it exists
        return build_problem(self.frames[idx], ds.obs_ids[idx], ds.obs_z[idx], idx, camera=self.camera,
                             config=config, frames=(min(self.held_from(v0), v0), v0, k),
                             motion=(motion_from, self.step_inv[motion_from:k], self.sqrt_info[motion_from:k]),
                             prior=None if fix or v0 == 1 else self.prior,
                             landmark_prior=(self.prior_info, self.prior_eta, self.prior_const) if fix else None)

    def hold(self, v):
        """Pose ``v`` leaves the ``"fix"`` window: each observation, linearised at ``m0`` (residual ``r``,
        Jacobian ``J``, robust weight ``w``), adds ``J^T w J`` to ``Lambda``, ``J^T w (J m0 - r)`` to ``eta``.
        """
        ds = self.dataset
        idx = np.arange(ds.frame_ptr[v], ds.frame_ptr[v + 1])
        idx = idx[self.status[idx] == OBS_USED]
        idx = idx[np.isfinite(self.landmarks[ds.obs_ids[idx], 0])]
        ids = ds.obs_ids[idx]
        if not len(idx):
            return
        m0 = self.landmarks[ids]
        z, _, J, _ = stereo_projection(self.camera.Ks, self.camera.cam_T_imu, self.world_T_imu[v], m0)
        r = z - ds.obs_z[idx]
        s = (r * r).sum(axis=1) / self.config.sigma_pixel**2
        w = robust_loss(s, self.config.loss, self.config.loss_scale)[1] / self.config.sigma_pixel**2
        JtW = np.swapaxes(J, 1, 2) * w[:, None, None]
        offset = (J @ m0[:, :, None])[:, :, 0] - r  # r + J (m - m0) = J m - offset
        np.add.at(self.prior_info, ids, JtW @ J)
        np.add.at(self.prior_eta, ids, (JtW @ offset[:, :, None])[:, :, 0])
        np.add.at(self.prior_const, ids, w * (offset * offset).sum(axis=1))
        np.add.at(self.held_count, ids, 1)


def _drop_close(state, problem, m):
    """Drop for good the landmarks predicted closer than ``min_depth``; their usable observations: ``OBS_DROPPED``."""
    _, depth = _normal.observation_errors(problem, state.world_T_imu, m)
    close = np.zeros(problem.num_landmarks, dtype=bool)
    np.logical_or.at(close, problem.obs_landmark, ~(depth >= problem.min_depth))
    if close.any():
        problem.landmark_active[close] = False
        problem.active &= problem.landmark_active[problem.obs_landmark]
        gone = np.isin(state.dataset.obs_ids, problem.landmark_ids[close])
        state.status[gone & (state.status == OBS_USED)] = OBS_DROPPED
        state.dropped["landmarks_behind_camera"] += int(close.sum())


def _reject(state, problem, m):
    """Reject the window's observations beyond the chi-square threshold (for good)."""
    s, _ = _normal.observation_errors(problem, state.world_T_imu, m)
    bad = problem.active & (s > state.threshold)
    state.status[problem.obs_source[bad]] = OBS_GATED


def _next_prior(state, cov, v0):
    """Marginalise pose ``v0`` (window marginal ``cov``) through its motion step into a prior on ``v0 + 1``."""
    step_inv = state.step_inv[v0]
    F = lie.adjoint(step_inv)  # perturbation transition exp(-tau curlyhat(u))
    propagated = F @ cov @ F.T + np.diag(1.0 / state.sqrt_info[v0] ** 2)
    info = np.linalg.inv(0.5 * (propagated + propagated.T))
    return PosePrior(v0 + 1, state.world_T_imu[v0] @ lie.se3_inv(step_inv), np.linalg.cholesky(info).T)


def _process_frame(state, k, history):
    """Predict frame ``k``, optimise the window ending at it, bookkeep the pose leaving next."""
    config, last = state.config, k == state.dataset.num_frames - 1
    state.predict(k)
    v0 = max(1, k - config.window_size + 1)
    problem = state.problem(k, v0)
    m = state.landmarks[problem.landmark_ids]
    _drop_close(state, problem, m)
    leaving = k >= config.window_size and not last  # pose v0 leaves the window after this frame
    marginalize = config.window_mode == "marginalize" and leaving
    covariance = marginalize or (config.pose_covariance and (leaving or last))
    T, m, lin, factor = levenberg_marquardt(problem, state.world_T_imu, m, config, history, round_index=k,
                                            max_iterations=config.window_iterations, final_linearization=False)
    if problem.dropped_in_steps:
        gone = problem.landmark_ids[~problem.landmark_active]
        state.status[np.isin(state.dataset.obs_ids, gone) & (state.status == OBS_USED)] = OBS_DROPPED
        state.dropped["landmarks_behind_camera"] += problem.dropped_in_steps
    state.world_T_imu[v0:k + 1] = T[v0:k + 1]
    state.landmarks[problem.landmark_ids[problem.landmark_active]] = m[problem.landmark_active]
    state.online[k] = state.world_T_imu[k]
    _reject(state, problem, m)
    if covariance:
        cov = _envelope.inverse_diagonal(factor) if factor is not None else \
            _normal.marginals(problem, lin, landmark_covariance=False)[0]
        state.pose_cov[v0:k + 1] = cov if last else state.pose_cov[v0:k + 1]
        state.pose_cov[v0] = cov[0]
        if marginalize:
            state.prior = _next_prior(state, cov[0], v0)
    if leaving and config.window_mode == "fix" and v0 - HELD_FRAMES >= 0:
        state.hold(v0 - HELD_FRAMES)


def smooth_window(dataset, world_T_imu0=None, imu_T_cam=None, config=None, blas_threads=1):
    """Fixed-lag sliding-window smoother over the whole drive, frame by frame (module docstring).

    ``world_T_imu0`` (4, 4): the first pose (held), identity by default; ``imu_T_cam``, ``config``, ``blas_threads``:
    as in :func:`~._batch.smooth` (and refused as there). A window longer than the drive optimises every frame so far
    at each new frame.

    Returns
    -------
    SmootherResult
        ``mode="window"``; ``world_T_imu`` holds each pose as estimated when it left the window (the last window's for
        its frames), ``pose_cov`` the window marginal at exit (conditioned on the held poses in ``"fix"`` mode, hence
        optimistic) from the factor of the frame's last, damped step (a cheap approximation); no landmark covariances.
    """
    config = as_smoother_config(config, "smooth_window")
    first = np.eye(4) if world_T_imu0 is None else check_trajectory(np.asarray(world_T_imu0)[None], 1,
                                                                      dataset.name)[0]
    with limit_blas_threads(blas_threads):
        return _run_window(dataset, first, rig_camera(dataset, imu_T_cam), config)


def _run_window(dataset, world_T_imu0, camera, config):
    start = time.perf_counter()
    state = _WindowState(dataset, world_T_imu0, camera, config)
    history = empty_history()
    frame_seconds = np.zeros(dataset.num_frames)
    for k in range(1, dataset.num_frames):
        t0 = time.perf_counter()
        _process_frame(state, k, history)
        frame_seconds[k] = time.perf_counter() - t0
    return _window_result(dataset, state, history, frame_seconds, config, time.perf_counter() - start)


def _final_landmarks(dataset, state, config):
    """The map without what the window never estimated, and the counts ``landmarks_too_far`` (never triangulated:
    all below ``min_disparity``) and ``landmarks_too_few``; their usable observations become ``OBS_DROPPED``.
    """
    status, M = state.status, dataset.num_landmarks
    used = np.bincount(dataset.obs_ids, status == OBS_USED, M)
    too_far = np.isnan(state.landmarks[:, 0]) & (used > 0)
    dropped = np.bincount(dataset.obs_ids, status == OBS_DROPPED, M) > 0  # behind a camera, counted already
    too_few = np.isfinite(state.landmarks[:, 0]) & ~dropped & (used < config.min_observations)
    landmarks = state.landmarks.copy()
    landmarks[used < config.min_observations] = np.nan
    status[(status == OBS_USED) & np.isnan(landmarks[dataset.obs_ids, 0])] = OBS_DROPPED
    return landmarks, {"landmarks_too_far": int(too_far.sum()), "landmarks_too_few": int(too_few.sum())}


def _window_result(dataset, state, history, frame_seconds, config, total):
    landmarks, dropped = _final_landmarks(dataset, state, config)
    status = state.status
    rejected = {"nonpositive_disparity": int(np.sum(status == OBS_NO_DEPTH)),
                "ignored": int(np.sum(status == OBS_IGNORED)), "landmarks_no_position": 0, **dropped,
                **state.dropped, "outliers": int(np.sum(status == OBS_GATED))}
    return SmootherResult(
        name=dataset.name, mode="window", time_stamps=dataset.time_stamps.copy(),
        world_T_imu=state.world_T_imu, landmarks=landmarks, pose_cov=state.pose_cov,
        landmark_cov=np.full((dataset.num_landmarks, 3, 3), np.nan), history=finish_history(history),
        rejected=rejected, obs_status=status, timing={"total": total}, config=config.to_dict(),
        imu_T_cam=state.camera.imu_T_cam.copy(), frame_seconds=frame_seconds, online_world_T_imu=state.online,
    )
