"""The invariant form of the joint EKF: Jacobians, correction, prediction, consistency."""

import numpy as np
import pytest

from fdiff import fd_jacobian
from visla_edu import ekf, lie, metrics, motion, run, simulate
from visla_edu.filters import FilterConfig
from visla_edu.filters._forms import InvariantForm, RightForm
from visla_edu.simulate import default_rig
from visla_edu.camera import StereoCamera


def _camera():
    K, b, imu_T_cam = default_rig()
    return StereoCamera(K, b, imu_T_cam)


def _pose_and_points(rng, n=5):
    """A random pose and ``n`` points in front of its camera."""
    cam = _camera()
    mu = lie.se3_exp(np.r_[rng.normal(0, 20, 3), rng.normal(0, 0.5, 3)])
    p_cam = np.c_[rng.uniform(-5, 5, n), rng.uniform(-2, 2, n), rng.uniform(5, 40, n)]
    world_T_cam = mu @ cam.imu_T_cam
    return cam, mu, p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


def test_invariant_jacobians_match_finite_differences():
    """z(xi, e) = h(exp(xi) mu, exp(theta) mu_m + e): d/dxi = [-J_landmark, 0], d/de = J_landmark."""
    rng = np.random.default_rng(0)
    cam, mu, points = _pose_and_points(rng)
    for m in points:
        def z_of(x):
            T = lie.se3_exp(x[:6]) @ mu
            p = lie.so3_exp(x[3:6]) @ m + x[6:]
            return cam.predict(T, p[None])[0]

        numeric = fd_jacobian(z_of, np.zeros(9), 1e-5)
        _, J_landmark, J_pose = cam.predict_with_jacobians(mu, m[None])
        analytic = np.concatenate([ekf.invariant_pose_jacobian(J_landmark)[0], J_landmark[0]], axis=1)
        np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-6 * np.abs(numeric).max())


def test_moving_the_whole_world_changes_no_invariant_observation():
    """The unobservable directions [t, 0, t] (and [0, theta, 0]) are in the null space at any estimate."""
    rng = np.random.default_rng(1)
    cam, mu, points = _pose_and_points(rng)
    _, J_landmark, _ = cam.predict_with_jacobians(mu, points)
    J_pose = ekf.invariant_pose_jacobian(J_landmark)
    t = rng.normal(size=3)
    moved = J_pose[:, :, :3] @ t + J_landmark @ t
    np.testing.assert_allclose(moved, 0.0, atol=1e-12)
    np.testing.assert_array_equal(J_pose[:, :, 3:], 0.0)


def test_invariant_retract_is_the_group_update():
    """mu <- exp(xi) mu exactly; mu_j <- R_xi mu_j + J_l(theta) e_j (the SE_K(3) exponential)."""
    rng = np.random.default_rng(2)
    _, mu, points = _pose_and_points(rng, 3)
    delta = rng.normal(0, 0.3, 6 + 9)
    T_new, p_new = ekf.invariant_retract(mu, points, delta)
    step = lie.se3_exp(delta[:6])
    np.testing.assert_allclose(T_new, step @ mu, atol=1e-12)
    for j, m in enumerate(points):
        # the landmark part of the group exponential is se3_exp([e_j; theta])'s translation
        expected = step[:3, :3] @ m + lie.se3_exp(np.r_[delta[6 + 3 * j:9 + 3 * j], delta[3:6]])[:3, 3]
        np.testing.assert_allclose(p_new[j], expected, atol=1e-12)


def _right_from_invariant(world_T_imu, means):
    """The linear map from invariant errors [xi; e_j] to right-form errors [delta; dm_j]."""
    n = len(means)
    M = np.zeros((6 + 3 * n, 6 + 3 * n))
    M[:6, :6] = lie.adjoint(lie.se3_inv(world_T_imu))
    for j, m in enumerate(means):
        rows = slice(6 + 3 * j, 9 + 3 * j)
        M[rows, 3:6] = -lie.hat(m)
        M[rows, rows] = np.eye(3)
    return M


def _random_spd(rng, D):
    A = rng.normal(size=(D, D))
    return A @ A.T / D + 0.1 * np.eye(D)


def test_invariant_prediction_equals_the_right_form_prediction():
    """Mapped to right-form errors, Sigma + B B^T is F Sigma F^T + W (pose) with static landmarks."""
    rng = np.random.default_rng(3)
    _, mu, means = _pose_and_points(rng, 4)
    u, tau = np.r_[8.0, 0.2, -0.1, 0.02, -0.01, 0.3], 0.1
    step, F, W = motion.imu_step(u, tau, [0.3, 0.1, 0.2], [0.02, 0.03, 0.05])
    mu_next = mu @ step
    Sigma_inv = _random_spd(rng, 6 + 3 * len(means))
    predicted_inv = motion.predict_invariant_covariance(Sigma_inv.copy(), mu_next, means, W)

    M, M_next = _right_from_invariant(mu, means), _right_from_invariant(mu_next, means)
    predicted_right = motion.predict_joint_covariance(M @ Sigma_inv @ M.T, F, W)
    np.testing.assert_allclose(M_next @ predicted_inv @ M_next.T, predicted_right, rtol=1e-9, atol=1e-9)


def test_invariant_landmark_covariances_are_those_of_the_landmark_error():
    """InvariantForm.landmark_covs and pose_cov are the marginals of the mapped covariance."""
    rng = np.random.default_rng(4)
    _, mu, means = _pose_and_points(rng, 3)
    Sigma = _random_spd(rng, 6 + 9)
    M = _right_from_invariant(mu, means)
    right = M @ Sigma @ M.T
    cols = ekf.slot_columns(np.arange(3))
    expected = right[cols[:, :, None], cols[:, None, :]]
    np.testing.assert_allclose(InvariantForm.landmark_covs(Sigma, cols, means), expected, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(InvariantForm.pose_cov(Sigma[:6, :6], mu), right[:6, :6], rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(RightForm.landmark_covs(Sigma, cols, means), Sigma[cols[:, :, None], cols[:, None, :]])


def _invariant_errors(mu, means, T, m):
    """The invariant errors ``[xi; e_j]`` of a true state (T, m) about the mean (mu, means).

    ``T = exp(xi^) mu`` and ``m_j = exp(theta^) mu_j + e_j``, ``xi = [p; theta]`` (world frame).
    """
    xi = lie.se3_log(T @ lie.se3_inv(mu))
    e = m - means @ lie.so3_exp(xi[3:]).T
    return np.r_[xi, e.ravel()]


def test_invariant_noise_factor_is_the_jacobian_of_the_errors_in_the_step_noise():
    """B = d[xi; e_j]/dn L for a step that ends at mu exp(n^) (n ~ N(0, W), W = L L^T), landmarks fixed."""
    rng = np.random.default_rng(5)
    for trial in range(3):
        _, mu, means = _pose_and_points(rng, 3)
        sigmas = rng.uniform(0.01, 0.5, 6)
        W = np.diag(sigmas**2)
        if trial == 2:  # a full (correlated) noise covariance takes the Cholesky branch
            A = rng.normal(size=(6, 6))
            W = A @ A.T / 6 + 0.01 * np.eye(6)
        L = np.linalg.cholesky(W)
        B = motion.invariant_noise_factor(mu, means, W)
        assert B.shape == (6 + 3 * len(means), 6)
        J = fd_jacobian(lambda n: _invariant_errors(mu, means, mu @ lie.se3_exp(n), means), np.zeros(6), 1e-5)
        np.testing.assert_allclose(B, J @ L, rtol=1e-7, atol=1e-7 * np.abs(B).max())


def test_invariant_landmark_sensitivity_is_the_jacobian_of_a_new_landmarks_error():
    """A landmark placed from the true pose exp(xi^) mu at the IMU-frame point p_imu has the error
    e = m - exp(theta^) mu p_imu, whose derivative in xi is [I, 0] (right form: G_pose)."""
    rng = np.random.default_rng(6)
    cam, mu, points = _pose_and_points(rng, 4)
    p_imu = (lie.se3_inv(mu) @ np.c_[points, np.ones(len(points))].T).T[:, :3]
    G_right = rng.normal(size=(len(points), 3, 6))  # only its length is used
    G = InvariantForm.landmark_sensitivity(G_right)
    np.testing.assert_array_equal(RightForm.landmark_sensitivity(G_right), G_right)
    for j, p in enumerate(p_imu):
        def error(xi, p=p):
            m_true = (lie.se3_exp(xi) @ mu @ np.r_[p, 1.0])[:3]
            return m_true - lie.so3_exp(xi[3:]) @ (mu @ np.r_[p, 1.0])[:3]
        np.testing.assert_allclose(G[j], fd_jacobian(error, np.zeros(6), 1e-5), atol=1e-8)


def test_invariant_covariances_convert_through_the_jacobian_of_the_error_change():
    """pose_cov and landmark_covs are M Sigma M^T with M = d[delta; m - mu_m]/d[xi; e] by finite
    differences (delta = log(mu^-1 T), the right perturbation the library reports)."""
    rng = np.random.default_rng(7)
    for _ in range(2):
        _, mu, means = _pose_and_points(rng, 3)
        n = len(means)

        def right_errors(x):
            T = lie.se3_exp(x[:6]) @ mu
            m = means @ lie.so3_exp(x[3:6]).T + x[6:].reshape(n, 3)
            return np.r_[lie.se3_log(lie.se3_inv(mu) @ T), (m - means).ravel()]

        M = fd_jacobian(right_errors, np.zeros(6 + 3 * n), 1e-5)
        Sigma = _random_spd(rng, 6 + 3 * n)
        right = M @ Sigma @ M.T
        np.testing.assert_allclose(InvariantForm.pose_cov(Sigma[:6, :6], mu), right[:6, :6], rtol=1e-7, atol=1e-9)
        cols = ekf.slot_columns(np.arange(n))
        np.testing.assert_allclose(InvariantForm.landmark_covs(Sigma, cols, means),
                                   right[cols[:, :, None], cols[:, None, :]], rtol=1e-7, atol=1e-9)


def _mean_nees(form, seeds, **sim):
    values = []
    for seed in seeds:
        ds = simulate.simulate_drive("small", seed, outlier_share=0.0, **sim)
        c = ds.extra["config"]
        cfg = FilterConfig(sigma_pixel=c.pixel_sigma, sigma_linear_velocity=c.linear_velocity_sigma,
                           sigma_angular_velocity=c.angular_velocity_sigma, extrinsic_correction="none",
                           slam_error=form)
        r = run.run_filter(ds, "slam", cfg, progress=False)
        e = metrics.pose_errors(r.world_T_imu, ds.ground_truth.world_T_imu)
        values.append(np.nanmean(metrics.nees(e, r.pose_cov)))
    return np.array(values)


@pytest.mark.slow
def test_invariant_form_is_consistent_where_the_right_form_is_not():
    """Sparse 300-frame drives with noisy velocities, noise known (measured: invariant mean
    NEES 4.9-7.9 over 4 seeds, right form 28-161; 6 is consistent)."""
    sparse = dict(num_landmarks=80, linear_velocity_sigma=0.5, angular_velocity_sigma=0.05)
    invariant = _mean_nees("invariant", range(4), **sparse)
    right = _mean_nees("right", range(4), **sparse)
    assert 3.0 < invariant.mean() < 12.0, invariant
    assert right.mean() > 3 * invariant.mean(), (right, invariant)
