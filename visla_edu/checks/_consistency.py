"""Checks of notebook 07 (tuning and consistency): the motion noise W, NEES and its chi-square band."""

import numpy as np

from visla_edu import ekf, metrics, motion
from visla_edu.checks._core import as_array, compare, exercise_check, fail, fmt, ok, rng, student
from visla_edu.checks._inputs import random_covariance

__all__ = ["check_motion_noise", "check_nees", "check_average_nees_bounds"]


@exercise_check
def check_motion_noise(motion_noise, hidden=False):
    """Exercise 07: ``motion_noise(tau, sigma_v, sigma_w) -> W (6, 6)`` for twists ``[v; w]``.

    ``W = tau^2 diag(sigma_v^2, sigma_v^2, sigma_v^2, sigma_w^2, sigma_w^2, sigma_w^2)``:
    compares with :func:`visla_edu.motion.motion_noise` (``rtol=1e-9``, ``atol=1e-15``) for 3
    fixed ``(tau, sigma_v, sigma_w)`` (hidden: 4 edge cases, zero sigmas among them, and 3
    random ones), each sigma one number. Recognises the angular variances first, a missing
    ``tau^2``, ``tau`` instead of ``tau^2``, and standard deviations instead of variances.
    Hides ``motion.motion_noise``.

    Parameters
    ----------
    motion_noise : callable
        The student's function: the step ``tau`` (s) and the velocity noise ``sigma_v`` (m/s)
        and ``sigma_w`` (rad/s) to the twist noise covariance (6, 6).
    hidden : bool
        Run the hidden cases instead (other inputs, the random ones drawn from
        ``VISLA_EDU_HIDDEN_SEED`` if set, else from a built-in seed) and print nothing on success;
        False prints one ``✓ ...`` line on success.

    Raises
    ------
    AssertionError
        The result has the wrong type, shape or values (the first line names the likely
        mistake), or the function raised, called a hidden library function or changed
        ``visla_edu``.
    NotImplementedError
        The function is still the notebook's stub.
    ValueError
        ``hidden`` is True and ``VISLA_EDU_HIDDEN_SEED`` is not a non-negative integer.
    """
    name = "motion_noise"
    cases = [(0.1, 0.5, 0.02), (0.104, 1.0, 0.05), (0.5, 0.2, 0.3)]
    if hidden:  # edge cases, then cases drawn from the teacher's seed
        generator = rng(hidden)
        cases = [(0.01, 2.0, 0.001), (1.0, 0.0, 0.1), (0.25, 0.3, 0.0), (0.1, 1e-3, 1e-4)] + [
            tuple(float(generator.uniform(low, high)) for low, high in ((0.01, 1.0), (0.0, 2.0), (0.0, 0.3)))
            for _ in range(3)]
    call = student(motion_noise, name, hide=[motion.motion_noise])
    for tau, sv, sw in cases:
        got = as_array(call(tau, sv, sw), name, (6, 6))
        ref = motion.motion_noise(tau, sv, sw)
        compare(name, got, ref, f"for tau = {tau}, sigma_v = {sv}, sigma_w = {sw}", [
            ("wrong twist order: u = [v; w], linear variances first on the diagonal",
             lambda: motion.motion_noise(tau, sw, sv)),
            ("scale the variances by tau^2\na velocity error of sigma over tau seconds moves the pose by "
             "tau sigma", lambda: np.diag(np.repeat([sv**2, sw**2], 3))),
            ("variances scale with tau^2, not tau", lambda: np.diag(np.repeat([tau * sv**2, tau * sw**2], 3))),
            ("W holds variances: square the standard deviations (tau sigma)^2",
             lambda: np.diag(np.repeat([tau * sv, tau * sw], 3))),
        ], rtol=1e-9, atol=1e-15)
    ok(f"{name}: W = tau^2 diag(sigma_v^2 I, sigma_w^2 I)", hidden)


@exercise_check
def check_nees(nees, hidden=False):
    """Exercise 07: ``nees(error (n,), cov (n, n)) -> float`` = ``e^T cov^-1 e``.

    For random errors of dimension 3, 6 and 6 (hidden: 1, 4, 6 and 15) drawn from random
    covariances; the result must be one number (an array of one entry fails). Compares with
    :func:`visla_edu.metrics.nees` (``rtol=1e-7``). Recognises ``e^T cov e``, the square root,
    a division by ``n`` and ``e^T e``. Hides ``metrics.nees`` and ``ekf.mahalanobis_squared``.

    Parameters
    ----------
    nees : callable
        The student's function: an error ``e`` (n,) and its covariance (n, n) to the normalised
        estimation error squared.
    hidden : bool
        Run the hidden cases instead (other inputs, the random ones drawn from
        ``VISLA_EDU_HIDDEN_SEED`` if set, else from a built-in seed) and print nothing on success;
        False prints one ``✓ ...`` line on success.

    Raises
    ------
    AssertionError
        The result has the wrong type, shape or values (the first line names the likely
        mistake), or the function raised, called a hidden library function or changed
        ``visla_edu``.
    NotImplementedError
        The function is still the notebook's stub.
    ValueError
        ``hidden`` is True and ``VISLA_EDU_HIDDEN_SEED`` is not a non-negative integer.
    """
    name = "nees"
    generator = rng(hidden)
    call = student(nees, name, hide=[metrics.nees, ekf.mahalanobis_squared])
    for n in ((1, 4, 6, 15) if hidden else (3, 6, 6)):
        cov = random_covariance(generator, n) * 1e-3
        e = generator.multivariate_normal(np.zeros(n), cov)
        got = call(e, cov)
        if np.size(got) == 1 and np.ndim(got) > 0:  # [x] or [[x]] (e.g. e[None] @ ... @ e[:, None])
            raise fail(name, "return one number, not an array of one", f"got {fmt(got)}: use float(...) or .item()")
        ref = float(metrics.nees(e[None], cov[None])[0])
        compare(name, got, ref, f"for a random {n}-dim error", [
            ("you multiplied by the covariance; NEES uses its inverse\nNEES = e^T Sigma^-1 e",
             lambda: e @ cov @ e),
            ("NEES is the squared distance, do not take the square root", lambda: np.sqrt(ref)),
            ("you divided by the dimension: NEES itself is not averaged", lambda: ref / n),
            ("you ignored the covariance (squared norm of e)", lambda: e @ e),
        ], rtol=1e-7)
    ok(f"{name}: e^T Sigma^-1 e (chi-square with n dof when the filter is consistent)", hidden)


@exercise_check
def check_average_nees_bounds(average_nees_bounds, hidden=False):
    """Exercise 07: ``average_nees_bounds(dof, n, probability=0.95) -> (lo, hi)`` for a mean of n NEES.

    The two-sided chi-square quantiles of ``n dof`` degrees of freedom at ``(1 - p) / 2`` and
    ``1 - (1 - p) / 2``, divided by ``n``: compares (``rtol=1e-6``) for 4 fixed ``(dof, n, p)``
    (hidden: 3 edge cases and 3 random ones); the result must have 2 entries. Recognises the
    quantiles of ``dof`` degrees of freedom, quantiles not divided by ``n``, and a one-sided
    split. Hides ``metrics.average_nees_bounds`` and ``metrics.chi2_bounds``.

    Parameters
    ----------
    average_nees_bounds : callable
        The student's function: the degrees of freedom of one NEES, the number ``n`` of values
        averaged and the probability ``p`` to the bounds ``(lo, hi)``.
    hidden : bool
        Run the hidden cases instead (other inputs, the random ones drawn from
        ``VISLA_EDU_HIDDEN_SEED`` if set, else from a built-in seed) and print nothing on success;
        False prints one ``✓ ...`` line on success.

    Raises
    ------
    AssertionError
        The result has the wrong type, shape or values (the first line names the likely
        mistake), or the function raised, called a hidden library function or changed
        ``visla_edu``.
    NotImplementedError
        The function is still the notebook's stub.
    ValueError
        ``hidden`` is True and ``VISLA_EDU_HIDDEN_SEED`` is not a non-negative integer.
    """
    name = "average_nees_bounds"
    cases = [(6, 1, 0.95), (6, 50, 0.95), (4, 200, 0.99), (3, 10, 0.9)]
    if hidden:  # edge cases, then cases drawn from the teacher's seed
        generator = rng(hidden)
        cases = [(6, 1000, 0.95), (1, 3, 0.5), (2, 25, 0.999)] + [
            (int(generator.integers(1, 7)), int(generator.integers(1, 500)), float(generator.uniform(0.5, 0.999)))
            for _ in range(3)]
    call = student(average_nees_bounds, name, hide=[metrics.average_nees_bounds, metrics.chi2_bounds])
    for dof, n, p in cases:
        got = as_array(call(dof, n, p), name, (2,), "bounds")
        tail = (1 - p) / 2
        ref = metrics.chi2_quantile([tail, 1 - tail], dof * n) / n
        compare(name, got, ref, f"for dof {dof}, {n} values, probability {p}", [
            ("use n * dof degrees of freedom, then divide by n\nthe sum of n values is chi-square with "
             "n * dof degrees of freedom; divide its quantiles by n",
             lambda: np.array(metrics.chi2_quantile([tail, 1 - tail], dof))),
            ("you forgot to divide the quantiles of the sum by n",
             lambda: np.array(metrics.chi2_quantile([tail, 1 - tail], dof * n))),
            ("two-sided: put (1 - p) / 2 in each tail", lambda: np.array(metrics.chi2_quantile([1 - p, p], dof * n)) / n),
            ("the bounds are swapped: return (lower, upper)", lambda: ref[::-1]),
        ], rtol=1e-6)
    ok(f"{name}: chi-square bounds of the average NEES", hidden)
