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
