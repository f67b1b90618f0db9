"""The IMU velocity noise the filter should assume, per axis, from the velocities alone.

Two parts add up (in variance):

* **white**: the sensor's own noise. For a smooth signal plus white noise of standard
  deviation ``s``, ``var(x[t+1] - 2 x[t] + x[t-1]) = 6 s^2``; robustly,
  ``white = 1.4826 MAD(second differences) / sqrt(6)``.
* **hold**: the motion model's own error. The filter holds each velocity sample constant over
  its step while the true velocity changes within it; the first differences measure by how
  much: ``rms(x[t+1] - x[t])^2 = change^2 + 2 white^2``, and holding a linearly changing
  velocity at one end of the step is wrong by half the change on average:
  ``hold = sqrt(max(rms(diff)^2 - 2 white^2, 0)) / 2``. The rms leaves out first differences
  beyond :data:`GLITCH_MADS` robust standard deviations of the axis's first differences: one
  glitched sample must not set the noise of a whole drive (the filter's divergence check
  reports it at its frame instead).

The filter's noise is ``sqrt(white^2 + hold^2)`` per axis, floored at
:data:`MIN_SIGMA_LINEAR` and :data:`MIN_SIGMA_ANGULAR` (a velocity known better than that is
not a physical sensor). A drive of fewer than :data:`MIN_NOISE_SAMPLES` velocity samples is too
short to measure either part (a median of one or two differences is 0); its noise is then the
course's own choice, :data:`UNMEASURED_SIGMA_LINEAR` and :data:`UNMEASURED_SIGMA_ANGULAR`, not the
floors, which would make a filter trust a velocity nobody measured.
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
    """White and hold noise of each velocity axis and the filter's noise from them.

    Parameters
    ----------
    twists : array_like, shape (T, 6)
        Velocity samples ``[v; w]`` (m/s, rad/s).

    Returns
    -------
    dict
        ``white`` (6,), ``hold`` (6,) and ``sigma`` (6,) ``= max(sqrt(white^2 + hold^2), floor)``,
        linear axes first, and ``measured`` (bool). With fewer than :data:`MIN_NOISE_SAMPLES`
        samples ``measured`` is False, the parts are 0 and ``sigma`` is
        ``UNMEASURED_SIGMA_LINEAR`` (3) and ``UNMEASURED_SIGMA_ANGULAR`` (3).

    Raises
    ------
    ValueError
        ``twists`` does not have shape (T, 6).
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
    """Per-axis rms of ``first`` (n, 6), leaving out values beyond :data:`GLITCH_MADS` robust sigmas."""
    centre = np.median(first, axis=0)
    scale = _MAD_TO_SIGMA * np.median(np.abs(first - centre), axis=0)
    keep = np.abs(first - centre) <= GLITCH_MADS * scale
    return np.sqrt(np.sum(np.where(keep, first, 0.0) ** 2, axis=0) / np.maximum(keep.sum(axis=0), 1))
