"""One driver for every filter mode: a step iterator and a whole-run function.

:func:`make_filter` builds a mode by name (:data:`MODES`, from :mod:`visla_edu.codes`),
:func:`iterate_filter` steps it, :func:`run_filter` runs it to the end into a
:class:`RunResult` (per-frame arrays in a :class:`RunArrays`), :func:`save_result` and
:func:`load_result` write and read it (atomically, :func:`visla_edu._files.atomic_write`). How
the driver runs is in its arguments, not in the filter's settings: the BLAS thread limit
(:func:`limit_blas_threads`) and the progress bar. :func:`run_smoother` runs the batch or the
sliding-window smoother (:mod:`visla_edu.smoother`) into the same :class:`RunResult`.
:mod:`visla_edu.workload` says what a run will cost before it starts and names the likely cause
when one fails.

>>> from visla_edu import data, run
>>> ds = data.load("sim-tiny")
>>> result = run.run_filter(ds, mode="slam", progress=False)
>>> result.world_T_imu.shape == (ds.num_frames, 4, 4)
True
"""

import contextlib
import time
from dataclasses import dataclass, field

import numpy as np

from visla_edu import data, diagnostics, filters, metrics, motion
from visla_edu._blas import check_blas_threads as _check_blas_threads
from visla_edu._blas import limit_blas_threads
from visla_edu._files import atomic_write, expand_user, format_bytes
from visla_edu.camera import StereoCamera
from visla_edu.codes import (DEADRECKON, MAPPING, MODES, OBS_GATED, OBS_IGNORED, OBS_NO_DEPTH, OBS_USED, SLAM, SMOOTH,
                             SMOOTHER_MODES, STATUS_NAMES, VIO, WINDOW)
from visla_edu.filters import FilterConfig

__all__ = ["MODES", "RunArrays", "RunResult", "limit_blas_threads", "make_filter", "resolve_config", "iterate_filter",
           "run_filter", "run_smoother", "evaluate_result", "save_result", "load_result"]

#: The filter class of each mode but ``"slam"`` (``filters.JointSlam`` takes ``dense``).
_MODE_CLASSES = {DEADRECKON: filters.DeadReckoning, MAPPING: filters.LandmarkMapping,
                 VIO: filters.VisualInertialOdometry}


def make_filter(dataset, mode=SLAM, config=None, dense=False, verbose=False):
    """Build the filter object for ``mode`` with the settings and calibration resolved.

    Settings left at ``"auto"`` (the velocity noise, the IMU lag, the extrinsic correction)
    are measured from the data first (:func:`resolve_config`).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"deadreckon", "mapping", "vio", "slam"}
        One of :data:`visla_edu.codes.MODES`.
    config : visla_edu.filters.FilterConfig, optional
    dense : bool
        Textbook joint EKF over all (strided) landmarks; only for ``mode="slam"``.
    verbose : bool
        Print the evidence of an automatic extrinsic correction.

    Returns
    -------
    filters.DeadReckoning, filters.LandmarkMapping, filters.VisualInertialOdometry or filters.JointSlam
        Its ``config`` is the resolved one (no ``"auto"`` left but ``extrinsic_correction``).

    Raises
    ------
    ValueError
        A bad mode, ``dense`` without ``"slam"``, a dataset without observations for a mode
        that needs them, or a dataset with an implausible calibration
        (:func:`visla_edu.data.calibration_problems`: in-memory datasets are held to the
        ranges the loader enforces on files, since the filter would silently turn an absurd
        focal length, baseline or extrinsic into inf/NaN covariances or a garbage map).
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if dense and mode != SLAM:
        raise ValueError(f"dense=True is the textbook joint filter and needs mode='slam', got mode={mode!r}")
    problems = data.calibration_problems(dataset)
    if problems:
        raise ValueError(f"cannot run the filter: {problems[0]}")
    _check_enough_data(dataset, mode)
    config = resolve_config(dataset, config or FilterConfig())
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(dataset, config.extrinsic_correction)
    if verbose and evidence:
        print(evidence)
    camera = StereoCamera(dataset.K, dataset.b, imu_T_cam)
    if mode == SLAM:
        return filters.JointSlam(dataset, camera, config, dense=dense)
    return _MODE_CLASSES[mode](dataset, camera, config)


def _check_enough_data(dataset, mode):
    """Refuse a mode the dataset cannot feed.

    Every mode but dead reckoning needs observations; the smoothers need at least two frames
    (one motion factor).
    """
    if mode == DEADRECKON:
        return
    if dataset.num_observations == 0:
        raise ValueError(f"mode {mode} needs stereo observations and {dataset.name!r} has none (every feature is -1, "
                         "not observed); use mode deadreckon")
    if mode in SMOOTHER_MODES and dataset.num_frames < 2:
        raise ValueError(f"mode {mode} needs at least 2 frames, {dataset.name!r} has {dataset.num_frames}")


def resolve_config(dataset, config):
    """``config`` with its ``"auto"`` settings measured from ``dataset``.

    The velocity noise and the IMU lag come from :func:`visla_edu.diagnostics.calibrate`
    (cached by the data's content); ``extrinsic_correction="auto"`` stays as it is and is
    resolved with the camera (:func:`visla_edu.diagnostics.resolve_extrinsics`, the same
    calibration).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    config : visla_edu.filters.FilterConfig

    Returns
    -------
    visla_edu.filters.FilterConfig
        The same object when nothing was ``"auto"``.
    """
    if config.resolved:
        return config
    return config.resolve(diagnostics.calibrate(dataset))


def iterate_filter(dataset, mode=SLAM, config=None, dense=False, blas_threads=1):
    """Yield one :class:`~visla_edu.filters.StepRecord` per frame.

    Parameters
    ----------
    dataset, mode, config, dense, blas_threads
        As in :func:`run_filter` (no progress bar, nothing printed); the BLAS thread limit
        holds while the generator runs.

    Yields
    ------
    visla_edu.filters.StepRecord
        One per frame, ``t = 0 .. T - 1``.

    Raises
    ------
    ValueError, visla_edu.filters.FilterDivergedError, numpy.linalg.LinAlgError
        As :func:`run_filter`; being a generator, it raises them at the first ``next()``,
        not when called.
    """
    flt = make_filter(dataset, mode, config, dense)
    with limit_blas_threads(blas_threads):
        while not flt.done:
            yield flt.step()


@dataclass
class RunResult:
    """Everything a whole run produced.

    Attributes
    ----------
    name, mode : str
    dense : bool
    time_stamps : ndarray, shape (T,)
    world_T_imu : ndarray, shape (T, 4, 4)
        ``world`` is the IMU frame at the first time stamp.
    pose_cov : ndarray, shape (T, 6, 6)
    landmarks : ndarray, shape (M, 3)
        NaN for landmarks never initialised.
    landmark_cov : ndarray, shape (M, 3, 3)
    dead_reckoning : ndarray, shape (T, 4, 4)
        The IMU-only trajectory, for comparison.
    nis, nis_dof : ndarray, shape (T,)
    status_counts : ndarray of int, shape (T, 6)
        Observations per frame by status (:data:`visla_edu.codes.STATUS_NAMES`).
    step_seconds : ndarray, shape (T,)
    config : dict
    imu_T_cam : ndarray, shape (4, 4)
        The calibration used (after any correction).
    evaluation : dict
        Figures against ground truth, filled by :func:`evaluate_result` (empty without):
        ``estimate_<name>``, ``dead_reckoning_<name>`` (and for the batch smoother
        ``start_<name>``, the EKF it started from) for every field of
        :class:`visla_edu.metrics.TrajectoryEvaluation`, and ``ground_truth_source``.
    start_world_T_imu : ndarray, shape (T, 4, 4), or None
        Batch smoother: the joint EKF's trajectory it started from (None otherwise).
    notes : str
        Lines the mode adds to :meth:`summary` (the smoothers' iterations and rejections).
    """

    name: str
    mode: str
    dense: bool
    time_stamps: np.ndarray
    world_T_imu: np.ndarray
    pose_cov: np.ndarray
    landmarks: np.ndarray
    landmark_cov: np.ndarray
    dead_reckoning: np.ndarray
    nis: np.ndarray
    nis_dof: np.ndarray
    status_counts: np.ndarray
    step_seconds: np.ndarray
    config: dict = field(default_factory=dict)
    imu_T_cam: np.ndarray = None
    evaluation: dict = field(default_factory=dict)
    start_world_T_imu: np.ndarray = None
    notes: str = ""

    def status_totals(self):
        """Total observations by status name, e.g. ``{"used": ..., "gated": ...}``."""
        return dict(zip(STATUS_NAMES, self.status_counts.sum(axis=0).tolist()))

    def summary(self):
        """A few lines a student can read: mode, counts, timing."""
        totals = self.status_totals()
        lines = [
            f"{self.name}: mode {self.mode}{' (dense)' if self.dense else ''}, {len(self.time_stamps)} frames, "
            f"{int(np.isfinite(self.landmarks[:, 0]).sum())} of {len(self.landmarks)} landmarks mapped",
            "observations: " + ", ".join(f"{k} {v}" for k, v in totals.items() if v),
        ]
        if totals["used"] + totals["gated"]:
            lines.append(f"gated as outliers: {100 * metrics.gated_share(totals):.2f}% of the observations the gate "
                         "tested (gated / (used + gated))")
        if self.notes:
            lines.append(self.notes)
        else:
            lines.append(f"time: {self.step_seconds.sum():.2f} s, median step "
                         f"{1e3 * np.median(self.step_seconds):.2f} ms")
        return "\n".join(lines)


def run_filter(dataset, mode=SLAM, config=None, dense=False, progress=None, verbose=False, blas_threads=1):
    """Run a filter over the whole dataset.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"deadreckon", "mapping", "vio", "slam"}
        One of :data:`visla_edu.codes.MODES`.
    config : visla_edu.filters.FilterConfig, optional
    dense : bool
        Textbook dense joint filter (``mode="slam"`` only).
    progress : bool, optional
        Show a tqdm progress bar; by default only for runs longer than 500 frames.
    verbose : bool
        Print the evidence of an automatic extrinsic correction.
    blas_threads : int or None
        BLAS threads while the filter runs (the per-step matrices are small, so 1 is
        fastest); None leaves numpy's setting alone. See :func:`limit_blas_threads`.

    Returns
    -------
    RunResult

    Raises
    ------
    ValueError
        As :func:`make_filter` (bad mode or settings, implausible calibration, no
        observations for a mode that needs them), or a bad ``blas_threads``.
    visla_edu.filters.FilterDivergedError, numpy.linalg.LinAlgError, ArithmeticError, MemoryError
        The filter failed; the exception's ``frame`` attribute is the frame it failed at
        (see :func:`visla_edu.workload.divergence_hint`).
    """
    _check_blas_threads(blas_threads)
    config = config or FilterConfig()
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
    )


def run_smoother(dataset, mode=SMOOTH, config=None, smoother_config=None, progress=None, verbose=False,
                 blas_threads=1, smoother_settings=None):
    """Run a smoother over the whole dataset, into the same :class:`RunResult` as the filters.

    ``"smooth"``: the batch smoother (:func:`visla_edu.smoother.smooth`) started from the joint
    EKF's trajectory and map (:func:`run_filter` with ``"slam"``, kept as
    ``start_world_T_imu``). ``"window"``: the fixed-lag sliding window
    (:func:`visla_edu.smoother.smooth_window`). Both use the filter's model: the resolved
    ``config`` (velocity noise and lag measured from the data when ``"auto"``) and its camera
    calibration.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"smooth", "window"}
        One of :data:`visla_edu.codes.SMOOTHER_MODES`.
    config : visla_edu.filters.FilterConfig, optional
    smoother_config : visla_edu.smoother.SmootherConfig, optional
        Default: :meth:`~visla_edu.smoother.SmootherConfig.from_filter_config` of ``config``.
    progress, verbose, blas_threads
        As in :func:`run_filter` (the progress bar is the EKF's).
    smoother_settings : dict, optional
        Smoother settings of its own (:data:`visla_edu.smoother.OWN_SETTINGS`, e.g.
        ``{"window_size": 40}``) over the default model; not with ``smoother_config``.

    Returns
    -------
    RunResult
        ``nis`` is NaN (a smoother has no innovations); ``status_counts`` count per frame the
        observations the smoother used (``used``), rejected as outliers (``gated``), could not
        use (``no depth``) or left out (``ignored``: landmarks dropped, repeated frames).
    """
    from visla_edu import smoother

    if mode not in SMOOTHER_MODES:
        raise ValueError(f"mode must be one of {SMOOTHER_MODES}, got {mode!r}")
    _check_enough_data(dataset, mode)
    if config is not None and config.landmark_stride != 1:
        raise ValueError(f"landmark_stride={config.landmark_stride} thins the map of the filters (mapping, vio, slam); "
                         f"mode {mode} uses every landmark: leave landmark_stride at 1")
    if smoother_config is not None and smoother_settings:
        raise ValueError("run_smoother: give smoother_config or smoother_settings, not both")
    config = resolve_config(dataset, config or FilterConfig())
    settings = smoother_config or _smoother_settings(config, mode, smoother_settings)  # before the EKF: fail fast
    start = None
    if mode == SMOOTH:
        start = run_filter(dataset, SLAM, config, progress=progress, verbose=verbose, blas_threads=blas_threads)
        imu_T_cam = start.imu_T_cam
    else:
        imu_T_cam, evidence = diagnostics.resolve_extrinsics(dataset, config.extrinsic_correction)
        if verbose and evidence:
            print(evidence)
    if mode == SMOOTH:
        solved = smoother.smooth(dataset, start.world_T_imu, start.landmarks, imu_T_cam, settings, blas_threads)
    else:
        solved = smoother.smooth_window(dataset, None, imu_T_cam, settings, blas_threads)
    return _smoother_run_result(dataset, config, solved, start)


def _smoother_settings(config, mode, own=None):
    """The smoother's model from the filter's resolved settings, or a ValueError saying where it came from.

    Parameters
    ----------
    config : visla_edu.filters.FilterConfig
        Resolved.
    mode : str
        Names the mode in the message.
    own : dict, optional
        Settings of the smoother's own (:data:`visla_edu.smoother.OWN_SETTINGS`).

    Returns
    -------
    visla_edu.smoother.SmootherConfig

    Raises
    ------
    ValueError
        A filter setting the smoother cannot take (e.g. a velocity noise of 0, which the
        filters accept and the smoother's motion factors cannot weigh), or an ``own`` name
        that is not one of the smoother's own settings or that ``mode`` does not use.
    """
    from visla_edu import smoother

    unknown = sorted(set(own or ()) - set(smoother.OWN_SETTINGS))
    if unknown:
        raise ValueError(f"smoother_settings: {unknown} are not the smoother's own settings; they are "
                         f"{', '.join(smoother.OWN_SETTINGS)} (noise and lag come from the filter's config)")
    smoother.check_mode_settings(mode, own or ())
    smoother.SmootherConfig(**(own or {}))  # a bad value of its own is named as the smoother's
    try:
        return smoother.SmootherConfig.from_filter_config(config, **(own or {}))
    except ValueError as err:
        raise ValueError(f"mode {mode} cannot use these filter settings: {err}") from None


#: Smoother observation status (:data:`visla_edu.smoother.STATUS_NAMES`) -> the filters' codes.
_SMOOTHER_STATUS = {"used": OBS_USED, "rejected": OBS_GATED, "nonpositive_disparity": OBS_NO_DEPTH,
                    "repeated_frame": OBS_IGNORED, "landmark_dropped": OBS_IGNORED}


def _smoother_run_result(dataset, config, solved, start):
    """A :class:`RunResult` from a :class:`~visla_edu.smoother.SmootherResult`."""
    from visla_edu import smoother

    T = dataset.num_frames
    codes = np.array([_SMOOTHER_STATUS[name] for name in smoother.STATUS_NAMES])[solved.obs_status]
    counts = np.zeros((T, len(STATUS_NAMES)), dtype=np.int64)
    np.add.at(counts, (dataset.observation_frames(), codes), 1)
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
    """ATE and KITTI drift of a run's estimate and of its dead reckoning against the ground truth.

    Stores the figures in ``result.evaluation`` (so :func:`save_result` writes them).

    Parameters
    ----------
    result : RunResult
    ground_truth : visla_edu.dataset.GroundTruth
        Poses of the first ``n <= T`` frames; those frames are compared.

    Returns
    -------
    dict of str to visla_edu.metrics.TrajectoryEvaluation
        ``{"estimate": ..., "dead_reckoning": ...}`` and, for the batch smoother, ``"start"``
        (the joint EKF it started from).
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


class RunArrays:
    """Per-frame arrays of a run, filled one :class:`~visla_edu.filters.StepRecord` at a time.

    The whole-run driver (:func:`run_filter`) and the stepper (:class:`visla_edu.stepper.Stepper`)
    both keep their per-frame figures here.

    Parameters
    ----------
    num_frames : int
        ``T``.

    Attributes
    ----------
    world_T_imu : ndarray, shape (T, 4, 4)
    pose_cov : ndarray, shape (T, 6, 6)
    nis : ndarray, shape (T,)
        NaN where there was no update.
    nis_dof : ndarray of int, shape (T,)
    status_counts : ndarray of int, shape (T, 6)
        Observations per frame by status (:data:`visla_edu.codes.STATUS_NAMES`).
    step_seconds : ndarray, shape (T,)
        Wall time of each filter step.
    """

    #: The arrays, in the order :class:`RunResult` lists them.
    FIELDS = ("world_T_imu", "pose_cov", "nis", "nis_dof", "status_counts", "step_seconds")

    def __init__(self, num_frames):
        T = num_frames
        self.world_T_imu = np.empty((T, 4, 4))
        self.pose_cov = np.empty((T, 6, 6))
        self.nis = np.full(T, np.nan)
        self.nis_dof = np.zeros(T, dtype=np.int64)
        self.status_counts = np.zeros((T, len(STATUS_NAMES)), dtype=np.int64)
        self.step_seconds = np.zeros(T)

    def store(self, rec, seconds=0.0):
        """Write frame ``rec.t``'s figures (``seconds``: wall time of its step)."""
        t = rec.t
        self.world_T_imu[t] = rec.world_T_imu
        self.pose_cov[t] = rec.pose_cov
        self.nis[t] = rec.nis
        self.nis_dof[t] = rec.nis_dof
        self.status_counts[t] = np.bincount(rec.status, minlength=len(STATUS_NAMES))
        self.step_seconds[t] = seconds

    def as_dict(self):
        """``{name: array}`` of :attr:`FIELDS` (the arrays themselves, not copies)."""
        return {name: getattr(self, name) for name in self.FIELDS}


class _NoBar:
    def update(self, n):
        pass


@contextlib.contextmanager
def _progress_bar(total, show, desc):
    if not show:
        yield _NoBar()
        return
    from tqdm.auto import tqdm

    with tqdm(total=total, desc=desc, unit="frame") as bar:
        yield bar


def save_result(result, path):
    """Save a :class:`RunResult` to ``path`` (npz), atomically; return the path written.

    Keys: ``time_stamps`` (T,), ``world_T_imu`` (T, 4, 4), ``landmarks`` (M, 3) (NaN where never
    initialised), ``pose_cov``, ``landmark_cov``, ``dead_reckoning``, ``nis``, ``nis_dof``,
    ``status_counts``, ``step_seconds``, ``imu_T_cam``, ``name``, ``mode``, ``dense`` and
    ``config_<name>`` for every setting used (a setting of None is stored as an empty array,
    so the file loads without pickle; files of earlier versions hold ``blas_threads`` so), and
    ``eval_<name>`` for the figures against ground truth (:attr:`RunResult.evaluation`),
    ``notes`` (the smoothers' summary; empty for the filters) and, from the batch smoother,
    ``start_world_T_imu``.

    Parameters
    ----------
    result : RunResult
    path : str or os.PathLike
        ``.npz`` is appended if missing (as ``numpy.savez`` does). The file is written to a
        temporary file first and then renamed (:func:`visla_edu._files.atomic_write`), so an
        interrupted save leaves a previous result there intact.

    Returns
    -------
    pathlib.Path
        The absolute path written.
    """
    path = expand_user(path)
    if path.suffix.lower() != ".npz":
        path = path.with_name(path.name + ".npz")
    arrays = {k: v for k, v in vars(result).items() if k not in ("config", "evaluation") and v is not None}
    arrays.update({f"config_{k}": np.zeros(0) if v is None else v for k, v in result.config.items()})
    arrays.update({f"eval_{k}": v for k, v in result.evaluation.items()})
    with atomic_write(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path.resolve()


def _setting(array):
    """A saved setting back: None (empty), a number or string, or a per-axis tuple."""
    if array.size == 0:
        return None
    return array.item() if array.size == 1 else tuple(array.tolist())


def load_result(path):
    """Load a :class:`RunResult` written by :func:`save_result`.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz`` that :func:`save_result` (or ``visla-edu run --out``) wrote.

    Returns
    -------
    RunResult

    Raises
    ------
    FileNotFoundError, ValueError, KeyError
        As :func:`numpy.load` for a missing or broken file, or a file without the keys a
        result has.
    """
    with np.load(path, allow_pickle=False) as f:
        config = {k[len("config_"):]: _setting(f[k]) for k in f.files if k.startswith("config_")}
        evaluation = {k[len("eval_"):]: f[k].item() for k in f.files if k.startswith("eval_")}
        fields = {k: f[k] for k in f.files if not k.startswith(("config_", "eval_"))}
    for key in ("name", "mode", "notes"):
        if key in fields:
            fields[key] = str(fields[key])
    fields["dense"] = bool(fields["dense"])
    return RunResult(config=config, evaluation=evaluation, **fields)
