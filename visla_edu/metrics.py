"""Accuracy and consistency metrics: ATE, RPE, KITTI drift, NEES, NIS, chi-square bounds, the gated share.

Errors of a pose estimate ``mu`` against the truth ``T`` are right perturbations
(:mod:`visla_edu.lie`): ``e = se3_log(inv(mu) @ T)``.
:func:`evaluate` gathers ATE (raw and aligned) and KITTI drift in a :class:`TrajectoryEvaluation`.

Trajectories ``est_world_T_imu``, ``gt_world_T_imu`` (T, 4, 4), ``world`` the first IMU frame for
both, need ``T >= 1`` and every pose finite and rigid to :data:`~visla_edu.validation.POSE_RIGID_TOL`,
else a ``ValueError`` names the first bad frame.
"""

from dataclasses import dataclass

import numpy as np

from visla_edu import lie
from visla_edu.validation import POSE_RIGID_TOL, check_rigid_poses

__all__ = ["align_se3", "ate", "rpe", "pose_errors", "nees", "chi2_bounds", "nis_band", "average_nees_bounds",
           "DRIFT_LENGTHS", "DRIFT_STEP", "path_distances", "kitti_drift", "TrajectoryEvaluation", "evaluate",
           "gated_share"]


def _check_trajectories(est, gt, caller="metrics"):
    """Both as float arrays of the same shape (T, 4, 4), T >= 1, every pose finite and rigid."""
    est = np.asarray(est, dtype=float)
    gt = np.asarray(gt, dtype=float)
    if est.shape != gt.shape or est.ndim != 3 or est.shape[1:] != (4, 4):
        raise ValueError(f"{caller}: trajectories must both have shape (T, 4, 4), got {est.shape} and {gt.shape}")
    if not len(est):
        raise ValueError(f"{caller}: the trajectories are empty (T = 0)")
    for name, poses in (("estimate", est), ("ground truth", gt)):
        _check_poses(poses, name, caller)
    return est, gt


def _check_poses(poses, name, caller):
    """A ValueError naming the first frame whose pose is not finite or not rigid (validation.check_rigid_poses)."""
    bad = np.flatnonzero(~np.isfinite(poses).all(axis=(1, 2)))
    if len(bad):
        raise ValueError(f"{caller}: the {name}'s pose of frame {bad[0]} is not finite")
    check_rigid_poses(poses, f"{caller}: the {name}'s pose", POSE_RIGID_TOL)


def align_se3(p_est, p_gt):
    """Rigid ``gt_T_est`` minimising ``sum |p_gt - (R p_est + t)|^2`` over ``p_est, p_gt`` (N, 3) (Kabsch, no scale).

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
    align : bool
        First apply :func:`align_se3`; without it both trajectories must share the world frame.

    Returns
    -------
    float
    """
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu, "ate")
    p_est, p_gt = est[:, :3, 3], gt[:, :3, 3]
    if align:
        T = align_se3(p_est, p_gt)
        p_est = p_est @ T[:3, :3].T + T[:3, 3]
    return float(np.sqrt(np.mean(np.sum((p_est - p_gt) ** 2, axis=1))))


def rpe(est_world_T_imu, gt_world_T_imu, delta=10):
    """RMS translation (m) and rotation (rad) of ``inv(rel_est) rel_gt``, ``rel = inv(T[t]) T[t+delta]``.

    Parameters
    ----------
    delta : int
        ``1 <= delta < T``, else a ``ValueError``.

    Returns
    -------
    (float, float)
    """
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu, "rpe")
    if isinstance(delta, bool) or not isinstance(delta, (int, np.integer)):
        raise ValueError(f"rpe: delta must be a whole number of frames, got {delta!r}")
    if not 0 < delta < len(est):
        raise ValueError(f"rpe: delta must be in [1, {len(est) - 1}], got {delta}")
    rel_est = lie.se3_inv(est[:-delta]) @ est[delta:]
    rel_gt = lie.se3_inv(gt[:-delta]) @ gt[delta:]
    err = lie.se3_inv(rel_est) @ rel_gt
    trans = np.linalg.norm(err[:, :3, 3], axis=1)
    rot = np.linalg.norm(lie.so3_log(err[:, :3, :3]), axis=1)
    return float(np.sqrt(np.mean(trans**2))), float(np.sqrt(np.mean(rot**2)))


def pose_errors(est_world_T_imu, gt_world_T_imu):
    """Right-perturbation errors ``e_t = se3_log(inv(mu_t) T_t)`` (twist ``[v; w]``), ``mu_t`` estimated, ``T_t`` true.

    Returns
    -------
    ndarray, shape (T, 6)
    """
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu, "pose_errors")
    return lie.se3_log(lie.se3_inv(est) @ gt)


def nees(errors, covariances, skip_singular=True):
    """Normalised estimation error squared ``e_t^T Sigma_t^{-1} e_t`` per step: chi-square(n) when consistent.

    Parameters
    ----------
    errors, covariances : ndarray, shapes (T, n) and (T, n, n)
    skip_singular : bool
        NaN where the covariance is singular (e.g. the exactly known first pose); else a ``ValueError``.

    Returns
    -------
    ndarray, shape (T,)
    """
    errors = np.asarray(errors, dtype=float)
    covariances = np.asarray(covariances, dtype=float)
    if errors.ndim != 2 or covariances.shape != (*errors.shape, errors.shape[1]):
        raise ValueError(f"nees: errors must have shape (T, n) and covariances (T, n, n), got {errors.shape} and "
                         f"{covariances.shape}")
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


def chi2_quantile(probability, dof):
    """Chi-square quantile ``x = 2 gammaincinv(dof / 2, probability)`` (``chi2.ppf`` without importing scipy.stats).

    Parameters
    ----------
    probability : float or array_like
        Lower-tail probability in [0, 1] (0 gives 0, 1 gives inf; outside is NaN).
    dof : int or array_like of int
        Entries ``<= 0`` give NaN.

    Returns
    -------
    float or ndarray (``probability`` and ``dof`` broadcast)
    """
    from scipy import special

    dof = np.asarray(dof, dtype=float)
    quantile = 2.0 * special.gammaincinv(np.where(dof > 0, dof, np.nan) / 2.0, probability)
    return quantile if np.ndim(quantile) else float(quantile)


def chi2_bounds(dof, probability=0.95):
    """Two-sided ``probability`` interval ``[chi2.ppf(a, dof), chi2.ppf(1 - a, dof)]``, ``a = (1 - probability) / 2``.

    Parameters
    ----------
    dof : int or array_like of int

    Returns
    -------
    lower, upper : float, or ndarray of the shape of ``dof``
    """
    tail = (1 - probability) / 2
    dof = np.asarray(dof, dtype=float)
    lower, upper = chi2_quantile(tail, dof), chi2_quantile(1 - tail, dof)
    if dof.ndim == 0:
        return float(lower), float(upper)
    return lower, upper


def nis_band(dof, probability=0.95):
    """Two-sided ``probability`` band of ``chi2(dof) / dof``: where NIS per degree of freedom should stay.

    Parameters
    ----------
    dof : int or array_like of int
        Entries ``<= 0`` (no update) give NaN.

    Returns
    -------
    lower, upper : ndarray (the shape of ``dof``)
    """
    dof = np.asarray(dof, dtype=float)
    lower, upper = chi2_bounds(dof, probability)
    with np.errstate(divide="ignore", invalid="ignore"):  # dof 0: NaN / 0
        return np.asarray(lower / dof), np.asarray(upper / dof)


def average_nees_bounds(dof, runs, probability=0.95):
    """Interval ``chi2_bounds(runs * dof, probability) / runs`` of the average of ``runs`` chi-square(dof) values.

    Parameters
    ----------
    dof, runs : int
        Degrees of freedom of each value (6 for a pose NEES); how many independent values are averaged
        (e.g. Monte-Carlo runs, or time steps).

    Returns
    -------
    lower, upper : float
    """
    lo, hi = chi2_bounds(dof * runs, probability)
    return lo / runs, hi / runs


# ----------------------------------------------------------------------------- KITTI drift

#: Segment lengths (m of ground-truth path) of the KITTI odometry benchmark's drift figures.
DRIFT_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
#: A segment starts every this many frames.
DRIFT_STEP = 10


def path_distances(world_T_imu):
    """Distance (m) along ``world_T_imu`` (T, 4, 4) up to each frame: ``d_0 = 0``, ``d_i = d_{i-1} + |p_i - p_{i-1}|``.

    Returns
    -------
    ndarray, shape (T,)
    """
    p = np.asarray(world_T_imu, dtype=float)[:, :3, 3]
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def kitti_drift(est_world_T_imu, gt_world_T_imu, lengths=DRIFT_LENGTHS, step=DRIFT_STEP):
    """KITTI-style drift: relative pose error over segments of ``lengths`` (m of ground-truth path).

    For every start frame ``f = 0, step, 2 step, ...`` and segment length ``L``, the segment ends at
    the first frame ``l`` whose ground-truth path distance exceeds ``d_f + L`` (none when the drive
    ends first); its error is ``E = inv(inv(est_f) est_l) (inv(gt_f) gt_l)``, averaged over all
    segments (the KITTI devkit's definition, the angle ``|so3_log|``, not ``acos`` of the trace).

    Returns
    -------
    translation_percent : float or None
        Mean ``100 |t(E)| / L`` (%); None when no segment fits in the drive.
    rotation_deg_per_100m : float or None
        Mean ``angle(E) / L`` in degrees per 100 m.
    segments : int
    """
    est, gt = _check_trajectories(est_world_T_imu, gt_world_T_imu, "kitti_drift")
    dist = path_distances(gt)
    first = np.arange(0, len(gt), step)
    t_err, r_err = [], []
    for length in lengths:
        last = np.searchsorted(dist, dist[first] + length, side="right")  # first frame with d > d_f + L
        f, l = first[last < len(gt)], last[last < len(gt)]
        if len(f) == 0:
            continue
        err = lie.se3_inv(lie.se3_inv(est[f]) @ est[l]) @ (lie.se3_inv(gt[f]) @ gt[l])
        t_err.append(np.linalg.norm(err[:, :3, 3], axis=1) / length)
        r_err.append(np.linalg.norm(lie.so3_log(err[:, :3, :3]), axis=1) / length)
    if not t_err:
        return None, None, 0
    t_err, r_err = np.concatenate(t_err), np.concatenate(r_err)
    return float(100 * t_err.mean()), float(np.degrees(r_err.mean()) * 100), len(t_err)


@dataclass(frozen=True)
class TrajectoryEvaluation:
    """How close an estimated trajectory is to the ground truth (:func:`evaluate`).

    Attributes
    ----------
    ate_raw, ate_aligned : float
        :func:`ate` (m) without alignment, and after the best rigid alignment (:func:`align_se3`).
    drift_translation, drift_rotation : float or None
        :func:`kitti_drift` (%, degrees per 100 m) over ``drift_segments`` segments; None when
        unavailable, and ``drift_note`` says why (``""`` when available).
    path_length : float
        Ground-truth path length (m) over the compared frames.
    frames, total_frames : int
        Frames compared (the first ``frames`` poses, those the ground truth covers), and of the estimate.
    """

    ate_raw: float
    ate_aligned: float
    drift_translation: object  # float, or None without a segment
    drift_rotation: object
    drift_segments: int
    drift_note: str
    path_length: float
    frames: int
    total_frames: int

    def summary(self):
        """One line: ATE raw and aligned, drift (or why not), frames compared."""
        if self.drift_translation is None:
            drift = f"drift unavailable ({self.drift_note})"
        else:
            drift = (f"drift {self.drift_translation:.2f} % and {self.drift_rotation:.3f} deg/100 m "
                     f"({self.drift_segments} segments of {DRIFT_LENGTHS[0]:.0f}-{DRIFT_LENGTHS[-1]:.0f} m)")
        frames = f"{self.frames} frames" if self.frames == self.total_frames else \
            f"first {self.frames} of {self.total_frames} frames"
        return (f"ATE {self.ate_raw:.3f} m raw, {self.ate_aligned:.3f} m SE(3)-aligned; {drift}; "
                f"{frames}, {self.path_length:.0f} m of path")

    def as_dict(self, prefix=""):
        """``{prefix + name: value}`` of every field; an unavailable drift is NaN, ``drift_note`` says why."""
        return {prefix + k: (np.nan if v is None else v) for k, v in vars(self).items()}


def evaluate(est_world_T_imu, gt_world_T_imu):
    """ATE (raw and SE(3)-aligned) and KITTI drift of an estimate against the ground truth.

    Parameters
    ----------
    gt_world_T_imu : ndarray, shape (n, 4, 4)
        The ground truth of frames ``0 .. n - 1``, ``1 <= n <= T`` (else a ``ValueError``): a real
        drive's may cover fewer frames; the first ``n`` estimated poses are compared.

    Returns
    -------
    TrajectoryEvaluation
    """
    est = np.asarray(est_world_T_imu, dtype=float)
    gt = np.asarray(gt_world_T_imu, dtype=float)
    if est.ndim != 3 or gt.ndim != 3 or est.shape[1:] != (4, 4) or gt.shape[1:] != (4, 4) or not 1 <= len(gt):
        raise ValueError(f"evaluate: trajectories must have shapes (T, 4, 4) and (n, 4, 4), got {est.shape} "
                         f"and {gt.shape}")
    if len(gt) > len(est):
        raise ValueError(f"evaluate: the ground truth has {len(gt)} frames but the estimate only {len(est)}")
    n = len(gt)
    _check_trajectories(est[:n], gt, "evaluate")
    translation, rotation, segments = kitti_drift(est[:n], gt)
    length = float(path_distances(gt)[-1])
    note = "" if segments else f"ground-truth path {length:.0f} m is shorter than {DRIFT_LENGTHS[0]:.0f} m"
    return TrajectoryEvaluation(
        ate_raw=ate(est[:n], gt, align=False), ate_aligned=ate(est[:n], gt, align=True),
        drift_translation=translation, drift_rotation=rotation, drift_segments=segments, drift_note=note,
        path_length=length, frames=n, total_frames=len(est))


def gated_share(status_totals):
    """The gated share of a run, in [0, 1]: ``gated / (used + gated)``, 0 when the gate tested none.

    Observations the gate never saw (new landmarks, no depth, too far, ignored) are left out: the
    share compares with ``1 - gate_probability``, what a consistent filter without outliers rejects.

    Parameters
    ----------
    status_totals : dict
        Counts by status name (:meth:`visla_edu.run.RunResult.status_totals`); missing ones count as 0.

    Returns
    -------
    float
    """
    used, gated = int(status_totals.get("used", 0)), int(status_totals.get("gated", 0))
    return gated / (used + gated) if used + gated else 0.0
