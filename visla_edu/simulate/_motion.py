"""The true motion of a simulated car, and the IMU's noisy measurement of it."""

import numpy as np
from scipy.ndimage import gaussian_filter1d

__all__ = ["simulate_motion", "add_imu_noise", "lag_samples"]


def _smooth_noise(rng, n, step, timescale):
    """Gaussian-filtered white noise with unit stationary standard deviation, shape (n,)."""
    white = rng.standard_normal(n)
    sigma = timescale / step
    if sigma < 0.3:
        return white
    x = np.arange(-int(4.0 * sigma + 0.5), int(4.0 * sigma + 0.5) + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    kernel /= kernel.sum()  # the kernel of gaussian_filter1d (truncate=4)
    return gaussian_filter1d(white, sigma, mode="reflect") / np.sqrt(np.sum(kernel**2))


def _rates_of(angle, time_stamps):
    """Piecewise-constant rates that step ``angle`` from sample to sample, shape (T,)."""
    rates = np.diff(angle) / np.diff(time_stamps)
    return np.append(rates, rates[-1])


def _turn_yaw_rates(time_stamps, config, rng):
    """Yaw rates of a few raised-cosine turns, each turning by its angle, shape (T,)."""
    t0, duration = time_stamps[0], time_stamps[-1] - time_stamps[0]
    n_turns = int(duration // config.turn_interval) if config.turn_interval > 0 else 0
    if n_turns == 0:
        return np.zeros_like(time_stamps)
    centres = t0 + (np.arange(n_turns) + 0.5 + rng.uniform(-0.25, 0.25, n_turns)) * duration / n_turns
    angles = rng.choice([-1.0, 1.0], n_turns) * rng.uniform(*config.turn_angle_range, n_turns)
    lengths = rng.uniform(*config.turn_duration_range, n_turns)
    phase = (time_stamps[None, :] - centres[:, None]) / lengths[:, None] + 0.5
    inside = (phase >= 0) & (phase <= 1)
    bumps = (angles / lengths)[:, None] * (1 - np.cos(2 * np.pi * phase))
    return np.sum(np.where(inside, bumps, 0.0), axis=0)


def _time_stamps(config, rng):
    """Slightly jittered, strictly increasing time stamps, shape (T,)."""
    steps = config.time_step + config.time_step_jitter * rng.standard_normal(config.num_frames - 1)
    steps = np.maximum(steps, 0.1 * config.time_step)
    return config.start_time + np.concatenate([[0.0], np.cumsum(steps)])


def simulate_motion(config, rng):
    """True time stamps (T,) and body velocities (x forward, y left, z up), (T, 3) each, of a car-like drive.

    The velocities are constant over each step ``[t_k, t_{k+1})``; the last row is unused by the poses.
    """
    n, step = config.num_frames, config.time_step
    t = _time_stamps(config, rng)
    lo, hi = config.speed_range
    speed = 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.tanh(_smooth_noise(rng, n, step, config.speed_timescale))
    lateral, vertical = (config.side_velocity_sigma * _smooth_noise(rng, n, step, 1.0) for _ in range(2))
    roll, pitch = (config.roll_pitch_amplitude * _smooth_noise(rng, n, step, config.roll_pitch_timescale)
                   for _ in range(2))
    yaw_rate = config.yaw_rate_sigma * _smooth_noise(rng, n, step, config.yaw_timescale)
    yaw_rate = yaw_rate + _turn_yaw_rates(t, config, rng)
    linear = np.stack([speed, lateral, vertical], axis=1)
    angular = np.stack([_rates_of(roll, t), _rates_of(pitch, t), yaw_rate], axis=1)
    return t, linear, angular


def add_imu_noise(linear_velocity, angular_velocity, config, rng):
    """Measured IMU velocities, (T, 3) each: ``lag_samples(true, imu_lag)`` + white noise (+ ``gyro_bias``).

    ``linear_velocity``, ``angular_velocity`` (T, 3): the true velocities; the step ``t -> t+1`` uses sample ``t``.
    """
    noise_v = config.linear_velocity_sigma * rng.standard_normal(np.shape(linear_velocity))
    noise_w = config.angular_velocity_sigma * rng.standard_normal(np.shape(angular_velocity))
    bias = np.asarray(config.gyro_bias, dtype=float).reshape(1, 3)
    lag = config.imu_lag
    return lag_samples(linear_velocity, lag) + noise_v, lag_samples(angular_velocity, lag) + noise_w + bias


def lag_samples(samples, lag):
    """Samples (T, ...) recorded ``lag`` steps late (negative: early): ``out[k] = samples[clip(k - lag, 0, T - 1)]``.

    The inverse of :func:`visla_edu.motion.select_twists` with the same ``lag``, away from the ends.
    """
    samples = np.asarray(samples)
    index = np.clip(np.arange(len(samples)) - int(lag), 0, len(samples) - 1)
    return samples[index]
