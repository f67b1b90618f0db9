"""Visual-odometry evidence: the extrinsic axes check and the time alignment.

The left camera's motion ``cam_T_next`` (:func:`visla_edu.diagnostics.odometry.visual_odometry`),
mapped into the IMU frame through a candidate ``imu_T_cam``, must agree with the IMU's own motion
``exp(tau_t u[t + lag])``: axes that disagree turn the slope of one on the other negative, and the
right lag has the smallest rotation disagreement. Only pairs with at least :data:`MIN_INLIERS`
inliers are used: pairs of 3 points (common on sparse drives) have heavy-tailed rotation errors.
"""

from dataclasses import dataclass, field

import numpy as np

from visla_edu import lie
from visla_edu.motion import select_twists
from visla_edu.diagnostics.odometry import visual_odometry

__all__ = [
    "CORRECTIONS",
    "LAGS",
    "MIN_INLIERS",
    "MIN_VO_PAIRS",
    "MIN_SLOPE",
    "MIN_SIGNIFICANCE",
    "ExtrinsicCheck",
    "check_extrinsics",
    "corrections_of",
    "time_alignment",
    "odometry_of",
    "vo_pairs",
    "vo_in_imu_frame",
    "vo_motion_in_imu_frame",
    "imu_step_twists",
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
#: Candidate lags: the step ``t -> t+1`` uses the velocity sample ``u[t + lag]``.
LAGS = (-2, -1, 0, 1, 2)
#: Frame pairs need at least this many odometry inliers to enter a check.
MIN_INLIERS = 4
#: Fewer usable frame pairs than this: "not enough evidence".
MIN_VO_PAIRS = 30
#: A calibration agrees with the IMU when both VO-vs-IMU slopes exceed this.
MIN_SLOPE = 0.5
#: ... and disagrees when a slope is below ``MIN_SLOPE`` by this many standard errors.
MIN_SIGNIFICANCE = 3.0
#: Verdicts of the extrinsic check, per correction.
AGREES, DISAGREES, UNDECIDED = "agrees", "disagrees", "not enough evidence"


def corrections_of(imu_T_cam):
    """Every axis-flip candidate of a calibration: name -> ``CORRECTIONS[name] @ imu_T_cam``, shape (4, 4) each."""
    return {name: C @ np.asarray(imu_T_cam, dtype=float) for name, C in CORRECTIONS.items()}


def odometry_of(dataset):
    """The robust :class:`~.odometry.VisualOdometry` of ``dataset``, computed once and kept in ``dataset.extra``."""
    if "visual_odometry" not in dataset.extra:
        dataset.extra["visual_odometry"] = visual_odometry(dataset)
    return dataset.extra["visual_odometry"]


def vo_pairs(vo):
    """Frame pairs the checks use, (T-1,) bool: valid odometry with at least :data:`MIN_INLIERS` inliers."""
    return vo.valid & (vo.inliers >= MIN_INLIERS)


def vo_motion_in_imu_frame(vo, imu_T_cam):
    """``imu_T_cam cam_T_next inv(imu_T_cam)`` (T-1, 4, 4): IMU at ``t + 1`` in IMU at ``t``; identity if invalid."""
    return imu_T_cam @ vo.cam_T_next @ lie.se3_inv(imu_T_cam)


def vo_in_imu_frame(vo, imu_T_cam):
    """``se3_log`` of :func:`vo_motion_in_imu_frame`: twists ``[v; w]`` (T-1, 6), as :func:`imu_step_twists`."""
    return lie.se3_log(vo_motion_in_imu_frame(vo, imu_T_cam))


def imu_step_twists(dataset, lag=0):
    """IMU motion over each frame interval, ``tau_t u[t + lag]`` (T-1, 6), ``tau_t = t_{t+1} - t_t``; lag clipped."""
    return dataset.time_steps[:, None] * select_twists(dataset.twists, lag)


def _slope(vo, imu):
    """Least-squares slope ``s`` of ``vo ~ s imu`` over all entries, and its standard error (nan, inf if empty)."""
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
    """Result of :func:`check_extrinsics`, keyed by candidate name.

    Attributes
    ----------
    rotation_slope, translation_slope : dict
        Least-squares slope of the VO motion on the IMU's (rotation vectors, translations): near +1
        when the axes agree, negative rotation slope for a flipped axis pair; NaN without pairs.
    rotation_rms : dict
        RMS of the per-frame rotation disagreement (rad).
    rotation_slope_error, translation_slope_error : float
        Standard errors of the slopes (of the best-fitting candidate; large for a drive with little
        turning), infinite without pairs.
    recommended : str
        The candidate that agrees where the file's calibration disagrees (the best such), or ``"none"``.
    pairs : int
    verdict : dict
        ``"agrees"`` (both slopes above :data:`MIN_SLOPE`), ``"disagrees"`` (a slope below it by
        :data:`MIN_SIGNIFICANCE` standard errors), else (or with fewer than :data:`MIN_VO_PAIRS`
        pairs) ``"not enough evidence"``.
    """

    rotation_slope: dict
    translation_slope: dict
    rotation_rms: dict
    rotation_slope_error: float
    recommended: str
    pairs: int
    translation_slope_error: float = float("inf")
    verdict: dict = field(default_factory=dict)

    def agrees(self, key):
        """Both slopes of correction ``key`` above ``MIN_SLOPE``."""
        return self.rotation_slope[key] > MIN_SLOPE and self.translation_slope[key] > MIN_SLOPE

    def report(self, name=""):
        """Readable evidence, one line per candidate."""
        head = (f"extrinsic check{' of ' + name if name else ''}: visual odometry on {self.pairs} frame pairs "
                f"against the IMU motion through imu_T_cam (slope 1 = agreement)")
        if self.pairs < MIN_VO_PAIRS:
            return head + f": not enough evidence (fewer than {MIN_VO_PAIRS} pairs)"
        lines = [head + f", slope standard errors: rotation {self.rotation_slope_error:.2f}, "
                 f"translation {self.translation_slope_error:.2f}"]
        for key in self.verdict:
            mark = "  <- recommended by the odometry" if key == self.recommended and key != "none" else ""
            lines.append(f"  {key:8s} rotation slope {self.rotation_slope[key]:+6.2f} "
                         f"(rms {1e3 * self.rotation_rms[key]:6.2f} mrad/frame)   "
                         f"translation slope {self.translation_slope[key]:+6.2f}   {self.verdict[key]}{mark}")
        return "\n".join(lines)


def _verdict(rotation, translation, rotation_error, translation_error, pairs):
    """Verdict of one candidate from its slopes and their standard errors."""
    if pairs < MIN_VO_PAIRS:
        return UNDECIDED
    if rotation > MIN_SLOPE and translation > MIN_SLOPE:
        return AGREES
    if (MIN_SLOPE - rotation > MIN_SIGNIFICANCE * rotation_error
            or MIN_SLOPE - translation > MIN_SIGNIFICANCE * translation_error):
        return DISAGREES
    return UNDECIDED


def check_extrinsics(dataset, lag=0, candidates=None):
    """An :class:`ExtrinsicCheck` of each axis-flip correction of ``imu_T_cam`` (or other candidates).

    For every usable frame pair the VO twist in the IMU frame is regressed on ``tau u[t + lag]``.

    Parameters
    ----------
    candidates : dict of str to ndarray (4, 4), optional
        Name -> candidate ``imu_T_cam``; default :func:`corrections_of` the dataset's.
    """
    candidates = corrections_of(dataset.imu_T_cam) if candidates is None else candidates
    vo = odometry_of(dataset)
    used = vo_pairs(vo)
    imu = imu_step_twists(dataset, lag)[used]
    rot_slope, trans_slope, rot_rms, rot_err, trans_err = {}, {}, {}, {}, {}
    for key, imu_T_cam in candidates.items():
        vo_imu = vo_in_imu_frame(vo, imu_T_cam)[used]
        rot_slope[key], rot_err[key] = _slope(vo_imu[:, 3:], imu[:, 3:])
        trans_slope[key], trans_err[key] = _slope(vo_imu[:, :3], imu[:, :3])
        rot_rms[key] = _rms(vo_imu[:, 3:] - imu[:, 3:])
    pairs = int(used.sum())
    rotation_error, translation_error = min(rot_err.values()), min(trans_err.values())
    verdict = {key: _verdict(rot_slope[key], trans_slope[key], rotation_error, translation_error, pairs)
               for key in candidates}
    recommended = "none"
    agreeing = [key for key in candidates if verdict[key] == AGREES]
    if verdict.get("none") == DISAGREES and agreeing:
        recommended = max(agreeing, key=lambda k: rot_slope[k] + trans_slope[k])
    return ExtrinsicCheck(rot_slope, trans_slope, rot_rms, rotation_error, recommended, pairs,
                          translation_error, verdict)


def time_alignment(dataset, imu_T_cam, lags=LAGS):
    """Which velocity sample best explains the odometry's rotation from frame t to t+1 (a dict).

    ``residual``: lag -> median over the usable pairs of ``|log(R_vo) - tau w[t + lag]|`` (rad per
    frame; rotation changes faster than speed, so it carries the timing); ``best``: the lag with the
    smallest, None with fewer than :data:`MIN_VO_PAIRS` pairs; ``pairs``.
    """
    vo = odometry_of(dataset)
    used = vo_pairs(vo)
    rotation = vo_in_imu_frame(vo, imu_T_cam)[used, 3:]
    residual = {}
    for lag in lags:
        imu = imu_step_twists(dataset, lag)[used, 3:]
        norms = np.linalg.norm(rotation - imu, axis=1)
        residual[lag] = float(np.median(norms)) if len(norms) else float("nan")
    pairs = int(used.sum())
    best = min(residual, key=residual.get) if pairs >= MIN_VO_PAIRS else None
    return {"residual": residual, "best": best, "pairs": pairs}
