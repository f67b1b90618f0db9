"""Tests of visla_edu.motion: dead reckoning and the EKF prediction step.

Every analytic Jacobian is compared with finite differences; the covariance prediction is
checked against the spread of sampled noisy integrations.
"""

import numpy as np
import pytest
from scipy.linalg import block_diag, expm

from visla_edu import lie, motion, simulate

RNG_SEED = 20240611


def _random_twist(rng, v_scale=5.0, w_scale=0.5):
    return np.concatenate([v_scale * rng.standard_normal(3), w_scale * rng.standard_normal(3)])


def _random_pose(rng):
    return lie.se3_exp(np.concatenate([3.0 * rng.standard_normal(3), rng.standard_normal(3)]))


def _random_spd(rng, n, scale=1.0):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T + n * np.eye(n))


# ----------------------------------------------------------------------------- select_twists


def test_select_twists_lag_semantics():
    twists = np.arange(5 * 6, dtype=float).reshape(5, 6)
    np.testing.assert_array_equal(motion.select_twists(twists, 0), twists[:4])
    np.testing.assert_array_equal(motion.select_twists(twists), twists[:4])
    np.testing.assert_array_equal(motion.select_twists(twists, 1), twists[1:])
    # clipped at both ends
    np.testing.assert_array_equal(motion.select_twists(twists, 2), twists[[2, 3, 4, 4]])
    np.testing.assert_array_equal(motion.select_twists(twists, -1), twists[[0, 0, 1, 2]])
    assert motion.select_twists(twists, 7).shape == (4, 6)


def test_select_twists_rejects_bad_shape():
    with pytest.raises(ValueError, match="shape"):
        motion.select_twists(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="shape"):
        motion.select_twists(np.zeros(6))


# ----------------------------------------------------------------------------- dead_reckon


def test_dead_reckon_equals_explicit_loop():
    rng = np.random.default_rng(RNG_SEED)
    T = 25
    stamps = np.cumsum(0.05 + 0.1 * rng.random(T))
    twists = np.stack([_random_twist(rng) for _ in range(T)])
    T0 = _random_pose(rng)
    for lag in (0, 1):
        poses = motion.dead_reckon(stamps, twists, world_T_imu0=T0, lag=lag)
        assert poses.shape == (T, 4, 4)
        expected = T0.copy()
        np.testing.assert_allclose(poses[0], T0)
        for t in range(T - 1):
            u = twists[min(t + lag, T - 1)]
            expected = expected @ lie.se3_exp((stamps[t + 1] - stamps[t]) * u)
            np.testing.assert_allclose(poses[t + 1], expected, atol=1e-10)
    # the lags really differ
    assert not np.allclose(motion.dead_reckon(stamps, twists, lag=0), motion.dead_reckon(stamps, twists, lag=1))


def test_dead_reckon_starts_at_identity_by_default():
    poses = motion.dead_reckon([0.0, 0.1, 0.2], np.tile([1.0, 0, 0, 0, 0, 0.1], (3, 1)))
    np.testing.assert_array_equal(poses[0], np.eye(4))
    # 1 m/s forward for 0.2 s with a slow turn: about 0.2 m travelled
    assert np.linalg.norm(poses[-1, :3, 3]) == pytest.approx(0.2, rel=1e-3)


@pytest.mark.parametrize("seed", [0, 3])
def test_dead_reckon_reproduces_noise_free_simulated_drive(seed):
    ds = simulate.simulate_drive("tiny", seed, linear_velocity_sigma=0.0, angular_velocity_sigma=0.0)
    poses = motion.dead_reckon(ds.time_stamps, ds.twists)
    truth = ds.ground_truth.world_T_imu
    assert np.max(np.abs(poses - truth)) < 1e-9
    # and the noisy IMU of the same drive does not (the test can fail)
    noisy = simulate.simulate_drive("tiny", seed)
    assert np.max(np.abs(motion.dead_reckon(noisy.time_stamps, noisy.twists) - truth)) > 1e-3


# ----------------------------------------------------------------------------- pose_transition


def test_pose_transition_is_expm_of_curly_hat():
    rng = np.random.default_rng(RNG_SEED + 1)
    for _ in range(10):
        u = _random_twist(rng)
        tau = 0.02 + 0.2 * rng.random()
        F = motion.pose_transition(u, tau)
        np.testing.assert_allclose(F, expm(-tau * lie.curly_hat(u)), atol=1e-10)
    # near-zero rotation (series branch of the closed forms)
    u = np.array([3.0, 0.1, -0.2, 1e-9, 0.0, 2e-9])
    np.testing.assert_allclose(motion.pose_transition(u, 0.1), expm(-0.1 * lie.curly_hat(u)), atol=1e-12)


def _propagated_error(mu, u, tau, delta):
    """delta_{t+1} from mu exp(delta) exp(tau u) = mu exp(tau u) exp(delta_{t+1})."""
    step = lie.se3_exp(tau * u)
    return lie.se3_log(lie.se3_inv(mu @ step) @ mu @ lie.se3_exp(delta) @ step)


def test_pose_transition_matches_finite_differences_of_error_propagation():
    rng = np.random.default_rng(RNG_SEED + 2)
    eps = 1e-6
    for _ in range(5):
        mu = _random_pose(rng)
        u = _random_twist(rng)
        tau = 0.1
        F = motion.pose_transition(u, tau)
        F_fd = np.empty((6, 6))
        for j in range(6):
            e = np.zeros(6)
            e[j] = eps
            F_fd[:, j] = (_propagated_error(mu, u, tau, e) - _propagated_error(mu, u, tau, -e)) / (2 * eps)
        np.testing.assert_allclose(F, F_fd, atol=1e-7)
        # the transpose (a classic slip) is not the Jacobian
        assert not np.allclose(F.T, F_fd, atol=1e-4)


def test_imu_step_agrees_with_the_separate_functions():
    rng = np.random.default_rng(RNG_SEED + 6)
    for _ in range(5):
        u, tau = _random_twist(rng), 0.05 + 0.1 * rng.random()
        step, F, W = motion.imu_step(u, tau, 0.3, 0.02)
        mu = _random_pose(rng)
        np.testing.assert_allclose(mu @ step, motion.predict_pose(mu, u, tau), atol=1e-12)
        np.testing.assert_allclose(F, motion.pose_transition(u, tau), atol=1e-12)
        np.testing.assert_array_equal(W, motion.motion_noise(tau, 0.3, 0.02))


def test_predict_pose_is_right_multiplication():
    rng = np.random.default_rng(RNG_SEED + 3)
    mu, u = _random_pose(rng), _random_twist(rng)
    np.testing.assert_allclose(motion.predict_pose(mu, u, 0.1), mu @ lie.se3_exp(0.1 * u))


# ----------------------------------------------------------------------------- noise, covariance


def test_motion_noise_shape_and_values():
    W = motion.motion_noise(0.1, 0.3, 0.02)
    assert W.shape == (6, 6)
    np.testing.assert_allclose(W, np.diag([0.03**2] * 3 + [0.002**2] * 3), rtol=1e-12)
    np.testing.assert_array_equal(motion.motion_noise(0.1, 0.0, 0.0), np.zeros((6, 6)))
    # quadratic in the time step
    np.testing.assert_allclose(motion.motion_noise(0.2, 0.3, 0.02), 4 * W)


def test_predict_pose_covariance():
    rng = np.random.default_rng(RNG_SEED + 4)
    P = _random_spd(rng, 6)
    F = motion.pose_transition(_random_twist(rng), 0.1)
    W = motion.motion_noise(0.1, 0.3, 0.02)
    np.testing.assert_allclose(motion.predict_pose_covariance(P, F, W), F @ P @ F.T + W)


@pytest.mark.parametrize("n_landmarks", [0, 1, 7])
def test_predict_joint_covariance_equals_dense_block_form(n_landmarks):
    rng = np.random.default_rng(RNG_SEED + 5 + n_landmarks)
    D = 6 + 3 * n_landmarks
    Sigma = _random_spd(rng, D)
    F = motion.pose_transition(_random_twist(rng), 0.1)
    W = motion.motion_noise(0.1, 0.3, 0.02)
    F_big = block_diag(F, np.eye(3 * n_landmarks)) if n_landmarks else F
    W_big = np.zeros((D, D))
    W_big[:6, :6] = W
    expected = F_big @ Sigma @ F_big.T + W_big
    work = Sigma.copy()
    out = motion.predict_joint_covariance(work, F, W)
    assert out is work  # in place
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(out, out.T, atol=1e-10)


# ----------------------------------------------------------------------------- Monte Carlo


def _integrate_batch(twists, tau):
    """Integrate (N, steps, 6) twists from the identity: (N, 4, 4)."""
    T = np.broadcast_to(np.eye(4), (twists.shape[0], 4, 4)).copy()
    for k in range(twists.shape[1]):
        T = T @ lie.se3_exp(tau * twists[:, k])
    return T


def _mc_setup(n_samples=400, steps=30, tau=0.1, sv=0.3, sw=0.03, seed=11):
    rng = np.random.default_rng(seed)
    u = np.column_stack([np.full(steps, 8.0), np.full(steps, 0.2), np.zeros(steps),
                         np.full(steps, 0.02), np.full(steps, -0.01), np.linspace(-0.4, 0.4, steps)])
    mu = _integrate_batch(u[None], tau)[0]
    noise = rng.standard_normal((n_samples, steps, 6)) * np.array([sv] * 3 + [sw] * 3)
    samples = _integrate_batch(u[None] + noise, tau)
    errors = lie.se3_log(lie.se3_inv(mu) @ samples)  # T = mu exp(e)
    return u, tau, sv, sw, errors


def _whitened_spread(P, errors):
    """Mean NEES of the samples under P and eigenvalues of their whitened covariance."""
    L = np.linalg.cholesky(P)
    white = np.linalg.solve(L, errors.T).T
    return np.mean(np.sum(white**2, axis=1)), np.linalg.eigvalsh(white.T @ white / len(errors))


def _predicted_cov(u, tau, sv, sw, transition):
    P = np.zeros((6, 6))
    for x in u:
        P = motion.predict_pose_covariance(P, transition(x), motion.motion_noise(tau, sv, sw))
    return P


def test_predicted_covariance_matches_monte_carlo_spread():
    u, tau, sv, sw, errors = _mc_setup()
    P = _predicted_cov(u, tau, sv, sw, lambda x: motion.pose_transition(x, tau))
    mean_nees, eig = _whitened_spread(P, errors)
    # 400 samples: mean of chi2(6) has sd 0.17; whitened covariance eigenvalues near 1
    assert 5.2 < mean_nees < 6.8, mean_nees
    assert eig.min() > 0.65 and eig.max() < 1.45, eig


@pytest.mark.parametrize("wrong", ["transpose", "identity", "sign"])
def test_monte_carlo_check_rejects_wrong_transitions(wrong):
    """The same criterion fails for the classic slips, so the Monte Carlo test has teeth."""
    u, tau, sv, sw, errors = _mc_setup()
    transition = {
        "transpose": lambda x: motion.pose_transition(x, tau).T,
        "identity": lambda x: np.eye(6),
        "sign": lambda x: motion.pose_transition(-x, tau),
    }[wrong]
    mean_nees, eig = _whitened_spread(_predicted_cov(u, tau, sv, sw, transition), errors)
    assert not (5.2 < mean_nees < 6.8 and eig.min() > 0.65 and eig.max() < 1.45)
