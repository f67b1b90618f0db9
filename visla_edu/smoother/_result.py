"""What a smoother returns: :class:`SmootherResult`, and the shared input checks."""

from dataclasses import dataclass, field

import numpy as np

from visla_edu.codes import STATUS_NAMES

__all__ = ["SmootherResult", "check_trajectory", "check_landmarks", "HISTORY_FIELDS", "STOP_REASONS"]

#: Per-iteration records in :attr:`SmootherResult.history`.
HISTORY_FIELDS = ("round", "cost", "step_norm", "accepted", "damping")
#: Why Levenberg-Marquardt stopped (:attr:`SmootherResult.stop_reasons`): the cost (or the step)
#: became small, the iteration budget ran out, or no damping found a step that lowers the cost.
CONVERGED, ITERATION_CAP, NO_DESCENT = STOP_REASONS = ("converged", "iteration cap", "no descent")


@dataclass
class SmootherResult:
    """Everything a smoother run produced (``mode`` "smooth" or "window").

    Attributes
    ----------
    time_stamps : ndarray, shape (T,)
    world_T_imu, online_world_T_imu : ndarray, shape (T, 4, 4)
        ``world`` is the IMU frame at the first time stamp. ``online_world_T_imu``, window only: each pose when its
        frame was the newest (the real-time estimate).
    landmarks : ndarray, shape (M, 3)
        NaN where a landmark was not estimated (dropped, or never usable).
    pose_cov, landmark_cov : ndarray, shape (T, 6, 6), (M, 3, 3)
        Marginal covariances (of each pose's right perturbation; zeros for a held pose), NaN where not computed or
        (landmarks) not estimated.
    history : dict of ndarray
        Per iteration, each of :data:`HISTORY_FIELDS`: the rejection round (batch) or new frame ``k`` (window: the cost
        is that frame's window problem's); the cost after the iteration (a rejected step leaves it, unless it dropped
        landmarks it sent behind a camera: then the cost without them); the step norm; accepted; the damping.
    rejected : dict of int
        ``outliers`` (rejected by the chi-square test), ``nonpositive_disparity`` and ``ignored`` (observations never
        used: repeated frames, stale copies); landmarks dropped (:class:`~visla_edu.smoother.SmootherConfig`):
        ``landmarks_no_position``, ``landmarks_too_few``, ``landmarks_behind_camera``, ``landmarks_too_far``.
    obs_status : ndarray of int8, shape (N,)
        Each dataset observation's ``OBS_*`` code (:mod:`visla_edu.codes`): ``OBS_USED``, ``OBS_GATED`` (an outlier),
        ``OBS_NO_DEPTH``, ``OBS_IGNORED`` (a repeated frame, a stale copy) or ``OBS_DROPPED`` (its landmark left out).
    timing : dict of float
        Seconds: ``setup``, ``solve``, ``covariance``, ``total`` (the window: ``total`` only).
    imu_T_cam : ndarray, shape (4, 4)
    frame_seconds : ndarray, shape (T,)
        Window only (the batch's is empty): time per new frame, 0 for the held frame 0.
    stop_reasons : list of str
        Batch only: why each round's Levenberg-Marquardt stopped (:data:`STOP_REASONS`), the final round last.
    """

    name: str
    mode: str
    time_stamps: np.ndarray
    world_T_imu: np.ndarray
    landmarks: np.ndarray
    pose_cov: np.ndarray
    landmark_cov: np.ndarray
    history: dict
    rejected: dict
    obs_status: np.ndarray
    timing: dict
    config: dict = field(default_factory=dict)
    imu_T_cam: np.ndarray = None
    frame_seconds: np.ndarray = field(default_factory=lambda: np.zeros(0))
    online_world_T_imu: np.ndarray = None
    stop_reasons: list = field(default_factory=list)

    def status_totals(self):
        """Observations by status name (:data:`visla_edu.codes.STATUS_NAMES`), e.g. ``{"used": ...}``."""
        counts = np.bincount(self.obs_status, minlength=len(STATUS_NAMES))
        return dict(zip(STATUS_NAMES, counts.tolist()))

    def _stop_note(self):
        """``"; final round: <reason>"``, with what the iteration cap means, or ``""``."""
        if not self.stop_reasons:
            return ""
        last = self.stop_reasons[-1]
        if last == ITERATION_CAP:
            return (f"; final round stopped at its iteration cap, max_iterations={self.config.get('max_iterations')} "
                    "(not converged: see SmootherConfig.max_iterations)")
        return f"; final round: {last}"

    def summary(self):
        """A few lines a student can read: mode, map, rejections, iterations, time."""
        kept = int(np.isfinite(self.landmarks[:, 0]).sum())
        totals = self.status_totals()
        lines = [
            f"{self.name}: mode {self.mode}, {len(self.time_stamps)} frames, "
            f"{kept} of {len(self.landmarks)} landmarks estimated",
            "observations: " + ", ".join(f"{k} {v}" for k, v in totals.items() if v),
            "dropped landmarks: " + ", ".join(
                f"{k[len('landmarks_'):]} {v}" for k, v in self.rejected.items() if k.startswith("landmarks_")),
        ]
        h = self.history
        if len(h["cost"]):
            lines.append(f"{len(h['cost'])} iterations ({int(np.sum(h['accepted']))} accepted), "
                         f"final cost {h['cost'][-1]:.6g}" + self._stop_note())
        lines.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in self.timing.items()))
        if len(self.frame_seconds) > 1:  # frame 0 is the held first pose: no work, not a frame
            lines.append(f"per frame: median {1e3 * np.median(self.frame_seconds[1:]):.2f} ms, "
                         f"max {1e3 * np.max(self.frame_seconds[1:]):.2f} ms")
        return "\n".join(lines)


def check_trajectory(world_T_imu, num_frames, name):
    """``world_T_imu`` as finite floats (``num_frames``, 4, 4), else ValueError naming ``name`` and a bad frame."""
    world_T_imu = np.asarray(world_T_imu, dtype=float)
    if world_T_imu.shape != (num_frames, 4, 4):
        raise ValueError(f"{name}: initial world_T_imu must have shape ({num_frames}, 4, 4) "
                         f"(one pose per frame of the dataset), got {world_T_imu.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(world_T_imu), axis=(1, 2)))
    if len(bad):
        raise ValueError(f"{name}: initial world_T_imu has non-finite entries at frame {bad[0]} "
                         f"({len(bad)} frames); start from a finite trajectory (e.g. dead reckoning)")
    return world_T_imu


def check_landmarks(landmarks, num_landmarks, name):
    """``landmarks`` as floats (``num_landmarks``, 3), NaN rows allowed, None kept; inf or another shape: ValueError."""
    if landmarks is None:
        return None
    landmarks = np.asarray(landmarks, dtype=float)
    if landmarks.shape != (num_landmarks, 3):
        raise ValueError(f"{name}: initial landmarks must have shape ({num_landmarks}, 3) "
                         f"(NaN rows for unknown ones), got {landmarks.shape}")
    bad = np.flatnonzero(np.any(np.isinf(landmarks), axis=1))
    if len(bad):
        raise ValueError(f"{name}: initial landmarks have infinite entries at landmark {bad[0]} "
                         f"({len(bad)} landmarks); use a NaN row for a landmark without a position")
    return landmarks


def empty_history():
    """A history dict with no iterations."""
    return {k: [] for k in HISTORY_FIELDS}


def finish_history(history):
    """The history lists as arrays (int round, float cost/step/damping, bool accepted)."""
    types = {"round": np.int64, "accepted": bool}
    return {k: np.asarray(v, dtype=types.get(k, float)) for k, v in history.items()}
