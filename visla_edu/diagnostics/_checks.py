"""The single checks with their defaults taken from :func:`~._calibration.calibrate`.

These keep the names the course and the driver have always used: :func:`resolve_extrinsics`
(the camera the filter uses), :func:`check_time_alignment` and :func:`imu_noise_and_bias`
(with the calibration found by default), and :func:`diagnose` (the report).
"""

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
    dataset : visla_edu.dataset.Dataset
    correction : str
        ``"auto"`` (what :func:`calibrate` decides), ``"none"`` or a key of :data:`CORRECTIONS`.

    Returns
    -------
    imu_T_cam : ndarray, shape (4, 4)
    evidence : str
        Why a correction was applied; with ``"auto"`` keeping the file's calibration, a
        warning when the odometry contradicts it and every correction of it (an inverted or
        foreign extrinsic, see :data:`UNEXPLAINED_SLOPE`); for a file whose extrinsics have
        several readings (2025+), first the reading chosen and why (and any warning). Empty
        otherwise. An explicit ``correction`` applies to ``dataset.imu_T_cam``, the loader's
        reading.

    Raises
    ------
    ValueError
        An unknown ``correction``.
    """
    if correction == "auto":
        calibration = calibrate(dataset)
        reading = _reading_lines(calibration)
        if calibration.extrinsic_correction == "none":
            if calibration.reading is not None:
                warning = _unexplained_extrinsic_warning(calibration)
                return calibration.imu_T_cam, "\n".join(filter(None, [reading, warning]))
            return dataset.imu_T_cam, _unexplained_extrinsic_warning(calibration)
        return calibration.imu_T_cam, "\n".join(filter(None, [reading, (
            f"applied extrinsic correction {calibration.extrinsic_correction!r} (extrinsic_correction='auto'): "
            f"{calibration.reasons['extrinsic_correction']}")]))
    if correction not in CORRECTIONS:
        raise ValueError(f"extrinsic_correction must be 'auto' or one of {list(CORRECTIONS)}, got {correction!r}")
    if correction == "none":
        return dataset.imu_T_cam, ""
    return CORRECTIONS[correction] @ dataset.imu_T_cam, f"applied extrinsic correction {correction!r} as requested"


def _reading_lines(calibration):
    """The reading of a 2025+ file's extrinsics the calibration chose, and its warning (``""`` for other files)."""
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
    """A warning when the odometry contradicts the file's ``imu_T_cam`` and every axis correction of it.

    That happens for an inverted extrinsic (``cam_T_imu`` stored as ``imu_T_cam``) or one in
    another convention, never on the course files (one candidate agrees on each), and the
    filters then produce garbage: the run goes on, but says so.
    """
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
    """Which velocity sample best explains the odometry's rotation from frame t to t+1.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    imu_T_cam : ndarray, shape (4, 4), optional
        Calibration to use (default: the one :func:`calibrate` chooses).
    lags : sequence of int
        Candidate offsets: the step ``t -> t+1`` uses ``u[t + lag]``.

    Returns
    -------
    dict
        ``residual`` (lag -> median rotation disagreement, rad per frame), ``best`` (or None
        without enough pairs), ``pairs``; see :func:`visla_edu.diagnostics._vo.time_alignment`.
    """
    if imu_T_cam is None:
        imu_T_cam = calibrate(dataset).imu_T_cam
    return time_alignment(dataset, imu_T_cam, lags)


def imu_noise_and_bias(dataset, imu_T_cam=None, lag=0):
    """IMU noise levels from the velocities and the gyro bias seen by the visual odometry.

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset
    imu_T_cam : ndarray, shape (4, 4), optional
        Calibration for the odometry (default: the one :func:`calibrate` chooses).
    lag : int
        The step ``t -> t+1`` uses ``u[t + lag]`` in the gyro-bias comparison.

    Returns
    -------
    dict
        ``linear_noise`` (3,) m/s and ``angular_noise`` (3,) rad/s: the white noise from second
        differences; ``linear_hold``, ``angular_hold`` (3,): the hold noise; ``gyro_bias`` (3,)
        rad/s and ``gyro_bias_stderr`` (3,) (NaN and inf without usable pairs), ``gyro_bias_verdict``.
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
    """The readable report of :func:`calibrate` (str): the diagnostics' evidence and decision.

    Runs :func:`calibrate` with its defaults, so a result already kept in
    ``dataset.extra["calibration"]`` or in the user cache is reused (and a new one is kept in
    both).

    Parameters
    ----------
    dataset : visla_edu.dataset.Dataset

    Returns
    -------
    str
        :meth:`Calibration.report` with the dataset's name: what ``visla-edu info`` prints,
        ending with "the filter will use: ...".

    Raises
    ------
    TypeError, ValueError
        As :func:`calibrate`.
    """
    return calibrate(dataset).report(dataset.name)
