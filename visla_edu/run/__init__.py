"""One driver for every filter mode and the smoothers: build, step, run, evaluate, save.

Entry points: :func:`make_filter`, :func:`iterate_filter`, :func:`run_filter`, :func:`run_smoother`,
:func:`evaluate_result`; results and their file: :mod:`visla_edu.run._results`; cost and failure hints:
:mod:`visla_edu.run.workload`. How the driver runs (:func:`limit_blas_threads`, the progress bar) is in its
arguments, not in the filter's settings.

**"auto" settings.** Every run first measures the settings left at ``"auto"`` from the data (:func:`resolve_config`):
the velocity noise and the IMU lag by :func:`visla_edu.diagnostics.calibrate` (cached by the data's content,
applied by :meth:`~visla_edu.filters.FilterConfig.resolve`), ``extrinsic_correction`` with the camera
(:func:`visla_edu.diagnostics.resolve_extrinsics`). The smoothers take the resolved values.
"""

import contextlib
import time
from dataclasses import replace

import numpy as np

from visla_edu import data, diagnostics, filters, metrics, motion
from visla_edu._blas import check_blas_threads as _check_blas_threads
from visla_edu._blas import limit_blas_threads
from visla_edu.run._results import RunArrays, RunResult, load_result, save_result
from visla_edu.codes import DEADRECKON, MAPPING, MODES, SLAM, SMOOTH, SMOOTHER_MODES, STATUS_NAMES, VIO
from visla_edu.filters import FilterConfig

__all__ = ["MODES", "RunArrays", "RunResult", "limit_blas_threads", "make_filter", "resolve_config", "iterate_filter",
           "run_filter", "run_smoother", "evaluate_result", "save_result", "load_result"]

#: The filter class of each mode but ``"slam"`` (``filters.JointSlam`` takes ``dense``).
_MODE_CLASSES = {DEADRECKON: filters.DeadReckoning, MAPPING: filters.LandmarkMapping,
                 VIO: filters.VisualInertialOdometry}


def make_filter(dataset, mode=SLAM, config=None, dense=False, verbose=False):
    """Build the filter object for ``mode`` with the settings and calibration resolved (module docstring).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"deadreckon", "mapping", "vio", "slam"}
    config : visla_edu.filters.FilterConfig, optional
    dense : bool
        Textbook joint EKF over all (strided) landmarks; only for ``mode="slam"``.
    verbose : bool
        Print the evidence of an automatic extrinsic correction.

    Returns
    -------
    filters.DeadReckoning, filters.LandmarkMapping, filters.VisualInertialOdometry or filters.JointSlam

    Raises
    ------
    ValueError
        A bad mode, ``dense`` without ``"slam"``, no observations for a mode that needs them, or an implausible
        calibration (:func:`visla_edu.data.calibration_problems`).
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if dense and mode != SLAM:
        raise ValueError(f"dense=True is the textbook joint filter and needs mode='slam', got mode={mode!r}")
    # In-memory datasets are held to the ranges the loader enforces on files: the filter would silently turn
    # an absurd focal length, baseline or extrinsic into inf/NaN covariances or a garbage map.
    problems = data.calibration_problems(dataset)
    if problems:
        raise ValueError(f"cannot run the filter: {problems[0]}")
    _check_enough_data(dataset, mode)
    config = resolve_config(dataset, config or FilterConfig())
    camera = dataset.stereo_camera(_imu_T_cam(dataset, config, verbose))
    if mode == SLAM:
        return filters.JointSlam(dataset, camera, config, dense=dense)
    return _MODE_CLASSES[mode](dataset, camera, config)


def _check_enough_data(dataset, mode):
    """Refuse a mode the dataset cannot feed: all but dead reckoning need observations, the smoothers two frames."""
    if mode == DEADRECKON:
        return
    if dataset.num_observations == 0:
        why = dataset.extra.get("no_features") or "every feature is -1, not observed"
        raise ValueError(f"mode {mode} needs stereo observations and {dataset.name!r} has none ({why}); use mode "
                         "deadreckon")
    if mode in SMOOTHER_MODES and dataset.num_frames < 2:
        raise ValueError(f"mode {mode} needs at least 2 frames, {dataset.name!r} has {dataset.num_frames}")


def resolve_config(dataset, config):
    """``config`` with its ``"auto"`` settings measured from ``dataset`` (module docstring), a FilterConfig.

    The same object when nothing was ``"auto"``; ``extrinsic_correction`` is left to the camera.
    """
    if config.resolved:
        return config
    needs = filters.AUTO_FIELDS + ("pixel_noise_inflation",)  # the inflation reads the track correlation
    calibration = diagnostics.calibrate(dataset) if any(getattr(config, n) == filters.AUTO for n in needs) else None
    return config.resolve(calibration, focal_length=float(dataset.K[0, 0]),
                          time_step=float(np.median(dataset.time_steps)) if dataset.num_frames > 1 else 0.1)


def _imu_T_cam(dataset, config, verbose):
    """The camera's extrinsic with ``config.extrinsic_correction`` applied (``"auto"`` resolved), shape (4, 4)."""
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(dataset, config.extrinsic_correction)
    if verbose and evidence:
        print(evidence)
    return imu_T_cam


def iterate_filter(dataset, mode=SLAM, config=None, dense=False, blas_threads=1):
    """Yield one :class:`~visla_edu.filters.StepRecord` per frame, ``t = 0 .. T - 1``.

    Arguments as :func:`run_filter` (no progress bar, nothing printed); the BLAS thread limit holds while the
    generator runs, and its errors come at the first ``next()``.
    """
    flt = make_filter(dataset, mode, config, dense)
    with limit_blas_threads(blas_threads):
        while not flt.done:
            yield flt.step()


def run_filter(dataset, mode=SLAM, config=None, dense=False, progress=None, verbose=False, blas_threads=1):
    """Run a filter over the whole dataset; return a :class:`RunResult`.

    Parameters
    ----------
    dataset, mode, config, dense, verbose
        As :func:`make_filter`.
    progress : bool, optional
        Show a tqdm progress bar; by default only for runs longer than 500 frames.
    blas_threads : int or None
        BLAS threads while the filter runs (1 is fastest for its small matrices); None: numpy's own. See
        :func:`limit_blas_threads`.

    Raises
    ------
    ValueError
        As :func:`make_filter`, or a bad ``blas_threads``.
    visla_edu.filters.FilterDivergedError, numpy.linalg.LinAlgError, ArithmeticError, MemoryError
        The filter failed; the exception's ``frame`` is the frame it failed at (for :func:`.workload.divergence_hint`).
    """
    _check_blas_threads(blas_threads)
    flt = make_filter(dataset, mode, config, dense, verbose=verbose)
    config = flt.config
    flt.record_landmarks = False  # a whole run keeps no per-frame landmarks
    T = dataset.num_frames
    arrays = RunArrays(T)
    show = T > 500 if progress is None else progress
    with limit_blas_threads(blas_threads), _progress_bar(T, show, f"{dataset.name} {mode}") as bar:
        try:
            for _ in range(T):
                start = time.perf_counter()
                rec = flt.step()
                arrays.store(rec, seconds=time.perf_counter() - start)
                bar.update(1)
        except (filters.FilterDivergedError, np.linalg.LinAlgError, ArithmeticError, MemoryError) as err:
            err.frame = flt.t  # the frame it failed at, for divergence_hint (the message is unchanged)
            raise
    landmarks, landmark_cov = flt.landmark_estimates()
    return RunResult(
        name=dataset.name, mode=mode, dense=dense, time_stamps=dataset.time_stamps.copy(),
        landmarks=landmarks, landmark_cov=landmark_cov,
        dead_reckoning=motion.dead_reckon(dataset.time_stamps, dataset.twists, lag=config.imu_lag),
        config=config.to_dict(), imu_T_cam=flt.camera.imu_T_cam.copy(), **arrays.as_dict(),
        track_counts={k: int(v) for k, v in getattr(flt, "track_counts", {}).items()} if getattr(flt, "window", 0) else {},
    )


def run_smoother(dataset, mode=SMOOTH, config=None, smoother_config=None, progress=None, verbose=False,
                 blas_threads=1, smoother_settings=None):
    """Run a smoother over the whole dataset, into the same :class:`RunResult` as the filters.

    ``"smooth"``: :func:`visla_edu.smoother.smooth` started from the joint EKF's trajectory and map (kept as
    ``start_world_T_imu``); ``"window"``: :func:`visla_edu.smoother.smooth_window`; both with the filter's model.

    Parameters
    ----------
    dataset, config
        As :func:`make_filter`.
    mode : {"smooth", "window"}
    smoother_config : visla_edu.smoother.SmootherConfig, optional
        Default: :meth:`~visla_edu.smoother.SmootherConfig.from_filter_config` of ``config``.
    progress, verbose, blas_threads
        As in :func:`run_filter` (the progress bar is the EKF's).
    smoother_settings : dict, optional
        Its own settings (:data:`visla_edu.smoother.OWN_SETTINGS`, e.g. ``{"window_size": 40}``) over the
        default model; not with ``smoother_config``.

    Returns
    -------
    RunResult
        ``nis`` is NaN; ``status_counts`` hold the smoother's codes (``ignored``: repeated frames).
    """
    from visla_edu import smoother

    if mode not in SMOOTHER_MODES:
        raise ValueError(f"mode must be one of {SMOOTHER_MODES}, got {mode!r}")
    smoother.check_own_settings(mode, smoother_settings or ())
    _check_enough_data(dataset, mode)
    if config is not None and config.landmark_stride != 1:
        raise ValueError(f"landmark_stride={config.landmark_stride} thins the map of the filters (mapping, vio, slam); "
                         f"mode {mode} uses every landmark: leave landmark_stride at 1")
    if smoother_config is not None and smoother_settings:
        raise ValueError("run_smoother: give smoother_config or smoother_settings, not both")
    config = resolve_config(dataset, config or FilterConfig())
    settings = smoother_config or _smoother_settings(config, mode, smoother_settings)  # before the EKF: fail fast
    start, start_note = None, ""
    if mode == SMOOTH:
        start, start_note = _best_start(dataset, config, settings, progress, verbose, blas_threads)
        solved = smoother.smooth(dataset, start.world_T_imu, start.landmarks, start.imu_T_cam, settings, blas_threads)
    else:
        solved = smoother.smooth_window(dataset, None, _imu_T_cam(dataset, config, verbose), settings, blas_threads)
    result = _smoother_run_result(dataset, config, solved, start)
    result.notes = "\n".join(line for line in (start_note, result.notes) if line)
    result.start_mode = "" if start is None else start.mode
    return result


def _best_start(dataset, config, settings, progress, verbose, blas_threads):
    """The batch smoother's start (a RunResult, its ``mode`` naming it) and a line of the candidates' costs.

    The joint EKF, or with ``start="best"`` the lowest :func:`visla_edu.smoother.start_cost` of dead reckoning
    (no map: the smoother triangulates it), VIO and the joint EKF.
    """
    from visla_edu import smoother

    candidates = [run_filter(dataset, mode, config, progress=progress and mode == SLAM, verbose=verbose and mode == SLAM,
                             blas_threads=blas_threads) for mode in (DEADRECKON, VIO, SLAM)]
    costs = [smoother.start_cost(dataset, c.world_T_imu, None if c.mode == DEADRECKON else c.landmarks, c.imu_T_cam,
                                 settings) for c in candidates]
    best = int(np.argmin(costs)) if settings.start == "best" else 2
    text = ", ".join(f"{c.mode} {cost:.4g}" for c, cost in zip(candidates, costs))
    why = "the lowest objective" if settings.start == "best" else "start=slam; the objectives"
    return candidates[best], f"start: {candidates[best].mode} ({why} of {text})"


def _smoother_settings(config, mode, own=None):
    """The smoother's model: the filter's resolved settings, then ``own``; ValueError (e.g. noise 0) names ``mode``."""
    from visla_edu import smoother

    try:
        model = smoother.SmootherConfig.from_filter_config(config)
    except ValueError as err:
        raise ValueError(f"mode {mode} cannot use these filter settings: {err}") from None
    return replace(model, **(own or {}))


def _smoother_run_result(dataset, config, solved, start):
    """A :class:`RunResult` from a :class:`~visla_edu.smoother.SmootherResult`."""
    T = dataset.num_frames
    counts = np.zeros((T, len(STATUS_NAMES)), dtype=np.int64)
    np.add.at(counts, (dataset.observation_frames(), solved.obs_status), 1)
    seconds = solved.frame_seconds if len(solved.frame_seconds) else np.full(T, solved.timing["total"] / T)
    settings = {**config.to_dict(), **{f"smoother_{k}": v for k, v in solved.config.items()}}
    return RunResult(
        name=dataset.name, mode=solved.mode, dense=False, time_stamps=dataset.time_stamps.copy(),
        world_T_imu=solved.world_T_imu, pose_cov=solved.pose_cov, landmarks=solved.landmarks,
        landmark_cov=solved.landmark_cov,
        dead_reckoning=motion.dead_reckon(dataset.time_stamps, dataset.twists, lag=solved.config["imu_lag"]),
        nis=np.full(T, np.nan), nis_dof=np.zeros(T, dtype=np.int64), status_counts=counts, step_seconds=seconds,
        config=settings, imu_T_cam=solved.imu_T_cam, start_world_T_imu=None if start is None else start.world_T_imu,
        notes="\n".join(solved.summary().splitlines()[2:]),
    )


def evaluate_result(result, ground_truth):
    """ATE and KITTI drift of a run's estimate and of its dead reckoning; also stored in ``result.evaluation``.

    Parameters
    ----------
    result : RunResult
    ground_truth : visla_edu.dataset.GroundTruth
        Poses of the first ``n <= T`` frames; those frames are compared.

    Returns
    -------
    dict of str to visla_edu.metrics.TrajectoryEvaluation
        ``{"estimate": ..., "dead_reckoning": ...}`` and, for the batch smoother, ``"start"``.
    """
    truth = ground_truth.world_T_imu
    evaluations = {"estimate": metrics.evaluate(result.world_T_imu, truth),
                   "dead_reckoning": metrics.evaluate(result.dead_reckoning, truth)}
    if result.start_world_T_imu is not None:
        evaluations["start"] = metrics.evaluate(result.start_world_T_imu, truth)
    result.evaluation = {"ground_truth_source": ground_truth.source or "simulation"}
    for who, evaluation in evaluations.items():
        result.evaluation.update(evaluation.as_dict(prefix=f"{who}_"))
    return evaluations


class _NoBar:
    def update(self, n):
        pass


def _progress_bar(total, show, desc):
    if not show:
        return contextlib.nullcontext(_NoBar())
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="frame")

