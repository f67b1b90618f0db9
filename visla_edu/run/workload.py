"""How much work a run will be (:func:`estimate_work`), and what to say when one fails (:func:`divergence_hint`).

The command line refuses a run past :data:`WORK_LIMIT_BYTES` or :data:`WORK_LIMIT_SECONDS` unless given ``--force``.
"""

from dataclasses import dataclass, replace

import numpy as np

from visla_edu import data, motion
from visla_edu._files import format_bytes
from visla_edu.codes import SLAM, SMOOTHER_MODES, VIO
from visla_edu.filters import FilterConfig

__all__ = ["WorkEstimate", "estimate_work", "divergence_hint", "WORK_LIMIT_BYTES", "WORK_LIMIT_SECONDS"]


#: Cost model of the filter's updates, fitted on the 2-core development machine with one BLAS
#: thread (``benchmarks/bench_work_estimate.py`` prints estimates against measurements). A joint
#: update with a D-dimensional state and m observation rows costs ``D^2 (a + b m)`` seconds (the
#: covariance update ``Sigma -= A^T A`` streams the D x D covariance and multiplies (D, m) by
#: (m, D)); factorising and assembling an m x m innovation covariance ``c m^3 + d m^2``; every
#: frame some milliseconds more. The estimates stay within a factor of 3 of the measured times.
SECONDS_PER_ENTRY = 1e-8  # a
SECONDS_PER_ENTRY_ROW = 2e-11  # b
SECONDS_PER_ROW_CUBED = 4e-11  # c
SECONDS_PER_ROW_SQUARED = 2e-8  # d
SECONDS_PER_FRAME = 5e-3  # the rest of a step (prediction, gating, bookkeeping)
#: The smoothers' time as a multiple of the joint EKF's (batch on dataset 03: about 3 times),
#: and their memory per observation (dataset 03: 270 MB for 66,000 observations).
SMOOTHER_FACTOR = 5
SMOOTHER_BYTES_PER_OBSERVATION = 4096
#: The limits of :meth:`WorkEstimate.over_limits` (the module docstring).
WORK_LIMIT_BYTES = 2 * 2**30
WORK_LIMIT_SECONDS = 15 * 60


@dataclass
class WorkEstimate:
    """What a run will cost, estimated from the observations before it starts (:func:`estimate_work`).

    Attributes
    ----------
    state_dim : int
        Largest state: ``6 + 3 n`` with n the landmarks in the joint state (SLAM), else 6.
    max_rows : int
        Most observation rows of one update.
    peak_bytes : int
        The largest matrices at once: in SLAM the covariance and its update's same-size product
        (``2 D^2 8`` bytes) and (D, m) and (m, m) blocks, in VIO the innovation covariance and factor.
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
        """What exceeds the limits (default :data:`WORK_LIMIT_BYTES`, :data:`WORK_LIMIT_SECONDS`), as phrases."""
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
        return (f"{self.mode}{' (dense)' if self.dense else ''}: states up to {self.state_dim} dimensions, updates up "
                f"to {self.max_rows} rows: about {format_bytes(self.peak_bytes)} of memory and "
                f"{_duration(self.seconds)} for {self.frames} frames (estimate)")


def estimate_work(dataset, mode=SLAM, config=None, dense=False):
    """Estimate the memory and time of ``run_filter(dataset, mode, config, dense=dense)``: a :class:`WorkEstimate`.

    ``config.landmark_stride`` decides the landmarks used. The dense filter carries every (strided) landmark, the
    active set those whose track spans the frame, both with 3 rows per observation; VIO solves a 4-row block per
    observation; mapping and dead reckoning work in cheap 3x3 and 6x6 blocks. The smoothers: the joint EKF's
    estimate times :data:`SMOOTHER_FACTOR`, plus their memory per observation.
    """
    config = config or FilterConfig()
    if mode in SMOOTHER_MODES:  # the smoothers start from the joint EKF and cost a few times as much
        estimate = estimate_work(dataset, SLAM, config, False)
        return replace(estimate, mode=mode,
                       peak_bytes=estimate.peak_bytes + SMOOTHER_BYTES_PER_OBSERVATION * dataset.num_observations,
                       seconds=SMOOTHER_FACTOR * estimate.seconds)
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
    """The likely cause of a filter failure at ``frame`` (int, optional), as one sentence.

    Names the implausible parts of the data first (:func:`visla_edu.data.dataset_problems`: calibration, time
    stamps, velocities), else the step into ``frame`` and then an angular rate beyond a car's (deg/s given as
    rad/s?) or the settings. ``dataset``, ``config``: as :func:`visla_edu.run.run_filter`.
    """
    problems = data.dataset_problems(dataset)
    if problems:
        return "likely cause: " + problems[0]
    calibration = dataset.extra.get("calibration")  # what the run resolved "auto" with, if it got that far
    if calibration is not None and not config.resolved:
        config = config.resolve(calibration, focal_length=float(dataset.K[0, 0]), time_step=0.1)
    where = ""
    if frame is not None and 0 < frame < dataset.num_frames:
        lag = config.imu_lag if isinstance(config.imu_lag, int) else 0
        twist = motion.select_twists(dataset.twists, lag)[frame - 1]
        speed, rate = data.magnitude(twist[:3]), data.magnitude(twist[3:])
        where = (f"the step into frame {frame} lasts {dataset.time_steps[frame - 1]:.4g} s at "
                 f"{speed:.4g} m/s and {rate:.4g} rad/s; ")
    units = _angular_rate_hint(dataset)
    if units:
        return where + units
    return (f"{where}the data look plausible, so check the settings (sigma_pixel {config.sigma_pixel:g} px, "
            f"velocity noise {_setting_text(config.sigma_linear_velocity)} m/s and "
            f"{_setting_text(config.sigma_angular_velocity)} rad/s) "
            "and the calibration (visla-edu info shows the diagnostics)")


#: A road vehicle's angular rate stays below this (rad/s) nearly all the time (1 rad/s = 57 deg/s).
CAR_ANGULAR_RATE = 2.0


def _angular_rate_hint(dataset):
    """A hint about deg/s when the angular velocity's 99th percentile is beyond what a car does, else ''."""
    rates = data.magnitude(np.asarray(dataset.angular_velocity, dtype=float))
    typical = float(np.percentile(rates, 99)) if rates.size else 0.0
    if typical <= CAR_ANGULAR_RATE:
        return ""
    return (f"the angular velocity reaches {typical:.3g} rad/s in 1% of the frames, beyond what a car does "
            f"(below {CAR_ANGULAR_RATE:g} rad/s): is it in deg/s? Convert with np.radians(angular_velocity)")


def _setting_text(value):
    """A setting for a message: ``0.5``, ``[0.05 0.006 0.014]`` or ``auto``."""
    if isinstance(value, str):
        return value
    if np.ndim(value):
        return np.array2string(np.asarray(value, dtype=float), precision=3)
    return f"{value:g}"


def _duration(seconds):
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
