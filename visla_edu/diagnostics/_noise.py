"""The IMU velocity noise the filter should assume, per axis, from the velocities alone.

``sigma = sqrt(white^2 + hold^2)``, floored at :data:`MIN_SIGMA_LINEAR`, :data:`MIN_SIGMA_ANGULAR`:

* **white**, the sensor's noise: ``white = 1.4826 MAD(second differences) / sqrt(6)``, as
  ``var(x[t+1] - 2 x[t] + x[t-1]) = 6 s^2`` for a smooth signal plus white noise ``s``.
* **hold**, the error of holding each sample over its step (half the change on average):
  ``hold = sqrt(max(rms(diff)^2 - 2 white^2, 0)) / 2``, as ``rms(diff)^2 = change^2 + 2 white^2``,
  leaving out first differences beyond :data:`GLITCH_MADS` robust sigmas.

Under :data:`MIN_NOISE_SAMPLES` samples neither part is measured: the noise is then
:data:`UNMEASURED_SIGMA_LINEAR`, :data:`UNMEASURED_SIGMA_ANGULAR`, not the floors.
"""

import numpy as np

__all__ = ["imu_noise", "MIN_SIGMA_LINEAR", "MIN_SIGMA_ANGULAR", "MIN_NOISE_SAMPLES", "UNMEASURED_SIGMA_LINEAR",
           "UNMEASURED_SIGMA_ANGULAR"]

#: Floor of the linear velocity noise (m/s).
MIN_SIGMA_LINEAR = 1e-3
#: Floor of the angular velocity noise (rad/s).
MIN_SIGMA_ANGULAR = 1e-4
#: Fewer velocity samples than this: the noise is not measured (:data:`UNMEASURED_SIGMA_LINEAR`).
MIN_NOISE_SAMPLES = 10
#: Linear velocity noise (m/s) of a drive too short to measure it: the course's value.
UNMEASURED_SIGMA_LINEAR = 0.5
#: Angular velocity noise (rad/s) of a drive too short to measure it: the course's value.
UNMEASURED_SIGMA_ANGULAR = 0.05
_MAD_TO_SIGMA = 1.4826
#: First differences farther than this many robust standard deviations from their median are
#: glitches, not motion (a car's acceleration and turn rate stay well inside it).
GLITCH_MADS = 20.0


def imu_noise(twists):
    """White and hold noise of each axis of ``twists`` (T, 6) and the filter's noise from them.

    Returns
    -------
    dict
        ``white``, ``hold``, ``sigma`` (6,), linear axes first; ``measured`` (False for a drive too
        short: parts 0, ``sigma`` the unmeasured values).
    """
    twists = np.asarray(twists, dtype=float)
    floor = np.repeat([MIN_SIGMA_LINEAR, MIN_SIGMA_ANGULAR], 3)
    if twists.ndim != 2 or twists.shape[1] != 6:
        raise ValueError(f"imu_noise: twists must have shape (T, 6) as [v; w], got {twists.shape}")
    if len(twists) < MIN_NOISE_SAMPLES:
        unmeasured = np.repeat([UNMEASURED_SIGMA_LINEAR, UNMEASURED_SIGMA_ANGULAR], 3)
        return {"white": np.zeros(6), "hold": np.zeros(6), "sigma": unmeasured, "measured": False}
    second = np.diff(twists, n=2, axis=0)
    white = _MAD_TO_SIGMA * np.median(np.abs(second - np.median(second, axis=0)), axis=0) / np.sqrt(6)
    first_rms = _rms_without_glitches(np.diff(twists, axis=0))
    hold = np.sqrt(np.maximum(first_rms**2 - 2 * white**2, 0.0)) / 2
    return {"white": white, "hold": hold, "sigma": np.maximum(np.hypot(white, hold), floor), "measured": True}


def _rms_without_glitches(first):
    """Per-axis rms of ``first`` (n, 6) without values beyond :data:`GLITCH_MADS` robust sigmas."""
    centre = np.median(first, axis=0)
    scale = _MAD_TO_SIGMA * np.median(np.abs(first - centre), axis=0)
    keep = np.abs(first - centre) <= GLITCH_MADS * scale
    return np.sqrt(np.sum(np.where(keep, first, 0.0) ** 2, axis=0) / np.maximum(keep.sum(axis=0), 1))
