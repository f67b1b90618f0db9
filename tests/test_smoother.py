"""Tests for visla_edu.smoother: Jacobians, the Schur/envelope solver, marginals, convergence.

Conventions under test (README, "Conventions"): twist ``u = [v; w]``, poses ``world_T_imu``, right
perturbation ``T = mu exp(delta^)``; motion residual ``e_t = log(exp(-tau u^) T_t^{-1} T_{t+1})``.
Every analytic Jacobian is checked against finite differences (tests/fdiff.py).
"""

import re

import numpy as np
import pytest
from scipy.sparse import linalg as sparse_linalg

from fdiff import fd_jacobian  # tests/fdiff.py
from visla_edu import codes, lie, metrics, motion, run, settings, simulate, smoother
from visla_edu.camera import StereoCamera
from visla_edu.filters import FilterConfig
from visla_edu.smoother import _batch, _envelope, _normal, _problem

FD_REL = 1e-6


def rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b)


# --- residuals ------------------------------------------------------------------------------


def _random_motion(rng, K=4):
    poses = lie.se3_exp(np.concatenate([rng.normal(0, 5, (K + 1, 3)), rng.normal(0, 0.8, (K + 1, 3))], 1))
    step_inv = lie.se3_exp(-np.concatenate([rng.normal(0, 1, (K, 3)), rng.normal(0, 0.1, (K, 3))], 1))
    return poses, step_inv


def test_motion_residual_jacobians_match_finite_differences():
    rng = np.random.default_rng(2)
    poses, step_inv = _random_motion(rng)
    _, J_prev, J_next = smoother.motion_residuals(poses, step_inv)
    for t in range(len(step_inv)):
        for which, J in ((t, J_prev[t]), (t + 1, J_next[t])):
            def e(d, which=which, t=t):
                moved = poses.copy()
                moved[which] = poses[which] @ lie.se3_exp(d)
                return smoother.motion_residuals(moved, step_inv, jacobians=False)[t]
            assert rel(J, fd_jacobian(e, np.zeros(6), 1e-6)) < FD_REL


def test_motion_residual_is_zero_on_dead_reckoning():
    rng = np.random.default_rng(3)
    stamps = np.cumsum(rng.uniform(0.09, 0.11, 20))
    twists = np.concatenate([rng.normal(5, 1, (20, 3)), rng.normal(0, 0.1, (20, 3))], 1)
    for lag in (0, 1):
        poses = motion.dead_reckon(stamps, twists, lag=lag)
        step_inv, _ = smoother._factors.motion_steps(stamps, twists, lag)
        assert np.abs(smoother.motion_residuals(poses, step_inv, jacobians=False)).max() < 1e-12


@pytest.fixture(scope="module")
def rig():
    return simulate.default_rig()


def test_reprojection_equals_the_camera_model_and_its_jacobians(rig):
    rng = np.random.default_rng(4)
    cam = StereoCamera(*rig)
    poses = lie.se3_exp(np.concatenate([rng.normal(0, 3, (6, 3)), rng.normal(0, 0.2, (6, 3))], 1))
    p_world = np.stack([(T @ cam.imu_T_cam @ np.r_[rng.uniform(-5, 5, 2), rng.uniform(5, 40), 1])[:3]
                        for T in poses])
    z, depth, J_m, J_p = smoother.reprojection(cam.Ks, cam.cam_T_imu, poses, p_world)
    for i, T in enumerate(poses):
        z_c, J_m_c, J_p_c = cam.predict_with_jacobians(T, p_world[i:i + 1])
        assert np.allclose(z[i], z_c[0]) and np.allclose(J_m[i], J_m_c[0]) and np.allclose(J_p[i], J_p_c[0])
        fd_p = fd_jacobian(lambda d, i=i: smoother.reprojection(
            cam.Ks, cam.cam_T_imu, (poses[i] @ lie.se3_exp(d))[None], p_world[i:i + 1], False)[0][0], np.zeros(6), 1e-6)
        fd_m = fd_jacobian(lambda d, i=i: smoother.reprojection(
            cam.Ks, cam.cam_T_imu, poses[i:i + 1], (p_world[i] + d)[None], False)[0][0], np.zeros(3), 1e-6)
        assert rel(J_p[i], fd_p) < FD_REL and rel(J_m[i], fd_m) < FD_REL
    assert np.all(depth > 0)


@pytest.mark.parametrize("loss", ["cauchy", "huber", "none"])
def test_robust_weight_is_the_derivative_of_the_loss(loss):
    s = np.array([0.1, 2.0, 8.9, 9.1, 30.0, 400.0])
    rho, weight = smoother.robust_loss(s, loss, 3.0)
    fd = np.array([(smoother.robust_loss(np.array([x + 1e-6]), loss, 3.0)[0][0]
                    - smoother.robust_loss(np.array([x - 1e-6]), loss, 3.0)[0][0]) / 2e-6 for x in s])
    assert np.allclose(weight, fd, rtol=1e-5)
    assert np.all(rho <= s + 1e-12)


# --- the problem on a tiny drive ------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny():
    return simulate.simulate_drive("tiny", 3, outlier_share=0.05)


def _problem_at(dataset, world_T_imu, config, landmarks=None):
    """The batch problem at a state, after the initial landmark checks (as :func:`smooth` builds it)."""
    camera = _problem.rig_camera(dataset)
    problem, m, _, _ = _batch._setup(dataset, world_T_imu, landmarks, camera, config)
    _batch.drop_landmarks(problem, world_T_imu, m, config.min_observations)
    return problem, m


def test_normal_equations_are_jtwj_of_the_checked_jacobians(tiny):
    _assert_normal_equations_are_jtwj(tiny)


def test_normal_equations_of_a_rig_with_two_intrinsics_are_jtwj_too():
    """K_r != K_l: the closed-form blocks (_projection_information_two) against the camera's Jacobians."""
    K = np.array(simulate.default_rig()[0], dtype=float)
    K_right = K @ np.array([[1.04, 0.0, 0.02], [0.0, 1.03, -0.03], [0.0, 0.0, 1.0]])
    _assert_normal_equations_are_jtwj(simulate.simulate_drive("tiny", 3, outlier_share=0.05, K_right=K_right))


def _assert_normal_equations_are_jtwj(tiny):
    config = smoother.SmootherConfig(loss="huber", loss_scale=1.0)
    T = tiny.ground_truth.world_T_imu
    problem, m = _problem_at(tiny, T, config)
    problem.active[::7] = False  # inactive observations must contribute nothing
    lin = _normal.linearize(problem, T, m)
    H, g = _normal.normal_equations(problem, lin)
    n, L = problem.num_vars, problem.num_landmarks
    z, _, J_m, J_p = smoother.reprojection(problem.Ks, problem.cam_T_imu, T[problem.obs_frame], m[problem.obs_landmark])
    r = z - problem.obs_z
    s = np.sum(r * r, axis=1) / config.sigma_pixel**2
    w = smoother.robust_loss(s, config.loss, config.loss_scale)[1] / config.sigma_pixel**2 * problem.active
    J = np.zeros((4 * len(r), 6 * n + 3 * L))
    for i, (t, j) in enumerate(zip(problem.obs_frame, problem.obs_landmark)):
        if t >= 1:
            J[4 * i:4 * i + 4, 6 * (t - 1):6 * t] = J_p[i]
        J[4 * i:4 * i + 4, 6 * n + 3 * j:6 * n + 3 * j + 3] = J_m[i]
    W = np.repeat(w, 4)
    H_ref, g_ref = J.T @ (W[:, None] * J), J.T @ (W * r.ravel())
    e, J_prev, J_next = smoother.motion_residuals(T, problem.step_inv)
    J_mo = np.zeros((6 * len(e), 6 * n + 3 * L))
    sq = problem.motion_sqrt_information
    for k in range(len(e)):
        if k >= 1:
            J_mo[6 * k:6 * k + 6, 6 * (k - 1):6 * k] = sq[k][:, None] * J_prev[k]
        J_mo[6 * k:6 * k + 6, 6 * k:6 * k + 6] = sq[k][:, None] * J_next[k]
    H_ref += J_mo.T @ J_mo
    g_ref += J_mo.T @ (sq * e).ravel()
    for j in np.flatnonzero(~problem.landmark_active):  # dropped landmarks: an identity block, no coupling
        H_ref[6 * n + 3 * j:6 * n + 3 * j + 3, 6 * n + 3 * j:6 * n + 3 * j + 3] = np.eye(3)
    assert rel(H.toarray(), H_ref) < 1e-12 and rel(g, g_ref) < 1e-12


def test_public_normal_equations_are_the_batch_problems(tiny):
    """smoother.normal_equations builds the problem smooth() solves and returns its full system."""
    T = tiny.ground_truth.world_T_imu
    config = smoother.SmootherConfig()
    problem, m = _problem_at(tiny, T, config)
    H_ref, g_ref = _normal.normal_equations(problem, _normal.linearize(problem, T, m))
    system = smoother.normal_equations(tiny, T, config=config)
    n, L = tiny.num_frames - 1, problem.num_landmarks
    assert system.num_poses == n and system.H.shape == (6 * n + 3 * L,) * 2
    assert (system.H != H_ref).nnz == 0 and np.array_equal(system.g, g_ref)
    assert np.array_equal(system.landmark_ids, problem.landmark_ids)
    assert np.array_equal(system.landmark_active, problem.landmark_active)
    assert system.cost == pytest.approx(_normal.evaluate(problem, T, m), rel=1e-12)
    assert abs(system.H - system.H.T).max() <= 1e-12 * abs(system.H).max()  # symmetric to round-off
    with pytest.raises(ValueError, match=r"initial world_T_imu must have shape \(60, 4, 4\)"):
        smoother.normal_equations(tiny, T[:10])


def test_gradient_matches_finite_differences_of_the_robust_cost(tiny):
    ekf = run.run_filter(tiny, "slam", progress=False)
    problem, m = _problem_at(tiny, ekf.world_T_imu, smoother.SmootherConfig(), ekf.landmarks)
    T = ekf.world_T_imu
    lin = _normal.linearize(problem, T, m)
    for frame in (1, 30, 59):
        def cost(d, frame=frame):
            moved = T.copy()
            moved[frame] = T[frame] @ lie.se3_exp(d)
            return np.array([_normal.evaluate(problem, moved, m)])
        assert rel(2 * lin.g_p[frame - 1], fd_jacobian(cost, np.zeros(6), 1e-6)[0]) < 1e-6
    for j in (0, 40):
        def cost(d, j=j):
            moved = m.copy()
            moved[j] = m[j] + d
            return np.array([_normal.evaluate(problem, T, moved)])
        assert rel(2 * lin.g_m[j], fd_jacobian(cost, np.zeros(3), 1e-6)[0]) < 1e-6


def test_schur_solve_equals_the_full_sparse_solve(tiny):
    """The Schur complement + envelope Cholesky step equals scipy's sparse LU on the full system.

    The full system's condition number is about 1e10 (far landmarks), so the two agree to
    about 1e-8 relative (rounding, and the 1e-12 relative floor on landmark blocks); a wrong
    block would show up at order one.
    """
    T = motion.dead_reckon(tiny.time_stamps, tiny.twists)
    problem, m = _problem_at(tiny, T, smoother.SmootherConfig())
    lin = _normal.linearize(problem, T, m)
    for damping in (0.0, 1e-3):
        step = _normal.solve_step(problem, lin, damping)
        H, g = _normal.normal_equations(problem, lin)
        H = H + damping * sparse_diag(H)
        full = sparse_linalg.spsolve(H.tocsc(), -g)
        mine = np.concatenate([step.d_pose.ravel(), step.d_landmark.ravel()])
        assert rel(mine, full) < 1e-6


def sparse_diag(H):
    from scipy import sparse
    return sparse.diags(np.maximum(H.diagonal(), 1e-12))


def test_marginals_equal_the_dense_inverse_of_the_hessian(tiny):
    T = tiny.ground_truth.world_T_imu
    problem, m = _problem_at(tiny, T, smoother.SmootherConfig())
    lin = _normal.linearize(problem, T, m)
    pose_cov, landmark_cov = _normal.marginals(problem, lin)
    H, _ = _normal.normal_equations(problem, lin)
    Sigma = np.linalg.inv(H.toarray())
    n = problem.num_vars
    for t in (0, 17, n - 1):
        assert rel(pose_cov[t], Sigma[6 * t:6 * t + 6, 6 * t:6 * t + 6]) < 1e-8
    for j in (0, 25, problem.num_landmarks - 1):
        k = 6 * n + 3 * j
        assert rel(landmark_cov[j], Sigma[k:k + 3, k:k + 3]) < 1e-8


# --- the envelope solver ---------------------------------------------------------------------


@pytest.mark.parametrize("n,corrections,longest", [(1, 0, 1), (3, 2, 3), (40, 30, 8), (150, 200, 6), (70, 30, 60)])
def test_envelope_factor_solve_and_inverse_match_dense(n, corrections, longest):
    rng = np.random.default_rng(n)
    lo = rng.integers(0, n, corrections)
    hi = np.minimum(lo + rng.integers(0, longest, corrections), n - 1)
    start = np.concatenate([[0], np.cumsum(hi - lo + 1)])[:-1].astype(np.int64)
    rows = 0.3 * rng.normal(size=(int(np.sum(hi - lo + 1)), 6, 3))
    diag = rng.normal(size=(n, 6, 6))
    diag = diag @ np.swapaxes(diag, 1, 2) + 60 * np.eye(6)
    system = _envelope.EnvelopeSystem(diag, rng.normal(size=(n - 1, 6, 6)), lo, hi, start, rows)
    A = _envelope.to_dense(system)
    shift = max(0.0, 1.0 - np.linalg.eigvalsh(A).min())
    system.diag += shift * np.eye(6)
    A = _envelope.to_dense(system)
    factor = _envelope.cholesky(system)
    rhs = rng.normal(size=(n, 6))
    assert rel(_envelope.solve(factor, rhs).ravel(), np.linalg.solve(A, rhs.ravel())) < 1e-10
    A_inv = np.linalg.inv(A)
    blocks = np.array([A_inv[6 * i:6 * i + 6, 6 * i:6 * i + 6] for i in range(n)])
    assert rel(_envelope.inverse_diagonal(factor), blocks) < 1e-10


def test_envelope_cholesky_reports_a_matrix_that_is_not_positive_definite():
    system = _envelope.EnvelopeSystem(-np.eye(6)[None].repeat(2, 0), np.zeros((1, 6, 6)), np.zeros(0, int),
                                      np.zeros(0, int), np.zeros(0, int), np.zeros((0, 6, 3)))
    with pytest.raises(np.linalg.LinAlgError):
        _envelope.cholesky(system)


# --- the smoothers --------------------------------------------------------------------------


def test_noise_free_drive_converges_to_the_truth():
    ds = simulate.simulate_drive("tiny", 0, linear_velocity_sigma=0, angular_velocity_sigma=0, pixel_sigma=0,
                                 outlier_share=0, nonpositive_disparity_share=0)
    truth = ds.ground_truth.world_T_imu
    rng = np.random.default_rng(0)
    start = truth.copy()
    start[1:] = truth[1:] @ lie.se3_exp(np.concatenate([rng.normal(0, 0.3, (ds.num_frames - 1, 3)),
                                                         rng.normal(0, 0.01, (ds.num_frames - 1, 3))], 1))
    result = smoother.smooth(ds, start)
    assert np.abs(result.world_T_imu[:, :3, 3] - truth[:, :3, 3]).max() < 1e-6
    kept = np.isfinite(result.landmarks[:, 0])
    assert kept.sum() > 0.9 * ds.num_landmarks
    assert np.abs(result.landmarks[kept] - ds.ground_truth.landmarks[kept]).max() < 1e-6
    assert result.rejected["outliers"] == 0


def test_batch_reports_why_each_round_stopped(tiny):
    ekf = run.run_filter(tiny, "slam", progress=False)
    converged = smoother.smooth(tiny, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam,
                                smoother.SmootherConfig(max_iterations=50))
    assert converged.stop_reasons[-1] == "converged"
    assert len(converged.stop_reasons) == len(np.unique(converged.history["round"]))
    assert "final round: converged" in converged.summary()
    capped = smoother.smooth(tiny, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam,
                             smoother.SmootherConfig(max_iterations=1, rejection_rounds=0))
    assert capped.stop_reasons == ["iteration cap"] and len(capped.history["cost"]) == 1
    assert "iteration cap, max_iterations=1 (not converged" in capped.summary()
    assert set(capped.stop_reasons) <= set(smoother.STOP_REASONS)


def test_batch_result_shapes_history_and_counts(tiny):
    ekf = run.run_filter(tiny, "slam", progress=False)
    result = smoother.smooth(tiny, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam)
    T, M = tiny.num_frames, tiny.num_landmarks
    assert result.world_T_imu.shape == (T, 4, 4) and result.landmarks.shape == (M, 3)
    assert result.pose_cov.shape == (T, 6, 6) and result.landmark_cov.shape == (M, 3, 3)
    assert np.all(result.pose_cov[0] == 0) and np.all(np.linalg.eigvalsh(result.pose_cov[1:]) > 0)
    kept = np.isfinite(result.landmarks[:, 0])
    assert np.all(np.isfinite(result.landmark_cov[kept])) and np.all(np.isnan(result.landmark_cov[~kept]))
    h = result.history
    assert set(h) == set(smoother.HISTORY_FIELDS) and len(h["cost"]) >= 2
    accepted_costs = h["cost"][h["accepted"] & (h["round"] == h["round"][-1])]
    assert np.all(np.diff(accepted_costs) < 0)
    totals = result.status_totals()
    assert totals["gated"] == result.rejected["outliers"] > 0
    assert totals["no depth"] == result.rejected["nonpositive_disparity"] > 0
    assert "landmarks estimated" in result.summary()


def test_batch_is_never_worse_than_the_ekf_on_a_tiny_drive_with_outliers(tiny):
    ekf = run.run_filter(tiny, "slam", progress=False)
    result = smoother.smooth(tiny, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam)
    truth = tiny.ground_truth.world_T_imu
    assert metrics.ate(result.world_T_imu, truth, align=False) < metrics.ate(ekf.world_T_imu, truth, align=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_batch_is_never_worse_than_the_ekf_on_small_drives(seed):
    ds = simulate.simulate_drive("small", seed, outlier_share=0.05)
    ekf = run.run_filter(ds, "slam", FilterConfig(msckf_window=0), progress=False)  # the joint EKF without clones
    result = smoother.smooth(ds, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam)
    truth = ds.ground_truth.world_T_imu
    assert metrics.ate(result.world_T_imu, truth, align=False) < 0.5 * metrics.ate(ekf.world_T_imu, truth, align=False)


@pytest.mark.parametrize("mode", smoother.WINDOW_MODES)
def test_window_smoother_runs_online_and_beats_dead_reckoning(tiny, mode):
    result = smoother.smooth_window(tiny, config=smoother.SmootherConfig(window_mode=mode, window_size=8))
    truth = tiny.ground_truth.world_T_imu
    T = tiny.num_frames
    assert result.mode == "window" and result.world_T_imu.shape == (T, 4, 4)
    assert result.online_world_T_imu.shape == (T, 4, 4) and np.all(result.frame_seconds[1:] > 0)
    assert np.all(np.isfinite(result.pose_cov[1:])) and np.all(np.linalg.eigvalsh(result.pose_cov[1:]) > 0)
    dead = metrics.ate(motion.dead_reckon(tiny.time_stamps, tiny.twists), truth, align=False)
    assert metrics.ate(result.world_T_imu, truth, align=False) < dead
    assert metrics.ate(result.online_world_T_imu, truth, align=False) < dead


def test_window_costs_are_sums_of_squares_with_the_folded_landmark_priors(tiny):
    """The priors from held frames carry the squared errors they folded in: no cost is negative."""
    result = smoother.smooth_window(tiny, config=smoother.SmootherConfig(window_size=8))
    costs = np.asarray(result.history["cost"])
    assert len(costs) > tiny.num_frames // 2 and np.all(np.isfinite(costs)) and costs.min() >= 0


# --- input checks ---------------------------------------------------------------------------


@pytest.mark.parametrize("field,value", [
    ("sigma_pixel", 0.0), ("sigma_linear_velocity", -1.0), ("sigma_angular_velocity", np.nan),
    ("loss", "l1"), ("loss_scale", 0), ("max_iterations", 0), ("max_iterations", 2.5),
    ("function_tolerance", -1e-6), ("rejection_probability", 0.0), ("rejection_probability", 1.5),
    ("rejection_rounds", -1), ("min_observations", 1), ("min_depth", -0.1), ("min_disparity", np.inf),
    ("imu_lag", 0.5), ("window_size", 1), ("window_iterations", 0), ("window_mode", "drop"),
    ("initial_damping", 0.0), ("step_tolerance", np.inf),
])
def test_config_rejects_bad_values_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"SmootherConfig.{field}"):
        smoother.SmootherConfig(**{field: value})



@pytest.mark.parametrize("text, expected", [
    ("window_size=40", ("window_size", 40)), (" loss = Huber ", ("loss", "huber")),
    ("pose_covariance=false", ("pose_covariance", False)), ("loss_scale=2", ("loss_scale", 2.0)),
    ("landmark_covariance=No", ("landmark_covariance", False)), ("pose_covariance=1", ("pose_covariance", True)),
    ("window_mode=marginalize", ("window_mode", "marginalize")),
])
def test_parse_setting_reads_a_value_as_its_setting_type(text, expected):
    name, value = settings.parse_setting(smoother.SmootherConfig, text)
    assert (name, value) == expected and type(value) is type(expected[1])


@pytest.mark.parametrize("text, message", [
    ("window_size", "expected NAME=VALUE"), ("window_size=2.5", "window_size needs an int (an integer >= 2"),
    ("pose_covariance=maybe", "pose_covariance needs a bool (true or false"),
    ("loss_scale=nan", "loss_scale needs a float (a number > 0"),
    ("window_mode=drop", "window_mode must be one of 'fix', 'marginalize'"),
])
def test_parse_setting_names_what_is_wrong(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        settings.parse_setting(smoother.SmootherConfig, text)

def test_bad_initial_values_get_a_clear_error(tiny):
    T = tiny.ground_truth.world_T_imu
    with pytest.raises(ValueError, match=r"world_T_imu must have shape \(60, 4, 4\)"):
        smoother.smooth(tiny, T[:-1])
    bad = T.copy()
    bad[7, 0, 3] = np.nan
    with pytest.raises(ValueError, match="non-finite entries at frame 7"):
        smoother.smooth(tiny, bad)
    with pytest.raises(ValueError, match=r"landmarks must have shape"):
        smoother.smooth(tiny, T, np.zeros((3, 3)))


def test_infinite_initial_landmarks_are_refused_and_nan_rows_allowed(tiny):
    T = tiny.ground_truth.world_T_imu
    given = np.full((tiny.num_landmarks, 3), np.nan)  # NaN rows: not mapped, triangulated
    given[4] = [1.0, 2.0, 3.0]
    assert smoother.normal_equations(tiny, T, given).H.shape[0] > 0
    given[9, 1] = np.inf
    with pytest.raises(ValueError, match=r"infinite entries at landmark 9 \(1 landmarks\); use a NaN row"):
        smoother.smooth(tiny, T, given)
    with pytest.raises(ValueError, match="infinite entries at landmark 9"):
        smoother.normal_equations(tiny, T, given)


def test_initial_landmarks_come_from_the_largest_disparity_observation(tiny):
    usable = tiny.obs_z[:, 0] - tiny.obs_z[:, 2] > 0
    T = tiny.ground_truth.world_T_imu
    given = np.full((tiny.num_landmarks, 3), np.nan)
    given[0] = [1.0, 2.0, 3.0]  # a given position is kept
    m = smoother.triangulate_landmarks(tiny, tiny.camera, T, usable, given)
    assert np.array_equal(m[0], given[0])
    frames = tiny.observation_frames()
    for j in (5, 40, 90):
        obs = np.flatnonzero((tiny.obs_ids == j) & usable)
        best = obs[np.argmax(tiny.obs_z[obs, 0] - tiny.obs_z[obs, 2])]
        assert np.allclose(m[j], tiny.camera.triangulate(tiny.obs_z[best:best + 1], T[frames[best]])[0])


@pytest.mark.slow
@pytest.mark.data
def test_batch_improves_on_the_ekf_and_dead_reckoning_on_kitti_0020(require_data, data_dir):
    """0020 = KITTI odometry 06; its velocities are nearly noise-free, so both use small noise."""
    from visla_edu import data

    ds = data.load(str(require_data("0020")))
    poses = data_dir / "kitti_odometry_06_poses.txt"
    if not poses.is_file():
        pytest.skip(f"{poses.name} not found in {data_dir}")
    rows = np.loadtxt(poses).reshape(-1, 3, 4)
    P = np.tile(np.eye(4), (len(rows), 1, 1))
    P[:, :3, :] = rows
    truth = ds.imu_T_cam @ P @ lie.se3_inv(ds.imu_T_cam)  # world_T_imu = imu_T_cam P cam_T_imu
    noise = {"imu_lag": 1, "sigma_linear_velocity": 0.05, "sigma_angular_velocity": 0.005}
    ekf = run.run_filter(ds, "slam", FilterConfig(**noise), progress=False)
    result = smoother.smooth(ds, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam, smoother.SmootherConfig(**noise))
    n = len(truth)
    ate = {name: metrics.ate(T[:n], truth, align=False) for name, T in (
        ("smoother", result.world_T_imu), ("ekf", ekf.world_T_imu),
        ("dead reckoning", motion.dead_reckon(ds.time_stamps, ds.twists, lag=1)))}
    assert ate["smoother"] < ate["ekf"] < ate["dead reckoning"], ate


def test_window_keeps_the_status_of_unusable_observations_of_a_landmark_it_drops(tiny):
    """A landmark dropped as too close keeps its non-positive-disparity observation counted as such."""
    import dataclasses

    reference = smoother.smooth_window(tiny, config=smoother.SmootherConfig(window_size=8))
    assert reference.rejected["landmarks_behind_camera"] > 0
    j = tiny.obs_ids[np.flatnonzero(reference.obs_status == codes.OBS_DROPPED)[0]]
    i = np.flatnonzero(tiny.obs_ids == j)[-1]
    z = tiny.obs_z.copy()
    z[i, 2] = z[i, 0] + 1.0  # no depth: never usable
    ds = dataclasses.replace(tiny, obs_z=z, extra={})
    result = smoother.smooth_window(ds, config=smoother.SmootherConfig(window_size=8))
    nonpositive = int(np.sum(z[:, 0] - z[:, 2] <= 0))
    assert result.obs_status[i] == codes.OBS_NO_DEPTH
    assert result.rejected["nonpositive_disparity"] == result.status_totals()["no depth"] == nonpositive


@pytest.mark.parametrize("min_disparity,rejection_probability", [(8.0, 0.999), (3.0, 0.05)])
def test_window_counts_every_landmark_it_did_not_estimate_as_the_batch_does(tiny, min_disparity,
                                                                            rejection_probability):
    """No observation counts as used unless its landmark is in the map; each landmark left out is
    counted once (8 px: far landmarks, never triangulated; 0.05: most observations rejected)."""
    config = smoother.SmootherConfig(window_size=8, min_disparity=min_disparity,
                                     rejection_probability=rejection_probability)
    result = smoother.smooth_window(tiny, config=config)
    batch = smoother.smooth(tiny, tiny.ground_truth.world_T_imu, config=config)
    assert set(result.rejected) == set(batch.rejected)
    estimated = np.isfinite(result.landmarks[:, 0])
    assert not np.any((result.obs_status == codes.OBS_USED) & ~estimated[tiny.obs_ids])
    usable = np.bincount(tiny.obs_ids, np.isin(result.obs_status, [codes.OBS_USED, codes.OBS_DROPPED, codes.OBS_GATED]),
                         tiny.num_landmarks) > 0
    left_out = {k: v for k, v in result.rejected.items() if k.startswith("landmarks_")}
    assert sum(left_out.values()) == usable.sum() - estimated.sum() > 0
    if min_disparity > 3:
        assert result.rejected["landmarks_too_far"] > 0


def test_window_time_per_frame_leaves_out_the_held_first_frame(tiny):
    result = smoother.smooth_window(tiny.segment(0, 2))
    assert result.frame_seconds[0] == 0 and result.frame_seconds[1] > 0
    ms = f"{1e3 * result.frame_seconds[1]:.2f} ms"
    assert f"per frame: median {ms}, max {ms}" in result.summary()


@pytest.mark.parametrize("field,value", [
    ("imu_lag", 100), ("imu_lag", -3), ("sigma_pixel", True), ("min_depth", False),
    ("rejection_probability", True), ("rejection_probability", "0.5"), ("initial_damping", np.True_),
    ("sigma_linear_velocity", True), ("sigma_angular_velocity", (True, 0.1, 0.1)),
])
def test_config_refuses_what_it_would_clip_or_read_as_a_number(field, value):
    """A lag beyond the filter's -2 .. 2 was clipped to the drive's ends by select_twists; a bool
    was read as 0 or 1; a string probability raised a TypeError."""
    with pytest.raises(ValueError, match=f"SmootherConfig.{field} must"):
        smoother.SmootherConfig(**{field: value})
    assert smoother.SmootherConfig(imu_lag=-2).imu_lag == -2


# --- the window's priors: Jacobians against finite differences ---------------------------------


def _with_priors(tiny, rng):
    """The batch problem at a perturbed truth, with a pose prior and landmark priors (as the window builds)."""
    T = tiny.ground_truth.world_T_imu @ lie.se3_exp(rng.normal(0, 0.01, (tiny.num_frames, 6)))
    T[0] = tiny.ground_truth.world_T_imu[0]
    problem, m = _problem_at(tiny, T, smoother.SmootherConfig())
    m = m + rng.normal(0, 0.05, m.shape)
    U = np.triu(rng.normal(0, 1, (6, 6))) + 5 * np.eye(6)
    problem.prior = _problem.PosePrior(7, T[7] @ lie.se3_exp(rng.normal(0, 0.05, 6)), U)
    A = rng.normal(0, 1, (problem.num_landmarks, 3, 3))
    problem.landmark_prior = (A @ np.swapaxes(A, 1, 2) + np.eye(3), rng.normal(0, 1, (problem.num_landmarks, 3)),
                              np.zeros(problem.num_landmarks))
    return problem, T, m


def test_pose_prior_jacobian_matches_finite_differences(tiny):
    problem, T, _ = _with_priors(tiny, np.random.default_rng(11))
    frame = problem.prior.frame

    def residual(d):
        moved = T.copy()
        moved[frame] = T[frame] @ lie.se3_exp(d)
        return _normal._prior_residual(problem, moved)[0]
    assert rel(_normal._prior_residual(problem, T)[1], fd_jacobian(residual, np.zeros(6), 1e-6)) < FD_REL


def test_gradient_with_pose_and_landmark_priors_matches_finite_differences(tiny):
    problem, T, m = _with_priors(tiny, np.random.default_rng(12))
    lin = _normal.linearize(problem, T, m)
    assert lin.cost == pytest.approx(_normal.evaluate(problem, T, m), rel=1e-12)
    frame = problem.prior.frame

    def pose_cost(d):
        moved = T.copy()
        moved[frame] = T[frame] @ lie.se3_exp(d)
        return np.array([_normal.evaluate(problem, moved, m)])
    assert rel(2 * lin.g_p[frame - problem.first_var], fd_jacobian(pose_cost, np.zeros(6), 1e-6)[0]) < 1e-6
    for j in (0, 40):
        def landmark_cost(d, j=j):
            moved = m.copy()
            moved[j] = m[j] + d
            return np.array([_normal.evaluate(problem, T, moved)])
        # the priors' cost is large (m^T Lambda m over every landmark): a wider step keeps rounding out
        assert rel(2 * lin.g_m[j], fd_jacobian(landmark_cost, np.zeros(3), 1e-4)[0]) < 1e-6


def test_held_frame_landmark_prior_is_the_linearised_observation_cost():
    """``_WindowState.hold``: the folded prior m^T Lambda m - 2 m^T eta + c has the observations'
    cost sum w |r(m)|^2 and its gradient (finite differences) at the linearisation point m0."""
    from visla_edu.smoother import _window

    ds = simulate.simulate_drive("tiny", 1)
    config = smoother.SmootherConfig(loss="none")
    camera = _problem.rig_camera(ds)
    state = _window._WindowState(ds, ds.ground_truth.world_T_imu[0], camera, config)
    state.world_T_imu[:] = ds.ground_truth.world_T_imu
    rng = np.random.default_rng(14)
    state.landmarks[:] = ds.ground_truth.landmarks + rng.normal(0, 0.3, ds.ground_truth.landmarks.shape)
    v = 5
    state.hold(v)
    idx = np.arange(ds.frame_ptr[v], ds.frame_ptr[v + 1])
    idx = idx[state.status[idx] == codes.OBS_USED]
    ids = ds.obs_ids[idx]
    assert len(ids) > 3 and np.all(state.held_count[ids] == 1)
    for i, j in zip(idx[:4], ids[:4]):
        m0 = state.landmarks[j]

        def observed_cost(m, i=i):
            z = smoother.reprojection(camera.Ks, camera.cam_T_imu, state.world_T_imu[v][None], m[None], False)[0]
            return np.array([np.sum((z[0] - ds.obs_z[i]) ** 2) / config.sigma_pixel**2])

        Lam, eta, c = state.prior_info[j], state.prior_eta[j], state.prior_const[j]
        assert m0 @ Lam @ m0 - 2 * m0 @ eta + c == pytest.approx(observed_cost(m0)[0], rel=1e-6)
        assert rel(2 * (Lam @ m0 - eta), fd_jacobian(observed_cost, m0, 1e-4)[0]) < 1e-6


def test_marginalised_pose_prior_propagates_through_the_motion_jacobian():
    """``_next_prior``: ``F = Ad(exp(-tau u^))`` is the Jacobian of ``log(mean^{-1} T_v exp(a) exp(tau u^))``."""
    import types

    from visla_edu.smoother import _window

    rng = np.random.default_rng(13)
    step_inv = lie.se3_exp(-np.r_[rng.normal(0, 1, 3), rng.normal(0, 0.1, 3)])
    T_v = lie.se3_exp(rng.normal(0, 1, 6))
    state = types.SimpleNamespace(step_inv=step_inv[None], sqrt_info=np.full((1, 6), 3.0), world_T_imu=T_v[None])
    A = rng.normal(0, 0.1, (6, 6))
    cov = A @ A.T
    prior = _window._next_prior(state, cov, 0)
    assert prior.frame == 1 and np.allclose(prior.mean, T_v @ lie.se3_inv(step_inv))
    F = fd_jacobian(lambda a: lie.se3_log(lie.se3_inv(prior.mean) @ T_v @ lie.se3_exp(a) @ lie.se3_inv(step_inv)),
                    np.zeros(6), 1e-6)
    information = prior.sqrt_information.T @ prior.sqrt_information
    assert rel(np.linalg.inv(information), F @ cov @ F.T + np.eye(6) / 9) < 1e-8


def test_a_filter_config_or_a_dict_as_smoother_config_gets_a_clear_error(tiny):
    """They used to fail deep inside (AttributeError: no attribute 'min_disparity', int('auto'))."""
    T = tiny.ground_truth.world_T_imu
    for call, name in ((lambda c: smoother.smooth(tiny, T, config=c), "smooth"),
                       (lambda c: smoother.smooth_window(tiny, config=c), "smooth_window"),
                       (lambda c: smoother.normal_equations(tiny, T, config=c), "normal_equations")):
        with pytest.raises(TypeError, match=rf"{name}: config must be a SmootherConfig, got FilterConfig; "
                                            r"smoother.SmootherConfig.from_filter_config"):
            call(FilterConfig())
        with pytest.raises(TypeError, match=rf"{name}: config must be a SmootherConfig, got dict"):
            call({"window_size": 5})
