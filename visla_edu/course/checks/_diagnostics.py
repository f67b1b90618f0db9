"""Checks of notebook 04 (diagnose and calibrate): the white velocity noise from second differences."""

import numpy as np

from visla_edu import diagnostics
from visla_edu.course.checks._core import as_array, compare, exercise_check, ok, rng, student

__all__ = ["check_white_noise"]

#: The median absolute deviation of a Gaussian is 0.6745 standard deviations.
_MAD_TO_SIGMA = 1.4826


def _mad_sigma(x):
    """Robust standard deviation of each column: 1.4826 MAD (about the median)."""
    return _MAD_TO_SIGMA * np.median(np.abs(x - np.median(x, axis=0)), axis=0)


def _white_variants(twists):
    second = np.diff(twists, n=2, axis=0)
    return [
        ("use a robust spread (the MAD), not the standard deviation\nthe velocities have glitches: one "
         "sample far off moves np.std but not the median absolute deviation",
         lambda: np.std(second, axis=0) / np.sqrt(6)),
        ("divide by sqrt(6)\nfor white noise of standard deviation s, var(x[t+1] - 2 x[t] + x[t-1]) = "
         "(1 + 4 + 1) s^2 = 6 s^2", lambda: _mad_sigma(second)),
        ("divide by sqrt(6), not by 6\nthe variance of a second difference is 6 s^2, its standard deviation "
         "sqrt(6) s", lambda: _mad_sigma(second) / 6),
        ("scale the MAD by 1.4826 to get a standard deviation\nthe median absolute deviation of a Gaussian is "
         "0.6745 sigma", lambda: _mad_sigma(second) / _MAD_TO_SIGMA / np.sqrt(6)),
        ("use second differences: first differences keep the motion\nx[t+1] - x[t] is the change of a "
         "smooth velocity plus noise; x[t+1] - 2 x[t] + x[t-1] removes a smoothly changing velocity",
         lambda: _mad_sigma(np.diff(twists, axis=0)) / np.sqrt(2)),
    ]


def _white_cases(generator, hidden):
    """Velocity records (T, 6): a smooth drive plus per-axis white noise and a few glitched samples."""
    cases = []
    for T in ((400, 150) if not hidden else (600, 90, 250)):
        t = np.arange(T) * 0.1
        smooth = np.concatenate([8 + 2 * np.sin(0.05 * t)[:, None] * np.ones(3) * [1, 0.1, 0.05],
                                 0.2 * np.sin(0.3 * t)[:, None] * np.array([0.05, 0.05, 1.0])], axis=1)
        sigma = np.r_[generator.uniform(0.01, 0.5, 3), generator.uniform(0.001, 0.05, 3)]
        twists = smooth + generator.normal(size=(T, 6)) * sigma
        glitches = generator.choice(T, size=max(2, T // 50), replace=False)
        twists[glitches] += 50 * sigma * generator.choice([-1.0, 1.0], size=(len(glitches), 6))
        cases.append(twists)
    return cases


@exercise_check
def check_white_noise(white_noise, hidden=False):
    """Exercise 04: ``white_noise(twists (T, 6)) -> (6,)``, the white noise of each velocity axis.

    ``1.4826 MAD(x[t+1] - 2 x[t] + x[t-1]) / sqrt(6)`` per axis, the MAD about the median, on
    velocities ``[v; w]`` (m/s, rad/s) of a smooth drive plus white noise and a few glitches:
    compares with the ``white`` part of :func:`visla_edu.diagnostics.imu_noise` (``rtol=1e-9``,
    ``atol=1e-12``), which it hides.
    """
    name = "white_noise"
    call = student(white_noise, name, hide=[diagnostics.imu_noise])
    cases = _white_cases(rng(hidden), hidden)
    for twists in cases:
        got = as_array(call(twists), name, (6,), "noise per axis")
        ref = diagnostics.imu_noise(twists)["white"]
        compare(name, got, ref, f"for {len(twists)} velocity samples with a few glitches", _white_variants(twists),
                rtol=1e-9, atol=1e-12)
    ok(f"{name}: 1.4826 MAD of the second differences / sqrt(6), per axis, on {len(cases)} records", hidden)
