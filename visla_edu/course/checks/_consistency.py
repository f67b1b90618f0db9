"""Checks of notebooks 10 and 11 (consistency, outliers and real data): W, NEES and its band, the gate, the alignment."""

import numpy as np

from visla_edu import ekf, metrics, motion
from visla_edu.course.checks._core import as_array, compare, exercise_check, fail, fmt, ok, rng, student
from visla_edu.course.checks._inputs import random_covariance, random_pose

__all__ = ["check_motion_noise", "check_nees", "check_average_nees_bounds", "check_gate", "check_align_rigid"]


@exercise_check
def check_motion_noise(motion_noise, hidden=False):
    """Exercise 10: ``motion_noise(tau, sigma_v, sigma_w) -> W (6, 6)`` for twists ``[v; w]``.

    ``W = tau^2 diag(sigma_v^2 I3, sigma_w^2 I3)``, ``tau`` in s, each sigma one number (m/s, rad/s):
    compares with :func:`visla_edu.motion.motion_noise` (``rtol=1e-9``, ``atol=1e-15``) for fixed cases
    (hidden: edge cases, zero sigmas among them, and random ones). Hides ``motion.motion_noise``.
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
    """Exercise 10: ``nees(error (n,), cov (n, n)) -> float`` = ``e^T cov^-1 e``.

    For errors drawn from random covariances; the result must be one number (an array of one entry
    fails). Compares with :func:`visla_edu.metrics.nees` (``rtol=1e-7``). Hides ``metrics.nees``
    and ``ekf.mahalanobis_squared``.
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
    """Exercise 10: ``average_nees_bounds(dof, n, probability=0.95) -> (lo, hi)`` for a mean of n NEES.

    ``dof`` of one NEES: the chi-square quantiles of ``n dof`` degrees of freedom at ``(1 - p) / 2``
    and ``1 - (1 - p) / 2``, divided by ``n``: compares both (``rtol=1e-6``). Hides
    ``metrics.average_nees_bounds`` and ``metrics.chi2_bounds``.
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


# --------------------------------------------------------------------------- the gate (notebook 11)


def _gate_cases(generator, hidden):
    """``(innovations (k, 4), S (k, 4, 4), probability)``: distances spread around the gate's threshold."""
    cases = []
    for k, probability in (((60, 0.999), (40, 0.9), (25, 0.5)) if hidden else ((50, 0.99), (30, 0.95))):
        Q = np.linalg.qr(generator.normal(size=(k, 4, 4)))[0]  # random orientations, eigenvalues 0.05 to 20
        S = Q @ (np.exp(generator.uniform(np.log(0.05), np.log(20.0), (k, 4)))[:, :, None] * np.swapaxes(Q, 1, 2))
        radius = np.sqrt(generator.uniform(0.0, 2.5, k) * metrics.chi2_quantile(probability, 4))
        direction = generator.normal(size=(k, 4))
        direction /= np.sqrt(ekf.mahalanobis_squared(direction, S))[:, None]  # unit Mahalanobis length
        cases.append((radius[:, None] * direction, S, probability))
    return cases


def _gate_variants(r, S, probability):
    d2 = ekf.mahalanobis_squared(r, S)
    threshold = metrics.chi2_quantile(probability, 4)
    return [
        ("the gate is the chi-square quantile at probability, not 1 - p\nwith p = 0.999 a consistent filter "
         "keeps 99.9% of its good observations", lambda: d2 <= metrics.chi2_quantile(1 - probability, 4)),
        ("compare the SQUARED distance with the chi-square quantile\nr^T S^-1 r is chi-square; its square root "
         "is not", lambda: np.sqrt(d2) <= threshold),
        ("the distance uses the inverse of S: r^T S^-1 r, not r^T S r",
         lambda: np.einsum("ki,kij,kj->k", r, S, r) <= threshold),
        ("each observation has 4 degrees of freedom (uL, vL, uR, vR)\nthe gate tests one observation at a "
         "time: chi-square with 4 dof", lambda: d2 <= metrics.chi2_quantile(probability, 2)),
        ("you returned the rejected ones: True means inside the gate\nkeep d2 <= threshold",
         lambda: d2 > threshold),
        ("the distance must use S: r^T S^-1 r, not |r|^2", lambda: np.sum(r * r, axis=1) <= threshold),
    ]


@exercise_check
def check_gate(gate, hidden=False):
    """Exercise 11: ``gate(innovations (k, 4), S (k, 4, 4), probability) -> (k,) bool``, inside the gate.

    ``r_i^T S_i^-1 r_i <= chi2.ppf(probability, 4)`` per innovation ``r_i = z - z_pred`` (px): the mask
    must equal the library's (:func:`visla_edu.ekf.mahalanobis_squared`,
    :func:`visla_edu.metrics.chi2_quantile`) exactly. Hides :func:`visla_edu.ekf.mahalanobis_squared`.
    """
    name = "gate"
    call = student(gate, name, hide=[ekf.mahalanobis_squared])
    for r, S, probability in _gate_cases(rng(hidden), hidden):
        k = len(r)
        got = as_array(call(r, S, probability), name, (k,), "mask")
        ref = ekf.mahalanobis_squared(r, S) <= metrics.chi2_quantile(probability, 4)
        compare(name, got, ref, f"for {k} innovations, probability {probability}",
                _gate_variants(r, S, probability), rtol=0, atol=0)
    ok(f"{name}: r^T S^-1 r <= chi2.ppf(p, 4) for every observation", hidden)


# --------------------------------------------------------------------------- the alignment (notebook 11)


def _rigid(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _align_variants(p_est, p_gt, ref):
    mu_e, mu_g = p_est.mean(axis=0), p_gt.mean(axis=0)
    U, _, Vt = np.linalg.svd((p_est - mu_e).T @ (p_gt - mu_g))
    R = ref[:3, :3]
    U0, _, Vt0 = np.linalg.svd(p_est.T @ p_gt)
    return [
        ("the rotation block is transposed: R = Q D U^T\nwith U diag(s) Q^T = svd(sum (p_est - c_est)(p_gt - c_gt)^T)",
         lambda: _rigid(R.T, mu_g - R.T @ mu_e)),
        ("the result is a reflection (det -1): fix the sign\nR = Q diag(1, 1, det(Q U^T)) U^T is the best "
         "rotation; without the fix the SVD may give a mirror image", lambda: _rigid(Vt.T @ U.T, mu_g - Vt.T @ U.T @ mu_e)),
        ("rotate the centroid: p = c_gt - R c_est, not c_gt - c_est",
         lambda: _rigid(R, mu_g - mu_e)),
        ("remove the centroids before the SVD\nthe cross-covariance is sum (p_est - c_est)(p_gt - c_gt)^T",
         lambda: _rigid(Vt0.T @ U0.T, mu_g - Vt0.T @ U0.T @ mu_e)),
        ("you returned est_T_gt, the inverse: map p_est onto p_gt",
         lambda: np.linalg.inv(ref)),
    ]


def _align_cases(generator, hidden):
    """``(p_est, p_gt)`` pairs: a noisy rigidly moved drive, and one whose best fit the SVD gives as a reflection."""
    cases = []
    for n in ((200, 12) if not hidden else (300, 40, 8)):
        along = np.cumsum(generator.normal([1.0, 0.0, 0.0], [0.2, 0.3, 0.05], (n, 3)), axis=0)
        gt_T_est = random_pose(generator, scale=50.0)
        p_gt = along @ gt_T_est[:3, :3].T + gt_T_est[:3, 3] + generator.normal(scale=0.3, size=(n, 3))
        cases.append((along, p_gt))
    planar = np.c_[generator.normal(size=(10, 2)) * 10, np.zeros(10)]  # flat, then mirrored: det(V U^T) = -1
    cases.append((planar, planar * [1.0, -1.0, 1.0] + generator.normal(scale=0.01, size=(10, 3))))
    return cases


@exercise_check
def check_align_rigid(align_rigid, hidden=False):
    """Exercise 11: ``align_rigid(p_est (N, 3), p_gt (N, 3)) -> gt_T_est (4, 4)``, the best rigid alignment.

    Row ``i`` of both is the same frame. The ``R``, ``p`` minimising ``sum |p_gt - (R p_est + p)|^2``
    (Kabsch, no scale): ``R = Q diag(1, 1, det(Q U^T)) U^T`` from ``U diag(s) Q^T = svd(sum (p_est -
    c_est)(p_gt - c_gt)^T)`` and ``p = c_gt - R c_est``, also for flat points against their mirror
    image (an SVD reflection); compares with :func:`visla_edu.metrics.align_se3` (``rtol=1e-7``,
    ``atol=1e-8``). Hides it and :func:`visla_edu.metrics.ate`.
    """
    name = "align_rigid"
    call = student(align_rigid, name, hide=[metrics.align_se3, metrics.ate])
    for p_est, p_gt in _align_cases(rng(hidden), hidden):
        ref = metrics.align_se3(p_est, p_gt)
        got = as_array(call(p_est, p_gt), name, (4, 4), "pose gt_T_est")
        flat = not np.any(p_est[:, 2])
        compare(name, got, ref, f"for {len(p_est)} {'flat, mirrored ' if flat else ''}positions",
                _align_variants(p_est, p_gt, ref), rtol=1e-7, atol=1e-8)
    ok(f"{name}: R = Q diag(1, 1, det(Q U^T)) U^T, p = c_gt - R c_est", hidden)
