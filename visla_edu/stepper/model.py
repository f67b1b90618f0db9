"""The filter stepper's model: a filter you can move through in time, forwards and backwards.

A :class:`Stepper` owns one filter (:func:`visla_edu.run.make_filter`, or with ``filter_factory`` any
:class:`SteppableFilter`, e.g. a student's own, notebook 12) and the :class:`~visla_edu.filters.StepRecord` of
every frame processed so far. The *frontier* is the last frame processed: ``goto(t)`` reads the history up to
it, and beyond it steps the filter to ``t`` and no further (a step forward costs one filter step, never a
re-run). Changing the dataset, the mode or the noise settings resets the filter to frame 0. It imports neither
ipywidgets nor matplotlib (the views: :mod:`visla_edu.stepper.figure`, :mod:`visla_edu.stepper.widget`).
"""

import time
from dataclasses import fields, replace
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from visla_edu import metrics, motion, run
from visla_edu.codes import DEADRECKON, MAPPING, MODES, SLAM, STATUS_NAMES, VIO
from visla_edu.filters import FilterConfig, StepRecord

__all__ = ["MODE_LABELS", "NOISE_FIELDS", "SteppableFilter", "Stepper", "dataset_choices", "world_position_covariance"]

#: Human-readable names of the filter modes (keys: :data:`visla_edu.codes.MODES`).
MODE_LABELS = {
    DEADRECKON: "dead reckoning (IMU only)",
    MAPPING: "landmark mapping (poses from IMU)",
    VIO: "visual-inertial odometry",
    SLAM: "SLAM (joint EKF)",
}

#: The FilterConfig fields the stepper's noise and initialisation controls change.
NOISE_FIELDS = ("sigma_pixel", "sigma_linear_velocity", "sigma_angular_velocity", "landmark_prior_sigma",
                "landmark_prior_inflation", "gate_probability")

#: Simulated drives offered besides what :func:`visla_edu.data.available` lists.
_EXTRA_SIMULATED = ("sim-small", "sim-tiny")


def dataset_choices(data_dir=None):
    """``[(label, name), ...]`` for a menu: :func:`visla_edu.data.available`'s, then ``"sim-small"``, ``"sim-tiny"``."""
    from visla_edu import data

    names = list(data.available(data_dir))
    names += [n for n in _EXTRA_SIMULATED if n not in names]
    directory = Path(data.data_dir(data_dir))
    labels = {
        "03": "03 (KITTI-360 drive 0003)",
        "0022": "0022 (KITTI drive 0022, 2019 format)",
        "0020": "0020 (KITTI drive 0020 = odometry 06, ground truth)"
        if data.ground_truth_files("0020", directory) else "0020 (KITTI drive 0020 = odometry 06)",
        "10": "10 (KITTI-360 drive 0010)" if (directory / "10.npz").is_file()
        else "10 (STAND-IN: simulated tracks on its real IMU drive)",
        "sim": "sim (simulated, ground truth)",
        "sim-small": "sim-small (simulated, ground truth)",
        "sim-tiny": "sim-tiny (simulated, 60 frames)",
    }
    return [(labels.get(n, n), n) for n in names]


def world_position_covariance(world_T_imu, pose_cov):
    """World-frame covariance of the IMU position, ``R Sigma_vv R^T``, shape (3, 3).

    To first order ``p = p_mu + R_mu v`` (right perturbation ``[v; w]``, see :mod:`visla_edu.lie`);
    ``world_T_imu`` is (4, 4), ``pose_cov`` (6, 6).
    """
    R = np.asarray(world_T_imu)[:3, :3]
    return R @ np.asarray(pose_cov)[:3, :3] @ R.T


@runtime_checkable
class SteppableFilter(Protocol):
    """The interface of a filter the :class:`Stepper` can step (the library's filters have it).

    ``config``: the resolved :class:`~visla_edu.filters.FilterConfig` the factory received (keeping it is enough):
    the noise sliders show it, the dead-reckoning reference uses its ``imu_lag``. ``step()``: the next frame's
    :class:`~visla_edu.filters.StepRecord` (frames ``0, 1, 2, ...``, one per call, only while frames remain): ``t``,
    ``world_T_imu`` (4, 4) and ``pose_cov`` (6, 6, right perturbation ``[v; w]``), the frame's observations with
    their status codes, the active landmarks the map draws (empty arrays are fine). What it raises propagates;
    the stepper stays at the last good frame.
    """

    config: FilterConfig

    def step(self) -> StepRecord:
        """Process the next frame; return its record."""


class Stepper:
    """A filter run you can step through: the filter, its history, and the current time.

    Parameters
    ----------
    dataset : str or visla_edu.dataset.Dataset
        A name :func:`visla_edu.data.load` understands (``"sim-tiny"``, ``"03"``...; from ``data_dir``) or a dataset.
    mode : {"deadreckon", "mapping", "vio", "slam"}
    config : visla_edu.filters.FilterConfig, optional
    blas_threads : int or None
        BLAS thread limit while the filter steps (:func:`visla_edu.run.limit_blas_threads`).
    filter_factory : callable, optional
        ``filter_factory(dataset, config) -> filter``, a :class:`SteppableFilter` (``config`` resolved), instead of
        :func:`visla_edu.run.make_filter`; called again at every reset. ``mode`` then only labels the views.

    Attributes
    ----------
    records : list of StepRecord
        ``records[k]`` is frame ``k``'s snapshot, for ``k = 0 .. frontier``.
    filter : SteppableFilter
        Its state is at the frontier.
    steps_computed : int
        Filter steps run since the last reset (each frame is computed once).
    last_update_seconds : float
        Wall time of the last :meth:`goto`.
    generation : int
        Counts the resets (0 after construction); views redraw their static parts when it changes.
    """

    def __init__(self, dataset="sim-tiny", mode=SLAM, config=None, data_dir=None, blas_threads=1,
                 filter_factory=None):
        if filter_factory is not None and not callable(filter_factory):
            raise TypeError("Stepper: filter_factory must be a callable (dataset, config) -> filter, "
                            f"got {type(filter_factory).__name__}")
        self.filter_factory = filter_factory
        self.data_dir = data_dir
        self.blas_threads = blas_threads
        self._cache = {}
        self._dataset = self._load(dataset)
        self._mode = self._check_mode(mode)
        self._config = self._check_config(config)
        self.last_update_seconds = 0.0
        self.reset()

    # ------------------------------------------------------------------ configuration
    @property
    def dataset(self):
        """The :class:`~visla_edu.dataset.Dataset` being filtered."""
        return self._dataset

    @property
    def mode(self):
        """The filter mode (one of :data:`visla_edu.codes.MODES`)."""
        return self._mode

    @property
    def config(self):
        """The :class:`~visla_edu.filters.FilterConfig` asked for (replace it via :meth:`configure`)."""
        return self._config

    @property
    def config_in_use(self):
        """The filter's resolved :class:`~visla_edu.filters.FilterConfig` (``"auto"`` settings measured)."""
        return self.filter.config

    def configure(self, dataset=None, mode=None, config=None, **settings):
        """Change the dataset, mode or noise settings; True if anything changed (the filter then restarts at frame 0).

        ``dataset``, ``mode``: as the constructor's; ``config`` replaces the whole configuration; ``**settings`` are
        :class:`FilterConfig` fields (e.g. ``sigma_pixel=4.0``) applied after ``config``, an unknown one a ValueError.
        """
        new_dataset = self._dataset if dataset is None else self._load(dataset)
        new_mode = self._mode if mode is None else self._check_mode(mode)
        new_config = self._config if config is None else self._check_config(config)
        if settings:
            known = {f.name for f in fields(FilterConfig)}
            unknown = sorted(set(settings) - known)
            if unknown:
                raise ValueError(f"Stepper.configure: unknown FilterConfig field(s) {unknown}; known: {sorted(known)}")
            new_config = replace(new_config, **settings)
        changed = (new_dataset is not self._dataset or new_mode != self._mode
                   or new_config.to_dict() != self._config.to_dict())
        if changed:
            self._dataset, self._mode, self._config = new_dataset, new_mode, new_config
            self.reset()
        return changed

    def reset(self):
        """Build a fresh filter and forget the history; the time goes back to frame 0."""
        ds = self._dataset
        T = ds.num_frames
        self.filter = self._make_filter(ds)
        self.generation = getattr(self, "generation", -1) + 1
        self.records = []
        self.steps_computed = 0
        self._arrays = run.RunArrays(T)
        # Landmarks that left the active set: their estimate when they left, and the frame.
        self._retired_frame = np.full(ds.num_landmarks, np.iinfo(np.int64).max)
        self._retired_means = np.full((ds.num_landmarks, 3), np.nan)
        self._retired_order = []  # ids in the order they retired (for "map so far" lookups)
        self._retired_count = np.zeros(T, dtype=np.int64)  # retired landmarks at each frame
        self._dead_reckoning = None
        self._bands = {}
        self._t = 0
        self.goto(0)

    # ------------------------------------------------------------------ time
    @property
    def num_frames(self):
        """T, the number of frames of the dataset."""
        return self._dataset.num_frames

    @property
    def frontier(self):
        """The last frame processed by the filter (-1 before the first step)."""
        return len(self.records) - 1

    @property
    def t(self):
        """The current frame."""
        return self._t

    @t.setter
    def t(self, value):
        self.goto(value)

    def goto(self, t):
        """Move to frame ``t`` (``0 <= t < num_frames``, else IndexError) and return its StepRecord.

        History up to the frontier, then filter steps. What the filter raises on the way (e.g. ``FilterDivergedError``)
        propagates; the stepper stays at the last good frame.
        """
        if isinstance(t, (bool, np.bool_)) or int(t) != t:
            raise TypeError(f"Stepper.goto: t must be an integer frame index, got {t!r}")
        t = int(t)
        if not 0 <= t < self.num_frames:
            raise IndexError(f"Stepper.goto: frame {t} out of range [0, {self.num_frames}) of {self._dataset.name}")
        start = time.perf_counter()
        try:
            if t > self.frontier:
                with run.limit_blas_threads(self.blas_threads):
                    while self.frontier < t:
                        step_start = time.perf_counter()
                        rec = self.filter.step()
                        self._append(rec, time.perf_counter() - step_start)
        except Exception:
            self._t = max(self.frontier, 0)
            raise
        finally:
            self.last_update_seconds = time.perf_counter() - start
        self._t = t
        return self.records[t]

    def step(self, n=1):
        """Move ``n`` frames (negative: back), clipped to the run; return the record."""
        return self.goto(int(np.clip(self._t + int(n), 0, self.num_frames - 1)))

    def back(self, n=1):
        """Move ``n`` frames back (clipped at 0); return the record."""
        return self.step(-int(n))

    def _append(self, rec, seconds):
        if not isinstance(rec, StepRecord):
            raise TypeError(f"Stepper: the filter's step() must return a visla_edu.filters.StepRecord, "
                            f"got {type(rec).__name__}")
        self.steps_computed += 1
        t = rec.t
        if t != len(self.records):
            raise RuntimeError(f"Stepper: the filter returned frame {t}, expected {len(self.records)}")
        self._arrays.store(rec, seconds)
        if self.records:
            prev = self.records[-1]
            gone = ~np.isin(prev.active_ids, rec.active_ids, assume_unique=True)
            if np.any(gone):
                ids = prev.active_ids[gone]
                fresh = self._retired_frame[ids] > t  # not retired before (a landmark may come back)
                self._retired_frame[ids[fresh]] = t
                self._retired_means[ids[fresh]] = prev.active_means[gone][fresh]
                self._retired_order.extend(ids[fresh].tolist())
        self._retired_count[t] = len(self._retired_order)
        self.records.append(rec)

    # ------------------------------------------------------------------ what views read
    @property
    def record(self):
        """The :class:`~visla_edu.filters.StepRecord` of the current frame."""
        return self.records[self._t]

    @property
    def trajectory(self):
        """Estimated poses of frames ``0..t``, shape (t + 1, 4, 4) (read-only view)."""
        return self._readonly(self._arrays.world_T_imu[: self._t + 1])

    @property
    def nis(self):
        """NIS of frames ``0..t`` (NaN where there was no update), shape (t + 1,)."""
        return self._readonly(self._arrays.nis[: self._t + 1])

    @property
    def nis_dof(self):
        """Degrees of freedom of each NIS value, shape (t + 1,) (0 where there was no update)."""
        return self._readonly(self._arrays.nis_dof[: self._t + 1])

    def nis_band_series(self, probability=0.95):
        """The ``probability`` band of ``chi2(dof)/dof`` (:func:`visla_edu.metrics.nis_band`) for frames
        ``0..t``: lower, upper (t + 1,), NaN where there was no update.
        """
        if probability not in self._bands:
            self._bands[probability] = [0, np.full(self.num_frames, np.nan), np.full(self.num_frames, np.nan)]
        band = self._bands[probability]
        done, stop = band[0], self.frontier + 1
        if stop > done:  # computed once per frame, when first asked for
            band[1][done:stop], band[2][done:stop] = metrics.nis_band(self._arrays.nis_dof[done:stop], probability)
            band[0] = stop
        return self._readonly(band[1][: self._t + 1]), self._readonly(band[2][: self._t + 1])

    @property
    def status_counts(self):
        """Observations per frame by status (:data:`visla_edu.codes.STATUS_NAMES`), (t + 1, len(STATUS_NAMES))."""
        return self._readonly(self._arrays.status_counts[: self._t + 1])

    @property
    def time_stamps(self):
        """Seconds since the first frame, shape (T,) (the whole run)."""
        ts = self._dataset.time_stamps
        return ts - ts[0]

    @property
    def ground_truth(self):
        """The dataset's :class:`~visla_edu.dataset.GroundTruth`, or None (course data without KITTI poses)."""
        return self._dataset.ground_truth

    @property
    def dead_reckoning(self):
        """IMU-only trajectory of the whole run, shape (T, 4, 4) (computed once per reset)."""
        if self._dead_reckoning is None:
            ds = self._dataset
            self._dead_reckoning = motion.dead_reckon(ds.time_stamps, ds.twists, lag=self.config_in_use.imu_lag)
        return self._dead_reckoning

    def position_covariance(self):
        """World-frame covariance of the current IMU position, (3, 3): ``R Sigma_vv R^T``."""
        rec = self.record
        return world_position_covariance(rec.world_T_imu, rec.pose_cov)

    def retired_landmarks(self):
        """Landmarks that left the active set by the current frame, with their last active estimates:
        ids (k,), means (k, 3). With the record's active landmarks, the map built so far.
        """
        ids = np.asarray(self._retired_order[: self._retired_count[self._t]], dtype=np.int64)
        return ids, self._retired_means[ids]

    def ground_truth_pose(self):
        """True pose of the current frame, (4, 4), or None (no ground truth, or the frame is past
        the ones a real drive's ground truth covers)."""
        gt = self.ground_truth
        return None if gt is None or self._t >= gt.num_frames else gt.world_T_imu[self._t]

    def summary(self):
        """One line about the current frame: time, observations by status, NIS, active set."""
        rec = self.record
        counts = self._arrays.status_counts[self._t]
        obs = ", ".join(f"{name} {c}" for name, c in zip(STATUS_NAMES, counts) if c)
        nis = f"NIS/dof {rec.nis / rec.nis_dof:.2f} (dof {rec.nis_dof})" if rec.nis_dof else "no update"
        return (f"t = {self._t} / {self.num_frames - 1} ({self.time_stamps[self._t]:.2f} s): "
                f"{len(rec.ids)} observations{' (' + obs + ')' if obs else ''}; {nis}; "
                f"{len(rec.active_ids)} active landmarks")

    # ------------------------------------------------------------------ helpers
    def _make_filter(self, ds):
        """The library's filter for the mode, or the factory's (checked for the step interface)."""
        if self.filter_factory is None:
            return run.make_filter(ds, self._mode, self._config)
        flt = self.filter_factory(ds, run.resolve_config(ds, self._config))
        missing = [name for name in ("step", "config") if not hasattr(flt, name)]
        if missing or not callable(flt.step):
            lacks = missing or ["a callable step"]
            raise TypeError(f"Stepper: the filter_factory's {type(flt).__name__} lacks {lacks} "
                            "of the step interface (see visla_edu.stepper.SteppableFilter)")
        if not isinstance(flt.config, FilterConfig):
            raise TypeError(f"Stepper: {type(flt).__name__}.config must be a FilterConfig, "
                            f"got {type(flt.config).__name__}")
        return flt

    @staticmethod
    def _readonly(view):
        view = view.view()
        view.flags.writeable = False
        return view

    def _load(self, dataset):
        if not isinstance(dataset, str):
            if not hasattr(dataset, "num_frames") or not hasattr(dataset, "observations"):
                raise TypeError(f"Stepper: dataset must be a name or a Dataset, got {type(dataset).__name__}")
            return dataset
        if dataset not in self._cache:
            from visla_edu import data

            self._cache[dataset] = data.load(dataset, data_dir=self.data_dir)
        return self._cache[dataset]

    @staticmethod
    def _check_mode(mode):
        if mode not in MODES:
            raise ValueError(f"Stepper: mode must be one of {MODES}, got {mode!r}")
        return mode

    @staticmethod
    def _check_config(config):
        if config is None:
            return FilterConfig()
        if not isinstance(config, FilterConfig):
            raise TypeError(f"Stepper: config must be a FilterConfig, got {type(config).__name__}")
        return config

    def __repr__(self):
        return (f"Stepper({self._dataset.name!r}, mode={self._mode!r}, t={self._t}, "
                f"frontier={self.frontier}, frames={self.num_frames})")
