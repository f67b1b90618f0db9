"""The IMU velocity noise the filter should assume, per axis, from the velocities alone.

Two parts add up (in variance):

* **white**: the sensor's own noise. For a smooth signal plus white noise of standard
  deviation ``s``, ``var(x[t+1] - 2 x[t] + x[t-1]) = 6 s^2``; robustly,
  ``white = 1.4826 MAD(second differences) / sqrt(6)``.
* **hold**: the motion model's own error. The filter holds each velocity sample constant over
  its step while the true velocity changes within it; the first differences measure by how
  much: ``rms(x[t+1] - x[t])^2 = change^2 + 2 white^2``, and holding a linearly changing
  velocity at one end of the step is wrong by half the change on average:
  ``hold = sqrt(max(rms(diff)^2 - 2 white^2, 0)) / 2``.

The filter's noise is ``sqrt(white^2 + hold^2)`` per axis, floored at
:data:`MIN_SIGMA_LINEAR` and :data:`MIN_SIGMA_ANGULAR` (a velocity known better than that is
not a physical sensor).
"""

import numpy as np

__all__ = ["imu_noise", "MIN_SIGMA_LINEAR", "MIN_SIGMA_ANGULAR"]

#: Floor of the linear velocity noise (m/s).
MIN_SIGMA_LINEAR = 1e-3
#: Floor of the angular velocity noise (rad/s).
MIN_SIGMA_ANGULAR = 1e-4
_MAD_TO_SIGMA = 1.4826


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
        linear axes first. With fewer than 3 samples the parts are 0 and ``sigma`` the floors.
    """
    twists = np.asarray(twists, dtype=float)
    floor = np.repeat([MIN_SIGMA_LINEAR, MIN_SIGMA_ANGULAR], 3)
    if twists.ndim != 2 or twists.shape[1] != 6:
        raise ValueError(f"imu_noise: twists must have shape (T, 6) as [v; w], got {twists.shape}")
    if len(twists) < 3:
        zero = np.zeros(6)
        return {"white": zero, "hold": zero.copy(), "sigma": floor}
    second = np.diff(twists, n=2, axis=0)
    white = _MAD_TO_SIGMA * np.median(np.abs(second - np.median(second, axis=0)), axis=0) / np.sqrt(6)
    first_rms = np.sqrt(np.mean(np.diff(twists, axis=0) ** 2, axis=0))
    hold = np.sqrt(np.maximum(first_rms**2 - 2 * white**2, 0.0)) / 2
    return {"white": white, "hold": hold, "sigma": np.maximum(np.hypot(white, hold), floor)}
