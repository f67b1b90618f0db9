"""Checks of notebook 00b (the Kalman-filter primer): a scalar update and the linear prediction."""

import numpy as np

from visla_edu import ekf, motion
from visla_edu.course import kalman
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, ok, rng, student
from visla_edu.course.checks._inputs import random_covariance

__all__ = ["check_kalman_update_1d", "check_kalman_predict"]


def _pair(got, name, what):
    """The two parts of a result that must be a pair ``(first, second)``."""
    if not isinstance(got, (tuple, list)) or len(got) != 2:
        raise fail(name, f"return the pair {what}", f"got {type(got).__name__}"
                   + (f" of length {len(got)}" if isinstance(got, (tuple, list)) else ""))
    return got


def _scalar(value, name, what):
    arr = np.asarray(value, dtype=float)
    if arr.size != 1:
        raise fail(name, f"the {what} must be one number", f"got shape {arr.shape}")
    return float(arr.reshape(()))


def _update_cases(hidden):
    """``(mean, variance, z, noise_variance)`` cases: visible fixed ones, hidden random and edge ones."""
    if not hidden:
        return [(0.0, 4.0, 1.0, 1.0), (10.0, 1.0, 12.5, 4.0), (-3.0, 0.25, 5.0, 100.0), (2.0, 9.0, -1.0, 0.01)]
    generator = rng(hidden=True)
    cases = [(float(generator.normal(scale=10)), float(np.exp(generator.normal(scale=2))),
              float(generator.normal(scale=10)), float(np.exp(generator.normal(scale=2)))) for _ in range(4)]
    return cases + [(1.0, 0.0, 5.0, 2.0), (1.0, 3.0, 5.0, 0.0)]  # a certain prior; a perfect sensor


def _update_variants(m, var, z, r):
    gain = var / (var + r)
    right = kalman.update_1d(m, var, z, r)
    swapped = r / (var + r)
    by_std = np.sqrt(var) / (np.sqrt(var) + np.sqrt(r))
    return [
        ("the variance must shrink: (1 - L) * variance\nan update adds information; only the prediction "
         "makes the variance grow", lambda: np.array([right[0], var])),
        ("the gain L is variance / (variance + V): you swapped them\nV is the noise variance; the gain is near 1 when the prior is uncertain "
         "(trust the measurement)", lambda: np.array([m + swapped * (z - m), (1 - swapped) * var])),
        ("use variances, not standard deviations, in the gain",
         lambda: np.array([m + by_std * (z - m), (1 - by_std) * var])),
        ("the innovation is z - mean, not mean - z", lambda: np.array([m - gain * (z - m), right[1]])),
        ("the gain L is variance / (variance + V), not variance / V",
         lambda: np.array([m + var / r * (z - m), (1 - var / r) * var])),
        ("the new variance is (1 - L) * variance, not variance - L", lambda: np.array([right[0], var - gain])),
        ("return (mean, variance), in this order", lambda: np.array([right[1], right[0]])),
    ]


@exercise_check
def check_kalman_update_1d(kalman_update_1d, hidden=False):
    """Exercise 00b: ``kalman_update_1d(mean, variance, z, noise_variance) -> (mean, variance)``.

    ``L = variance / (variance + V)`` (``V`` the noise variance), ``(mean + L (z - mean), (1 - L)
    variance)``, a pair of single numbers: compares with :func:`visla_edu.course.kalman.update_1d`
    (``rtol=1e-9``, ``atol=1e-12``), also (hidden) for a prior or a sensor of variance 0. Hides
    ``kalman.update_1d``, ``kalman.update`` and ``ekf.cholesky_update``.
    """
    name = "kalman_update_1d"
    call = student(kalman_update_1d, name, hide=[kalman.update_1d, kalman.update, ekf.cholesky_update])
    for m, var, z, r in _update_cases(hidden):
        first, second = _pair(call(m, var, z, r), name, "(mean, variance)")
        got = np.array([_scalar(first, name, "mean"), _scalar(second, name, "variance")])
        ref = np.array(kalman.update_1d(m, var, z, r))
        with np.errstate(all="ignore"):
            compare(name, got, ref, f"for mean {m:g}, variance {var:g}, z {z:g}, noise variance {r:g}",
                    _update_variants(m, var, z, r), rtol=1e-9, atol=1e-12)
    ok(f"{name}: L = var / (var + V), mean + L (z - mean), (1 - L) var", hidden)


def _predict_cases(hidden):
    """``(x, Sigma, F, W)``: a position-velocity model, then random models (F not symmetric)."""
    generator = rng(hidden)
    tau = 0.1 if not hidden else 0.25
    F_cv = np.array([[1.0, tau], [0.0, 1.0]])
    Q_cv = 0.3**2 * np.array([[tau**4 / 4, tau**3 / 2], [tau**3 / 2, tau**2]])
    cases = [(np.array([2.0, -1.0]), random_covariance(generator, 2), F_cv, Q_cv)]
    for n in ((1, 3, 5) if hidden else (3, 4)):
        F = np.eye(n) + 0.5 * generator.normal(size=(n, n))
        cases.append((generator.normal(size=n), random_covariance(generator, n), F,
                       0.1 * random_covariance(generator, n)))
    return cases


@exercise_check
def check_kalman_predict(kalman_predict, hidden=False):
    """Exercise 00b: ``kalman_predict(x (n,), Sigma, F, W (n, n each)) -> (F x, F Sigma F^T + W)``.

    On a position-velocity model and random ones (``F`` not symmetric); compares with
    :func:`visla_edu.course.kalman.predict` (``rtol=1e-9``, ``atol=1e-12``). Hides it and
    ``motion.predict_pose_covariance`` (``F P F^T + W`` for any size).
    """
    name = "kalman_predict"
    call = student(kalman_predict, name, hide=[kalman.predict, motion.predict_pose_covariance])
    for x, P, F, Q in _predict_cases(hidden):
        n = len(x)
        first, second = _pair(call(x, P, F, Q), name, "(mean, covariance)")
        got_x = as_array(first, name, (n,), "predicted mean")
        got_P = as_array(second, name, (n, n), "predicted covariance")
        ref_x, ref_P = kalman.predict(x, P, F, Q)
        where = f"for a {n}-state model, F =\n{np.array2string(F, precision=3)}"
        compare(name, got_x, ref_x, where, [
            ("the mean moves too: F @ x", lambda: x),
            ("the mean is F @ x, not F.T @ x", lambda: F.T @ x),
        ], rtol=1e-9, atol=1e-12)
        compare(name, got_P, ref_P, where, [
            ("add the motion noise W to the covariance", lambda: F @ P @ F.T),
            ("F @ Sigma @ F.T, not F.T @ Sigma @ F (transposed)", lambda: F.T @ P @ F + Q),
            ("multiply by F.T on the right too: F @ Sigma @ F.T + W", lambda: F @ P + Q),
            ("the second F is transposed: F @ Sigma @ F.T + W", lambda: F @ P @ F + Q),
            ("W is added after propagating: F (Sigma + W) F^T is wrong", lambda: F @ (P + Q) @ F.T),
        ], rtol=1e-9, atol=1e-12)
    ok(f"{name}: (F x, F Sigma F^T + W) for a position-velocity model and random ones", hidden)
