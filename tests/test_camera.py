"""Tests for visla_edu.camera: stereo matrix, projection, Jacobians, triangulation.

Model under test (visla_edu.camera): ``z = Ks pi(cam_T_imu inv(world_T_imu) m)`` with
``Ks = [[fsu,0,cu,0],[0,fsv,cv,0],[fsu,0,cu,-fsu*b],[0,fsv,cv,0]]``, ``pi(q) = q / q3``
and the right perturbation ``world_T_imu = mu exp(delta^)``.

The calibration is KITTI-like and written here (no course data): the camera optical
axis (z) is the IMU x axis, camera x (right) is IMU -y, camera y (down) is IMU -z.
"""

import numpy as np
import pytest

from visla_edu import camera, lie
from visla_edu.camera import StereoCamera
from fdiff import fd_jacobian  # tests/fdiff.py

FSU, FSV, CU, CV, B = 550.0, 550.0, 680.0, 240.0, 0.6
K = np.array([[FSU, 0.0, CU], [0.0, FSV, CV], [0.0, 0.0, 1.0]])
IMU_R_CAM = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
IMU_T_CAM = np.eye(4)
IMU_T_CAM[:3, :3] = IMU_R_CAM
IMU_T_CAM[:3, 3] = [1.08, -0.32, 0.73]

FD_REL = 1e-6  # required relative accuracy of the analytic Jacobians vs finite differences
TRI_REL = 1e-9  # triangulation on noise-free pixels


@pytest.fixture
def cam():
    return StereoCamera(K, B, IMU_T_CAM)




def rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b)


def points_in_view(rng, n, depth_range):
    """Points in the left camera frame inside a 1360x480 image, depths in ``depth_range``."""
    depth = rng.uniform(*depth_range, size=n)
    u = rng.uniform(20, 1340, size=n)
    v = rng.uniform(20, 460, size=n)
    return np.column_stack([(u - CU) * depth / FSU, (v - CV) * depth / FSV, depth])


def random_pose(rng):
    return lie.se3_exp(np.r_[rng.normal(size=3) * 20, rng.normal(size=3)])


def to_world(world_T_imu, p_cam):
    world_T_cam = world_T_imu @ IMU_T_CAM
    return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


def pixels(p_cam):
    """Noise-free stereo pixels of left-camera points, written out by hand."""
    x, y, d = p_cam.T
    return np.column_stack([FSU * x / d + CU, FSV * y / d + CV, FSU * (x - B) / d + CU, FSV * y / d + CV])


DEPTHS = {"near": (0.5, 0.5), "mid": (2.0, 60.0), "far": (100.0, 500.0)}


# ----------------------------------------------------------------------------- stereo matrix


def test_stereo_matrix_layout():
    Kx = np.array([[550.0, 0.0, 680.0], [0.0, 540.0, 240.0], [0.0, 0.0, 1.0]])  # fsu != fsv
    Ks = camera.stereo_matrix(Kx, 0.6)
    expected = [
        [550.0, 0.0, 680.0, 0.0],
        [0.0, 540.0, 240.0, 0.0],
        [550.0, 0.0, 680.0, -550.0 * 0.6],
        [0.0, 540.0, 240.0, 0.0],
    ]
    np.testing.assert_array_equal(Ks, expected)


@pytest.mark.parametrize("bad_K", [np.eye(4), np.zeros((3, 4)), np.zeros(9), np.zeros((1, 3, 3))])
def test_stereo_matrix_rejects_bad_K(bad_K):
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\)"):
        camera.stereo_matrix(bad_K, 0.6)


@pytest.mark.parametrize("bad_b", [0.0, -0.6, np.nan, np.inf])
def test_stereo_matrix_rejects_bad_baseline(bad_b):
    with pytest.raises(ValueError, match="baseline"):
        camera.stereo_matrix(K, bad_b)


def test_camera_rejects_bad_inputs():
    with pytest.raises(ValueError, match="imu_T_cam"):
        StereoCamera(K, B, np.eye(4)[:3])
    with pytest.raises(ValueError, match="baseline"):
        StereoCamera(K, 0.0, IMU_T_CAM)
    with pytest.raises(ValueError, match="K must have shape"):
        StereoCamera(np.eye(2), B, IMU_T_CAM)


def test_camera_attributes(cam):
    np.testing.assert_array_equal(cam.Ks, camera.stereo_matrix(K, B))
    assert np.abs(cam.cam_T_imu - np.linalg.inv(IMU_T_CAM)).max() < 1e-15
    assert "550" in repr(cam) and "0.6" in repr(cam)


# ----------------------------------------------------------------------------- projection


def test_projection_values_and_shapes():
    q = np.array([2.0, -4.0, 8.0, 1.0])
    np.testing.assert_array_equal(camera.projection(q), [0.25, -0.5, 1.0, 0.125])
    rng = np.random.default_rng(0)
    Q = rng.normal(size=(2, 5, 4)) + [0, 0, 10, 0]
    P = camera.projection(Q)
    assert P.shape == (2, 5, 4)
    np.testing.assert_allclose(P[..., 2], 1.0, rtol=0, atol=0)
    assert camera.projection_jacobian(Q).shape == (2, 5, 4, 4)
    for f in (camera.projection, camera.projection_jacobian):
        with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
            f(np.zeros(3))


@pytest.mark.parametrize("regime", sorted(DEPTHS))
@pytest.mark.parametrize("q4", [1.0, 0.0, 0.37])
def test_projection_jacobian_vs_finite_differences(regime, q4):
    rng = np.random.default_rng(1)
    for p in points_in_view(rng, 20, DEPTHS[regime]):
        q = np.r_[p, q4]
        J = camera.projection_jacobian(q)
        J_fd = fd_jacobian(camera.projection, q, 1e-4 * q[2])
        assert rel(J, J_fd) < FD_REL
        np.testing.assert_array_equal(J[2], np.zeros(4))  # pi_3 == 1 is constant


# ----------------------------------------------------------------------------- predict


def test_predict_matches_hand_computation(cam):
    rng = np.random.default_rng(2)
    for _ in range(5):
        T = random_pose(rng)
        m = to_world(T, points_in_view(rng, 10, (1.0, 200.0))) + rng.normal(size=(10, 3))
        z = cam.predict(T, m)
        assert z.shape == (10, 4)
        for j in range(10):
            q = np.linalg.inv(IMU_T_CAM) @ np.linalg.inv(T) @ np.r_[m[j], 1.0]
            z_hand = cam.Ks @ (q / q[2])
            assert rel(z[j], z_hand) < 1e-12
        q = cam.points_in_camera(T, m)
        np.testing.assert_allclose(q[:, 3], 1.0, rtol=0, atol=1e-15)


def test_predict_geometry(cam):
    """A point on the optical axis hits the principal point; the right image is shifted
    left by the disparity fsu b / depth; rows match; camera forward is IMU +x."""
    T = np.eye(4)
    for depth in [0.5, 10.0, 500.0]:
        m = to_world(T, np.array([[0.0, 0.0, depth]]))
        z = cam.predict(T, m)[0]
        np.testing.assert_allclose(z, [CU, CV, CU - FSU * B / depth, CV], rtol=1e-13)
    # a point straight ahead of the IMU (on its x axis) far away is near the image centre
    z = cam.predict(T, np.array([[1e6, 0.0, 0.0]]))[0]
    assert abs(z[0] - CU) < 1.0 and abs(z[1] - CV) < 1.0
    # a point to the IMU's left (+y) appears left of the centre (smaller u)
    assert cam.predict(T, np.array([[20.0, 5.0, 0.73]]))[0, 0] < CU
    rng = np.random.default_rng(3)
    p = points_in_view(rng, 50, (0.5, 500.0))
    z = cam.predict(T, to_world(T, p))
    np.testing.assert_allclose(z, pixels(p), rtol=1e-12)
    assert np.all(z[:, 0] > z[:, 2])


@pytest.mark.parametrize("regime", sorted(DEPTHS))
def test_predict_with_jacobians_vs_finite_differences(cam, regime):
    rng = np.random.default_rng(4)
    for _ in range(4):
        mu = random_pose(rng)
        m = to_world(mu, points_in_view(rng, 6, DEPTHS[regime]))
        z, J_m, J_pose = cam.predict_with_jacobians(mu, m)
        assert z.shape == (6, 4) and J_m.shape == (6, 4, 3) and J_pose.shape == (6, 4, 6)
        assert np.abs(z - cam.predict(mu, m)).max() < 1e-9  # pixels
        np.testing.assert_array_equal(J_m, cam.jacobian_landmark(mu, m))
        np.testing.assert_array_equal(J_pose, cam.jacobian_pose(mu, m))
        for j in range(len(m)):
            depth = cam.points_in_camera(mu, m[j : j + 1])[0, 2]
            J_m_fd = fd_jacobian(lambda x: cam.predict(mu, x[None])[0], m[j], 1e-4 * depth)
            assert rel(J_m[j], J_m_fd) < FD_REL
            J_pose_fd = fd_jacobian(
                lambda d: cam.predict(mu @ lie.se3_exp(d), m[j : j + 1])[0], np.zeros(6), 1e-4
            )
            assert rel(J_pose[j], J_pose_fd) < FD_REL
            # the left perturbation exp(d) @ mu gives a different Jacobian: the test can tell
            J_left_fd = fd_jacobian(
                lambda d: cam.predict(lie.se3_exp(d) @ mu, m[j : j + 1])[0], np.zeros(6), 1e-4
            )
            assert rel(J_pose[j], J_left_fd) > 1e-3


def test_pose_jacobian_matches_design_formula(cam):
    """J_z_pose = -Ks dpi/dq(q) cam_T_imu odot(inv(mu) m), J_z_landmark = Ks dpi/dq cam_T_imu inv(mu) P^T."""
    rng = np.random.default_rng(5)
    mu = random_pose(rng)
    m = to_world(mu, points_in_view(rng, 8, (0.5, 300.0)))
    _, J_m, J_pose = cam.predict_with_jacobians(mu, m)
    P_T = np.eye(4)[:, :3]
    for j in range(len(m)):
        s = lie.se3_inv(mu) @ np.r_[m[j], 1.0]
        q = cam.cam_T_imu @ s
        dpi = camera.projection_jacobian(q)
        assert rel(J_pose[j], -cam.Ks @ dpi @ cam.cam_T_imu @ lie.odot(s)) < 1e-12
        assert rel(J_m[j], cam.Ks @ dpi @ cam.cam_T_imu @ lie.se3_inv(mu) @ P_T) < 1e-12


def test_project_points_jacobians_vs_finite_differences(cam):
    """J_z_point = Ks dpi/dq A P^T and J_z_transform (right perturbation A exp(delta^)) for batched transforms."""
    rng = np.random.default_rng(11)
    A = np.stack([[lie.se3_exp(rng.normal(size=6) * 0.1) for _ in range(3)] for _ in range(2)])  # (2, 3, 4, 4)
    p = np.stack([[points_in_view(rng, 5, (2.0, 60.0)) for _ in range(3)] for _ in range(2)])  # (2, 3, 5, 3)
    z, q, J_point, J_transform = camera.project_points(cam.Ks, A, p)
    assert z.shape == (2, 3, 5, 4) and q.shape == (2, 3, 5, 4)
    assert J_point.shape == (2, 3, 5, 4, 3) and J_transform.shape == (2, 3, 5, 4, 6)
    z_only, q_only = camera.project_points(cam.Ks, A, p, jacobians=False)
    np.testing.assert_array_equal(z_only, z)
    np.testing.assert_array_equal(q_only, q)
    for i, k, n in [(0, 0, 0), (1, 2, 4), (0, 1, 3)]:
        np.testing.assert_allclose(z[i, k, n], camera.projection(A[i, k] @ np.r_[p[i, k, n], 1.0]) @ cam.Ks.T,
                                   rtol=1e-12)
        fd_p = fd_jacobian(lambda x: camera.project_points(cam.Ks, A[i, k], x[None], False)[0][0], p[i, k, n], 1e-4)
        assert rel(J_point[i, k, n], fd_p) < FD_REL
        fd_A = fd_jacobian(lambda d: camera.project_points(cam.Ks, A[i, k] @ lie.se3_exp(d), p[i, k, n][None],
                                                           False)[0][0], np.zeros(6), 1e-5)
        assert rel(J_transform[i, k, n], fd_A) < FD_REL


def test_stereo_projection_one_pose_or_one_per_landmark(cam):
    """A pose per landmark gives, landmark by landmark, what the single-pose call gives (the smoother's use)."""
    rng = np.random.default_rng(12)
    poses = np.stack([random_pose(rng) for _ in range(4)])
    m = np.concatenate([to_world(T, points_in_view(rng, 1, (1.0, 80.0))) for T in poses])
    z, depth, J_m, J_pose = camera.stereo_projection(cam.Ks, cam.cam_T_imu, poses, m)
    for j, T in enumerate(poses):
        z_j, J_m_j, J_pose_j = cam.predict_with_jacobians(T, m[j:j + 1])
        np.testing.assert_allclose(z[j], z_j[0], rtol=1e-12)
        np.testing.assert_allclose(J_m[j], J_m_j[0], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(J_pose[j], J_pose_j[0], rtol=1e-10, atol=1e-9)
        assert abs(depth[j] - cam.points_in_camera(T, m[j:j + 1])[0, 2]) < 1e-9
    z_only, depth_only = camera.stereo_projection(cam.Ks, cam.cam_T_imu, poses, m, jacobians=False)
    np.testing.assert_array_equal(z_only, z)
    np.testing.assert_array_equal(depth_only, depth)


# ----------------------------------------------------------------------------- triangulation


@pytest.mark.parametrize("regime", sorted(DEPTHS))
def test_triangulation_recovers_true_points(regime):
    rng = np.random.default_rng(6)
    p = points_in_view(rng, 200, DEPTHS[regime])
    z = pixels(p)
    p_disp = camera.triangulate_disparity(z, K, B)
    p_bear = camera.triangulate_bearing(z, K, B)
    for est in (p_disp, p_bear):
        err = np.linalg.norm(est - p, axis=1) / np.linalg.norm(p, axis=1)
        assert err.max() < TRI_REL
    err = np.linalg.norm(p_disp - p_bear, axis=1) / np.linalg.norm(p, axis=1)
    assert err.max() < TRI_REL


def test_triangulation_batch_shapes():
    rng = np.random.default_rng(7)
    p = points_in_view(rng, 6, (1.0, 50.0))
    z = pixels(p).reshape(2, 3, 4)
    for f in (camera.triangulate_disparity, camera.triangulate_bearing):
        out = f(z, K, B)
        assert out.shape == (2, 3, 3)
        assert rel(out.reshape(6, 3), p) < TRI_REL
        assert f(z[0, 0], K, B).shape == (3,)
        with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
            f(np.zeros((5, 3)), K, B)


@pytest.mark.filterwarnings("error")  # no RuntimeWarning either
@pytest.mark.parametrize("method", ["disparity", "bearing"])
def test_non_positive_disparity_gives_nan_rows(cam, method):
    f = {"disparity": camera.triangulate_disparity, "bearing": camera.triangulate_bearing}[method]
    z = np.array(
        [
            [700.0, 250.0, 690.0, 250.0],  # disparity 10 px: fine
            [700.0, 250.0, 700.0, 250.0],  # zero disparity (point at infinity)
            [700.0, 250.0, 710.0, 250.0],  # negative disparity
            [700.0, 250.0, 700.0 + 1e-12, 250.0],  # tiny negative
            [700.0, 250.0, 700.0, 251.0],  # zero disparity, rows differ
            [700.0, 250.0, 650.0, 250.0],  # disparity 50 px: fine
        ]
    )
    out = f(z, K, B)
    ok = np.array([True, False, False, False, False, True])
    assert np.all(np.isfinite(out[ok]))
    assert np.all(np.isnan(out[~ok]))
    np.testing.assert_allclose(out[0, 2], FSU * B / 10.0, rtol=1e-12)
    assert np.all(out[ok, 2] > 0)
    # single rows and the camera method behave the same, with or without a pose
    assert np.all(np.isnan(f(z[1], K, B)))
    T = lie.se3_exp([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    out_world = cam.triangulate(z, T, method=method)
    assert np.all(np.isnan(out_world[~ok])) and np.all(np.isfinite(out_world[ok]))


@pytest.mark.parametrize("method", ["disparity", "bearing"])
def test_triangulate_rejects_bad_calibration(method):
    f = {"disparity": camera.triangulate_disparity, "bearing": camera.triangulate_bearing}[method]
    z = pixels(np.array([[1.0, 0.5, 10.0]]))
    with pytest.raises(ValueError, match="baseline"):
        f(z, K, -B)
    with pytest.raises(ValueError, match="baseline"):
        f(z, K, 0.0)
    with pytest.raises(ValueError, match="K must have shape"):
        f(z, np.eye(4), B)


@pytest.mark.parametrize("method", ["disparity", "bearing"])
@pytest.mark.parametrize("regime", sorted(DEPTHS))
def test_triangulate_world_points_and_reprojection(cam, method, regime):
    rng = np.random.default_rng(8)
    for _ in range(5):
        T = random_pose(rng)
        m = to_world(T, points_in_view(rng, 30, DEPTHS[regime]))
        z = cam.predict(T, m)
        m_est = cam.triangulate(z, T, method=method)
        p_cam = cam.triangulate(z, method=method)
        # distance from the camera sets the scale of the achievable error
        err = np.linalg.norm(m_est - m, axis=1) / np.linalg.norm(p_cam, axis=1)
        assert err.max() < TRI_REL
        assert np.abs(cam.predict(T, m_est) - z).max() < 1e-9  # pixels


def test_triangulate_rejects_unknown_method(cam):
    with pytest.raises(ValueError, match="method"):
        cam.triangulate(np.zeros((1, 4)), method="midpoint")


def test_triangulation_far_limit_is_well_conditioned():
    """At 500 m the disparity is 0.66 px; the depth still comes back to 1e-9."""
    p = np.array([[3.0, -1.0, 500.0], [0.0, 0.0, 2000.0]])
    z = pixels(p)
    assert 0 < z[1, 0] - z[1, 2] < 0.2
    for f in (camera.triangulate_disparity, camera.triangulate_bearing):
        assert rel(f(z, K, B), p) < TRI_REL


# ----------------------------------------------------------------------------- a rig with two intrinsics
#
# The right camera is the left one translated by B along its x axis, with intrinsics of its own:
# uR = fsu' (x - B) / z + cu', vR = fsv' y / z + cv' (rows 3 and 4 of Ks).

K_R = np.array([[FSU * 1.04, 0.0, CU + 15.0], [0.0, FSV * 1.03, CV - 8.0], [0.0, 0.0, 1.0]])


@pytest.fixture
def cam_two():
    return StereoCamera(K, B, IMU_T_CAM, K_R)


def pixels_two(p_cam):
    """Noise-free pixels of left-camera points for the two-intrinsics rig, written out by hand."""
    x, y, d = p_cam.T
    return np.column_stack([FSU * x / d + CU, FSV * y / d + CV, K_R[0, 0] * (x - B) / d + K_R[0, 2],
                            K_R[1, 1] * y / d + K_R[1, 2]])


def test_stereo_matrix_of_two_intrinsics_puts_the_right_camera_in_rows_3_and_4(cam_two):
    Ks = camera.stereo_matrix(K, B, K_R)
    np.testing.assert_array_equal(Ks[:2], camera.stereo_matrix(K, B)[:2])
    np.testing.assert_array_equal(Ks[2], [K_R[0, 0], 0.0, K_R[0, 2], -K_R[0, 0] * B])
    np.testing.assert_array_equal(Ks[3], [0.0, K_R[1, 1], K_R[1, 2], 0.0])
    assert not cam_two.same_intrinsics and not camera.single_intrinsics(Ks)
    # K_right = K (or None) is the one-intrinsics rig, bit for bit
    one = StereoCamera(K, B, IMU_T_CAM, K.copy())
    assert one.same_intrinsics and one.stereo_rows is camera.STEREO_ROWS
    np.testing.assert_array_equal(one.Ks, camera.stereo_matrix(K, B))
    with pytest.raises(ValueError, match="K_right"):
        camera.stereo_matrix(K, B, [[500.0, 1.0, 300.0], [0.0, 500.0, 200.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("regime", sorted(DEPTHS))
def test_two_intrinsics_predict_and_jacobians_vs_finite_differences(cam_two, regime):
    rng = np.random.default_rng(21)
    for _ in range(3):
        mu = random_pose(rng)
        p = points_in_view(rng, 5, DEPTHS[regime])
        m = to_world(mu, p)
        z, J_m, J_pose = cam_two.predict_with_jacobians(mu, m)
        np.testing.assert_allclose(z, pixels_two(p), rtol=1e-10)
        np.testing.assert_allclose(z, cam_two.predict(mu, m), rtol=1e-12)
        for j in range(len(m)):
            J_m_fd = fd_jacobian(lambda x: cam_two.predict(mu, x[None])[0], m[j], 1e-4 * p[j, 2])
            assert rel(J_m[j], J_m_fd) < FD_REL
            J_pose_fd = fd_jacobian(lambda d: cam_two.predict(mu @ lie.se3_exp(d), m[j:j + 1])[0], np.zeros(6), 1e-4)
            assert rel(J_pose[j], J_pose_fd) < FD_REL


@pytest.mark.parametrize("regime", sorted(DEPTHS))
def test_two_intrinsics_triangulation_recovers_true_points(regime):
    rng = np.random.default_rng(22)
    p = points_in_view(rng, 200, DEPTHS[regime])
    z = pixels_two(p)
    for est in (camera.triangulate_disparity(z, K, B, K_R), camera.triangulate_bearing(z, K, B, K_R)):
        assert (np.linalg.norm(est - p, axis=1) / np.linalg.norm(p, axis=1)).max() < TRI_REL
    # ...while the one-intrinsics formulas are wrong for these pixels
    naive = np.linalg.norm(camera.triangulate_disparity(z, K, B) - p, axis=1) / np.linalg.norm(p, axis=1)
    assert np.mean(~(naive < 1e-3)) > 0.9  # off by far more than rounding, or NaN (no depth)
    np.testing.assert_allclose(camera.disparity(z, K, K_R), FSU * B / p[:, 2], rtol=1e-9)
    np.testing.assert_array_equal(camera.disparity(z, K), z[:, 0] - z[:, 2])  # one intrinsics: uL - uR


def test_two_intrinsics_triangulation_jacobian_vs_finite_differences(cam_two):
    rng = np.random.default_rng(23)
    z = pixels_two(points_in_view(rng, 8, (2.0, 80.0)))
    J = cam_two.triangulation_jacobian(z)
    np.testing.assert_array_equal(J, camera.triangulation_jacobian(z, K, B, K_R))
    for i in range(len(z)):
        fd = fd_jacobian(lambda zi: camera.triangulate_disparity(zi[None], K, B, K_R)[0], z[i], 1e-4)
        assert rel(J[i], fd) < FD_REL


def test_right_pixels_map_into_the_left_intrinsics_and_back():
    rng = np.random.default_rng(24)
    p = points_in_view(rng, 20, (2.0, 80.0))
    mapped = camera.right_in_left_pixels(pixels_two(p), K, K_R)
    np.testing.assert_allclose(mapped, pixels(p), rtol=1e-12)  # as if the right camera had K
    np.testing.assert_allclose(camera.left_in_right_u(mapped[:, 2], K, K_R), pixels_two(p)[:, 2], rtol=1e-12)
    z = pixels(p)
    assert camera.right_in_left_pixels(z, K, None) is z and camera.right_in_left_pixels(z, K, K.copy()) is z


@pytest.mark.parametrize("f_right", [FSV, FSV * 1.03])
def test_stereo_rows_are_an_exact_orthonormal_reduction(f_right):
    """The dropped combination of vL and vR has a zero Jacobian: no information about the state is lost."""
    K_right = K.copy()
    K_right[1, 1] = f_right
    cam = StereoCamera(K, B, IMU_T_CAM, K_right)
    rows = cam.stereo_rows
    np.testing.assert_allclose(rows @ rows.T, np.eye(3), atol=1e-15)
    dropped = np.eye(4) - rows.T @ rows  # projector on the dropped row
    rng = np.random.default_rng(25)
    mu = random_pose(rng)
    _, J_m, J_pose = cam.predict_with_jacobians(mu, to_world(mu, points_in_view(rng, 6, (2.0, 60.0))))
    assert np.abs(dropped @ J_m).max() < 1e-12 * np.abs(J_m).max()
    assert np.abs(dropped @ J_pose).max() < 1e-12 * np.abs(J_pose).max()


# ----------------------------------------------------------------------------- the rig from two extrinsics


def _translation(x, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def test_rig_from_extrinsics_derives_the_baseline():
    imu_T_right = IMU_T_CAM @ _translation(B)
    cam = StereoCamera.from_extrinsics(K, K_R, IMU_T_CAM, imu_T_right)
    assert cam.b == pytest.approx(B, rel=1e-12)
    np.testing.assert_array_equal(cam.imu_T_cam, IMU_T_CAM)
    np.testing.assert_array_equal(cam.Ks, camera.stereo_matrix(K, cam.b, K_R))


@pytest.mark.parametrize("right_in_left, message", [
    (lie.se3_exp([B, 0, 0, 0, 0.05, 0]), r"rotated 2\.86 deg from the left one"),
    (_translation(B, 0.1, 0.0), r"0\.1 m off its x axis"),
    (_translation(-B), r"on the left camera's left \(-x\)"),
    (np.eye(4), "no baseline"),
])
def test_a_pair_that_is_not_rectified_is_refused_with_the_reason(right_in_left, message):
    with pytest.raises(ValueError, match="not a rectified stereo pair: .*" + message):
        StereoCamera.from_extrinsics(K, K, IMU_T_CAM, IMU_T_CAM @ right_in_left)
    # within the tolerances (rounding, the raw poses of a rectified rig) it is accepted
    slightly = lie.se3_exp([B, 0.002 * B, 0.0, 0.0, 0.5 * camera.MAX_RIG_ROTATION, 0.0])
    assert camera.rectified_baseline(IMU_T_CAM, IMU_T_CAM @ slightly) == pytest.approx(B, rel=1e-3)


@pytest.mark.parametrize("direction", camera.DIRECTIONS)
@pytest.mark.parametrize("frame", camera.FRAMES)
def test_each_reading_of_written_extrinsics_gives_back_the_rig(direction, frame):
    """write_extrinsic and extrinsic_readings are inverse; only the reading written is rectified here."""
    imu_T_right = IMU_T_CAM @ _translation(B)
    ext_left = camera.write_extrinsic(IMU_T_CAM, direction, frame)
    ext_right = camera.write_extrinsic(imu_T_right, direction, frame)
    readings = {r.name: r for r in camera.extrinsic_readings(ext_left, ext_right)}
    assert list(readings) == [camera.reading_name(d, f) for d in camera.DIRECTIONS for f in camera.FRAMES]
    right = readings[camera.reading_name(direction, frame)]
    np.testing.assert_allclose(right.imu_T_left, IMU_T_CAM, atol=1e-15)
    np.testing.assert_allclose(right.offset, [B, 0.0, 0.0], atol=1e-15)
    assert right.rectified and [r.name for r in readings.values() if r.rectified] == [right.name]
    if frame == "regular":  # the regular frame: x forward, y left, z up
        np.testing.assert_allclose(lie.se3_inv(ext_left if direction == "IMU->camera" else lie.se3_inv(ext_left))
                                   [:3, :3] @ IMU_T_CAM[:3, :3] @ [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], atol=1e-15)
    with pytest.raises(ValueError, match="direction in"):
        camera.write_extrinsic(IMU_T_CAM, "left->right", frame)
