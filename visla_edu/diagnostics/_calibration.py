"""One decision from the evidence: :func:`calibrate` and the :class:`Calibration` it returns.

The rules (one setting for every drive, never per-drive tuning):

* **Extrinsic correction**: the one the track reprojection chooses (every other correction
  worse with 95% confidence, :class:`~._tracks.TrackScorer`) unless the visual odometry, with
  enough pairs, "disagrees" with it; otherwise the file's calibration (``"none"``).
* **IMU lag**: the track evidence among the lags -2..+2 with that correction; otherwise 0
  (:func:`_decide_lag`).
* **Velocity noise**: white + hold noise per axis, with floors (:mod:`._noise`).
* **Gyro bias and velocity scale**: reported with a standard error and a verdict, not applied.

The result is kept in ``dataset.extra["calibration"]`` and in the user cache (:func:`cache_path`).
"""

import contextlib
import time
from dataclasses import asdict, dataclass

import numpy as np

from visla_edu import cache as user_cache
from visla_edu.motion import dead_reckon
from visla_edu.camera import right_in_left_pixels
from visla_edu.dataset import Dataset, repeated_frames
from visla_edu.diagnostics._correlation import track_correlation
from visla_edu.diagnostics._motion import gyro_bias, velocity_scale
from visla_edu.diagnostics._noise import (MIN_NOISE_SAMPLES, MIN_SIGMA_ANGULAR, MIN_SIGMA_LINEAR,
                                          UNMEASURED_SIGMA_ANGULAR, UNMEASURED_SIGMA_LINEAR, imu_noise)
from visla_edu.diagnostics._readings import ReadingEvidence, _finite_or_none, choose_reading
from visla_edu.diagnostics._report import calibration_report
from visla_edu.diagnostics._tracks import NOT_ENOUGH, TrackEvidence, TrackScorer
from visla_edu.diagnostics._vo import (
    CORRECTIONS,
    DISAGREES,
    LAGS,
    check_extrinsics,
    corrections_of,
    odometry_of,
    time_alignment,
    vo_pairs,
)

__all__ = ["CALIBRATION_VERSION", "CACHED_ARRAYS", "VoEvidence", "Calibration", "calibrate", "cache_path",
           "outlier_indicators"]

#: Bump whenever the diagnostics change what they compute: cached calibrations of older
#: versions are then ignored.
CALIBRATION_VERSION = 6
#: The dataset arrays the cache key is computed from (with ``K_right`` and the readings' left
#: cameras, ``extrinsic_readings``, when the dataset has them).
CACHED_ARRAYS = ("time_stamps", "linear_velocity", "angular_velocity", "K", "b", "imu_T_cam", "frame_ptr",
                 "obs_ids", "obs_z")


@dataclass
class VoEvidence:
    """What the robust visual odometry says (JSON-safe: None where it has no value).

    Attributes
    ----------
    frame_pairs, pairs : int
        Consecutive frame pairs, and those usable (:func:`~._vo.vo_pairs`).
    stale_pairs, stale_points : int
        Frame pairs holding stale copies (:func:`visla_edu.dataset.stale_copies`), and such points.
    rotation_slope, translation_slope, extrinsic_verdict : dict
        Correction -> :class:`~._vo.ExtrinsicCheck`'s slope (at lag ``slope_lag``) and verdict.
    lag_residual, lag_best : list, int or None
        :func:`~._vo.time_alignment`'s residual (rad per frame) for each lag of ``LAGS``, best lag.
    gyro_bias, velocity_scale : dict
        :func:`~._motion.gyro_bias`, :func:`~._motion.velocity_scale` (chosen correction and lag).
    """

    frame_pairs: int
    pairs: int
    stale_pairs: int
    stale_points: int
    slope_lag: int
    rotation_slope: dict
    translation_slope: dict
    rotation_slope_error: object
    translation_slope_error: object
    extrinsic_verdict: dict
    lag_residual: list
    lag_best: object
    gyro_bias: dict
    velocity_scale: dict


@dataclass
class Calibration:
    """What the filter will use, and why.

    Attributes
    ----------
    extrinsic_correction, imu_T_cam : str, ndarray (4, 4)
        Key of :data:`CORRECTIONS`, and ``CORRECTIONS[extrinsic_correction] @`` the file's
        ``imu_T_cam`` (or the chosen reading's).
    sigma_linear_velocity, sigma_angular_velocity : ndarray, shape (3,)
        Velocity noise per axis (m/s, rad/s): :func:`~._noise.imu_noise`'s ``sigma``.
    white_noise, hold_noise : ndarray, shape (6,)
        Its two parts, linear axes first.
    reasons : dict
        ``"extrinsic_correction"``, ``"imu_lag"``, ``"noise"`` -> one line of why.
    repeated_frames, outliers : list of int, dict
        Frames repeating the previous frame exactly; :func:`outlier_indicators`.
    track_correlation, correlated_tracks : float, int
        :func:`~._correlation.track_correlation` along the dead-reckoned poses (chosen lag, correction).
    seconds, source, version : float, str, int
        Time the computation took; ``"computed"`` or ``"cache <path>"``; the
        :data:`CALIBRATION_VERSION` of the code that computed it.
    reading : ReadingEvidence or None
        The reading of a file whose extrinsics have several (:func:`~._readings.choose_reading`).
    """

    extrinsic_correction: str
    imu_T_cam: np.ndarray
    imu_lag: int
    sigma_linear_velocity: np.ndarray
    sigma_angular_velocity: np.ndarray
    white_noise: np.ndarray
    hold_noise: np.ndarray
    reasons: dict
    tracks: TrackEvidence
    vo: VoEvidence
    repeated_frames: list
    outliers: dict
    track_correlation: float = 0.0
    correlated_tracks: int = 0
    seconds: float = 0.0
    source: str = "computed"
    version: int = CALIBRATION_VERSION
    reading: ReadingEvidence = None

    _ARRAYS = {"imu_T_cam": (4, 4), "sigma_linear_velocity": (3,), "sigma_angular_velocity": (3,),
               "white_noise": (6,), "hold_noise": (6,)}

    def report(self, name=""):
        """The readable evidence and decision: what ``visla-edu info`` prints."""
        return calibration_report(self, name)

    def to_dict(self):
        """JSON-safe dict (arrays as nested lists); :meth:`from_dict` inverts it."""
        out = {key: value for key, value in asdict(self).items() if key not in ("tracks", "vo", "source", "reading")}
        for key in self._ARRAYS:
            out[key] = np.asarray(getattr(self, key), dtype=float).tolist()
        out["tracks"] = self.tracks.to_dict()
        out["vo"] = asdict(self.vo)
        out["reading"] = None if self.reading is None else self.reading.to_dict()
        return out

    @classmethod
    def from_dict(cls, d, source="computed"):
        """A :class:`Calibration` from :meth:`to_dict`'s output; ValueError if it is malformed."""
        try:
            fields = dict(d)
            for key, shape in cls._ARRAYS.items():
                fields[key] = np.array(fields[key], dtype=float)
                if fields[key].shape != shape or not np.all(np.isfinite(fields[key])):
                    raise ValueError(f"{key} must be finite with shape {shape}, got {fields[key].shape}")
            fields["tracks"] = TrackEvidence.from_dict(fields["tracks"])
            fields["vo"] = VoEvidence(**fields["vo"])
            fields["reading"] = None if fields.get("reading") is None else ReadingEvidence.from_dict(fields["reading"])
            if fields["extrinsic_correction"] not in CORRECTIONS:
                raise ValueError(f"unknown extrinsic_correction {fields['extrinsic_correction']!r}")
            _check_decisions(fields)
            return cls(**fields, source=source)
        except (KeyError, TypeError, AttributeError) as err:
            raise ValueError(f"Calibration.from_dict: malformed calibration ({type(err).__name__}: {err})") from None


def _check_decisions(fields):
    """ValueError unless the lag, noise and report fields are what :func:`calibrate` writes (an edited cache)."""
    lag = fields["imu_lag"]
    if type(lag) is not int or lag not in LAGS:
        raise ValueError(f"imu_lag must be one of {LAGS}, got {lag!r}")
    for key, floor in (("sigma_linear_velocity", MIN_SIGMA_LINEAR), ("sigma_angular_velocity", MIN_SIGMA_ANGULAR)):
        if not np.all(fields[key] >= floor):
            raise ValueError(f"{key} must be at least {floor:g} (the floor), got {fields[key].tolist()}")
    if not (np.all(fields["white_noise"] >= 0) and np.all(fields["hold_noise"] >= 0)):
        raise ValueError("white_noise and hold_noise must not be negative")
    reasons, outliers, repeated = fields["reasons"], fields["outliers"], fields["repeated_frames"]
    if not all(isinstance(reasons.get(k, ""), str) for k in ("extrinsic_correction", "imu_lag", "noise")):
        raise ValueError(f"reasons must be text, got {reasons!r}")
    shares = [outliers[k] for k in ("non_positive_disparity", "epipolar", "vo_rejected")]
    if not all(type(x) in (int, float) and 0 <= x <= 1 for x in shares):
        raise ValueError(f"outliers must be shares in [0, 1], got {outliers!r}")
    if not all(type(t) is int and t >= 0 for t in repeated):
        raise ValueError(f"repeated_frames must be frame indices, got {repeated!r}")
    rho, tracks = fields.get("track_correlation"), fields.get("correlated_tracks")
    if type(rho) not in (int, float) or not -1 <= rho <= 1 or type(tracks) is not int or tracks < 0:
        raise ValueError(f"track_correlation must be in [-1, 1] and correlated_tracks a count, got {rho!r}, {tracks!r}")


def _noise_reason(noise, samples):
    """How the filter's velocity noise was chosen, one line."""
    if noise["measured"]:
        return (f"measured from {samples} velocity samples: sqrt(white^2 + hold^2), floors {MIN_SIGMA_LINEAR:g} m/s "
                f"and {MIN_SIGMA_ANGULAR:g} rad/s")
    return (f"not measured: {samples} velocity samples, fewer than {MIN_NOISE_SAMPLES}; the course's "
            f"{UNMEASURED_SIGMA_LINEAR:g} m/s and {UNMEASURED_SIGMA_ANGULAR:g} rad/s")


def outlier_indicators(dataset, epipolar_px=3.0):
    """A dict of the shares in [0, 1] of the observations that break the rectified stereo geometry.

    ``non_positive_disparity`` (``uL - uR <= 0``), ``epipolar`` (``|vL - vR| > epipolar_px``, px)
    and ``vo_rejected`` (tracked points of the valid odometry pairs that are not inliers). With two
    intrinsics the right pixels are first mapped into the left camera's
    (:func:`visla_edu.camera.right_in_left_pixels`).
    """
    z = right_in_left_pixels(dataset.obs_z, dataset.K, dataset.K_right)
    n = max(len(z), 1)
    vo = odometry_of(dataset)
    tracked = int(vo.tracked[vo.valid].sum())
    return {
        "non_positive_disparity": float(np.sum(z[:, 0] - z[:, 2] <= 0) / n),
        "epipolar": float(np.sum(np.abs(z[:, 1] - z[:, 3]) > epipolar_px) / n),
        "vo_rejected": float(1 - vo.inliers[vo.valid].sum() / tracked) if tracked else 0.0,
    }


def _decide_correction(choice, check):
    """The correction to use and why, from the track choice and the odometry's check."""
    if choice.chosen is None:
        return "none", f"kept the file's imu_T_cam ('none'): track reprojection, {choice.verdict}"
    vo_says = check.verdict[choice.chosen]
    if vo_says == DISAGREES:
        return "none", (f"kept the file's imu_T_cam ('none'): track reprojection chooses {choice.chosen!r} "
                        f"but the visual odometry disagrees with it")
    what = "no correction" if choice.chosen == "none" else f"correction {choice.chosen!r}"
    return choice.chosen, (f"{what}: every other correction has a larger track-reprojection error "
                           f"with 95% confidence; visual odometry: {vo_says}")


def _decide_lag(choice):
    """The lag and why: one that beats every other with 95% confidence, else the best if it beats lag 0 so.

    The lags it cannot be told from then all beat 0 too; otherwise the course's convention, 0.
    """
    if choice.chosen is not None:
        return int(choice.chosen), "every other lag has a larger track-reprojection error with 95% confidence"
    over_zero = choice.margins.get("+0")
    if choice.best not in (None, 0) and over_zero is not None and over_zero[1] > 0:
        return int(choice.best), (f"lag {int(choice.best):+d} beats lag 0 with 95% confidence "
                                  f"(by {over_zero[0]:.2f} px, 95% lower bound {over_zero[1]:+.2f} px); "
                                  f"{choice.verdict.removeprefix(NOT_ENOUGH + ': ')}")
    return 0, f"kept lag 0: track reprojection, {choice.verdict}"


def _vo_evidence(dataset, check, slope_lag, imu_T_cam, lag):
    """Collect the odometry's evidence at the chosen calibration into a :class:`VoEvidence`."""
    vo = odometry_of(dataset)
    timing = time_alignment(dataset, imu_T_cam, LAGS)
    return VoEvidence(
        frame_pairs=len(vo.valid), pairs=int(vo_pairs(vo).sum()), stale_pairs=int(np.sum(vo.stale > 0)),
        stale_points=int(vo.stale.sum()), slope_lag=int(slope_lag),
        rotation_slope={k: _finite_or_none(v) for k, v in check.rotation_slope.items()},
        translation_slope={k: _finite_or_none(v) for k, v in check.translation_slope.items()},
        rotation_slope_error=_finite_or_none(check.rotation_slope_error),
        translation_slope_error=_finite_or_none(check.translation_slope_error),
        extrinsic_verdict=dict(check.verdict),
        lag_residual=[_finite_or_none(timing["residual"][lag_]) for lag_ in LAGS], lag_best=timing["best"],
        gyro_bias=gyro_bias(dataset, imu_T_cam, lag), velocity_scale=velocity_scale(dataset, imu_T_cam, lag))


def _check_inputs(dataset):
    """TypeError for a non-dataset, ValueError naming the first bad time stamp or velocity sample."""
    if not isinstance(dataset, Dataset):
        raise TypeError(f"calibrate: expected a visla_edu.dataset.Dataset, got {type(dataset).__name__}")
    stamps = np.asarray(dataset.time_stamps, dtype=float).reshape(-1)
    for name in ("linear_velocity", "angular_velocity"):
        shape = np.shape(getattr(dataset, name))
        if shape != (len(stamps), 3):
            raise ValueError(f"calibrate: {dataset.name}: {name} must have shape ({len(stamps)}, 3), one sample "
                             f"per time stamp, got {shape}")
    bad = ~np.all(np.isfinite(dataset.twists), axis=1) | ~np.isfinite(stamps)
    if bad.any():
        raise ValueError(f"calibrate: {dataset.name}: non-finite time stamp or velocity at frame {np.argmax(bad)}; "
                         f"fix or drop it before calibrating")
    if np.any(np.diff(stamps) <= 0):
        raise ValueError(f"calibrate: {dataset.name}: time stamps must increase, but frame "
                         f"{np.argmax(np.diff(stamps) <= 0) + 1} does not")


def _compute(dataset):
    """The calibration of ``dataset`` from its data (no cache)."""
    start = time.perf_counter()
    odometry_of(dataset)  # checks the pixels
    base, reading = dataset.imu_T_cam, None
    if dataset.extrinsic_readings:
        chosen, reading = choose_reading(dataset)
        base = chosen.imu_T_left
    scorer = TrackScorer(dataset, corrections_of(base))
    correction_choice = scorer.choose_correction()
    slope_lag = scorer.best_lag(correction_choice.best or "none")
    check = check_extrinsics(dataset, slope_lag, corrections_of(base))
    correction, why_correction = _decide_correction(correction_choice, check)
    lag_choice = scorer.choose_lag(correction)
    lag, why_lag = _decide_lag(lag_choice)
    imu_T_cam = CORRECTIONS[correction] @ base
    noise = imu_noise(dataset.twists)
    rho, correlated = track_correlation(dataset, dead_reckon(dataset.time_stamps, dataset.twists, lag=lag), imu_T_cam)
    return Calibration(
        extrinsic_correction=correction, imu_T_cam=imu_T_cam, imu_lag=lag,
        sigma_linear_velocity=noise["sigma"][:3], sigma_angular_velocity=noise["sigma"][3:],
        white_noise=noise["white"], hold_noise=noise["hold"],
        reasons={"extrinsic_correction": why_correction, "imu_lag": why_lag,
                 "noise": _noise_reason(noise, dataset.num_frames)},
        tracks=scorer.evidence(correction_choice, lag_choice),
        vo=_vo_evidence(dataset, check, slope_lag, imu_T_cam, lag),
        repeated_frames=repeated_frames(dataset), outliers=outlier_indicators(dataset),
        track_correlation=rho, correlated_tracks=correlated, seconds=time.perf_counter() - start, reading=reading)


def cache_path(dataset):
    """The cache file of ``dataset``'s calibration, a :class:`pathlib.Path` (nothing is created).

    ``<cache dir>/calibration-<hash>.json`` in :func:`visla_edu.cache.cache_dir`, the
    :func:`visla_edu.cache.content_hash` of :data:`CACHED_ARRAYS` and :data:`CALIBRATION_VERSION`; a
    ValueError when the cache folder's name cannot be expanded.
    """
    arrays = {name: getattr(dataset, name) for name in CACHED_ARRAYS}
    if dataset.K_right is not None:
        arrays["K_right"] = dataset.K_right
    if dataset.extrinsic_readings:
        arrays["extrinsic_readings"] = np.stack([r.imu_T_left for r in dataset.extrinsic_readings])
    key = user_cache.content_hash(arrays, f"visla-edu calibration {CALIBRATION_VERSION}")
    return user_cache.cache_dir() / f"calibration-{key}.json"


def _load(path):
    """The calibration cached at ``path``, or None (missing, corrupt, unreportable, another version)."""
    stored = user_cache.load_json(path)
    if stored is None or stored.get("version") != CALIBRATION_VERSION:
        return None
    try:
        calibration = Calibration.from_dict(stored.get("calibration"), source=f"cache {path}")
        calibration.report()
    except (ValueError, TypeError, KeyError, AttributeError, IndexError):
        return None
    return calibration


def calibrate(dataset, cache=True):
    """The :class:`Calibration` of a drive from its own data, by the module docstring's rules.

    Parameters
    ----------
    cache : bool
        Reuse and store the result in the user cache folder (:func:`cache_path`); a corrupt cache
        file is recomputed, a folder that cannot be written is skipped.

    Raises
    ------
    ValueError
        A non-finite time stamp, velocity or pixel, non-increasing time stamps or misshapen velocities.
    """
    _check_inputs(dataset)
    if "calibration" in dataset.extra:
        return dataset.extra["calibration"]
    path = None
    if cache:
        with contextlib.suppress(ValueError):  # a cache folder whose name cannot be expanded: no cache, never an error
            path = cache_path(dataset)
    calibration = _load(path) if path is not None else None
    if calibration is None:
        calibration = _compute(dataset)
        if path is not None:
            user_cache.save_json(path, {"version": CALIBRATION_VERSION, "calibration": calibration.to_dict()})
    dataset.extra["calibration"] = calibration
    return calibration
