"""One driver for every filter mode: a step iterator and a whole-run function.

:func:`make_filter` builds a mode by name (:data:`MODES`, from :mod:`visla_edu.codes`),
:func:`iterate_filter` steps it, :func:`run_filter` runs it to the end into a
:class:`RunResult` (per-frame arrays in a :class:`RunArrays`), :func:`save_result` and
:func:`load_result` write and read it. How the driver runs is in its arguments, not in the
filter's settings: the BLAS thread limit (:func:`limit_blas_threads`) and the progress bar.

>>> from visla_edu import data, run
>>> ds = data.load("sim-tiny")
>>> result = run.run_filter(ds, mode="slam", progress=False)
>>> result.world_T_imu.shape == (ds.num_frames, 4, 4)
True
"""

import contextlib
import functools
import time
from dataclasses import dataclass, field

import numpy as np

from visla_edu import diagnostics, filters, metrics, motion
from visla_edu.camera import StereoCamera
from visla_edu.codes import DEADRECKON, MAPPING, MODES, SLAM, STATUS_NAMES, VIO
from visla_edu.filters import FilterConfig

__all__ = ["MODES", "RunArrays", "RunResult", "limit_blas_threads", "make_filter", "iterate_filter", "run_filter",
           "evaluate_result", "save_result", "load_result"]

#: The filter class of each mode but ``"slam"`` (``filters.JointSlam`` takes ``dense``).
_MODE_CLASSES = {DEADRECKON: filters.DeadReckoning, MAPPING: filters.LandmarkMapping,
                 VIO: filters.VisualInertialOdometry}


def limit_blas_threads(n):
    """Context manager limiting the BLAS threads of numpy and scipy to ``n`` (None: leave as is).

    The filter's per-step matrices are a few hundred rows at most; on a 2-core machine a
    multi-threaded BLAS spends more time synchronising than computing, so the driver runs
    with one thread unless told otherwise (the ``blas_threads`` argument of
    :func:`run_filter`, :func:`iterate_filter` and :class:`visla_edu.stepper.Stepper`).
    The BLAS libraries are looked up once per process: a lookup costs about 1.5 ms, as much
    as a filter step, and the stepper enters the limit at every move.

    Parameters
    ----------
    n : int or None
        Threads, >= 1.
    """
    if _check_blas_threads(n) is None:
        return contextlib.nullcontext()
    return _blas_controller().limit(limits=int(n), user_api="blas")


def _check_blas_threads(n):
    if n is not None and (isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1):
        raise ValueError(f"blas_threads must be a positive integer or None, got {n!r}")
    return n


@functools.cache
def _blas_controller():
    """The BLAS libraries loaded in this process (numpy's and scipy's), looked up once."""
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS before the lookup)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def make_filter(dataset, mode=SLAM, config=None, dense=False, verbose=False):
    """Build the filter object for ``mode`` with the corrected calibration.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"deadreckon", "mapping", "vio", "slam"}
        One of :data:`visla_edu.codes.MODES`.
    config : visla_edu.filters.FilterConfig, optional
    dense : bool
        Textbook joint EKF over all (strided) landmarks; only for ``mode="slam"``.
    verbose : bool
        Print the extrinsic diagnostic's evidence when a correction is applied.

    Returns
    -------
    filters.DeadReckoning, filters.LandmarkMapping, filters.VisualInertialOdometry or filters.JointSlam
    """
    config = config or FilterConfig()
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if dense and mode != SLAM:
        raise ValueError(f"dense=True is the textbook joint filter and needs mode='slam', got mode={mode!r}")
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(dataset, config.extrinsic_correction)
    if verbose and evidence:
        print(evidence)
    camera = StereoCamera(dataset.K, dataset.b, imu_T_cam)
    if mode == SLAM:
        return filters.JointSlam(dataset, camera, config, dense=dense)
    return _MODE_CLASSES[mode](dataset, camera, config)


def iterate_filter(dataset, mode=SLAM, config=None, dense=False, blas_threads=1):
    """Yield one :class:`~visla_edu.filters.StepRecord` per frame.

    Parameters are those of :func:`run_filter`; the BLAS thread limit holds while the
    generator runs.
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
        ``estimate_<name>`` and ``dead_reckoning_<name>`` for every field of
        :class:`visla_edu.metrics.TrajectoryEvaluation`, and ``ground_truth_source``.
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

    def status_totals(self):
        """Total observations by status name, e.g. ``{"used": ..., "gated": ...}``."""
        return dict(zip(STATUS_NAMES, self.status_counts.sum(axis=0).tolist()))

    def summary(self):
        """A few lines a student can read: mode, counts, timing."""
        totals = self.status_totals()
        seen = sum(v for k, v in totals.items() if k != "ignored")
        lines = [
            f"{self.name}: mode {self.mode}{' (dense)' if self.dense else ''}, {len(self.time_stamps)} frames, "
            f"{int(np.isfinite(self.landmarks[:, 0]).sum())} of {len(self.landmarks)} landmarks mapped",
            "observations: " + ", ".join(f"{k} {v}" for k, v in totals.items() if v),
        ]
        if seen:
            lines.append(f"gated as outliers: {100 * totals['gated'] / seen:.2f}% of observations")
        lines.append(f"time: {self.step_seconds.sum():.2f} s, median step {1e3 * np.median(self.step_seconds):.2f} ms")
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
    """
    _check_blas_threads(blas_threads)
    config = config or FilterConfig()
    flt = make_filter(dataset, mode, config, dense, verbose=verbose)
    T = dataset.num_frames
    arrays = RunArrays(T)
    show = T > 500 if progress is None else progress
    with limit_blas_threads(blas_threads), _progress_bar(T, show, f"{dataset.name} {mode}") as bar:
        for _ in range(T):
            start = time.perf_counter()
            rec = flt.step()
            arrays.store(rec, seconds=time.perf_counter() - start)
            bar.update(1)
    landmarks, landmark_cov = flt.landmark_estimates()
    return RunResult(
        name=dataset.name, mode=mode, dense=dense, time_stamps=dataset.time_stamps.copy(),
        landmarks=landmarks, landmark_cov=landmark_cov,
        dead_reckoning=motion.dead_reckon(dataset.time_stamps, dataset.twists, lag=config.imu_lag),
        config=config.to_dict(), imu_T_cam=flt.camera.imu_T_cam.copy(), **arrays.as_dict(),
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
        ``{"estimate": ..., "dead_reckoning": ...}``.
    """
    truth = ground_truth.world_T_imu
    evaluations = {"estimate": metrics.evaluate(result.world_T_imu, truth),
                   "dead_reckoning": metrics.evaluate(result.dead_reckoning, truth)}
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
    """Save a :class:`RunResult` to ``path`` (npz).

    Keys: ``time_stamps`` (T,), ``world_T_imu`` (T, 4, 4), ``landmarks`` (M, 3) (NaN where never
    initialised), ``pose_cov``, ``landmark_cov``, ``dead_reckoning``, ``nis``, ``nis_dof``,
    ``status_counts``, ``step_seconds``, ``imu_T_cam``, ``name``, ``mode``, ``dense`` and
    ``config_<name>`` for every setting used (a setting of None is stored as an empty array,
    so the file loads without pickle; files of earlier versions hold ``blas_threads`` so), and
    ``eval_<name>`` for the figures against ground truth (:attr:`RunResult.evaluation`).
    """
    arrays = {k: v for k, v in vars(result).items() if k not in ("config", "evaluation")}
    arrays.update({f"config_{k}": np.zeros(0) if v is None else v for k, v in result.config.items()})
    arrays.update({f"eval_{k}": v for k, v in result.evaluation.items()})
    np.savez_compressed(path, **arrays)


def load_result(path):
    """Load a :class:`RunResult` written by :func:`save_result`."""
    with np.load(path, allow_pickle=False) as f:
        config = {k[len("config_"):]: (None if f[k].size == 0 else f[k].item())
                  for k in f.files if k.startswith("config_")}
        evaluation = {k[len("eval_"):]: f[k].item() for k in f.files if k.startswith("eval_")}
        fields = {k: f[k] for k in f.files if not k.startswith(("config_", "eval_"))}
    for key in ("name", "mode"):
        fields[key] = str(fields[key])
    fields["dense"] = bool(fields["dense"])
    return RunResult(config=config, evaluation=evaluation, **fields)
