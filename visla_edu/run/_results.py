"""A whole run's result, its per-frame arrays, and its file (re-exported by :mod:`visla_edu.run`).

**The file** (``.npz``, no pickle, written atomically by :func:`save_result`, read by :func:`load_result`): one
key per array field of :class:`RunResult` (``start_world_T_imu`` only from the batch smoother), ``name``, ``mode``,
``dense``, ``notes`` and ``start_mode``; ``config_<name>`` for every setting used (None stored as an empty array),
``eval_<name>`` for :attr:`RunResult.evaluation`, ``track_<name>`` for :attr:`RunResult.track_counts`, and
``status_names``, the name of each column of ``status_counts``. Codes are only appended, so a file of an earlier
version (fewer columns, or no ``status_names``: the first codes) loads with zeros in the missing ones; its
smoother runs counted the observations of dropped landmarks as ``ignored`` (the file cannot tell them apart).
"""

from dataclasses import dataclass, field

import numpy as np

from visla_edu._files import atomic_write, expand_user
from visla_edu.codes import STATUS_NAMES
from visla_edu.metrics import gated_share

__all__ = ["RunResult", "RunArrays", "save_result", "load_result"]


@dataclass
class RunResult:
    """Everything a whole run produced.

    Attributes
    ----------
    time_stamps, step_seconds : ndarray, shape (T,)
        ``step_seconds``: wall time of each step.
    world_T_imu, dead_reckoning : ndarray, shape (T, 4, 4)
        The estimate and the IMU-only trajectory; ``world`` is the IMU frame at the first time stamp.
    pose_cov : ndarray, shape (T, 6, 6)
    landmarks : ndarray, shape (M, 3)
        NaN for landmarks never initialised.
    landmark_cov : ndarray, shape (M, 3, 3)
    nis, nis_dof : ndarray, shape (T,)
        NaN (0) where there was no update.
    status_counts : ndarray of int, shape (T, len(STATUS_NAMES))
        Observations per frame by status (:data:`visla_edu.codes.STATUS_NAMES`).
    imu_T_cam : ndarray, shape (4, 4)
        The calibration used (after any correction).
    evaluation : dict
        Filled by :func:`evaluate_result`: ``estimate_<name>``, ``dead_reckoning_<name>`` (batch smoother:
        ``start_<name>`` too) per :class:`visla_edu.metrics.TrajectoryEvaluation` field, ``ground_truth_source``.
    start_world_T_imu : ndarray, shape (T, 4, 4), or None
        Batch smoother: the trajectory it started from (None otherwise).
    start_mode : str
        Batch smoother: the mode of that start (``"deadreckon"``, ``"vio"`` or ``"slam"``), else ``""``.
    track_counts : dict of str -> int
        Joint SLAM with clones: :attr:`visla_edu.filters.JointSlam.track_counts` (empty otherwise).
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
    start_mode: str = ""
    track_counts: dict = field(default_factory=dict)
    notes: str = ""

    def status_totals(self):
        """Total observations by status name, e.g. ``{"used": ..., "gated": ...}``.

        With clones, the ``delayed`` observations of tracks used or gated later count as ``used`` or ``gated``
        (:attr:`track_counts`); the rest stay ``delayed`` (short, failed or still open tracks).
        """
        totals = dict(zip(STATUS_NAMES, self.status_counts.sum(axis=0).tolist()))
        used, gated = (int(self.track_counts.get(k, 0)) for k in ("observations_used", "observations_gated"))
        totals["used"] += used
        totals["gated"] += gated
        totals["delayed"] -= used + gated
        return totals

    def summary(self):
        """A few lines a student can read: mode, counts, timing."""
        totals = self.status_totals()
        lines = [
            f"{self.name}: mode {self.mode}{' (dense)' if self.dense else ''}, {len(self.time_stamps)} frames, "
            f"{int(np.isfinite(self.landmarks[:, 0]).sum())} of {len(self.landmarks)} landmarks mapped",
            "observations: " + ", ".join(f"{k} {v}" for k, v in totals.items() if v),
        ]
        if totals["used"] + totals["gated"]:
            lines.append(f"gated as outliers: {100 * gated_share(totals):.2f}% of the observations the gate "
                         "tested (gated / (used + gated))")
        if self.track_counts:
            c = self.track_counts
            lines.append(f"tracks: {c['tracks_used']} used in multi-frame updates, {c['tracks_gated']} gated whole, "
                         f"{c['entered']} entered the state, {c['tracks_short']} too short")
        camera = self._camera_line()
        if camera:
            lines.append(camera)
        lines.append(self.notes or f"time: {self.step_seconds.sum():.2f} s, median step "
                                   f"{1e3 * np.median(self.step_seconds):.2f} ms")
        return "\n".join(lines)

    def _camera_line(self):
        """How far the run trusted the camera (resolved ``pixel_noise_inflation``, in slam the clones), or None."""
        c = self.config or {}
        inflation, window = c.get("pixel_noise_inflation"), c.get("msckf_window")
        if self.mode == "deadreckon" or not isinstance(inflation, (int, float)) or "sigma_pixel" not in c:
            return None
        line = f"camera: sigma_pixel {c['sigma_pixel']:g} px x pixel_noise_inflation {inflation:.3g}"
        if self.mode == "slam" and not self.dense and isinstance(window, int):
            line += f", msckf_window {window}" + ("" if window else " (the joint EKF without clones)")
        return line


class RunArrays:
    """Per-frame arrays of a run (of :func:`run_filter` and the stepper), filled one StepRecord at a time.

    ``num_frames`` is ``T``; the attributes, :attr:`FIELDS`, are as :class:`RunResult`'s.
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


def save_result(result, path):
    """Write ``result`` to ``path`` atomically (the module docstring's file); return its absolute pathlib.Path.

    Parameters
    ----------
    result : RunResult
    path : str or os.PathLike
        ``.npz`` is appended if missing (as ``numpy.savez`` does).
    """
    path = expand_user(path)
    if path.suffix.lower() != ".npz":
        path = path.with_name(path.name + ".npz")
    skip = ("config", "evaluation", "track_counts")
    arrays = {k: v for k, v in vars(result).items() if k not in skip and v is not None}
    arrays.update({f"config_{k}": np.zeros(0) if v is None else v for k, v in result.config.items()})
    arrays.update({f"track_{k}": v for k, v in result.track_counts.items()})
    arrays.update({f"eval_{k}": v for k, v in result.evaluation.items()})
    arrays["status_names"] = np.array(STATUS_NAMES)
    with atomic_write(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path.resolve()


def _setting(array):
    """A saved setting back: None (empty), a number or string, or a per-axis tuple."""
    if array.size == 0:
        return None
    return array.item() if array.size == 1 else tuple(array.tolist())


def load_result(path):
    """Load a :class:`RunResult` written by :func:`save_result` (or ``visla-edu run --out``), of an earlier version too.

    Raises
    ------
    FileNotFoundError, ValueError, KeyError
        As :func:`numpy.load` for a missing or broken file, a file without a result's keys; ValueError: newer statuses.
    """
    with np.load(path, allow_pickle=False) as f:
        config = {k[len("config_"):]: _setting(f[k]) for k in f.files if k.startswith("config_")}
        evaluation = {k[len("eval_"):]: f[k].item() for k in f.files if k.startswith("eval_")}
        track_counts = {k[len("track_"):]: int(f[k]) for k in f.files if k.startswith("track_")}
        fields = {k: f[k] for k in f.files if not k.startswith(("config_", "eval_", "track_"))}
    fields["track_counts"] = track_counts
    fields["status_counts"] = _status_columns(fields["status_counts"], fields.pop("status_names", None), path)
    for key in ("name", "mode", "notes", "start_mode"):
        if key in fields:
            fields[key] = str(fields[key])
    fields["dense"] = bool(fields["dense"])
    return RunResult(config=config, evaluation=evaluation, **fields)


def _status_columns(counts, names, path):
    """A saved ``status_counts`` (T, k) in the columns of :data:`~visla_edu.codes.STATUS_NAMES`.

    ``names``: the file's ``status_names``, or None (the first ``k`` codes).
    """
    named = names is not None
    names = tuple(names.tolist()) if named else STATUS_NAMES[:counts.shape[1]]
    if len(names) != counts.shape[1] or not set(names) <= set(STATUS_NAMES):
        what = f"the statuses {', '.join(names)}" if named else f"{counts.shape[1]} status columns"
        raise ValueError(f"{path}: status_counts holds {what}, but this visla-edu knows only "
                         f"{', '.join(STATUS_NAMES)}; was it written by a newer visla-edu? Upgrade to read it")
    out = np.zeros((len(counts), len(STATUS_NAMES)), dtype=np.int64)
    out[:, [STATUS_NAMES.index(name) for name in names]] = counts
    return out
