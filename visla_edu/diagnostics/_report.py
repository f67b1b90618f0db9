"""The readable report of a :class:`~._calibration.Calibration` (what ``visla-edu info`` prints).

Nothing here computes; a value that could not be measured is printed as "not enough evidence", never NaN.
"""

import numpy as np

from visla_edu.diagnostics._tracks import BLOCK, MAX_GAP, MIN_DISPARITY
from visla_edu.diagnostics._vo import CORRECTIONS, LAGS, MIN_INLIERS

__all__ = ["calibration_report"]


def _vector(values, digits=4):
    """``[a b c]`` rounded, or "n/a" for None."""
    return "n/a" if values is None else np.array2string(np.round(np.asarray(values, float), digits), separator=" ")


def _track_lines(tracks):
    """Scores of every candidate and the two verdicts."""
    lines = [f"track reprojection: {tracks.pairs} pairs of {tracks.landmarks} landmarks (first observation with "
             f"disparity > {MIN_DISPARITY:g} px moved 1-{MAX_GAP} frames by the dead-reckoned IMU motion), "
             f"bootstrap over {tracks.groups} blocks of {BLOCK} anchor frames; median left-image error (px) when "
             f"step t->t+1 uses u[t+lag]:"]
    lines.append("  correction " + " ".join(f"lag {lag:+d}".rjust(8) for lag in tracks.lags))
    for name, scores in tracks.scores.items():
        cells = " ".join(("n/a" if s is None else f"{s:.2f}").rjust(8) for s in scores)
        lines.append(f"  {name:10s} {cells}")
    for label, choice in (("extrinsic correction", tracks.correction), ("IMU lag", tracks.lag)):
        margins = ", ".join(f"{k} +{d:.2f} px (95% lower bound {lo:+.2f})" for k, (d, lo) in choice.margins.items())
        if choice.best is None:
            best = "no scored pairs"
        else:
            best = "best " + (f"{choice.best:+d}" if isinstance(choice.best, int) else repr(choice.best))
        lines.append(f"  {label}: {best}, {choice.verdict}" + (f"; others: {margins}" if margins else ""))
    return lines


def _slope_lines(vo):
    """The odometry's extrinsic check, one line per correction."""
    head = (f"  extrinsic check: slope of the odometry's motion on the IMU's through imu_T_cam (1 = agreement, "
            f"lag {vo.slope_lag:+d})")
    if vo.rotation_slope_error is None or all(v == "not enough evidence" for v in vo.extrinsic_verdict.values()):
        return [head + ": not enough evidence"]
    lines = [head + f", standard errors: rotation {vo.rotation_slope_error:.3f}, "
             f"translation {vo.translation_slope_error:.3f}"]
    for name in CORRECTIONS:
        lines.append(f"    {name:8s} rotation slope {vo.rotation_slope[name]:+6.2f}, translation slope "
                     f"{vo.translation_slope[name]:+6.2f}: {vo.extrinsic_verdict[name]}")
    return lines


def _vo_lines(vo, repeated):
    """Coverage, slopes, time alignment, gyro bias and velocity scale."""
    lines = [f"visual odometry (robust RANSAC stereo, pairs with >= {MIN_INLIERS} inliers): {vo.pairs} of "
             f"{vo.frame_pairs} frame pairs usable; {vo.stale_pairs} pairs hold stale copies "
             f"({vo.stale_points} points repeating the previous frame bit for bit, left out)"]
    lines += _slope_lines(vo)
    if vo.lag_best is None:
        lines.append("  time alignment, median rotation disagreement per lag: not enough evidence")
    else:
        residuals = ", ".join(f"lag {lag:+d}: {1e3 * r:.3f}" for lag, r in zip(LAGS, vo.lag_residual))
        lines.append(f"  time alignment, median rotation disagreement (mrad/frame) when step t->t+1 uses u[t+lag]: "
                     f"{residuals}  -> best lag {vo.lag_best:+d}")
    bias = vo.gyro_bias
    lines.append(f"  gyro bias vs visual odometry: {_vector(bias['bias'], 4)} +- {_vector(bias['stderr'], 4)} rad/s "
                 f"({bias['pairs']} pairs): {bias['verdict']} (reported, not applied)")
    scale = vo.velocity_scale
    value = "n/a" if scale["scale"] is None else f"{scale['scale']:.3f} +- {scale['stderr']:.3f}"
    lines.append(f"  velocity scale |t_vo| / |tau v_imu|: {value} ({scale['pairs']} pairs): {scale['verdict']} "
                 f"(reported, not applied)")
    lines.append(f"frames repeating the previous frame exactly: {repeated if repeated else 'none'}")
    return lines


def _reading_lines(reading):
    """The four readings of a 2025+ file's extrinsics, their evidence, the choice and any warning."""
    lines = ["extrinsics: extL_T_imu, extR_T_imu read four ways (camera->IMU or IMU->camera, optical or regular "
             "camera frame); the evidence for each:",
             f"  {'reading':22s} {'right camera in the left camera':>32s} {'rotation':>11s} {'track px':>9s} "
             f"{'odometry slopes rot/trans':>26s}"]
    for name in reading.names:
        geometry, scores = reading.geometry[name], [x for x in reading.track_scores[name] if x is not None]
        offset = "[" + ", ".join(f"{x:+.3f}" for x in geometry["offset"]) + "] m"
        track = f"{min(scores):.2f}" if scores else "n/a"
        slopes = "/".join("n/a" if v is None else f"{v:+.2f}" for v in (reading.rotation_slope[name],
                                                                         reading.translation_slope[name]))
        rig = "rectified" if not geometry["problem"] else "not rectified"
        lines.append(f"  {name:22s} {offset:>32s} {geometry['rotation_deg']:7.2f} deg {track:>9s} {slopes:>14s} "
                     f"{reading.vo_verdict[name]:>11s}; {rig}")
    margins = ", ".join(f"{k} +{d:.2f} px (95% lower bound {lo:+.2f})" for k, (d, lo) in reading.track.margins.items())
    best = "no scored pairs" if reading.track.best is None else f"best {reading.track.best!r}"
    lines.append(f"  track reprojection among the readings: {best}, {reading.track.verdict}"
                 + (f"; others: {margins}" if margins else ""))
    lines.append(f"  read as {reading.chosen!r} (the loader started from {reading.loader!r}): {reading.reason}")
    return lines + ([f"  {reading.warning}"] if reading.warning else [])


def calibration_report(calibration, name=""):
    """Readable report (str) of a :class:`Calibration` of dataset ``name``, ending "the filter will use: ..."."""
    c = calibration
    origin = ("computed" if c.source == "computed" else f"reused from the {c.source}")
    lines = [f"calibration from the data{' of ' + name if name else ''} ({origin}; "
             f"computing it took {c.seconds:.2f} s)"]
    lines += _reading_lines(c.reading) if c.reading is not None else []
    lines += _track_lines(c.tracks)
    lines += _vo_lines(c.vo, c.repeated_frames)
    noise_reason = c.reasons.get("noise", "")
    if noise_reason.startswith("not measured"):
        lines.append(f"IMU noise per axis from the velocities: {noise_reason}")
    else:
        lines.append(f"IMU noise per axis from the velocities: white (second differences) linear "
                     f"{_vector(c.white_noise[:3])} m/s, angular {_vector(c.white_noise[3:], 5)} rad/s; hold (change "
                     f"within a step) linear {_vector(c.hold_noise[:3])} m/s, angular {_vector(c.hold_noise[3:], 5)} rad/s")
    out = c.outliers
    lines.append(f"observations with non-positive disparity: {100 * out['non_positive_disparity']:.2f}%, "
                 f"breaking the epipolar line by > 3 px: {100 * out['epipolar']:.2f}%, "
                 f"tracked points rejected by visual odometry: {100 * out['vo_rejected']:.1f}%")
    lines.append(f"residual correlation along tracks (dead-reckoned poses): rho {c.track_correlation:+.2f} over "
                 f"{c.correlated_tracks} tracks, so a track of L observations is worth about "
                 f"{(1 - c.track_correlation) / (1 + c.track_correlation):.2f} L independent ones "
                 f"(the dead reckoning's own drift adds to it where the gyro is noisy; pixel_noise_inflation='auto' reads it "
                 f"only where the gyro beats the camera)")
    lines.append(f"extrinsic correction: {c.reasons['extrinsic_correction']}")
    lines.append(f"IMU lag: {c.reasons['imu_lag']}")
    lines.append(f"the filter will use: extrinsic_correction {c.extrinsic_correction!r}, imu_lag {c.imu_lag:+d}, "
                 f"sigma_linear_velocity {_vector(c.sigma_linear_velocity)} m/s, sigma_angular_velocity "
                 f"{_vector(c.sigma_angular_velocity, 5)} rad/s ({noise_reason or 'sqrt(white^2 + hold^2)'}; "
                 f"gyro bias and velocity scale are not applied)")
    return "\n".join(lines)
