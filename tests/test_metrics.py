"""Tests of visla_edu.metrics: ATE with and without alignment, RPE, NEES, chi-square bounds."""

import numpy as np
import pytest
from scipy import stats

from visla_edu import lie, metrics


def _trajectory(rng, T=50):
    """A smooth random trajectory (T, 4, 4) starting at the identity."""
    poses = [np.eye(4)]
    for _ in range(T - 1):
        u = np.concatenate([[1.0, 0.0, 0.0] + 0.1 * rng.standard_normal(3), 0.05 * rng.standard_normal(3)])
        poses.append(poses[-1] @ lie.se3_exp(u))
    return np.stack(poses)


def _random_transform(rng, translation=3.0):
    return lie.se3_exp(np.concatenate([translation * rng.standard_normal(3), rng.standard_normal(3)]))


# ----------------------------------------------------------------------------- ATE


def test_ate_of_a_rigidly_transformed_copy():
    rng = np.random.default_rng(0)
    gt = _trajectory(rng)
    A = _random_transform(rng)
    est = A @ gt  # the same trajectory in another world frame
    assert metrics.ate(est, gt) < 1e-10
    p_est, p_gt = est[:, :3, 3], gt[:, :3, 3]
    expected = np.sqrt(np.mean(np.sum((p_est - p_gt) ** 2, axis=1)))
    assert metrics.ate(est, gt, align=False) == pytest.approx(expected, rel=1e-12)
    assert metrics.ate(est, gt, align=False) > 0.5
    assert metrics.ate(gt, gt, align=False) == 0.0


def test_ate_known_values():
    rng = np.random.default_rng(1)
    gt = _trajectory(rng)
    shifted = gt.copy()
    shifted[:, :3, 3] += [0.3, -0.4, 0.0]
    assert metrics.ate(shifted, gt, align=False) == pytest.approx(0.5, rel=1e-12)
    assert metrics.ate(shifted, gt) < 1e-10  # a pure offset is removed by the alignment
    # per-frame errors of known RMS that no rigid motion explains: +-d alternating along z
    wobble = gt.copy()
    wobble[:, 2, 3] += 0.2 * (-1.0) ** np.arange(len(gt))
    assert metrics.ate(wobble, gt, align=False) == pytest.approx(0.2, rel=1e-12)
    assert metrics.ate(wobble, gt) == pytest.approx(0.2, rel=0.05)
    assert metrics.ate(wobble, gt) <= metrics.ate(wobble, gt, align=False) + 1e-12


def test_align_se3_recovers_the_transform():
    rng = np.random.default_rng(2)
    p_est = rng.standard_normal((30, 3)) * 5
    A = _random_transform(rng)
    p_gt = p_est @ A[:3, :3].T + A[:3, 3]
    T = metrics.align_se3(p_est, p_gt)
    np.testing.assert_allclose(T, A, atol=1e-10)
    # a mirrored point set: the best *rotation* is returned, never a reflection
    T = metrics.align_se3(p_est, p_est * np.array([1.0, 1.0, -1.0]))
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)


def test_ate_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="shape"):
        metrics.ate(np.zeros((5, 4, 4)), np.zeros((6, 4, 4)))
    with pytest.raises(ValueError, match="shape"):
        metrics.ate(np.zeros((5, 3, 4)), np.zeros((5, 3, 4)))


def _straight_drive(T=8):
    poses = np.repeat(np.eye(4)[None], T, axis=0)
    poses[:, 0, 3] = np.arange(T)
    return poses


@pytest.mark.parametrize("metric", [lambda e, g: metrics.ate(e, g), lambda e, g: metrics.ate(e, g, align=False),
                                    lambda e, g: metrics.rpe(e, g, 2), metrics.pose_errors, metrics.evaluate])
def test_metrics_refuse_a_non_finite_or_non_rigid_pose_and_name_its_frame(metric):
    gt = _straight_drive()
    est = gt.copy()
    est[5, 1, 1] = np.nan
    with pytest.raises(ValueError, match="the estimate's pose of frame 5 is not finite"):
        metric(est, gt)
    est = gt.copy()
    est[3, :3, :3] *= 2.0  # a scaled rotation
    with pytest.raises(ValueError, match="the estimate's pose of frame 3 is not a rigid transform"):
        metric(est, gt)
    bad_gt = gt.copy()
    bad_gt[4, 3, 0] = 1.0
    with pytest.raises(ValueError, match="the ground truth's pose of frame 4 is not a rigid transform"):
        metric(gt, bad_gt)


def test_metrics_accept_the_rounding_the_trajectory_readers_accept():
    """KITTI files carry 7 digits; the readers accept |R^T R - I| up to 1e-3, and so do the metrics."""
    gt = _straight_drive()
    gt[:, :3, :3] *= 1 + 4e-4  # |R^T R - I| = 8e-4
    assert metrics.evaluate(_straight_drive(), gt).ate_raw == pytest.approx(0.0)


def test_metrics_refuse_empty_trajectories():
    with pytest.raises(ValueError, match=r"ate: the trajectories are empty \(T = 0\)"):
        metrics.ate(np.zeros((0, 4, 4)), np.zeros((0, 4, 4)))


def test_rpe_delta_must_be_a_whole_number_of_frames():
    with pytest.raises(ValueError, match="rpe: delta must be a whole number of frames, got 2.5"):
        metrics.rpe(_straight_drive(), _straight_drive(), delta=2.5)


def test_nees_refuses_errors_and_covariances_that_do_not_match():
    with pytest.raises(ValueError, match=r"nees: errors must have shape \(T, n\) and covariances \(T, n, n\), "
                                         r"got \(60, 6\) and \(10, 6, 6\)"):
        metrics.nees(np.zeros((60, 6)), np.repeat(np.eye(6)[None], 10, axis=0))
    with pytest.raises(ValueError, match=r"got \(60, 6\) and \(60, 3, 3\)"):
        metrics.nees(np.zeros((60, 6)), np.repeat(np.eye(3)[None], 60, axis=0))


# ----------------------------------------------------------------------------- RPE


def test_rpe_of_identical_and_world_shifted_trajectories_is_zero():
    rng = np.random.default_rng(3)
    gt = _trajectory(rng)
    t, r = metrics.rpe(gt, gt, delta=5)
    assert t < 1e-14 and r < 1e-14
    t, r = metrics.rpe(_random_transform(rng) @ gt, gt, delta=5)
    assert t < 1e-10 and r < 1e-10


@pytest.mark.parametrize("delta", [1, 4, 10])
def test_rpe_of_a_constant_speed_error(delta):
    """Truth moves 1 m and turns 0.01 rad per frame; the estimate 1.1 m and 0.03 rad per frame."""
    T = 30
    gt_step = lie.se3_exp([1.0, 0, 0, 0, 0, 0])
    est_step = lie.se3_exp([1.1, 0, 0, 0, 0, 0])
    gt = np.stack([np.linalg.matrix_power(gt_step, k) for k in range(T)])
    est = np.stack([np.linalg.matrix_power(est_step, k) for k in range(T)])
    trans, rot = metrics.rpe(est, gt, delta=delta)
    assert trans == pytest.approx(0.1 * delta, rel=1e-10) and rot == 0.0
    # rotation about z only
    gt = np.stack([lie.se3_exp([0, 0, 0, 0, 0, 0.01 * k]) for k in range(T)])
    est = np.stack([lie.se3_exp([0, 0, 0, 0, 0, 0.03 * k]) for k in range(T)])
    trans, rot = metrics.rpe(est, gt, delta=delta)
    assert rot == pytest.approx(0.02 * delta, rel=1e-10) and trans < 1e-12


def test_rpe_rejects_bad_delta():
    gt = np.broadcast_to(np.eye(4), (5, 4, 4))
    for delta in (0, 5, -1):
        with pytest.raises(ValueError, match="delta"):
            metrics.rpe(gt, gt, delta=delta)


# ----------------------------------------------------------------------------- pose errors, NEES


def test_pose_errors_follow_the_right_perturbation_convention():
    rng = np.random.default_rng(4)
    mu = np.stack([_random_transform(rng) for _ in range(6)])
    e = 0.1 * rng.standard_normal((6, 6))
    truth = mu @ lie.se3_exp(e)  # T = mu exp(e)
    np.testing.assert_allclose(metrics.pose_errors(mu, truth), e, atol=1e-12)
    # the left perturbation is a different error
    truth_left = lie.se3_exp(e) @ mu
    assert not np.allclose(metrics.pose_errors(mu, truth_left), e, atol=1e-3)


def test_nees_on_known_errors():
    rng = np.random.default_rng(5)
    T, n = 7, 6
    covs, errors, expected = [], [], []
    for _ in range(T):
        A = rng.standard_normal((n, n))
        P = A @ A.T + 0.1 * np.eye(n)
        w = rng.standard_normal(n)
        covs.append(P)
        errors.append(np.linalg.cholesky(P) @ w)  # e = L w  ->  e^T P^-1 e = |w|^2
        expected.append(w @ w)
    np.testing.assert_allclose(metrics.nees(errors, covs), expected, rtol=1e-9)
    # diagonal example by hand
    out = metrics.nees([[1.0, 2.0, 3.0]], [np.diag([1.0, 4.0, 0.25])])
    assert out[0] == pytest.approx(1 + 1 + 36)


def test_nees_singular_covariances():
    errors = np.ones((2, 6))
    covs = np.stack([np.zeros((6, 6)), np.eye(6)])
    out = metrics.nees(errors, covs)
    assert np.isnan(out[0]) and out[1] == pytest.approx(6.0)
    with pytest.raises(ValueError, match="step 0"):
        metrics.nees(errors, covs, skip_singular=False)


def test_nees_of_sampled_errors_averages_the_dof():
    rng = np.random.default_rng(6)
    P = np.diag([0.1, 0.2, 0.3, 0.01, 0.02, 0.03])
    errors = rng.multivariate_normal(np.zeros(6), P, size=4000)
    assert metrics.nees(errors, np.broadcast_to(P, (4000, 6, 6))).mean() == pytest.approx(6.0, abs=0.25)


# ----------------------------------------------------------------------------- chi-square bounds


@pytest.mark.parametrize("dof", [1, 3, 6, 40])
@pytest.mark.parametrize("p", [0.9, 0.95, 0.99])
def test_chi2_bounds_match_scipy(dof, p):
    lo, hi = metrics.chi2_bounds(dof, p)
    a = (1 - p) / 2
    assert lo == pytest.approx(stats.chi2.ppf(a, dof), rel=1e-12)
    assert hi == pytest.approx(stats.chi2.ppf(1 - a, dof), rel=1e-12)
    assert metrics.chi2_bounds(dof) == metrics.chi2_bounds(dof, 0.95)


def test_chi2_bounds_and_nis_band_on_arrays():
    dof = np.array([4, 0, 40])
    lo, hi = metrics.chi2_bounds(dof)
    assert lo.shape == hi.shape == (3,)
    for i in (0, 2):
        assert (lo[i], hi[i]) == metrics.chi2_bounds(int(dof[i]))
    assert np.isnan(lo[1]) and np.isnan(hi[1])  # no degrees of freedom: no band
    band_lo, band_hi = metrics.nis_band(dof)
    np.testing.assert_array_equal(band_lo[[0, 2]], lo[[0, 2]] / dof[[0, 2]])
    np.testing.assert_array_equal(band_hi[[0, 2]], hi[[0, 2]] / dof[[0, 2]])
    assert np.isnan(band_lo[1]) and np.isnan(band_hi[1])


@pytest.mark.parametrize("dof, runs", [(6, 1), (6, 8), (3, 50)])
def test_average_nees_bounds(dof, runs):
    lo, hi = metrics.average_nees_bounds(dof, runs)
    assert lo == pytest.approx(stats.chi2.ppf(0.025, dof * runs) / runs, rel=1e-12)
    assert hi == pytest.approx(stats.chi2.ppf(0.975, dof * runs) / runs, rel=1e-12)
    assert lo < dof < hi
    # coverage: ~95% of averages of `runs` chi-square(dof) values fall inside
    rng = np.random.default_rng(dof * 100 + runs)
    averages = rng.chisquare(dof, size=(4000, runs)).mean(axis=1)
    assert np.mean((averages > lo) & (averages < hi)) == pytest.approx(0.95, abs=0.015)


# ----------------------------------------------------------------------------- KITTI drift, evaluate


def _straight(n, step=0.25):
    """``n`` poses ``step`` m apart along x, identity rotations: path length ``step * (n - 1)``."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = step * np.arange(n)
    return poses


def test_drift_of_a_constant_scale_error_is_that_error():
    gt = _straight(4001)  # 1000 m
    est = gt.copy()
    est[:, :3, 3] *= 1.01  # 1% too long everywhere
    translation, rotation, segments = metrics.kitti_drift(est, gt)
    # the error over a segment is 1% of its chord, which exceeds the nominal length by < one 0.25 m step
    assert 1.0 <= translation <= 1.0 * (1 + 0.25 / 100) and rotation == 0.0
    # starts every 10 frames (2.5 m) whose segment of L m ends before 1000 m: sum of (1000 - L) / 2.5
    assert segments == sum(int((1000 - L) / 2.5) for L in range(100, 900, 100)) == 1760


def test_drift_of_a_constant_heading_error_rate():
    gt = _straight(4001)
    k = 1e-3  # rad of extra yaw per metre
    est = gt.copy()
    est[:, :3, :3] = lie.so3_exp(np.outer(k * gt[:, 0, 3], [0, 0, 1.0]))
    _, rotation, _ = metrics.kitti_drift(est, gt)
    assert np.degrees(k) * 100 <= rotation <= np.degrees(k) * 100 * (1 + 0.25 / 100)


def test_drift_matches_a_plain_loop_over_segments():
    rng = np.random.default_rng(5)
    gt = _trajectory(rng, T=400)
    est = gt @ lie.se3_exp(0.02 * rng.standard_normal((400, 6)))
    dist = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1))])
    t_errs, r_errs = [], []
    for first in range(0, 400, 10):
        for length in (100.0, 200.0, 300.0):
            later = [i for i in range(first, 400) if dist[i] > dist[first] + length]
            if not later:
                continue
            last = later[0]
            E = np.linalg.inv(np.linalg.inv(est[first]) @ est[last]) @ np.linalg.inv(gt[first]) @ gt[last]
            t_errs.append(np.linalg.norm(E[:3, 3]) / length)
            r_errs.append(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1, 1)) / length)
    translation, rotation, segments = metrics.kitti_drift(est, gt, lengths=(100.0, 200.0, 300.0))
    assert segments == len(t_errs) > 50
    assert translation == pytest.approx(100 * np.mean(t_errs), rel=1e-9)
    assert rotation == pytest.approx(np.degrees(np.mean(r_errs)) * 100, rel=1e-6)


def test_evaluate_gathers_ate_and_drift():
    rng = np.random.default_rng(2)
    gt = _straight(4001)
    est = gt.copy()
    est[:, :3, 3] *= 1.01
    est = _random_transform(rng) @ est  # another world frame: raw ATE sees it, aligned ATE and drift do not
    result = metrics.evaluate(est, gt)
    assert result.ate_raw == metrics.ate(est, gt, align=False) and result.ate_raw > 1
    assert result.ate_aligned == metrics.ate(est, gt, align=True)
    assert result.ate_aligned == pytest.approx(0.01 * np.std(gt[:, 0, 3]), rel=1e-6)  # the scale is left
    assert result.drift_translation == pytest.approx(1.0, rel=3e-3) and result.drift_note == ""
    assert (result.frames, result.total_frames, result.path_length) == (4001, 4001, 1000.0)
    line = result.summary()
    assert "\n" not in line and "1.00 %" in line and "1760 segments" in line and "raw" in line
    assert result.as_dict("estimate_")["estimate_drift_segments"] == 1760


def test_evaluate_a_short_drive_says_why_there_is_no_drift():
    gt = _straight(200)  # 49.75 m
    result = metrics.evaluate(gt, gt)
    assert result.drift_translation is None and result.drift_rotation is None and result.drift_segments == 0
    assert "shorter than 100 m" in result.drift_note and "drift unavailable" in result.summary()
    values = result.as_dict()
    assert np.isnan(values["drift_translation"]) and values["drift_note"] == result.drift_note


def test_evaluate_compares_the_frames_the_ground_truth_covers():
    gt = _straight(300)
    est = np.concatenate([gt, _straight(5) + 1.0])
    result = metrics.evaluate(est, gt)
    assert (result.frames, result.total_frames, result.ate_raw) == (300, 305, 0.0)
    assert "first 300 of 305 frames" in result.summary()
    with pytest.raises(ValueError, match="ground truth has 305 frames but the estimate only 300"):
        metrics.evaluate(gt, est)
    est[7, 0, 0] = np.nan
    with pytest.raises(ValueError, match="estimate's pose of frame 7 is not finite"):
        metrics.evaluate(est, gt)


def test_chi2_quantile_is_scipy_stats_chi2_ppf():
    q = np.array([1e-9, 0.001, 0.025, 0.5, 0.975, 0.999, 1 - 1e-9])
    for dof in (1, 2, 4, 6, 61, 6000):
        np.testing.assert_allclose(metrics.chi2_quantile(q, dof), stats.chi2.ppf(q, dof), rtol=1e-12)
    assert isinstance(metrics.chi2_quantile(0.95, 4), float)
    assert metrics.chi2_quantile(0.95, 4) == pytest.approx(9.487729036781154, rel=1e-12)
    edge = metrics.chi2_quantile(np.array([0.0, 1.0, 1.5]), 3)
    assert edge[0] == 0 and np.isinf(edge[1]) and np.isnan(edge[2])
    assert np.isnan(metrics.chi2_quantile(0.5, 0)) and np.isnan(metrics.chi2_quantile(0.5, -2))


def test_gated_share_is_gated_over_used_plus_gated():
    assert metrics.gated_share({"used": 75, "gated": 25, "new": 100, "no depth": 7, "too far": 3, "ignored": 9}) == 0.25
    assert metrics.gated_share({"used": 10}) == 0.0
    assert metrics.gated_share({"new": 5, "gated": 0, "used": 0}) == 0.0  # the gate tested nothing
    assert metrics.gated_share({"gated": 4}) == 1.0
