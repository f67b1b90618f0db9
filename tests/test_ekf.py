"""Tests of visla_edu.ekf: every fast update against its textbook (dense, explicit-inverse) form,
and the initialisation Jacobians against finite differences."""

import numpy as np
import pytest
from scipy import stats
from scipy.linalg import block_diag

from visla_edu import ekf, lie, simulate
from visla_edu.filters import FilterConfig
from visla_edu.camera import StereoCamera, triangulate_disparity, triangulation_jacobian

K_RIG, B_RIG, IMU_T_CAM = simulate.default_rig()
NOISE_VAR = 1.5**2


@pytest.fixture
def camera():
    return StereoCamera(K_RIG, B_RIG, IMU_T_CAM)


def _random_spd(rng, n, scale=1.0):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.5 * np.eye(n))


def _random_pose(rng):
    return lie.se3_exp(np.concatenate([5.0 * rng.standard_normal(3), 0.5 * rng.standard_normal(3)]))


def _points_in_view(rng, camera, world_T_imu, n, depth=(4.0, 40.0)):
    """World points in front of the left camera, well inside the image."""
    Z = rng.uniform(*depth, n)
    u = rng.uniform(100, 1300, n)
    v = rng.uniform(50, 450, n)
    K = camera.K
    p_cam = np.column_stack([(u - K[0, 2]) * Z / K[0, 0], (v - K[1, 2]) * Z / K[1, 1], Z])
    world_T_cam = world_T_imu @ camera.imu_T_cam
    return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


def _textbook_update(Sigma, H, r, R):
    """K = Sigma H^T S^-1, delta = K r, Sigma - K H Sigma, nis = r^T S^-1 r (explicit inverse)."""
    S = H @ Sigma @ H.T + R
    S_inv = np.linalg.inv(S)
    K = Sigma @ H.T @ S_inv
    return K @ r, Sigma - K @ H @ Sigma, float(r @ S_inv @ r)


def _fd(f, x, eps=1e-6):
    """Central finite-difference Jacobian of f at x (columns = entries of x)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = eps
        cols.append((f(x + e) - f(x - e)) / (2 * eps))
    return np.stack(cols, axis=-1)


# ----------------------------------------------------------------------------- cholesky_update


@pytest.mark.parametrize("seed", range(4))
def test_cholesky_update_equals_textbook(seed):
    rng = np.random.default_rng(seed)
    D, m = 12, 5
    Sigma = _random_spd(rng, D)
    cols = np.sort(rng.choice(D, size=7, replace=False))
    H = rng.standard_normal((m, len(cols)))
    H_full = np.zeros((m, D))
    H_full[:, cols] = H
    r = rng.standard_normal(m)
    R = _random_spd(rng, m, 0.3)
    delta_ref, Sigma_ref, nis_ref = _textbook_update(Sigma, H_full, r, R)

    work = Sigma.copy()
    delta, nis = ekf.cholesky_update(work, H, cols, r, R)
    np.testing.assert_allclose(delta, delta_ref, atol=1e-11)
    np.testing.assert_allclose(work, Sigma_ref, atol=1e-11)
    assert nis == pytest.approx(nis_ref, rel=1e-10)
    # posterior is still SPD and smaller than the prior
    assert np.all(np.linalg.eigvalsh(0.5 * (work + work.T)) > 0)
    assert np.all(np.linalg.eigvalsh(Sigma - work) > -1e-12)


def test_cholesky_update_raises_on_non_positive_definite_innovation():
    rng = np.random.default_rng(0)
    Sigma = _random_spd(rng, 6)
    with pytest.raises(np.linalg.LinAlgError):
        ekf.cholesky_update(Sigma, np.eye(6), np.arange(6), np.zeros(6), -10.0 * np.eye(6))


# ----------------------------------------------------------------------------- mahalanobis, S


def test_mahalanobis_squared_equals_explicit_formula():
    rng = np.random.default_rng(1)
    k = 9
    r = rng.standard_normal((k, 4))
    S = np.stack([_random_spd(rng, 4) for _ in range(k)])
    expected = [ri @ np.linalg.inv(Si) @ ri for ri, Si in zip(r, S)]
    np.testing.assert_allclose(ekf.mahalanobis_squared(r, S), expected, rtol=1e-10)
    assert ekf.mahalanobis_squared(np.zeros((0, 4)), np.zeros((0, 4, 4))).shape == (0,)


def _joint_problem(rng, camera, n=6, observed=(0, 2, 3, 5)):
    """Pose, n landmarks, a joint covariance and the observations of some slots."""
    world_T_imu = _random_pose(rng)
    p = _points_in_view(rng, camera, world_T_imu, n)
    D = 6 + 3 * n
    Sigma = _random_spd(rng, D, 0.05)
    Sigma[:6, :6] += 1e-3 * np.eye(6)
    slots = np.array(observed)
    z_true = camera.predict(world_T_imu, p[slots])
    z = z_true + 1.5 * rng.standard_normal(z_true.shape)
    return world_T_imu, p, Sigma, slots, z


def _explicit_H(J_pose, J_landmark, slots, D):
    """The dense 4k x D observation Jacobian of the joint state."""
    k = len(slots)
    H = np.zeros((4 * k, D))
    for i, s in enumerate(slots):
        H[4 * i:4 * i + 4, :6] = J_pose[i]
        H[4 * i:4 * i + 4, 6 + 3 * s:9 + 3 * s] = J_landmark[i]
    return H


def test_innovation_covariances_equal_explicit_H_Sigma_Ht(camera):
    rng = np.random.default_rng(2)
    world_T_imu, p, Sigma, slots, _ = _joint_problem(rng, camera)
    D = Sigma.shape[0]
    _, J_l, J_p = camera.predict_with_jacobians(world_T_imu, p[slots])
    cols = 6 + 3 * slots[:, None] + np.arange(3)
    S = ekf.innovation_covariances(J_p, J_l, Sigma[:6, :6], np.swapaxes(Sigma[:6][:, cols], 0, 1),
                                   Sigma[cols[:, :, None], cols[:, None, :]], NOISE_VAR)
    assert S.shape == (len(slots), 4, 4)
    H = _explicit_H(J_p, J_l, slots, D)
    full = H @ Sigma @ H.T + NOISE_VAR * np.eye(4 * len(slots))
    for i in range(len(slots)):
        np.testing.assert_allclose(S[i], full[4 * i:4 * i + 4, 4 * i:4 * i + 4], rtol=1e-10, atol=1e-8)
    # None terms count as zero
    S_l = ekf.innovation_covariances(None, J_l, None, None, Sigma[cols[:, :, None], cols[:, None, :]], NOISE_VAR)
    for i, s in enumerate(slots):
        c = cols[i]
        np.testing.assert_allclose(S_l[i], J_l[i] @ Sigma[np.ix_(c, c)] @ J_l[i].T + NOISE_VAR * np.eye(4),
                                   rtol=1e-10)
    S_p = ekf.innovation_covariances(J_p, J_l, Sigma[:6, :6], None, None, NOISE_VAR)
    for i in range(len(slots)):
        np.testing.assert_allclose(S_p[i], J_p[i] @ Sigma[:6, :6] @ J_p[i].T + NOISE_VAR * np.eye(4), rtol=1e-10)


# ----------------------------------------------------------------------------- joint_update


def test_stereo_rows_are_orthonormal():
    np.testing.assert_allclose(ekf.STEREO_ROWS @ ekf.STEREO_ROWS.T, np.eye(3), atol=1e-15)


@pytest.mark.parametrize("seed", range(3))
def test_joint_update_equals_dense_four_row_update(camera, seed):
    _assert_joint_update_equals_dense(camera, seed)


#: A right camera with intrinsics of its own (focal lengths 4% and 3% longer, principal point moved).
K_RIGHT = np.asarray(K_RIG, dtype=float) @ np.array([[1.04, 0.0, 0.02], [0.0, 1.03, -0.03], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("seed", range(3))
def test_joint_update_of_a_rig_with_two_intrinsics_equals_dense_four_row_update(seed):
    """K_l != K_r: rows vL, vR of Ks differ, and the rig's own 3-row reduction must stay exact."""
    camera = StereoCamera(K_RIG, B_RIG, IMU_T_CAM, K_RIGHT)
    assert camera.stereo_rows is not ekf.STEREO_ROWS
    np.testing.assert_allclose(camera.stereo_rows @ camera.stereo_rows.T, np.eye(3), atol=1e-15)
    _assert_joint_update_equals_dense(camera, seed)
    with pytest.raises(AssertionError):  # the one-intrinsics reduction is not exact for this rig
        _assert_joint_update_equals_dense(camera, seed, rows=ekf.STEREO_ROWS)


def _assert_joint_update_equals_dense(camera, seed, rows=None):
    rng = np.random.default_rng(10 + seed)
    world_T_imu, p, Sigma, slots, z = _joint_problem(rng, camera)
    D = Sigma.shape[0]
    # dense reference: explicit 4k x D Jacobian, 4 rows per observation, cholesky_update
    z_pred, J_l, J_p = camera.predict_with_jacobians(world_T_imu, p[slots])
    H = _explicit_H(J_p, J_l, slots, D)
    r = (z - z_pred).ravel()
    R = NOISE_VAR * np.eye(len(r))
    Sigma_ref = Sigma.copy()
    delta_ref, nis_ref = ekf.cholesky_update(Sigma_ref, H, np.arange(D), r, R)
    delta_tb, Sigma_tb, nis_tb = _textbook_update(Sigma, H, r, R)
    np.testing.assert_allclose(delta_ref, delta_tb, atol=1e-9)
    np.testing.assert_allclose(Sigma_ref, Sigma_tb, atol=1e-11)

    work = Sigma.copy()
    if rows is None:
        T_new, p_new, nis = ekf.joint_update(work, world_T_imu, p.copy(), slots, z, camera, NOISE_VAR)
    else:
        delta, nis = ekf.joint_correction(work, slots, z, NOISE_VAR, (z_pred, J_l, J_p), rows)
        T_new, p_new = world_T_imu @ lie.se3_exp(delta[:6]), p + delta[6:].reshape(-1, 3)
    np.testing.assert_allclose(T_new, world_T_imu @ lie.se3_exp(delta_ref[:6]), atol=1e-10)
    np.testing.assert_allclose(p_new, p + delta_ref[6:].reshape(-1, 3), atol=1e-9)
    np.testing.assert_allclose(work, Sigma_ref, atol=1e-11)
    np.testing.assert_array_equal(work, work.T)
    assert nis == pytest.approx(nis_ref, rel=1e-9)
    assert nis == pytest.approx(nis_tb, rel=1e-9)
    # unobserved landmarks move too, through their correlation with the pose
    unobserved = np.setdiff1d(np.arange(len(p)), slots)
    assert np.all(np.linalg.norm(p_new[unobserved] - p[unobserved], axis=1) > 0)


def test_joint_update_nis_counts_the_vertical_disparity_row(camera):
    """The dropped row (vL - vR) carries no state information but belongs to the NIS."""
    rng = np.random.default_rng(21)
    world_T_imu, p, Sigma, slots, z = _joint_problem(rng, camera)
    z_same = z.copy()
    z_same[:, 3] = z_same[:, 1]  # vR = vL
    z_apart = z_same.copy()
    z_apart[:, 1] += 1.0
    z_apart[:, 3] -= 1.0  # same (vL + vR), difference 2 px per observation
    out_same = ekf.joint_update(Sigma.copy(), world_T_imu, p.copy(), slots, z_same, camera, NOISE_VAR)
    out_apart = ekf.joint_update(Sigma.copy(), world_T_imu, p.copy(), slots, z_apart, camera, NOISE_VAR)
    np.testing.assert_allclose(out_apart[0], out_same[0], atol=1e-12)
    np.testing.assert_allclose(out_apart[1], out_same[1], atol=1e-10)
    assert out_apart[2] - out_same[2] == pytest.approx(len(slots) * 2.0**2 / (2 * NOISE_VAR), rel=1e-9)


# ----------------------------------------------------------------------------- landmark_update


def test_landmark_update_equals_per_landmark_textbook(camera):
    rng = np.random.default_rng(3)
    world_T_imu = _random_pose(rng)
    k = 7
    p_true = _points_in_view(rng, camera, world_T_imu, k)
    covs = np.stack([_random_spd(rng, 3, 0.5) for _ in range(k)])
    p = p_true + rng.standard_normal((k, 3)) * 0.5
    z = camera.predict(world_T_imu, p_true) + rng.standard_normal((k, 4))
    p_new, covs_new = ekf.landmark_update(p, covs, z, world_T_imu, camera, NOISE_VAR)
    for i in range(k):
        z_pred, J_l, _ = camera.predict_with_jacobians(world_T_imu, p[i:i + 1])
        delta, P, _ = _textbook_update(covs[i], J_l[0], z[i] - z_pred[0], NOISE_VAR * np.eye(4))
        np.testing.assert_allclose(p_new[i], p[i] + delta, atol=1e-10)
        np.testing.assert_allclose(covs_new[i], P, atol=1e-12)
    np.testing.assert_array_equal(covs_new, np.swapaxes(covs_new, 1, 2))


# ----------------------------------------------------------------------------- pose_update


def test_pose_update_equals_textbook(camera):
    rng = np.random.default_rng(4)
    world_T_imu = _random_pose(rng)
    k = 8
    p = _points_in_view(rng, camera, world_T_imu, k)
    z = camera.predict(world_T_imu, p) + rng.standard_normal((k, 4))
    Sigma_pose = _random_spd(rng, 6, 1e-3)
    Sigma_lm = np.stack([_random_spd(rng, 3, 0.1) for _ in range(k)])
    z_pred, J_l, J_p = camera.predict_with_jacobians(world_T_imu, p)
    H = J_p.reshape(4 * k, 6)
    for lm_cov in (None, Sigma_lm):
        R = NOISE_VAR * np.eye(4 * k)
        if lm_cov is not None:
            R = R + block_diag(*[J_l[i] @ lm_cov[i] @ J_l[i].T for i in range(k)])
        delta, P, nis_tb = _textbook_update(Sigma_pose, H, (z - z_pred).ravel(), R)
        T_new, P_new, nis = ekf.pose_update(world_T_imu, Sigma_pose, p, z, camera, NOISE_VAR, Sigma_landmark=lm_cov)
        np.testing.assert_allclose(T_new, world_T_imu @ lie.se3_exp(delta), atol=1e-10)
        np.testing.assert_allclose(P_new, P, atol=1e-13)
        assert nis == pytest.approx(nis_tb, rel=1e-9)


def test_pose_update_moves_pose_toward_truth(camera):
    rng = np.random.default_rng(5)
    truth = _random_pose(rng)
    p = _points_in_view(rng, camera, truth, 30, depth=(4.0, 25.0))
    z = camera.predict(truth, p) + 0.5 * rng.standard_normal((30, 4))
    sig = np.array([0.2, 0.2, 0.2, 0.02, 0.02, 0.02])
    for trial in range(5):
        err0 = sig * rng.standard_normal(6)
        mu = truth @ lie.se3_exp(-err0)  # truth = mu exp(err0)
        T_new, P_new, _ = ekf.pose_update(mu, np.diag(sig**2), p, z, camera, 0.25)
        err1 = lie.se3_log(lie.se3_inv(T_new) @ truth)
        assert np.linalg.norm(err1 / sig) < 0.3 * np.linalg.norm(err0 / sig)
        assert np.all(np.diag(P_new) < sig**2)


# ----------------------------------------------------------------------------- initialisation


def _stereo_pixels(rng, camera, n):
    """Noise-free-looking stereo pixels of points 3-60 m ahead."""
    p_cam = np.column_stack([rng.uniform(-8, 8, n), rng.uniform(-2, 2, n), rng.uniform(3, 60, n)])
    q = np.column_stack([p_cam, np.ones(n)])
    return (q / q[:, 2:3]) @ camera.Ks.T


def test_triangulation_jacobian_matches_finite_differences(camera):
    rng = np.random.default_rng(6)
    z = _stereo_pixels(rng, camera, 6)
    J = triangulation_jacobian(z, camera.K, camera.b)
    assert J.shape == (6, 3, 4)
    for i in range(6):
        J_fd = _fd(lambda x: triangulate_disparity(x, camera.K, camera.b), z[i], eps=1e-4)
        np.testing.assert_allclose(J[i], J_fd, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(J[:, :, 3], 0.0)  # vR is not used


def test_initialize_landmarks_pose_jacobian_and_covariance(camera):
    rng = np.random.default_rng(7)
    world_T_imu = _random_pose(rng)
    z = _stereo_pixels(rng, camera, 5)
    p_world, G_pose, C_tri = ekf.initialize_landmarks(world_T_imu, z, camera, NOISE_VAR)
    assert p_world.shape == (5, 3) and G_pose.shape == (5, 3, 6) and C_tri.shape == (5, 3, 3)
    np.testing.assert_allclose(p_world, camera.triangulate(z, world_T_imu), atol=1e-9)

    p_cam = triangulate_disparity(z, camera.K, camera.b)

    def world_point(delta, i):
        T = world_T_imu @ lie.se3_exp(delta) @ camera.imu_T_cam
        return T[:3, :3] @ p_cam[i] + T[:3, 3]

    R_wc = (world_T_imu @ camera.imu_T_cam)[:3, :3]
    for i in range(5):
        G_fd = _fd(lambda d: world_point(d, i), np.zeros(6))
        np.testing.assert_allclose(G_pose[i], G_fd, rtol=1e-6, atol=1e-6)
        # G_z: derivative of the world point w.r.t. the pixels
        G_z_fd = _fd(lambda x: triangulate_disparity(x, camera.K, camera.b) @ R_wc.T, z[i], eps=1e-4)
        G_z = R_wc @ triangulation_jacobian(z[i], camera.K, camera.b)
        np.testing.assert_allclose(G_z, G_z_fd, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(C_tri[i], NOISE_VAR * G_z @ G_z.T, rtol=1e-10, atol=1e-12)


def test_triangulation_covariance_matches_monte_carlo(camera):
    """C_tri is the spread of triangulated points under small pixel noise (near points)."""
    rng = np.random.default_rng(8)
    world_T_imu = _random_pose(rng)
    z = _stereo_pixels(rng, camera, 1)
    z[0, 0] = z[0, 2] + 60.0  # large disparity: a near point, nearly linear
    sigma = 0.3
    _, _, C = ekf.initialize_landmarks(world_T_imu, z, camera, sigma**2)
    samples = camera.triangulate(z + sigma * rng.standard_normal((4000, 4)), world_T_imu)
    np.testing.assert_allclose(np.cov(samples.T), C[0], rtol=0.15, atol=1e-3 * np.abs(C[0]).max())


# ----------------------------------------------------------------------------- FilterConfig


@pytest.mark.parametrize("field, value", [
    ("sigma_pixel", -1.0), ("sigma_pixel", 0.0), ("sigma_pixel", np.nan),
    ("sigma_linear_velocity", -0.1), ("sigma_angular_velocity", -0.01), ("sigma_angular_velocity", np.inf),
    ("landmark_prior_sigma", 0.0), ("landmark_prior_inflation", -1.0), ("initial_pose_sigma", -1e-3),
    ("min_init_disparity", -2.0),
    ("gate_probability", 0.0), ("gate_probability", 1.5), ("gate_probability", -0.5),
    ("landmark_stride", 0), ("landmark_stride", 1.5), ("landmark_stride", -3),
    ("imu_lag", 0.5),
])
def test_filter_config_rejects_bad_values_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        FilterConfig(**{field: value})


def test_filter_config_accepts_edge_values():
    cfg = FilterConfig(sigma_linear_velocity=0.0, sigma_angular_velocity=0.0, gate_probability=1.0,
                       imu_lag=-1, landmark_stride=20, min_init_disparity=0.0)
    assert cfg.gate_threshold == np.inf
    assert cfg.to_dict()["landmark_stride"] == 20


@pytest.mark.parametrize("p", [0.5, 0.95, 0.999])
def test_gate_threshold_is_chi2_quantile(p):
    cfg = FilterConfig(gate_probability=p, sigma_pixel=2.0)
    assert cfg.gate_threshold == pytest.approx(stats.chi2.ppf(p, 4), rel=1e-12)
    assert cfg.pixel_variance == 4.0
