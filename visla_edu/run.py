"""One driver for every filter mode: a step iterator and a whole-run function.

:func:`make_filter` builds a mode by name (:data:`MODES`, from :mod:`visla_edu.codes`),
:func:`iterate_filter` steps it, :func:`run_filter` runs it to the end into a
:class:`RunResult` (per-frame arrays in a :class:`RunArrays`), :func:`save_result` and
:func:`load_result` write and read it (atomically, :func:`visla_edu._files.atomic_write`). How
the driver runs is in its arguments, not in the filter's settings: the BLAS thread limit
(:func:`limit_blas_threads`) and the progress bar. :func:`estimate_work` says what a run will cost
before it starts; :func:`divergence_hint` names the likely cause when a run fails.

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
from pathlib import Path

import numpy as np

from visla_edu import data, diagnostics, filters, metrics, motion
from visla_edu._files import atomic_write, format_bytes
from visla_edu.camera import StereoCamera
from visla_edu.codes import DEADRECKON, MAPPING, MODES, SLAM, STATUS_NAMES, VIO
from visla_edu.filters import FilterConfig

__all__ = ["MODES", "RunArrays", "RunResult", "WorkEstimate", "limit_blas_threads", "make_filter", "iterate_filter",
           "run_filter", "evaluate_result", "save_result", "load_result", "estimate_work", "divergence_hint"]

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

    Raises
    ------
    ValueError
        A bad mode, or a dataset with an implausible calibration
        (:func:`visla_edu.data.calibration_problems`: in-memory datasets are held to the
        ranges the loader enforces on files, since the filter would silently turn an absurd
        focal length, baseline or extrinsic into inf/NaN covariances or a garbage map).
    """
    config = config or FilterConfig()
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if dense and mode != SLAM:
        raise ValueError(f"dense=True is the textbook joint filter and needs mode='slam', got mode={mode!r}")
    problems = data.calibration_problems(dataset)
    if problems:
        raise ValueError(f"cannot run the filter: {problems[0]}")
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

    Raises
    ------
    visla_edu.filters.FilterDivergedError, numpy.linalg.LinAlgError
        The filter failed; the exception's ``frame`` attribute is the frame it failed at
        (see :func:`divergence_hint`).
    """
    _check_blas_threads(blas_threads)
    config = config or FilterConfig()
    flt = make_filter(dataset, mode, config, dense, verbose=verbose)
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
    """Save a :class:`RunResult` to ``path`` (npz), atomically; return the path written.

    Keys: ``time_stamps`` (T,), ``world_T_imu`` (T, 4, 4), ``landmarks`` (M, 3) (NaN where never
    initialised), ``pose_cov``, ``landmark_cov``, ``dead_reckoning``, ``nis``, ``nis_dof``,
    ``status_counts``, ``step_seconds``, ``imu_T_cam``, ``name``, ``mode``, ``dense`` and
    ``config_<name>`` for every setting used (a setting of None is stored as an empty array,
    so the file loads without pickle; files of earlier versions hold ``blas_threads`` so), and
    ``eval_<name>`` for the figures against ground truth (:attr:`RunResult.evaluation`).

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
    path = Path(path).expanduser()
    if path.suffix.lower() != ".npz":
        path = path.with_name(path.name + ".npz")
    arrays = {k: v for k, v in vars(result).items() if k not in ("config", "evaluation")}
    arrays.update({f"config_{k}": np.zeros(0) if v is None else v for k, v in result.config.items()})
    arrays.update({f"eval_{k}": v for k, v in result.evaluation.items()})
    with atomic_write(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path.resolve()


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


#: Cost model of the filter's updates, fitted on the 2-core development machine with one BLAS
#: thread (``benchmarks/bench_work_estimate.py`` prints estimates against measurements). A joint
#: update with a D-dimensional state and m observation rows costs ``D^2 (a + b m)`` seconds (the
#: covariance update ``Sigma -= A^T A`` streams the D x D covariance and multiplies (D, m) by
#: (m, D)); factorising and assembling an m x m innovation covariance ``c m^3 + d m^2``; every
#: frame some milliseconds more. Estimated/measured time on 40-frame runs (a loaded 2-core
#: machine): 0.7 to 2.5 for dense SLAM (strides 2 to 8, simulated and dataset 03), 0.8 for
#: active-set SLAM and 2.8 for VIO with about 700 landmarks in view; dense SLAM on every
#: landmark of dataset 03 (D = 15321) measured 2.2 s a frame against 3.3 s estimated.
SECONDS_PER_ENTRY = 1e-8  # a
SECONDS_PER_ENTRY_ROW = 2e-11  # b
SECONDS_PER_ROW_CUBED = 4e-11  # c
SECONDS_PER_ROW_SQUARED = 2e-8  # d
SECONDS_PER_FRAME = 5e-3  # the rest of a step (prediction, gating, bookkeeping)
#: ``visla-edu run`` refuses a run estimated past these limits unless given ``--force``.
WORK_LIMIT_BYTES = 2 * 2**30
WORK_LIMIT_SECONDS = 15 * 60


@dataclass
class WorkEstimate:
    """What a run will cost, estimated from the observations before it starts (:func:`estimate_work`).

    Attributes
    ----------
    mode : str
    dense : bool
    state_dim : int
        Largest state: ``6 + 3 n`` with n the landmarks in the joint state (SLAM), else 6.
    frames : int
    max_rows : int
        Most observation rows of one update (3 per observation in SLAM, 4 in VIO).
    peak_bytes : int
        The largest matrices at once: in SLAM the covariance and the same-size product of its
        update (``2 D^2 8`` bytes) and the (D, m) and (m, m) blocks of the update, in VIO the
        innovation covariance and its factor.
    seconds : float
        See :data:`SECONDS_PER_ENTRY`.
    """

    mode: str
    dense: bool
    state_dim: int
    frames: int
    max_rows: int
    peak_bytes: int
    seconds: float

    def over_limits(self, max_bytes=None, max_seconds=None):
        """What exceeds the limits (default :data:`WORK_LIMIT_BYTES`, :data:`WORK_LIMIT_SECONDS`), as phrases.

        Empty when the run is within them.
        """
        max_bytes = WORK_LIMIT_BYTES if max_bytes is None else max_bytes
        max_seconds = WORK_LIMIT_SECONDS if max_seconds is None else max_seconds
        over = []
        if self.peak_bytes > max_bytes:
            over.append(f"{format_bytes(self.peak_bytes)} of memory (limit {format_bytes(max_bytes)})")
        if self.seconds > max_seconds:
            over.append(f"about {_duration(self.seconds)} (limit {_duration(max_seconds)})")
        return over

    def summary(self):
        """One line: the largest state and update, memory and time."""
        what = f"{self.mode}{' (dense)' if self.dense else ''}"
        return (f"{what}: states up to {self.state_dim} dimensions, updates up to {self.max_rows} rows: about "
                f"{format_bytes(self.peak_bytes)} of memory and {_duration(self.seconds)} for {self.frames} frames "
                "(estimate)")


def estimate_work(dataset, mode=SLAM, config=None, dense=False):
    """Estimate the memory and time of ``run_filter(dataset, mode, config, dense=dense)``.

    The dense filter carries every (strided) landmark; the active set those whose track
    spans the frame; both update with 3 rows per observation. VIO solves one 4-row block
    per observation; mapping and dead reckoning work in 3x3 and 6x6 blocks (cheap).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : str
    config : visla_edu.filters.FilterConfig, optional
        Its ``landmark_stride`` decides the landmarks used.
    dense : bool

    Returns
    -------
    WorkEstimate
    """
    config = config or FilterConfig()
    T = max(1, dataset.num_frames)
    in_stride = dataset.obs_ids % config.landmark_stride == 0
    per_frame = np.bincount(dataset.observation_frames()[in_stride], minlength=T).astype(float)
    if mode == SLAM:
        landmarks = _landmarks_in_state(dataset, config.landmark_stride, dense)
        D, m = 6 + 3 * landmarks, 3 * per_frame
        seconds = np.sum(D * D * (SECONDS_PER_ENTRY + SECONDS_PER_ENTRY_ROW * m) + SECONDS_PER_ROW_CUBED * m**3)
        peak = 16 * float(D.max()) ** 2 + 24 * float(np.max(D * m)) + 24 * float(m.max()) ** 2
    elif mode == VIO:
        D, m = np.full(T, 6.0), 4 * per_frame
        seconds = np.sum(SECONDS_PER_ROW_CUBED * m**3 + SECONDS_PER_ROW_SQUARED * m**2)
        peak = 24 * float(m.max()) ** 2
    else:
        D, m = np.full(T, 6.0), 3 * per_frame
        seconds, peak = float(np.sum(SECONDS_PER_ROW_SQUARED * m)), 8 * 64 * float(m.max())
    return WorkEstimate(mode=mode, dense=dense, state_dim=int(D.max()), frames=T, max_rows=int(m.max()),
                        peak_bytes=int(peak), seconds=float(seconds) + SECONDS_PER_FRAME * T)


def _landmarks_in_state(dataset, stride, dense):
    """Landmarks in the joint state at each frame (T,): every strided one (dense), else those being tracked."""
    T = max(1, dataset.num_frames)
    if dense:
        return np.full(T, float(len(range(0, dataset.num_landmarks, stride))))
    spans = dataset.track_spans()[::stride]
    spans = spans[spans[:, 0] >= 0]
    change = np.zeros(T + 1)
    np.add.at(change, spans[:, 0], 1)
    np.add.at(change, spans[:, 1] + 1, -1)
    return np.cumsum(change[:T])


def divergence_hint(dataset, config, frame=None):
    """The likely cause of a filter failure at ``frame``, as one sentence.

    Names the implausible parts of the data first (:func:`visla_edu.data.dataset_problems`:
    calibration, time stamps, velocities), else the step into ``frame`` and the settings.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    config : visla_edu.filters.FilterConfig
    frame : int, optional

    Returns
    -------
    str
    """
    problems = data.dataset_problems(dataset)
    if problems:
        return "likely cause: " + problems[0]
    where = ""
    if frame is not None and 0 < frame < dataset.num_frames:
        twist = motion.select_twists(dataset.twists, config.imu_lag)[frame - 1]
        speed, rate = data.magnitude(twist[:3]), data.magnitude(twist[3:])
        where = (f"the step into frame {frame} lasts {dataset.time_steps[frame - 1]:.4g} s at "
                 f"{speed:.4g} m/s and {rate:.4g} rad/s; ")
    return (f"{where}the data look plausible, so check the settings (sigma_pixel {config.sigma_pixel:g} px, "
            f"velocity noise {config.sigma_linear_velocity:g} m/s and {config.sigma_angular_velocity:g} rad/s) "
            "and the calibration (visla-edu info shows the diagnostics)")


def _duration(seconds):
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
