"""The joint filter's clone window: track Jacobians, triangulation, the null space, delayed entry,
the clone bookkeeping, the camera's noise inflation, and the filter with clones on simulated drives."""

import dataclasses

import numpy as np
import pytest
from fdiff import fd_jacobian

from visla_edu import diagnostics, ekf, lie, metrics, motion, run, simulate
from visla_edu.camera import StereoCamera
from visla_edu.filters import ActiveSet, FilterConfig, JointSlam, _tracks
from visla_edu.filters._config import GYRO_REGIME_RATIO, MAX_INFLATION, MSCKF_WINDOW, gyro_ratio, msckf_window, \
    pixel_noise_inflation
from visla_edu.filters._forms import InvariantForm, RightForm

RNG = np.random.default_rng(7)


@pytest.fixture(scope="module")
def camera():
    _, _, imu_T_cam = simulate.default_rig()
    K = np.array([[700.0, 0, 600], [0, 700.0, 180], [0, 0, 1]])
    return StereoCamera(K, 0.54, imu_T_cam)


def _pose(rng, scale=1.0):
    return lie.se3_exp(scale * rng.normal(size=6))


def _point_ahead(camera, world_T_imu, depth):
    """A world point ``depth`` m in front of the left camera of ``world_T_imu``."""
    p_cam = np.array([1.0, -0.5, depth])
    world_T_cam = world_T_imu @ camera.imu_T_cam
    return world_T_cam[:3, :3] @ p_cam + world_T_cam[:3, 3]


# ----------------------------------------------------------------------------- Jacobians


@pytest.mark.parametrize("form", [RightForm, InvariantForm])
def test_clone_jacobian_matches_finite_differences(camera, form):
    """``dz/dxi`` of an observation made from a clone, for the clone's error as the form defines it."""
    T = _pose(RNG, 0.3)
    m = _point_ahead(camera, T, 12.0)
    _, _, J_l, J_pose = _tracks._project(camera, T[None], m[None])
    H = form.clone_jacobian(J_l, J_pose, m[None])[0]

    def z_of(xi):
        moved = form.retract_clone(T[None], xi[None])[0]
        return camera.predict(moved, m[None])[0]

    np.testing.assert_allclose(H, fd_jacobian(z_of, np.zeros(6), 1e-6), rtol=1e-6, atol=1e-6)


def test_invariant_delayed_pose_jacobian_matches_finite_differences(camera):
    """A landmark entering now is ``m = exp(hat(theta)) mu_m + e``: its past observations depend on theta."""
    T_past = _pose(RNG, 0.3)
    mu = _point_ahead(camera, T_past, 9.0)
    _, _, J_l, _ = _tracks._project(camera, T_past[None], mu[None])
    H = InvariantForm.delayed_pose_jacobian(J_l, mu[None])[0]

    def z_of(xi):
        m = lie.so3_exp(xi[3:]) @ mu  # e = 0; the current pose's translation error does not enter
        return camera.predict(T_past, m[None])[0]

    np.testing.assert_allclose(H, fd_jacobian(z_of, np.zeros(6), 1e-6), rtol=1e-6, atol=1e-6)
    assert np.all(RightForm.delayed_pose_jacobian(J_l, mu[None]) == 0)


# ----------------------------------------------------------------------------- triangulation


def _track(camera, rng, depth, n=6, noise=0.0):
    """Poses driving forward and the stereo pixels of one point seen from each."""
    steps = [np.eye(4)]
    for _ in range(n - 1):
        steps.append(steps[-1] @ lie.se3_exp(np.r_[1.0, 0, 0, 0, 0, 0.01]))
    poses = np.array(steps)
    m = _point_ahead(camera, poses[0], depth) + np.array([0.0, 3.0, 0.5])
    z = np.array([camera.predict(T, m[None])[0] for T in poses]) + noise * rng.normal(size=(n, 4))
    return poses, z, m


@pytest.mark.parametrize("depth", [8.0, 60.0, 600.0])
def test_triangulation_recovers_near_and_far_points(camera, depth):
    """Inverse depth: a point whose disparity is below a pixel (600 m on this rig) is found too."""
    poses, z, m = _track(camera, RNG, depth)
    assert depth < 100 or (z[:, 0] - z[:, 2]).max() < 1.0
    p, ok = _tracks.triangulate_tracks(camera, poses, z, np.zeros(len(z), dtype=int), 1, 1.0)
    assert ok[0]
    np.testing.assert_allclose(p[0], m, rtol=1e-6 * depth)


def test_triangulation_is_batched_and_refuses_points_behind_a_camera(camera):
    poses_a, z_a, m_a = _track(camera, RNG, 10.0)
    poses_b, z_b, m_b = _track(camera, RNG, 20.0, n=4)
    poses = np.concatenate([poses_a, poses_b])
    z = np.concatenate([z_a, z_b])
    owner = np.r_[np.zeros(len(z_a), int), np.ones(len(z_b), int)]
    p, ok = _tracks.triangulate_tracks(camera, poses, z, owner, 2, 1.0)
    assert ok.all()
    np.testing.assert_allclose(p, [m_a, m_b], atol=1e-6)
    turned = poses.copy()
    turned[-1] = turned[-1] @ lie.se3_exp(np.r_[0, 0, 0, 0, 0, np.pi])  # the last camera of track b faces away
    _, ok = _tracks.triangulate_tracks(camera, turned, z, owner, 2, 1.0)
    assert ok[0] and not ok[1]


def test_triangulation_resists_one_wild_observation(camera, monkeypatch):
    """Huber weights: one observation 40 px off moves the point far less than in plain least squares."""
    poses, z, _ = _track(camera, RNG, 15.0, n=8, noise=0.3)
    clean, _ = _tracks.triangulate_tracks(camera, np.delete(poses, 3, 0), np.delete(z, 3, 0), np.zeros(7, int), 1, 1.0)
    z[3, :2] += 40.0
    robust, _ = _tracks.triangulate_tracks(camera, poses, z, np.zeros(8, dtype=int), 1, 1.0)
    monkeypatch.setattr(_tracks, "HUBER_SIGMAS", 1e9)
    plain, _ = _tracks.triangulate_tracks(camera, poses, z, np.zeros(8, dtype=int), 1, 1.0)
    assert np.linalg.norm(robust[0] - clean[0]) < 0.5 * np.linalg.norm(plain[0] - clean[0])


# ----------------------------------------------------------------------------- null space and entry


def test_null_space_rows_are_orthonormal_and_blind_to_the_point():
    H_point = RNG.normal(size=(3, 5, 4, 3))
    r = RNG.normal(size=(3, 5, 4))
    Q2T, Q1T, R1 = _tracks.project_out_point(r, H_point)
    H = H_point.reshape(3, 20, 3)
    np.testing.assert_allclose(Q2T @ H, 0, atol=1e-12)
    np.testing.assert_allclose(Q2T @ np.swapaxes(Q2T, 1, 2), np.broadcast_to(np.eye(17), (3, 17, 17)), atol=1e-12)
    np.testing.assert_allclose(Q1T @ H, R1, atol=1e-12)
    assert np.allclose(np.tril(R1, -1), 0)


def test_delayed_entry_and_null_space_update_equal_the_joint_update_from_a_flat_prior():
    """The point's Q1 rows enter it, its Q2 rows update the state: the joint EKF with a point of no prior."""
    D, n, var = 7, 4, 0.3
    A = RNG.normal(size=(D, D))
    Sigma = A @ A.T + np.eye(D)
    H_x, H_f, r = RNG.normal(size=(4 * n, D)), RNG.normal(size=(4 * n, 3)), RNG.normal(size=4 * n)
    # the joint posterior over [x; f] with a flat prior on f, in information form
    H = np.hstack([H_x, H_f])
    info = H.T @ H / var
    info[:D, :D] += np.linalg.inv(Sigma)
    post = np.linalg.inv(info)
    post_mean = post @ H.T @ r / var
    # the split
    Q2T, Q1T, R1 = (a[0] for a in _tracks.project_out_point(r.reshape(1, n, 4), H_f.reshape(1, n, 4, 3)))
    H1 = Q1T @ H_x
    mean, cross, block = _tracks.delayed_entry(Q1T @ r, R1, H1 @ Sigma, H1 @ Sigma @ H1.T, var)
    aug = np.zeros((D + 3, D + 3))
    aug[:D, :D], aug[D:, :D], aug[:D, D:], aug[D:, D:] = Sigma, cross, cross.T, block
    H2 = np.hstack([Q2T @ H_x, np.zeros((4 * n - 3, 3))])
    delta, _ = ekf.gain_update(aug, aug @ H2.T, H2 @ aug @ H2.T + var * np.eye(4 * n - 3), Q2T @ r)
    np.testing.assert_allclose(aug, post, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(delta + np.r_[np.zeros(D), mean], post_mean, rtol=1e-5, atol=1e-5)


def test_the_whole_track_gate_is_a_chi_square_test():
    H_o = np.zeros((2, 9, 6))
    r_o = np.stack([np.full(9, 0.5), np.full(9, 3.0)])
    inside, d2 = _tracks.gate_tracks(r_o, H_o, np.zeros((2, 6, 6)), 1.0, 0.95)
    np.testing.assert_allclose(d2, [9 * 0.25, 81.0])
    assert inside.tolist() == [True, False]


# ----------------------------------------------------------------------------- buffer and clones


def test_track_buffer_keeps_the_window():
    buffer = _tracks.TrackBuffer()
    for t in range(5):
        buffer.add(np.array([1, 2]) if t < 3 else np.array([2]), np.full((2 if t < 3 else 1, 4), float(t)), t)
    assert sorted(buffer.landmarks().tolist()) == [1, 2] and buffer.first_frame(np.array([2]))[0] == 0
    buffer.forget_before(2)
    frames, z, owner = buffer.pop(np.array([2, 1]))
    assert frames.tolist() == [2, 3, 4, 2] and owner.tolist() == [0, 0, 0, 1] and z[:, 0].tolist() == [2, 3, 4, 2]
    assert len(buffer) == 0


def test_clones_copy_the_pose_and_landmarks_enter_before_them():
    state = ActiveSet(10, np.diag(np.arange(1.0, 7.0)))
    state.enter(np.array([3]))
    state.Sigma[6:9, 6:9] = 5 * np.eye(3)
    state.clone_pose(0)
    np.testing.assert_array_equal(state.Sigma[state.clone_columns(0)][:, state.clone_columns(0)],
                                  state.Sigma[:6, :6])
    np.testing.assert_array_equal(state.Sigma[:6, state.clone_columns(0)], state.Sigma[:6, :6])
    before = state.Sigma.copy()
    state.enter(np.array([7]))
    assert state.dim == 6 + 6 + 6 and state.landmark_end == 12
    np.testing.assert_array_equal(state.Sigma[np.ix_(state.clone_columns(0), state.clone_columns(0))],
                                  before[9:15, 9:15])
    state.retire(np.array([3]))
    np.testing.assert_array_equal(state.Sigma[np.ix_(state.clone_columns(0), state.clone_columns(0))],
                                  before[9:15, 9:15])
    state.drop_clone(0)
    assert state.dim == 9 and state.clone_frames == []


# ----------------------------------------------------------------------------- the camera's trust


def test_pixel_noise_inflation_is_one_for_a_noisy_gyro_and_grows_for_a_clean_one():
    assert pixel_noise_inflation(1.5, 700.0, 0.05, 0.1) == 1.0  # one pixel beats a gyro step
    r = (1.5 / 700.0) / (0.005 * 0.1)
    assert pixel_noise_inflation(1.5, 700.0, [0.005] * 3, 0.1) == pytest.approx(r**2)
    assert pixel_noise_inflation(1.5, 700.0, 0.005, 0.1, power=1) == pytest.approx(r)
    assert pixel_noise_inflation(1.5, 700.0, 0.0, 0.1) == MAX_INFLATION


def test_auto_inflation_is_resolved_from_the_drive_and_reaches_the_filter():
    ds = simulate.simulate_drive("tiny", 0)
    config = run.resolve_config(ds, FilterConfig(sigma_angular_velocity=0.001))
    expected = pixel_noise_inflation(1.5, ds.K[0, 0], 0.001, np.median(ds.time_steps))
    assert config.pixel_noise_inflation == pytest.approx(expected) and expected > 1
    assert config.pixel_variance == pytest.approx((1.5 * expected) ** 2)
    assert run.make_filter(ds, "vio", config).noise_var == pytest.approx(config.pixel_variance)
    with pytest.raises(TypeError, match="needs the drive's focal_length"):
        FilterConfig(sigma_linear_velocity=0.1, sigma_angular_velocity=0.1, imu_lag=0).resolve(None)
    assert not FilterConfig(imu_lag=0, sigma_linear_velocity=0.1, sigma_angular_velocity=0.1).resolved


def test_track_correlation_raises_the_inflation_in_the_gyro_regime_only():
    clean, noisy = 0.002, 0.05  # rad/s: r = 10.7 and 0.43 for 1.5 px at 700 px in 0.1 s
    assert gyro_ratio(1.5, 700.0, clean, 0.1) > GYRO_REGIME_RATIO > gyro_ratio(1.5, 700.0, noisy, 0.1)
    r2 = gyro_ratio(1.5, 700.0, clean, 0.1) ** 2
    assert pixel_noise_inflation(1.5, 700.0, clean, 0.1, track_correlation=0.99) == pytest.approx(1.99 / 0.01)
    assert pixel_noise_inflation(1.5, 700.0, clean, 0.1, track_correlation=0.5) == pytest.approx(r2)  # 3 < r^2
    assert pixel_noise_inflation(1.5, 700.0, noisy, 0.1, track_correlation=0.99) == 1.0
    assert pixel_noise_inflation(1.5, 700.0, clean, 0.1, track_correlation=1.0) == MAX_INFLATION


def test_auto_clone_window_is_zero_in_the_gyro_regime_and_the_window_elsewhere():
    assert msckf_window(1.5, 700.0, 0.002, 0.1) == 0
    assert msckf_window(1.5, 700.0, 0.05, 0.1) == MSCKF_WINDOW
    ds = simulate.simulate_drive("tiny", 0)
    fixed = dict(sigma_linear_velocity=0.1, imu_lag=0, extrinsic_correction="none")
    assert run.resolve_config(ds, FilterConfig(sigma_angular_velocity=0.001, **fixed)).msckf_window == 0
    assert run.resolve_config(ds, FilterConfig(sigma_angular_velocity=0.05, **fixed)).msckf_window == MSCKF_WINDOW
    assert run.resolve_config(ds, FilterConfig(sigma_angular_velocity=0.001, msckf_window=7, **fixed)).msckf_window == 7
    assert not FilterConfig(sigma_angular_velocity=0.001, pixel_noise_inflation=1.0, **fixed).resolved


def _with_track_error(ds, rho, sigma, seed):
    """``ds`` with an AR(1) pixel error of correlation ``rho`` added along each track (the same shift on all four rows)."""
    rng = np.random.default_rng(seed)
    frames = np.repeat(np.arange(ds.num_frames), np.diff(ds.frame_ptr))
    z = ds.obs_z.copy()
    for landmark in np.unique(ds.obs_ids):
        rows = np.flatnonzero(ds.obs_ids == landmark)
        rows = rows[np.argsort(frames[rows])]
        e = np.empty(len(rows))
        e[0] = rng.normal(0, sigma)
        for k in range(1, len(rows)):
            e[k] = rho * e[k - 1] + rng.normal(0, sigma * np.sqrt(1 - rho**2))
        z[rows] += e[:, None]
    return dataclasses.replace(ds, obs_z=z, extra={})


def test_track_correlation_is_near_zero_for_white_pixels_and_finds_a_persistent_error():
    ds = simulate.simulate_drive("small", 0)
    truth = ds.ground_truth.world_T_imu
    white, tracks = diagnostics.track_correlation(ds, truth, ds.imu_T_cam)
    assert abs(white) < 0.15 and tracks > 100
    persistent, _ = diagnostics.track_correlation(_with_track_error(ds, 0.9, 3.0, 1), truth, ds.imu_T_cam)
    assert persistent > white + 0.4  # 0.9 x 9 / (9 + 1) = 0.81 less the short tracks' bias (module docstring)
    assert diagnostics.calibrate(ds, cache=False).correlated_tracks > 0
    with pytest.raises(ValueError, match=r"world_T_imu must have shape \(300, 4, 4\), one pose per frame"):
        diagnostics.track_correlation(ds, truth[:10], ds.imu_T_cam)


# ----------------------------------------------------------------------------- the filter


@pytest.fixture(scope="module")
def small():
    return simulate.simulate_drive("small", 1)


def _run(ds, **settings):
    return run.run_filter(ds, "slam", FilterConfig(pixel_noise_inflation=1.0, **settings), progress=False)


def test_clones_beat_dead_reckoning_and_use_most_tracks(small):
    result = _run(small)
    truth = small.ground_truth.world_T_imu
    dr = motion.dead_reckon(small.time_stamps, small.twists, lag=result.config["imu_lag"])
    assert metrics.ate(result.world_T_imu, truth) < 0.5 * metrics.ate(dr, truth)
    c = result.track_counts
    assert c["tracks_used"] > 10 * c["tracks_gated"] and c["entered"] > 0 and c["observations_used"] > 0
    totals = result.status_totals()
    assert totals["delayed"] >= 0 and totals["used"] > c["observations_used"]
    assert "entered the state" in result.summary()


def test_clones_are_consistent_on_a_simulated_drive(small):
    result = _run(small)
    errors = metrics.pose_errors(result.world_T_imu, small.ground_truth.world_T_imu)
    nees = metrics.nees(errors, result.pose_cov)
    assert 1.0 < np.nanmean(nees[10:]) < 30.0  # 6 is consistent; the right form reaches hundreds here


@pytest.mark.parametrize("form", ["right", "invariant"])
def test_both_error_forms_run_with_clones(small, form):
    part = small.segment(0, 200)
    result = _run(part, slam_error=form)
    assert metrics.ate(result.world_T_imu, part.ground_truth.world_T_imu) < 1.0


def test_no_clones_is_the_joint_ekf_without_them(small):
    """``msckf_window=0``: every landmark enters at its first observation, as the dense filter's."""
    part = small.segment(0, 120)
    config = FilterConfig(pixel_noise_inflation=1.0, msckf_window=0)
    active = run.run_filter(part, "slam", config, progress=False)
    dense = run.run_filter(part, "slam", config, dense=True, progress=False)
    np.testing.assert_allclose(active.world_T_imu, dense.world_T_imu, atol=1e-8)
    assert active.track_counts == {} and active.status_totals()["delayed"] == 0


def test_a_landmark_cap_of_zero_uses_every_track_in_pieces(small):
    part = small.segment(0, 150)
    result = _run(part, max_slam_landmarks=0)
    assert result.track_counts["entered"] == 0 and result.track_counts["tracks_used"] > 0
    assert metrics.ate(result.world_T_imu, part.ground_truth.world_T_imu) < 1.0


def test_the_filter_with_clones_steps_and_reports_its_landmarks(small):
    part = small.segment(0, 60)
    flt = run.make_filter(part, "slam", FilterConfig(pixel_noise_inflation=1.0, msckf_window=8))
    records = [flt.step() for _ in range(part.num_frames)]
    assert len(flt.state.clone_frames) <= 8 and isinstance(flt, JointSlam)
    assert any(len(r.active_ids) for r in records)
    landmarks, covs = flt.landmark_estimates()
    mapped = np.isfinite(landmarks[:, 0])
    assert mapped.sum() > 0.5 * part.num_landmarks
    assert np.all(np.linalg.eigvalsh(covs[mapped]) > 0)
