"""The single checks the course and the driver have always used, with :func:`~._calibration.calibrate`'s defaults."""

import numpy as np

from visla_edu.diagnostics._calibration import calibrate
from visla_edu.diagnostics._motion import gyro_bias
from visla_edu.diagnostics._noise import imu_noise
from visla_edu.diagnostics._vo import CORRECTIONS, DISAGREES, LAGS, time_alignment

__all__ = ["resolve_extrinsics", "check_time_alignment", "imu_noise_and_bias", "diagnose"]


def resolve_extrinsics(dataset, correction="auto"):
    """The ``imu_T_cam`` to use and a line to print about it.

    Parameters
    ----------
    correction : str
        ``"auto"`` (what :func:`calibrate` decides), or a key of :data:`CORRECTIONS` applied to
        ``dataset.imu_T_cam`` (the loader's reading); ValueError otherwise.

    Returns
    -------
    imu_T_cam : ndarray, shape (4, 4)
    evidence : str
        Why a correction was applied, or ``""``; with ``"auto"`` also a 2025+ file's chosen reading
        and the warnings (:func:`_unexplained_extrinsic_warning`).
    """
    if correction == "auto":
        calibration = calibrate(dataset)
        reading = _reading_lines(calibration)
        if calibration.extrinsic_correction == "none":
            imu_T_cam = dataset.imu_T_cam if calibration.reading is None else calibration.imu_T_cam
            return imu_T_cam, "\n".join(filter(None, [reading, _unexplained_extrinsic_warning(calibration)]))
        return calibration.imu_T_cam, "\n".join(filter(None, [reading, (
            f"applied extrinsic correction {calibration.extrinsic_correction!r} (extrinsic_correction='auto'): "
            f"{calibration.reasons['extrinsic_correction']}")]))
    if correction not in CORRECTIONS:
        raise ValueError(f"extrinsic_correction must be 'auto' or one of {list(CORRECTIONS)}, got {correction!r}")
    if correction == "none":
        return dataset.imu_T_cam, ""
    return CORRECTIONS[correction] @ dataset.imu_T_cam, f"applied extrinsic correction {correction!r} as requested"


def _reading_lines(calibration):
    """The chosen reading of a 2025+ file's extrinsics and its warning (``""`` for other files)."""
    reading = calibration.reading
    if reading is None:
        return ""
    line = f"extrinsics read as {reading.chosen!r} (extL_T_imu, extR_T_imu): {reading.reason}"
    return line + (f"\n{reading.warning}" if reading.warning else "")


#: Largest |rotation slope| (odometry vs IMU) of every correction below which the extrinsic is
#: unexplained: an inverted one gives 0.02-0.05 on the course files, a sound one 0.84-1.0, and a
#: 60-frame simulated drive 0.25.
UNEXPLAINED_SLOPE = 0.15


def _unexplained_extrinsic_warning(calibration):
    """A warning (or ``""``) when the odometry contradicts ``imu_T_cam`` and every axis correction of it."""
    verdicts = calibration.vo.extrinsic_verdict if calibration.vo is not None else {}
    if not verdicts or any(v != DISAGREES for v in verdicts.values()):
        return ""
    slopes = [abs(v) for v in calibration.vo.rotation_slope.values() if v is not None]
    if not slopes or max(slopes) >= UNEXPLAINED_SLOPE:
        return ""  # a short or straight drive attenuates every slope alike (sim-tiny: 0.25)
    return (f"warning: the visual odometry contradicts the file's imu_T_cam and every axis correction of it (rotation "
            f"slopes at most {max(slopes):.2f}, 1 expected): is it stored inverted (cam_T_imu), or in another "
            "convention (or the angular velocity in deg/s)? "
            "Expect a poor estimate; check them (visla-edu info shows the evidence)")


def check_time_alignment(dataset, imu_T_cam=None, lags=LAGS):
    """Which velocity sample best explains the odometry's rotation (a dict, :func:`~._vo.time_alignment`).

    ``imu_T_cam`` defaults to :func:`calibrate`'s; ``lags`` are the candidates.
    """
    if imu_T_cam is None:
        imu_T_cam = calibrate(dataset).imu_T_cam
    return time_alignment(dataset, imu_T_cam, lags)


def imu_noise_and_bias(dataset, imu_T_cam=None, lag=0):
    """IMU noise levels from the velocities and the gyro bias seen by the visual odometry.

    ``imu_T_cam`` defaults to :func:`calibrate`'s; ``lag`` is the gyro-bias comparison's.

    Returns
    -------
    dict
        ``linear_noise`` (3,) m/s, ``angular_noise`` (3,) rad/s: the white noise; ``linear_hold``,
        ``angular_hold`` (3,): the hold noise (:func:`~._noise.imu_noise`); ``gyro_bias`` (3,)
        rad/s, ``gyro_bias_stderr`` (3,) (NaN and inf without usable pairs) and
        ``gyro_bias_verdict`` (:func:`~._motion.gyro_bias`).
    """
    if imu_T_cam is None:
        imu_T_cam = calibrate(dataset).imu_T_cam
    noise = imu_noise(dataset.twists)
    bias = gyro_bias(dataset, imu_T_cam, lag)
    known = bias["bias"] is not None
    return {
        "linear_noise": noise["white"][:3], "angular_noise": noise["white"][3:],
        "linear_hold": noise["hold"][:3], "angular_hold": noise["hold"][3:],
        "gyro_bias": np.array(bias["bias"]) if known else np.full(3, np.nan),
        "gyro_bias_stderr": np.array(bias["stderr"]) if known else np.full(3, np.inf),
        "gyro_bias_verdict": bias["verdict"],
    }


def diagnose(dataset):
    """What ``visla-edu info`` prints: the :meth:`Calibration.report` of :func:`calibrate` (and its errors)."""
    return calibrate(dataset).report(dataset.name)
