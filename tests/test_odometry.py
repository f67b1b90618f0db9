"""Tests of visla_edu.diagnostics.odometry: the robust stereo visual odometry (RANSAC + Gauss-Newton on SE(3)).

Synthetic pairs and simulated drives carry their own truth; the course drive 0020 is checked
against its KITTI ground truth when VISLA_EDU_DATA is set (skipped otherwise). Accuracy
figures over whole drives are printed by benchmarks/bench_odometry.py.
"""

import dataclasses

import numpy as np
import pytest

from visla_edu import camera, lie, simulate
from visla_edu.diagnostics import odometry
from visla_edu.dataset import Dataset
from fdiff import fd_jacobian  # tests/fdiff.py

K_RIG, B_RIG, RIG = simulate.default_rig()
KS_RIG = camera.stereo_matrix(K_RIG, B_RIG)
WIDTH, HEIGHT = 1400, 500  # the default rig's image size
#: A car-like frame step: 1.2 m forward, a little sideways and up, a 40 mrad turn.
MOTION = lie.se3_exp(np.array([0.15, -0.03, 1.2, 0.01, 0.04, -0.005]))


def _pair_dataset(z_prev, z_next, ids_prev=None, ids_next=None):
    """A two-frame dataset on the default rig: the same landmarks (ids 0..n-1) in both frames."""
    z_prev, z_next = np.asarray(z_prev, float), np.asarray(z_next, float)
    ids_prev = np.arange(len(z_prev)) if ids_prev is None else np.asarray(ids_prev)
    ids_next = np.arange(len(z_next)) if ids_next is None else np.asarray(ids_next)
    return _dataset([ids_prev, ids_next], [z_prev, z_next])


def _dataset(ids, pixels):
    """A dataset on the default rig from per-frame landmark ids and pixels."""
    T = len(ids)
    zeros = np.zeros((T, 3))
    return Dataset(name="synthetic", source="tests/test_odometry.py", time_stamps=0.1 * np.arange(T),
                   linear_velocity=zeros, angular_velocity=zeros, K=K_RIG, b=B_RIG, imu_T_cam=RIG,
                   num_landmarks=int(max(np.max(i, initial=-1) for i in ids)) + 1,
                   frame_ptr=np.concatenate([[0], np.cumsum([len(i) for i in ids])]),
                   obs_ids=np.concatenate(ids).astype(np.int64), obs_z=np.concatenate(pixels))


def _synthetic_pair(rng, n=60, pixel_sigma=0.5):
    """Stereo pixels of n random points seen before and after ``MOTION``, with pixel noise."""
    p_next = np.column_stack([rng.uniform(-15, 15, 4 * n), rng.uniform(-3, 2, 4 * n), rng.uniform(5, 60, 4 * n)])
    p_prev = p_next @ MOTION[:3, :3].T + MOTION[:3, 3]
    z_prev = camera.projection(np.c_[p_prev, np.ones(len(p_prev))]) @ KS_RIG.T
    z_next = camera.projection(np.c_[p_next, np.ones(len(p_next))]) @ KS_RIG.T
    seen = np.all((z_prev[:, [0, 2]] > 0) & (z_prev[:, [0, 2]] < WIDTH) & (z_next[:, [0, 2]] > 0)
                  & (z_next[:, [0, 2]] < WIDTH) & (z_prev[:, [1]] < HEIGHT) & (z_next[:, [1]] < HEIGHT), axis=1)
    z_prev, z_next = z_prev[seen][:n], z_next[seen][:n]
    return (z_prev + pixel_sigma * rng.standard_normal(z_prev.shape),
            z_next + pixel_sigma * rng.standard_normal(z_next.shape))


def _random_pixels(rng, n):
    """Uniformly random stereo pixels inside the image, with uL > uR."""
    u = np.sort(rng.uniform(0, WIDTH, (n, 2)), axis=1)[:, ::-1]
    return np.column_stack([u[:, 0], rng.uniform(0, HEIGHT, n), u[:, 1], rng.uniform(0, HEIGHT, n)])


def _with_random_tracks(ds, share, rng):
    """``ds`` with the pixels of a share of its tracks replaced by uniformly random pixels."""
    seen = np.flatnonzero(ds.track_lengths() > 0)
    chosen = rng.choice(seen, size=int(round(share * len(seen))), replace=False)
    z = ds.obs_z.copy()
    hit = np.isin(ds.obs_ids, chosen)
    z[hit] = _random_pixels(rng, int(hit.sum()))
    return dataclasses.replace(ds, obs_z=z, extra={})


def _rotation_errors(vo, ds):
    true = odometry.camera_motion(ds.ground_truth.world_T_imu, ds.imu_T_cam)
    return odometry.motion_errors(vo.cam_T_next[vo.valid], true[vo.valid])[0]


# ------------------------------------------------------------------------ geometry


def test_transfer_jacobian_matches_finite_differences_and_the_camera_model():
    rng = np.random.default_rng(0)
    p_next = np.column_stack([rng.uniform(-10, 10, 7), rng.uniform(-2, 2, 7), rng.uniform(4, 50, 7)])
    z, J = odometry.transfer_pixels(MOTION, p_next, KS_RIG)

    def moved(delta):
        return odometry.transfer_pixels(MOTION @ lie.se3_exp(delta), p_next, KS_RIG, jacobian=False)

    J_fd = fd_jacobian(moved, np.zeros(6), 1e-5)
    assert np.allclose(z, moved(np.zeros(6)))
    assert np.linalg.norm(J - J_fd) < 1e-7 * np.linalg.norm(J_fd)
    # the same as Ks dpi/dq(q) mu odot(p_next) written with the camera module
    q = np.c_[p_next @ MOTION[:3, :3].T + MOTION[:3, 3], np.ones(7)]
    J_model = KS_RIG @ camera.projection_jacobian(q) @ MOTION @ lie.odot(np.c_[p_next, np.ones(7)])
    assert np.allclose(J, J_model, rtol=1e-12, atol=1e-9)


def test_transfer_jacobian_of_a_batch_of_motions_matches_finite_differences():
    """The RANSAC refinement calls transfer_pixels with (pairs, hypotheses) of motions at once."""
    rng = np.random.default_rng(10)
    motions = lie.se3_exp(rng.normal(size=(2, 3, 6)) * [0.3, 0.3, 1.0, 0.05, 0.05, 0.05])
    p_next = np.stack([np.column_stack([rng.uniform(-10, 10, 4), rng.uniform(-2, 2, 4), rng.uniform(4, 50, 4)])
                       for _ in range(6)]).reshape(2, 3, 4, 3)
    _, J = odometry.transfer_pixels(motions, p_next, KS_RIG)
    assert J.shape == (2, 3, 4, 4, 6)
    for a in range(2):
        for h in range(3):
            J_fd = fd_jacobian(lambda d, a=a, h=h: odometry.transfer_pixels(
                motions[a, h] @ lie.se3_exp(d), p_next[a, h], KS_RIG, jacobian=False), np.zeros(6), 1e-5)
            assert np.linalg.norm(J[a, h] - J_fd) < 1e-7 * np.linalg.norm(J_fd)


def test_transfer_information_carries_the_next_frames_pixel_noise_by_finite_differences():
    """W = (I + A A^T)^-1 with A = d z_pred / d z_next, the next frame's pixels seen through
    triangulation and the transfer: A from finite differences of the whole chain."""
    rng = np.random.default_rng(11)
    p_next = np.column_stack([rng.uniform(-10, 10, 5), rng.uniform(-2, 2, 5), rng.uniform(4, 50, 5)])
    z_next = camera.projection(np.c_[p_next, np.ones(5)]) @ KS_RIG.T
    W = odometry._transfer_information(MOTION, z_next, p_next, camera.StereoCamera(K_RIG, B_RIG, np.eye(4)))
    assert W.shape == (5, 4, 4)
    for i in range(5):
        A = fd_jacobian(lambda z: odometry.transfer_pixels(
            MOTION, camera.triangulate_disparity(z, K_RIG, B_RIG)[None], KS_RIG, jacobian=False)[0],
            z_next[i], 1e-4)
        np.testing.assert_allclose(W[i], np.linalg.inv(np.eye(4) + A @ A.T), rtol=1e-7, atol=1e-9)


def test_align_triples_recovers_a_rigid_motion_and_flags_collinear_triples():
    rng = np.random.default_rng(1)
    p_next = rng.normal(size=(50, 3, 3)) * [5.0, 2.0, 20.0]
    motions = lie.se3_exp(rng.normal(size=(50, 6)) * [1.0, 1.0, 1.0, 0.5, 0.5, 0.5])
    p_prev = p_next @ np.swapaxes(motions[:, :3, :3], -1, -2) + motions[:, None, :3, 3]
    R, t, ok = odometry.align_triples(p_prev, p_next)
    assert ok.all()
    assert np.allclose(R, motions[:, :3, :3], atol=1e-9) and np.allclose(t, motions[:, :3, 3], atol=1e-8)
    line = np.outer([0.0, 1.0, 2.0], [1.0, 2.0, 3.0])
    assert not odometry.align_triples(line, line)[2]


# ------------------------------------------------------------------------ accuracy and robustness


def test_noise_free_simulated_pairs_are_recovered_exactly():
    ds = simulate.simulate_drive("tiny", seed=0, pixel_sigma=0.0, outlier_share=0.0, nonpositive_disparity_share=0.0)
    vo = odometry.visual_odometry(ds)
    true = odometry.camera_motion(ds.ground_truth.world_T_imu, ds.imu_T_cam)
    rotation, translation = odometry.motion_errors(vo.cam_T_next, true)
    assert vo.valid.mean() > 0.95
    assert np.all(vo.inliers[vo.valid] == vo.tracked[vo.valid])
    assert rotation[vo.valid].max() < 1e-9 and translation[vo.valid].max() < 1e-8


def test_thirty_percent_random_outliers_on_a_synthetic_pair():
    rng = np.random.default_rng(2)
    z_prev, z_next = _synthetic_pair(rng)
    clean = odometry.visual_odometry(_pair_dataset(z_prev, z_next))
    outliers = rng.choice(len(z_next), size=int(0.3 * len(z_next)), replace=False)
    z_next[outliers] = _random_pixels(rng, len(outliers))
    vo = odometry.visual_odometry(_pair_dataset(z_prev, z_next))
    rot_clean, trans_clean = odometry.motion_errors(clean.cam_T_next, MOTION[None])
    rot, trans = odometry.motion_errors(vo.cam_T_next, MOTION[None])
    assert clean.valid[0] and vo.valid[0]
    assert rot_clean[0] < 1e-3 and rot[0] < 1.5e-3 and trans[0] < 0.05
    assert 0.9 * (len(z_next) - len(outliers)) <= vo.inliers[0] <= len(z_next) - len(outliers) + 1
    # the stated covariance covers the error (chi-square 6 dof, 99.9%)
    error = lie.se3_log(lie.se3_inv(vo.cam_T_next[0]) @ MOTION)
    assert error @ np.linalg.solve(vo.covariance[0], error) < 22.5


def test_random_outlier_tracks_barely_change_the_rotation_error():
    ds = simulate.simulate_drive("small", seed=0, outlier_share=0.0)
    noisy = _with_random_tracks(ds, 0.05, np.random.default_rng(3))
    rms_clean = np.sqrt(np.mean(_rotation_errors(odometry.visual_odometry(ds), ds) ** 2))
    vo = odometry.visual_odometry(noisy)
    rms = np.sqrt(np.mean(_rotation_errors(vo, noisy) ** 2))
    assert vo.valid.mean() > 0.98
    assert rms < 2e-3 and rms < 1.2 * rms_clean


# ------------------------------------------------------------------------ invalid pairs, determinism, errors


def test_pairs_without_enough_points_are_invalid_not_nan():
    rng = np.random.default_rng(4)
    z_a, z_b = _synthetic_pair(rng, n=8)
    ids = [np.arange(8), np.arange(2), np.arange(2), np.arange(10, 15), np.arange(10, 15), np.arange(20, 28)]
    pixels = [z_a, z_b[:2], z_b[:2] + 3.0, z_a[:5], z_a[:5], z_b]  # 2 points; 2; no overlap; stale copies; new
    vo = odometry.visual_odometry(_dataset(ids, pixels))
    assert not vo.valid.any()
    assert list(vo.tracked) == [2, 2, 0, 0, 0] and list(vo.stale) == [0, 0, 0, 5, 0]
    assert np.array_equal(vo.cam_T_next, np.broadcast_to(np.eye(4), (5, 4, 4)))
    assert np.all(np.isinf(np.diagonal(vo.covariance, axis1=1, axis2=2)))
    for field in (vo.cam_T_next, vo.covariance, vo.rms_px, vo.pixel_variance):
        assert not np.isnan(field).any()


def test_a_point_a_hypothesis_moves_onto_the_camera_plane_gets_no_weight_not_an_error():
    """A bad RANSAC hypothesis can move a point to nearly zero depth in frame t: its noise transfer A is then
    ~1e20 px per px and I + A A^T is singular in floats. The point gets zero information (it once raised
    numpy's LinAlgError from the calibration of a noisy simulated drive); the others are unchanged."""
    rng = np.random.default_rng(11)
    p_next = np.column_stack([rng.uniform(-10, 10, 5), rng.uniform(-2, 2, 5), rng.uniform(4, 50, 5)])
    z_next = camera.projection(np.c_[p_next, np.ones(5)]) @ KS_RIG.T
    rig = camera.StereoCamera(K_RIG, B_RIG, np.eye(4))
    onto_plane = np.eye(4)
    onto_plane[2, 3] = -p_next[0, 2] + 1e-9  # point 0 lands a nanometre in front of the camera at t
    W = odometry._transfer_information(onto_plane, z_next, p_next, rig)
    np.testing.assert_array_equal(W[0], np.zeros((4, 4)))
    np.testing.assert_allclose(W[1:], odometry._transfer_information(onto_plane, z_next[1:], p_next[1:], rig))


def test_same_seed_same_result():
    ds = simulate.simulate_drive("tiny", seed=5, outlier_share=0.1)
    first, second = odometry.visual_odometry(ds, seed=7), odometry.visual_odometry(ds, seed=7)
    for field in dataclasses.fields(odometry.VisualOdometry):
        a, b = getattr(first, field.name), getattr(second, field.name)
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b


@pytest.mark.parametrize("setting, value", [("pixel_sigma", -1.0), ("probability", 1.0), ("hypotheses", 0),
                                            ("min_inliers", 2), ("hypotheses", 1.5)])
def test_bad_settings_name_the_setting(setting, value):
    ds = simulate.simulate_drive("tiny", seed=0)
    with pytest.raises(ValueError, match=setting):
        odometry.visual_odometry(ds, **{setting: value})


def test_bad_inputs_give_clear_errors():
    with pytest.raises(TypeError, match="expected a visla_edu.dataset.Dataset"):
        odometry.visual_odometry("03")
    ds = simulate.simulate_drive("tiny", seed=0)
    z = ds.obs_z.copy()
    z[ds.frame_ptr[7]] = np.nan
    with pytest.raises(ValueError, match="non-finite pixels at frame 7"):
        odometry.visual_odometry(dataclasses.replace(ds, obs_z=z))


# ------------------------------------------------------------------------ course data


@pytest.mark.data
def test_course_drive_0020_against_its_ground_truth(require_data):
    from visla_edu import data

    path = require_data("0020")
    poses = path.parent / "kitti_odometry_06_poses.txt"
    if not poses.is_file():
        pytest.skip(f"{poses.name} not found beside {path.name}")
    P = np.zeros((1101, 4, 4))
    P[:, :3] = np.loadtxt(poses).reshape(-1, 3, 4)
    P[:, 3, 3] = 1.0
    true = lie.se3_inv(P[:-1]) @ P[1:]
    vo = odometry.visual_odometry(data.load(path))
    valid = vo.valid[:1100]
    rotation, _ = odometry.motion_errors(vo.cam_T_next[:1100][valid], true[valid])
    assert valid.mean() > 0.45 and (vo.stale > 0).sum() > 100
    assert np.median(rotation) < 4e-3
