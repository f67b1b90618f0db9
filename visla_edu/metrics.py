"""Accuracy and consistency metrics: ATE, RPE, NEES, NIS and chi-square bounds.

Errors of a pose estimate ``mu`` against the truth ``T`` use the filter's own perturbation
convention: ``T = mu exp(hat(e))``, so ``e = se3_log(inv(mu) @ T)`` (twist ``[v; w]``).
"""

import numpy as np
from scipy import stats

from visla_edu import lie

__all__ = ["align_se3", "ate", "rpe", "pose_errors", "nees", "chi2_bounds", "nis_band", "average_nees_bounds"]


def _check_trajectories(est, gt):
    est = np.asarray(est, dtype=float)
    gt = np.asarray(gt, dtype=float)
    if est.shape != gt.shape or est.ndim != 3 or est.shape[1:] != (4, 4):
        raise ValueError(f"trajectories must both have shape (T, 4, 4), got {est.shape} and {gt.shape}")
    return est, gt


def align_se3(p_est, p_gt):
    """Rigid transform ``gt_T_est`` that best maps estimated positions onto true ones.

    Least squares (Kabsch/Umeyama without scale): minimises ``sum |p_gt - (R p_est + t)|^2``.

    Parameters
    ----------
    p_est, p_gt : ndarray, shape (N, 3)

    Returns
    -------
    ndarray, shape (4, 4)
    """
    mu_e, mu_g = p_est.mean(axis=0), p_gt.mean(axis=0)
    U, _, Vt = np.linalg.svd((p_est - mu_e).T @ (p_gt - mu_g))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = mu_g - R @ mu_e
    return T


def ate(est_world_T_imu, gt_world_T_imu, align=True):
    """Absolute trajectory error: RMS of the position differences (m).

    Parameters
    ----------
    est_world_T_imu, gt_world_T_imu : ndarray, shape (T, 4, 4)
    align : bool
        First apply the rigid transform of :func:`align_se3` (removes the arbitrary choice of
        world frame); without it both trajectories must share the world frame (visla-edu's
        world is the first IMU frame, so they do).

    Returns
    -------
    float
    """
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu)
    p_est, p_gt = est[:, :3, 3], gt[:, :3, 3]
    if align:
        T = align_se3(p_est, p_gt)
        p_est = p_est @ T[:3, :3].T + T[:3, 3]
    return float(np.sqrt(np.mean(np.sum((p_est - p_gt) ** 2, axis=1))))


def rpe(est_world_T_imu, gt_world_T_imu, delta=10):
    """Relative pose error over ``delta`` frames: RMS translation (m) and rotation (rad).

    Compares ``inv(est[t]) est[t+delta]`` with ``inv(gt[t]) gt[t+delta]``; insensitive to the
    world frame and to drift accumulated before ``t``.

    Returns
    -------
    (float, float)
        Translation RMS and rotation RMS.
    """
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu)
    if not 0 < delta < len(est):
        raise ValueError(f"rpe: delta must be in [1, {len(est) - 1}], got {delta}")
    rel_est = lie.se3_inv(est[:-delta]) @ est[delta:]
    rel_gt = lie.se3_inv(gt[:-delta]) @ gt[delta:]
    err = lie.se3_inv(rel_est) @ rel_gt
    trans = np.linalg.norm(err[:, :3, 3], axis=1)
    rot = np.linalg.norm(lie.so3_log(err[:, :3, :3]), axis=1)
    return float(np.sqrt(np.mean(trans**2))), float(np.sqrt(np.mean(rot**2)))


def pose_errors(est_world_T_imu, gt_world_T_imu):
    """Right-perturbation errors ``e_t = se3_log(inv(mu_t) T_t)``, shape (T, 6)."""
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu)
    return lie.se3_log(lie.se3_inv(est) @ gt)


def nees(errors, covariances, skip_singular=True):
    """Normalised estimation error squared ``e_t^T Sigma_t^{-1} e_t`` per time step.

    Parameters
    ----------
    errors : ndarray, shape (T, n)
    covariances : ndarray, shape (T, n, n)
    skip_singular : bool
        Return NaN where the covariance is singular (e.g. the exactly known first pose).

    Returns
    -------
    ndarray, shape (T,)
        Chi-square with n dof per step when the filter is consistent.
    """
    errors = np.asarray(errors, dtype=float)
    covariances = np.asarray(covariances, dtype=float)
    out = np.full(len(errors), np.nan)
    for t, (e, P) in enumerate(zip(errors, covariances)):
        try:
            L = np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            if skip_singular:
                continue
            raise ValueError(f"nees: covariance at step {t} is not positive definite") from None
        w = np.linalg.solve(L, e)
        out[t] = w @ w
    return out


def chi2_bounds(dof, probability=0.95):
    """Two-sided ``probability`` interval of a chi-square value with ``dof`` degrees of freedom.

    ``[chi2.ppf(a, dof), chi2.ppf(1 - a, dof)]`` with ``a = (1 - probability) / 2``: the one
    place the package computes a chi-square band (NEES, NIS, the stepper's and the plots'
    bands all call it).

    Parameters
    ----------
    dof : int or array_like of int
        Degrees of freedom; entries ``<= 0`` give NaN.
    probability : float

    Returns
    -------
    lower, upper : float, or ndarray of the shape of ``dof``
    """
    tail = (1 - probability) / 2
    dof = np.asarray(dof, dtype=float)
    lower, upper = stats.chi2.ppf(tail, dof), stats.chi2.ppf(1 - tail, dof)
    if dof.ndim == 0:
        return float(lower), float(upper)
    return lower, upper


def nis_band(dof, probability=0.95):
    """Two-sided ``probability`` band of ``chi2(dof) / dof``: where NIS per degree of freedom should stay.

    Parameters
    ----------
    dof : int or array_like of int
        Degrees of freedom; entries ``<= 0`` (no update) give NaN.
    probability : float

    Returns
    -------
    lower, upper : ndarray (the shape of ``dof``)
    """
    dof = np.asarray(dof, dtype=float)
    lower, upper = chi2_bounds(dof, probability)
    with np.errstate(divide="ignore", invalid="ignore"):  # dof 0: NaN / 0
        return np.asarray(lower / dof), np.asarray(upper / dof)


def average_nees_bounds(dof, runs, probability=0.95):
    """Interval for the average of ``runs`` independent chi-square(dof) values.

    ``sum`` of the values is chi-square with ``runs * dof`` dof, so the average lies in
    ``chi2.ppf([a, 1 - a], runs * dof) / runs`` with ``a = (1 - probability) / 2``.
    """
    lo, hi = chi2_bounds(dof * runs, probability)
    return lo / runs, hi / runs
