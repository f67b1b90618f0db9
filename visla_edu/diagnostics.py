"""Diagnose a drive from its own data, without ground truth.

The stereo tracks give a small visual odometry (VO): triangulate the landmarks seen in two
consecutive frames and align the two point sets (Kabsch/Umeyama, with outlier rejection).
Comparing the VO motion, mapped into the IMU frame through ``imu_T_cam``, with the IMU's
integrated motion ``exp(tau u)`` reveals

* an extrinsic calibration whose axes disagree with the IMU's (wrong signs, flipped axes):
  :func:`check_extrinsics` scores every axis-flip correction in :data:`CORRECTIONS`;
* a time offset between the velocity samples and the frames: :func:`check_time_alignment`;
* a gyro bias: :func:`imu_noise_and_bias`.

The data alone also shows frames whose features exactly repeat the previous frame
(:func:`visla_edu.dataset.repeated_frames`) and stereo matches that break the rectified geometry
(:func:`outlier_indicators`). :func:`diagnose` runs them all and formats a report.
"""

from dataclasses import dataclass

import numpy as np

from visla_edu import lie
from visla_edu.camera import triangulate_disparity
from visla_edu.dataset import repeated_frames
from visla_edu.metrics import align_se3
from visla_edu.motion import select_twists

__all__ = [
    "CORRECTIONS",
    "VisualOdometry",
    "visual_odometry",
    "ExtrinsicCheck",
    "check_extrinsics",
    "resolve_extrinsics",
    "check_time_alignment",
    "imu_noise_and_bias",
    "outlier_indicators",
    "diagnose",
]

#: Candidate corrections of ``imu_T_cam``: rotations that flip two IMU axes, applied on the
#: left (``corrected = C @ imu_T_cam``). ``flip_yz`` turns an x-forward/y-right/z-down IMU
#: frame into x-forward/y-left/z-up.
CORRECTIONS = {
    "none": np.diag([1.0, 1.0, 1.0, 1.0]),
    "flip_yz": np.diag([1.0, -1.0, -1.0, 1.0]),
    "flip_xy": np.diag([-1.0, -1.0, 1.0, 1.0]),
    "flip_xz": np.diag([-1.0, 1.0, -1.0, 1.0]),
}


@dataclass
class VisualOdometry:
    """Frame-to-frame camera motion from stereo tracks.

    Attributes
    ----------
    cam_T_next : ndarray, shape (T - 1, 4, 4)
        Pose of the left camera at ``t + 1`` in the camera at ``t`` (identity where invalid).
    valid : ndarray of bool, shape (T - 1,)
        Enough tracked points with usable depth to trust the estimate.
    inliers : ndarray of int, shape (T - 1,)
    tracked : ndarray of int, shape (T - 1,)
        Points tracked through both frames with disparity above the threshold.
    """

    cam_T_next: np.ndarray
    valid: np.ndarray
    inliers: np.ndarray
    tracked: np.ndarray


def _rigid_fit(P, Q):
    """Rotation R (3, 3) and translation p (3,) minimising ``sum |P - (R Q + p)|^2`` (Kabsch).

    P, Q are (n, 3) matching points; :func:`visla_edu.metrics.align_se3` does the fit.
    """
    P_T_Q = align_se3(Q, P)
    return P_T_Q[:3, :3], P_T_Q[:3, 3]


def _robust_alignment(P, Q, min_points, iterations=4):
    """Kabsch with iterative rejection of points far from the fitted motion."""
    keep = np.ones(len(P), dtype=bool)
    R, p = _rigid_fit(P, Q)
    for _ in range(iterations):
        residual = np.linalg.norm(P - (Q @ R.T + p), axis=1)
        keep = residual < max(0.2, 2.5 * np.median(residual))
        if keep.sum() < min_points:
            return R, p, keep
        R, p = _rigid_fit(P[keep], Q[keep])
    return R, p, keep


def visual_odometry(dataset, min_disparity=10.0, min_points=8):
    """Stereo visual odometry between consecutive frames.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    min_disparity : float
        Only points with disparity above this (px) in both frames are used (near points,
        well-conditioned depth).
    min_points : int
        Fewer inliers than this marks the frame pair invalid.

    Returns
    -------
    VisualOdometry
    """
    T = dataset.num_frames
    cam_T_next = np.broadcast_to(np.eye(4), (T - 1, 4, 4)).copy()
    valid = np.zeros(T - 1, dtype=bool)
    inliers = np.zeros(T - 1, dtype=np.int64)
    tracked = np.zeros(T - 1, dtype=np.int64)
    ids_a, z_a = dataset.observations(0)
    for t in range(T - 1):
        ids_b, z_b = dataset.observations(t + 1)
        _, ia, ib = np.intersect1d(ids_a, ids_b, assume_unique=True, return_indices=True)
        ok = (z_a[ia, 0] - z_a[ia, 2] > min_disparity) & (z_b[ib, 0] - z_b[ib, 2] > min_disparity)
        tracked[t] = ok.sum()
        if tracked[t] >= min_points:
            P = triangulate_disparity(z_a[ia[ok]], dataset.K, dataset.b)
            Q = triangulate_disparity(z_b[ib[ok]], dataset.K, dataset.b)
            R, p, keep = _robust_alignment(P, Q, min_points)
            inliers[t] = keep.sum()
            valid[t] = inliers[t] >= min_points
            cam_T_next[t, :3, :3], cam_T_next[t, :3, 3] = R, p
        ids_a, z_a = ids_b, z_b
    return VisualOdometry(cam_T_next, valid, inliers, tracked)


def _vo(dataset):
    """Visual odometry of ``dataset``, computed once and cached in ``dataset.extra``."""
    if "visual_odometry" not in dataset.extra:
        dataset.extra["visual_odometry"] = visual_odometry(dataset)
    return dataset.extra["visual_odometry"]


def _vo_in_imu_frame(vo, imu_T_cam):
    """VO motions as IMU motions ``imu_T_cam cam_T_next cam_T_imu``, as twists (T-1, 6)."""
    rel = imu_T_cam @ vo.cam_T_next @ lie.se3_inv(imu_T_cam)
    return lie.se3_log(rel)


def _imu_step_twists(dataset, lag=0):
    """IMU motion over each frame interval as twists ``tau_t u[t + lag]`` (:func:`select_twists`), (T-1, 6)."""
    return dataset.time_steps[:, None] * select_twists(dataset.twists, lag)


def _slope(vo, imu):
    """Least-squares slope ``s`` of ``vo ~ s imu`` over all entries, and its standard error."""
    if len(imu) == 0:
        return float("nan"), float("inf")
    power = max(float(np.sum(imu * imu)), 1e-300)
    s = float(np.sum(vo * imu)) / power
    resid = vo - s * imu
    return s, float(np.sqrt(np.mean(resid**2) / power))


def _rms(x):
    return float(np.sqrt(np.mean(np.sum(x**2, axis=1)))) if len(x) else float("nan")


@dataclass
class ExtrinsicCheck:
    """Result of :func:`check_extrinsics`.

    Attributes
    ----------
    rotation_slope, translation_slope : dict
        Correction name -> least-squares slope of the VO motion against the IMU motion
        (rotation vectors, translations). Near +1 when the axes agree; a flipped axis pair
        turns the rotation slope negative.
    rotation_slope_error : float
        Standard error of the rotation slope (the same for every candidate): a drive with
        little turning cannot tell the candidates apart.
    rotation_rms : dict
        Correction name -> RMS of the per-frame rotation disagreement (rad).
    recommended : str
        A correction only on strong evidence: the file's calibration gives a slope below
        ``-MIN_SLOPE`` at least ``MIN_SIGNIFICANCE`` standard errors from zero, and the
        correction's slopes are both above ``MIN_SLOPE``; otherwise ``"none"``.
    pairs : int
        Frame pairs with valid visual odometry.
    """

    rotation_slope: dict
    translation_slope: dict
    rotation_rms: dict
    rotation_slope_error: float
    recommended: str
    pairs: int

    def agrees(self, key):
        """Both slopes of correction ``key`` above ``MIN_SLOPE``."""
        return self.rotation_slope[key] > MIN_SLOPE and self.translation_slope[key] > MIN_SLOPE

    def report(self, name=""):
        """Readable evidence, one line per candidate."""
        lines = [f"extrinsic check{' of ' + name if name else ''}: visual odometry on {self.pairs} frame pairs "
                 f"against the IMU motion through imu_T_cam (slope 1 = agreement, "
                 f"rotation slope standard error {self.rotation_slope_error:.2f})"]
        for key in CORRECTIONS:
            mark = "  <- used" if key == self.recommended else ""
            lines.append(f"  {key:8s} rotation slope {self.rotation_slope[key]:+6.2f} "
                         f"(rms {1e3 * self.rotation_rms[key]:6.2f} mrad/frame)   "
                         f"translation slope {self.translation_slope[key]:+6.2f}{mark}")
        return "\n".join(lines)


#: A calibration agrees with the IMU when both VO-vs-IMU slopes exceed this.
MIN_SLOPE = 0.5
#: ... and disagrees when a slope is below -MIN_SLOPE by this many standard errors.
MIN_SIGNIFICANCE = 5.0


def check_extrinsics(dataset, lag=0):
    """Score each axis-flip correction of ``imu_T_cam`` against the IMU's motion.

    For every frame pair with valid visual odometry, the VO twist mapped into the IMU frame
    is regressed on ``tau u_t``: a calibration whose axes disagree with the IMU's shows up as
    a negative rotation slope (turns seen the wrong way round) or translation slope.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    lag : int
        Velocity sample used per interval (see :func:`visla_edu.motion.select_twists`).

    Returns
    -------
    ExtrinsicCheck
    """
    vo = _vo(dataset)
    imu = _imu_step_twists(dataset, lag)[vo.valid]
    rot_slope, trans_slope, rot_rms = {}, {}, {}
    error = np.inf
    for key, C in CORRECTIONS.items():
        vo_imu = _vo_in_imu_frame(vo, C @ dataset.imu_T_cam)[vo.valid]
        rot_slope[key], err = _slope(vo_imu[:, 3:], imu[:, 3:])
        error = min(error, err)
        trans_slope[key], _ = _slope(vo_imu[:, :3], imu[:, :3])
        rot_rms[key] = _rms(vo_imu[:, 3:] - imu[:, 3:])
    check = ExtrinsicCheck(rot_slope, trans_slope, rot_rms, error, "none", int(vo.valid.sum()))
    worst = min(rot_slope["none"], trans_slope["none"])
    if worst < -MIN_SLOPE and -worst > MIN_SIGNIFICANCE * error:
        agreeing = [k for k in CORRECTIONS if check.agrees(k)]
        if agreeing:
            check.recommended = max(agreeing, key=lambda k: rot_slope[k] + trans_slope[k])
    return check


def resolve_extrinsics(dataset, correction="auto"):
    """The ``imu_T_cam`` to use and a line of evidence (empty when nothing was changed).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    correction : str
        ``"auto"``, ``"none"`` or a key of :data:`CORRECTIONS`.

    Returns
    -------
    imu_T_cam : ndarray, shape (4, 4)
    evidence : str
    """
    if correction == "auto":
        if "extrinsic_check" not in dataset.extra:
            dataset.extra["extrinsic_check"] = check_extrinsics(dataset)
        check = dataset.extra["extrinsic_check"]
        if check.recommended == "none":
            return dataset.imu_T_cam, ""
        return CORRECTIONS[check.recommended] @ dataset.imu_T_cam, (
            f"applied extrinsic correction {check.recommended!r} (extrinsic_correction='auto'):\n"
            + check.report(dataset.name))
    if correction not in CORRECTIONS:
        raise ValueError(f"extrinsic_correction must be 'auto' or one of {list(CORRECTIONS)}, got {correction!r}")
    if correction == "none":
        return dataset.imu_T_cam, ""
    return CORRECTIONS[correction] @ dataset.imu_T_cam, f"applied extrinsic correction {correction!r} as requested"


def check_time_alignment(dataset, imu_T_cam=None, lags=(-2, -1, 0, 1, 2)):
    """Which velocity sample best explains the motion from frame t to t+1.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    imu_T_cam : ndarray, shape (4, 4), optional
        Calibration to use (default: the auto-corrected one).
    lags : sequence of int
        Candidate offsets: the step ``t -> t+1`` uses ``u[t + lag]``.

    Returns
    -------
    dict
        ``{"residual": {lag: rms}, "best": lag}``: RMS rotation disagreement (rad per frame)
        between VO and the IMU (rotation changes faster than speed, so it carries the timing).
    """
    if imu_T_cam is None:
        imu_T_cam, _ = resolve_extrinsics(dataset, "auto")
    vo = _vo(dataset)
    vo_imu = _vo_in_imu_frame(vo, imu_T_cam)[vo.valid]
    residual = {}
    for lag in lags:
        imu = _imu_step_twists(dataset, lag)[vo.valid]
        residual[lag] = _rms(vo_imu[:, 3:] - imu[:, 3:])
    return {"residual": residual, "best": min(residual, key=residual.get)}


def imu_noise_and_bias(dataset, imu_T_cam=None):
    """IMU noise level from the data and a gyro bias visible against visual odometry.

    The noise level is estimated from second differences of each velocity channel: for a
    smooth signal plus white noise of standard deviation s, ``var(x[t+1] - 2 x[t] + x[t-1])
    = 6 s^2``. The gyro bias is the mean of ``w_imu - w_vo`` over the frames with valid VO.

    Returns
    -------
    dict
        ``linear_noise`` (3,) m/s, ``angular_noise`` (3,) rad/s, ``gyro_bias`` (3,) rad/s,
        ``gyro_bias_stderr`` (3,) rad/s.
    """
    if imu_T_cam is None:
        imu_T_cam, _ = resolve_extrinsics(dataset, "auto")
    second = np.diff(dataset.twists, n=2, axis=0)
    noise = 1.4826 * np.median(np.abs(second - np.median(second, axis=0)), axis=0) / np.sqrt(6)
    vo = _vo(dataset)
    taus = dataset.time_steps[vo.valid][:, None]
    w_vo = _vo_in_imu_frame(vo, imu_T_cam)[vo.valid, 3:] / taus
    diff = dataset.angular_velocity[:-1][vo.valid] - w_vo
    return {
        "linear_noise": noise[:3], "angular_noise": noise[3:],
        "gyro_bias": diff.mean(axis=0) if len(diff) else np.full(3, np.nan),
        "gyro_bias_stderr": diff.std(axis=0) / np.sqrt(len(diff)) if len(diff) else np.full(3, np.inf),
    }


def outlier_indicators(dataset, epipolar_px=3.0):
    """Shares of observations that break the rectified stereo geometry.

    Returns
    -------
    dict
        ``non_positive_disparity`` (uL - uR <= 0), ``epipolar`` (|vL - vR| > epipolar_px),
        and ``vo_rejected`` (share of tracked near points the robust VO rejected).
    """
    z = dataset.obs_z
    n = max(len(z), 1)
    vo = _vo(dataset)
    return {
        "non_positive_disparity": float(np.sum(z[:, 0] - z[:, 2] <= 0) / n),
        "epipolar": float(np.sum(np.abs(z[:, 1] - z[:, 3]) > epipolar_px) / n),
        "vo_rejected": float(1 - vo.inliers.sum() / max(vo.tracked.sum(), 1)),
    }


def diagnose(dataset):
    """Run every diagnostic and return a readable report (str)."""
    check = check_extrinsics(dataset)
    dataset.extra["extrinsic_check"] = check
    imu_T_cam, _ = resolve_extrinsics(dataset, "auto")
    timing = check_time_alignment(dataset, imu_T_cam)
    imu = imu_noise_and_bias(dataset, imu_T_cam)
    rep = repeated_frames(dataset)
    out = outlier_indicators(dataset)
    lines = [check.report(dataset.name)]
    if check.recommended != "none":
        lines.append(f"  -> the file's imu_T_cam disagrees with the IMU's axes; the filter applies "
                     f"{check.recommended!r} (FilterConfig.extrinsic_correction='auto')")
    lines.append("time alignment, rotation rms (mrad/frame) when step t->t+1 uses u[t+lag]: " + ", ".join(
        f"lag {k:+d}: {1e3 * v:.3f}" for k, v in timing["residual"].items()) + f"  -> best lag {timing['best']:+d}")
    lines.append(f"IMU noise (from second differences): linear {np.round(imu['linear_noise'], 4)} m/s, "
                 f"angular {np.round(imu['angular_noise'], 5)} rad/s")
    lines.append(f"gyro bias vs visual odometry: {np.round(imu['gyro_bias'], 5)} rad/s "
                 f"(+- {np.round(imu['gyro_bias_stderr'], 5)})")
    lines.append(f"frames repeating the previous frame exactly: {rep if len(rep) else 'none'}")
    lines.append(f"observations with non-positive disparity: {100 * out['non_positive_disparity']:.2f}%, "
                 f"breaking the epipolar line by > 3 px: {100 * out['epipolar']:.2f}%, "
                 f"near points rejected by visual odometry: {100 * out['vo_rejected']:.1f}%")
    return "\n".join(lines)
