"""One driver for every filter mode: a step iterator and a whole-run function.

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

from visla_edu import diagnostics, filters, motion
from visla_edu.camera import StereoCamera
from visla_edu.ekf import FilterConfig

__all__ = ["MODES", "RunResult", "make_filter", "iterate_filter", "run_filter", "save_result", "load_result"]

#: Filter modes by name.
MODES = ("deadreckon", "mapping", "vio", "slam")


def blas_threads(n):
    """Context manager limiting numpy's BLAS threads to ``n`` (None: leave as is).

    The filter's per-step matrices are a few hundred rows at most; on a 2-core machine a
    multi-threaded BLAS spends more time synchronising than computing, so the driver runs
    with one thread unless told otherwise (``FilterConfig.blas_threads``).
    """
    if n is None:
        return contextlib.nullcontext()
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=int(n), user_api="blas")


def make_filter(dataset, mode="slam", config=None, dense=False, verbose=False):
    """Build the filter object for ``mode`` with the corrected calibration.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"deadreckon", "mapping", "vio", "slam"}
    config : FilterConfig, optional
    dense : bool
        Textbook joint EKF over all (strided) landmarks; only for ``mode="slam"``.
    verbose : bool
        Print the extrinsic diagnostic's evidence when a correction is applied.

    Returns
    -------
    filters.DeadReckoning or subclass, or filters.JointSlam
    """
    config = config or FilterConfig()
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if dense and mode != "slam":
        raise ValueError(f"dense=True is the textbook joint filter and needs mode='slam', got mode={mode!r}")
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(dataset, config.extrinsic_correction)
    if verbose and evidence:
        print(evidence)
    camera = StereoCamera(dataset.K, dataset.b, imu_T_cam)
    if mode == "slam":
        return filters.JointSlam(dataset, camera, config, dense=dense)
    cls = {"deadreckon": filters.DeadReckoning, "mapping": filters.LandmarkMapping,
           "vio": filters.VisualInertialOdometry}[mode]
    return cls(dataset, camera, config)


def iterate_filter(dataset, mode="slam", config=None, dense=False):
    """Yield one :class:`~visla_edu.filters.StepRecord` per frame.

    The BLAS thread limit of ``config`` holds while the generator runs.
    """
    config = config or FilterConfig()
    flt = make_filter(dataset, mode, config, dense)
    with blas_threads(config.blas_threads):
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
        Observations per frame by status (``filters.STATUS_NAMES``).
    step_seconds : ndarray, shape (T,)
    config : dict
    imu_T_cam : ndarray, shape (4, 4)
        The calibration used (after any correction).
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

    def status_totals(self):
        """Total observations by status name, e.g. ``{"used": ..., "gated": ...}``."""
        return dict(zip(filters.STATUS_NAMES, self.status_counts.sum(axis=0).tolist()))

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


def run_filter(dataset, mode="slam", config=None, dense=False, progress=None, verbose=False):
    """Run a filter over the whole dataset.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    mode : {"deadreckon", "mapping", "vio", "slam"}
    config : FilterConfig, optional
    dense : bool
        Textbook dense joint filter (``mode="slam"`` only).
    progress : bool, optional
        Show a tqdm progress bar; by default only for runs longer than 500 frames.
    verbose : bool
        Print the evidence of an automatic extrinsic correction.

    Returns
    -------
    RunResult
    """
    config = config or FilterConfig()
    flt = make_filter(dataset, mode, config, dense, verbose=verbose)
    T = dataset.num_frames
    out = _allocate(T)
    show = T > 500 if progress is None else progress
    with blas_threads(config.blas_threads), _progress_bar(T, show, f"{dataset.name} {mode}") as bar:
        for t in range(T):
            start = time.perf_counter()
            rec = flt.step()
            out["step_seconds"][t] = time.perf_counter() - start
            _store(out, rec)
            bar.update(1)
    landmarks, landmark_cov = _landmark_estimates(flt)
    return RunResult(
        name=dataset.name, mode=mode, dense=dense, time_stamps=dataset.time_stamps.copy(),
        landmarks=landmarks, landmark_cov=landmark_cov,
        dead_reckoning=motion.dead_reckon(dataset.time_stamps, dataset.twists, lag=config.imu_lag),
        config=config.to_dict(), imu_T_cam=flt.camera.imu_T_cam.copy(), **out,
    )


def _allocate(T):
    return {
        "world_T_imu": np.empty((T, 4, 4)), "pose_cov": np.empty((T, 6, 6)),
        "nis": np.full(T, np.nan), "nis_dof": np.zeros(T, dtype=np.int64),
        "status_counts": np.zeros((T, len(filters.STATUS_NAMES)), dtype=np.int64),
        "step_seconds": np.zeros(T),
    }


def _store(out, rec):
    t = rec.t
    out["world_T_imu"][t] = rec.world_T_imu
    out["pose_cov"][t] = rec.pose_cov
    out["nis"][t] = rec.nis
    out["nis_dof"][t] = rec.nis_dof
    out["status_counts"][t] = np.bincount(rec.status, minlength=len(filters.STATUS_NAMES))


def _landmark_estimates(flt):
    if isinstance(flt, filters.JointSlam):
        return flt.landmark_estimates()
    return flt.landmarks.copy(), flt.landmark_cov.copy()


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
    ``config_<name>`` for every setting used (a setting of None, e.g. ``blas_threads``, is
    stored as an empty array: the file must load without pickle).
    """
    arrays = {k: v for k, v in vars(result).items() if k != "config"}
    arrays.update({f"config_{k}": np.zeros(0) if v is None else v for k, v in result.config.items()})
    np.savez_compressed(path, **arrays)


def load_result(path):
    """Load a :class:`RunResult` written by :func:`save_result`."""
    with np.load(path, allow_pickle=False) as f:
        config = {k[len("config_"):]: (None if f[k].size == 0 else f[k].item())
                  for k in f.files if k.startswith("config_")}
        fields = {k: f[k] for k in f.files if not k.startswith("config_")}
    for key in ("name", "mode"):
        fields[key] = str(fields[key])
    fields["dense"] = bool(fields["dense"])
    return RunResult(config=config, **fields)
