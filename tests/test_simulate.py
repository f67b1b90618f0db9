"""Tests of visla_edu.simulate (determinism, ground truth, track model, noise, scale) and of the
dataset-10 stand-in built with it (visla_edu.data.standin_dataset10).

The stand-in tests on the real drive need the course data (``VISLA_EDU_DATA``, e.g.
``/work/shared/data``) and are skipped with a reason otherwise.
"""

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from visla_edu import lie
from visla_edu.camera import StereoCamera
from visla_edu.data import STANDIN_LABEL, course_standin10, standin_dataset10
from visla_edu.data import save as save_course_file
from visla_edu.motion import dead_reckon, select_twists
from visla_edu.simulate import (
    PRESETS,
    SimulationConfig,
    default_rig,
    lag_samples,
    make_config,
    place_landmarks,
    simulate_along_drive,
    simulate_drive,
    simulate_tracks,
)

NOISE_FREE = dict(pixel_sigma=0.0, outlier_share=0.0, nonpositive_disparity_share=0.0,
                  linear_velocity_sigma=0.0, angular_velocity_sigma=0.0)


# ------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def tiny():
    return simulate_drive("tiny", seed=0)


@pytest.fixture(scope="module")
def small():
    return simulate_drive("small", seed=3)


@pytest.fixture(scope="module")
def course():
    return simulate_drive("course", seed=0)


def _data_file(name):
    """Path of a course file, or skip with the reason it is not available."""
    root = os.environ.get("VISLA_EDU_DATA")
    if not root:
        pytest.skip("VISLA_EDU_DATA is not set: the course data directory is needed for the stand-in")
    path = Path(root) / name
    if not path.is_file():
        pytest.skip(f"course file {path} not found (VISLA_EDU_DATA={root})")
    return path


@pytest.fixture(scope="module")
def standin_paths():
    return _data_file("10_imu_only.npz"), _data_file("03.npz")


@pytest.fixture(scope="module")
def standin(standin_paths):
    return standin_dataset10(*standin_paths, seed=0)


# -------------------------------------------------------------------------- helpers


def _arrays(d):
    g = d.ground_truth
    return [d.time_stamps, d.linear_velocity, d.angular_velocity, d.K, d.imu_T_cam, d.frame_ptr,
            d.obs_ids, d.obs_z, g.world_T_imu, g.landmarks, g.linear_velocity, g.angular_velocity,
            g.outlier]


def _true_points(d):
    """Camera-frame points of every observation at the true pose, shape (N, 4)."""
    g, cam = d.ground_truth, d.camera
    q = np.empty((d.num_observations, 4))
    for t in range(d.num_frames):
        lo, hi = d.frame_ptr[t], d.frame_ptr[t + 1]
        q[lo:hi] = cam.points_in_camera(g.world_T_imu[t], g.landmarks[d.obs_ids[lo:hi]])
    return q


def _predicted(d):
    """``StereoCamera.predict`` at the true pose for every observation, shape (N, 4)."""
    g, cam = d.ground_truth, d.camera
    z = np.empty((d.num_observations, 4))
    for t in range(d.num_frames):
        lo, hi = d.frame_ptr[t], d.frame_ptr[t + 1]
        z[lo:hi] = cam.predict(g.world_T_imu[t], g.landmarks[d.obs_ids[lo:hi]])
    return z


def _assert_valid_store(d, min_track_length=2):
    """Sparse layout, contiguous tracks, ids by first frame, every landmark tracked."""
    T, M, N = d.num_frames, d.num_landmarks, d.num_observations
    assert d.frame_ptr.shape == (T + 1,) and d.frame_ptr[0] == 0 and d.frame_ptr[-1] == N
    assert np.all(np.diff(d.frame_ptr) >= 0)
    assert d.obs_z.shape == (N, 4) and d.obs_ids.shape == (N,)
    assert np.all(np.isfinite(d.obs_z))
    for t in range(T):
        ids, _ = d.observations(t)
        assert np.all(np.diff(ids) > 0), f"ids not increasing within frame {t}"
    spans, lengths = d.track_spans(), d.track_lengths()
    assert np.all(spans[:, 0] >= 0), "a landmark without observations"
    assert np.all(lengths == spans[:, 1] - spans[:, 0] + 1), "a track is not one contiguous run"
    assert np.all(lengths >= min_track_length)
    assert np.all(np.diff(spans[:, 0]) >= 0), "ids are not ordered by first observation frame"
    g = d.ground_truth
    assert g.world_T_imu.shape == (T, 4, 4) and g.landmarks.shape == (M, 3)
    assert g.outlier.shape == (M,) and g.outlier.dtype == bool
    assert g.linear_velocity.shape == (T, 3) and g.angular_velocity.shape == (T, 3)
    assert d.linear_velocity.shape == (T, 3) and d.angular_velocity.shape == (T, 3)
    assert np.all(np.diff(d.time_stamps) > 0)


# ----------------------------------------------------------------------- determinism


def test_same_seed_gives_identical_arrays():
    a, b = simulate_drive("tiny", seed=7), simulate_drive("tiny", seed=7)
    for x, y in zip(_arrays(a), _arrays(b)):
        np.testing.assert_array_equal(x, y)
    assert a.num_landmarks == b.num_landmarks and a.source == b.source


def test_different_seed_gives_different_arrays():
    a, b = simulate_drive("tiny", seed=1), simulate_drive("tiny", seed=2)
    assert not np.array_equal(a.time_stamps, b.time_stamps)
    assert not np.array_equal(a.ground_truth.world_T_imu, b.ground_truth.world_T_imu)
    assert a.obs_z.shape != b.obs_z.shape or not np.array_equal(a.obs_z, b.obs_z)


def test_noise_settings_do_not_change_the_drive_or_the_map():
    a = simulate_drive("tiny", seed=4)
    b = simulate_drive("tiny", seed=4, pixel_sigma=2.0, linear_velocity_sigma=0.2)
    np.testing.assert_array_equal(a.ground_truth.world_T_imu, b.ground_truth.world_T_imu)
    np.testing.assert_array_equal(a.ground_truth.landmarks, b.ground_truth.landmarks)
    np.testing.assert_array_equal(a.obs_ids, b.obs_ids)


# ---------------------------------------------------------------------- ground truth


def test_true_velocities_integrate_to_true_poses(small):
    g = small.ground_truth
    pose = np.eye(4)
    np.testing.assert_array_equal(g.world_T_imu[0], np.eye(4))
    for k, tau in enumerate(small.time_steps):
        u = np.concatenate([g.linear_velocity[k], g.angular_velocity[k]])
        pose = pose @ lie.se3_exp(tau * u)
        np.testing.assert_allclose(g.world_T_imu[k + 1], pose, rtol=0, atol=1e-9)


def test_dead_reckoned_velocities_match_stepwise_exp():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.05, 0.15, 20))
    v, w = rng.normal(size=(20, 3)), 0.3 * rng.normal(size=(20, 3))
    poses = dead_reckon(t, np.hstack([v, w]))
    for k in range(19):
        step = lie.se3_exp((t[k + 1] - t[k]) * np.concatenate([v[k], w[k]]))
        np.testing.assert_allclose(poses[k + 1], poses[k] @ step, atol=1e-12)


def test_noise_free_pixels_equal_prediction_and_triangulate_to_landmarks():
    d = simulate_drive("tiny", seed=5, **NOISE_FREE)
    g = d.ground_truth
    np.testing.assert_array_equal(d.linear_velocity, g.linear_velocity)
    np.testing.assert_array_equal(d.angular_velocity, g.angular_velocity)
    assert not g.outlier.any()
    np.testing.assert_allclose(d.obs_z, _predicted(d), rtol=0, atol=1e-9)
    np.testing.assert_allclose(d.obs_z[:, 1], d.obs_z[:, 3], rtol=0, atol=1e-9)  # rectified
    cam = d.camera
    for t in range(d.num_frames):
        ids, z = d.observations(t)
        np.testing.assert_allclose(cam.triangulate(z, g.world_T_imu[t]), g.landmarks[ids],
                                   rtol=0, atol=1e-7)


def test_tracks_are_contiguous_in_front_and_inside_the_images(small):
    _assert_valid_store(small)
    config = small.extra["config"]
    depth = _true_points(small)[:, 2]
    assert depth.min() >= config.depth_range[0] and depth.max() <= config.depth_range[1]
    inlier = ~small.ground_truth.outlier[small.obs_ids]
    z = _predicted(small)[inlier]
    width, height = config.image_size
    assert z[:, [0, 2]].min() >= 0 and z[:, [0, 2]].max() < width
    assert z[:, 1].min() >= 0 and z[:, 1].max() < height


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cap=st.integers(8, 60), min_len=st.integers(2, 4))
def test_invariants_hold_for_any_seed(seed, cap, min_len):
    d = simulate_drive("tiny", seed=seed, max_observations_per_frame=cap, min_track_length=min_len)
    _assert_valid_store(d, min_track_length=min_len)
    assert np.diff(d.frame_ptr).max() <= cap


def test_per_frame_cap_drops_the_farthest():
    free = simulate_drive("tiny", seed=0, **NOISE_FREE)
    capped = simulate_drive("tiny", seed=0, max_observations_per_frame=15, **NOISE_FREE)
    assert np.diff(free.frame_ptr).max() > 15
    assert np.diff(capped.frame_ptr).max() <= 15
    _assert_valid_store(capped)
    # The capped frames keep near observations: their median depth is smaller.
    assert np.median(_true_points(capped)[:, 2]) < np.median(_true_points(free)[:, 2])


# ----------------------------------------------------------------- outliers, disparity


def test_outlier_and_nonpositive_disparity_shares_default(small):
    assert abs(small.ground_truth.outlier.mean() - 0.01) < 0.002
    disparity = small.obs_z[:, 0] - small.obs_z[:, 2]
    assert abs(np.mean(disparity <= 0) - 0.01) < 0.002


def test_outlier_and_nonpositive_disparity_shares_configured():
    d = simulate_drive("small", seed=1, outlier_share=0.05, nonpositive_disparity_share=0.03)
    assert abs(d.ground_truth.outlier.mean() - 0.05) < 0.002
    disparity = d.obs_z[:, 0] - d.obs_z[:, 2]
    assert abs(np.mean(disparity <= 0) - 0.03) < 0.003


def test_outlier_tracks_are_far_off_and_inliers_are_not():
    d = simulate_drive("small", seed=2, outlier_share=0.05, nonpositive_disparity_share=0.0)
    error = np.abs(d.obs_z - _predicted(d)).max(axis=1)
    out = d.ground_truth.outlier[d.obs_ids]
    assert np.all(error[~out] < 8.0)  # 1 px noise: 8 sigma
    assert np.all(error[out] > 10.0)


def test_uniform_outlier_tracks_are_random_pixels_in_the_image():
    d = simulate_drive("small", seed=2, outlier_share=0.05, outlier_kind="uniform")
    out = d.ground_truth.outlier[d.obs_ids]
    z = d.obs_z[out]
    width, height = d.extra["config"].image_size
    assert abs(d.ground_truth.outlier.mean() - 0.05) < 0.002
    assert np.all((z[:, [0, 2]] >= 0) & (z[:, [0, 2]] < width)) and np.all((z[:, 1] >= 0) & (z[:, 1] < height))
    assert np.all(z[:, 0] > z[:, 2])  # positive disparity
    assert np.std(z[:, 1] - z[:, 3]) < 1.5  # on the epipolar line up to pixel noise
    # random, not offset: consecutive observations of one outlier track jump across the image
    ids, frames = d.obs_ids[out], d.observation_frames()[out]
    order = np.lexsort((frames, ids))
    same = ids[order][1:] == ids[order][:-1]
    assert same.sum() > 100 and np.median(np.abs(np.diff(z[order, 0]))[same]) > 100
    error = np.abs(d.obs_z - _predicted(d)).max(axis=1)
    assert np.all(error[~out] < 8.0)


def test_imu_lag_records_the_velocities_late():
    for lag in (-1, 1, 2):
        d = simulate_drive("tiny", seed=0, imu_lag=lag, linear_velocity_sigma=0.0, angular_velocity_sigma=0.0)
        g = d.ground_truth
        true = np.concatenate([g.linear_velocity, g.angular_velocity], axis=1)
        used = select_twists(d.twists, lag)  # the sample that moves frame t to t+1
        # the recording has no sample for the first -lag steps (lag < 0) or the last lag - 1 (lag > 1)
        inside = slice(max(-lag, 0), len(used) - max(lag - 1, 0))
        np.testing.assert_array_equal(used[inside], true[:-1][inside])
        np.testing.assert_array_equal(lag_samples(true, lag)[max(lag, 0):], d.twists[max(lag, 0):])
    plain = simulate_drive("tiny", seed=0)
    np.testing.assert_array_equal(simulate_drive("tiny", seed=0, imu_lag=0).twists, plain.twists)


def test_reported_extrinsic_differs_from_the_simulated_one():
    K, b, rig = default_rig()
    flipped = np.diag([1.0, -1.0, -1.0, 1.0]) @ rig
    d = simulate_drive("tiny", seed=0, imu_T_cam=flipped, reported_imu_T_cam=rig, **NOISE_FREE)
    np.testing.assert_array_equal(d.imu_T_cam, rig)
    np.testing.assert_array_equal(d.extra["simulated_imu_T_cam"], flipped)
    # the tracks were made with the simulated one
    truth = dataclasses.replace(d, imu_T_cam=flipped)
    np.testing.assert_allclose(d.obs_z, _predicted(truth), atol=1e-9)
    assert "simulated_imu_T_cam" not in simulate_drive("tiny", seed=0).extra


# ------------------------------------------------------------------------ noise stats


def test_pixel_noise_has_the_configured_sigma():
    d = simulate_drive("small", seed=6, pixel_sigma=1.5, outlier_share=0.0,
                       nonpositive_disparity_share=0.0)
    residual = d.obs_z - _predicted(d)
    np.testing.assert_allclose(residual.std(axis=0), 1.5, rtol=0.03)
    np.testing.assert_allclose(residual.mean(axis=0), 0.0, atol=0.05)


def test_imu_noise_has_the_configured_sigma_and_bias():
    bias = (0.001, -0.002, 0.003)
    d = simulate_drive("course", seed=1, num_landmarks=50, linear_velocity_sigma=0.05,
                       angular_velocity_sigma=0.002, gyro_bias=bias)
    g = d.ground_truth
    dv, dw = d.linear_velocity - g.linear_velocity, d.angular_velocity - g.angular_velocity
    np.testing.assert_allclose(dv.std(axis=0), 0.05, rtol=0.08)
    np.testing.assert_allclose(dw.std(axis=0), 0.002, rtol=0.08)
    np.testing.assert_allclose(dw.mean(axis=0), bias, atol=3e-4)
    np.testing.assert_allclose(dv.mean(axis=0), 0.0, atol=6e-3)


# ------------------------------------------------------------------- motion and scale


def test_car_like_motion(course):
    d = course
    g = d.ground_truth
    lo, hi = d.extra["config"].speed_range
    assert g.linear_velocity[:, 0].min() >= lo and g.linear_velocity[:, 0].max() <= hi
    assert np.abs(g.linear_velocity[:, 1:]).max() < 0.2
    assert np.abs(g.angular_velocity[:, :2]).max() < 0.05
    assert 0.1 < np.abs(g.angular_velocity[:, 2]).max() < 1.0  # there are turns
    assert np.abs(g.world_T_imu[:, 2, 3]).max() < 20  # stays near the ground plane


def test_course_preset_has_dataset3_scale(course):
    d = course
    assert d.name == "sim" and "course" in d.label and "seed 0" in d.label
    assert "seed=0" in d.source and "SimulationConfig(" in d.source
    assert d.num_frames == 1010
    assert abs(np.mean(d.time_steps) - 0.1046) < 1e-3 and 0 < np.std(d.time_steps) < 1e-3
    assert 4800 <= d.num_landmarks <= 5000
    assert 55_000 <= d.num_observations <= 80_000
    per_frame = np.diff(d.frame_ptr)
    assert per_frame.min() >= 15 and per_frame.max() <= 130
    disparity = d.obs_z[:, 0] - d.obs_z[:, 2]
    assert np.mean((disparity > 0) & (disparity < 5)) > 0.05  # far points: tiny disparity
    _assert_valid_store(d)


def test_presets_and_names():
    assert set(PRESETS) == {"tiny", "small", "course"}
    tiny = simulate_drive("tiny")
    assert tiny.name == "sim-tiny" and tiny.num_frames == 60 and 100 <= tiny.num_landmarks <= 150
    small = make_config("small")
    assert small.num_frames == 300 and small.num_landmarks == 1000


def test_large_drive_scale():
    d = simulate_drive("course", seed=2, num_frames=3026, num_landmarks=13_000)
    assert d.num_frames == 3026 and d.num_landmarks > 12_000


# ------------------------------------------------------------------ config and rig


def test_config_errors_name_the_problem():
    with pytest.raises(ValueError, match="unknown preset"):
        make_config("huge")
    with pytest.raises(ValueError, match="pixel_sgima"):
        make_config("tiny", pixel_sgima=1.0)
    with pytest.raises(ValueError, match="outlier_share"):
        simulate_drive("tiny", outlier_share=1.5)
    with pytest.raises(ValueError, match="num_frames"):
        make_config("tiny", num_frames=1)
    with pytest.raises(ValueError, match="outlier_kind"):
        make_config("tiny", outlier_kind="gaussian")
    with pytest.raises(ValueError, match="imu_lag"):
        make_config("tiny", imu_lag=0.5)
    with pytest.raises(ValueError, match=r"reported_imu_T_cam.*\(3, 3\)"):
        make_config("tiny", reported_imu_T_cam=np.eye(3))


def test_default_rig_looks_forward():
    K, b, imu_T_cam = default_rig()
    R = imu_T_cam[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert R[:, 2] @ [1, 0, 0] > 0.999   # camera z = IMU x (forward)
    assert R[:, 0] @ [0, -1, 0] > 0.999  # camera x = -IMU y (right)
    assert R[:, 1] @ [0, 0, -1] > 0.999  # camera y = -IMU z (down)
    assert 0.5 < np.degrees(np.arccos((np.trace(R @ np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]])) - 1) / 2)) < 2
    assert b == 0.6 and K[0, 0] == K[1, 1]


def test_calibration_overrides_are_used():
    K, b, imu_T_cam = default_rig()
    other = imu_T_cam.copy()
    other[:3, 3] = [1.0, 0.1, 0.3]
    d = simulate_drive("tiny", b=0.5, imu_T_cam=other, **NOISE_FREE)
    assert d.b == 0.5
    np.testing.assert_array_equal(d.imu_T_cam, other)
    np.testing.assert_allclose(d.obs_z, _predicted(d), atol=1e-9)


# ------------------------------------------------------------- reusable building blocks


def _straight_poses(T=80, step=1.2):
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, 0, 3] = step * np.arange(T)
    return poses


def test_place_landmarks_along_a_straight_road():
    config = SimulationConfig(far_share=0.2)
    poses = _straight_poses()
    landmarks, appear = place_landmarks(poses, 2000, config, np.random.default_rng(0))
    assert landmarks.shape == (2000, 3) and appear.shape == (2000,)
    assert appear.min() >= 0 and appear.max() < len(poses) - 1
    lateral, height = np.abs(landmarks[:, 1]), landmarks[:, 2] + config.imu_height
    roadside = ((lateral >= config.lateral_range[0]) & (lateral <= config.lateral_range[1])
                & (height >= config.height_range[0]) & (height <= config.height_range[1]))
    distance = np.linalg.norm(landmarks[:, :2] - poses[appear, :2, 3], axis=1)  # horizontal
    far = ((distance >= config.far_range[0]) & (distance <= config.far_range[1])
           & (height >= config.far_height_range[0]) & (height <= config.far_height_range[1]))
    assert np.all(roadside | far)
    assert np.all(landmarks[:, 0] > poses[appear, 0, 3])  # ahead of their anchor pose
    assert 0.1 < np.mean(~roadside) < 0.3  # far points exist


def test_simulate_tracks_on_a_given_trajectory():
    config = make_config("tiny", **NOISE_FREE)
    poses = _straight_poses()
    rng = np.random.default_rng(1)
    landmarks, appear = place_landmarks(poses, 300, config, rng)
    K, b, imu_T_cam = default_rig()
    tracks = simulate_tracks(poses, landmarks, K, b, imu_T_cam, config, rng, appear=appear,
                             max_landmarks=100)
    assert len(tracks.landmarks) <= 100
    np.testing.assert_array_equal(tracks.landmarks, landmarks[tracks.source_index])
    cam = StereoCamera(K, b, imu_T_cam)
    for t in range(len(poses)):
        lo, hi = tracks.frame_ptr[t], tracks.frame_ptr[t + 1]
        ids = tracks.obs_ids[lo:hi]
        np.testing.assert_allclose(tracks.obs_z[lo:hi], cam.predict(poses[t], tracks.landmarks[ids]),
                                   atol=1e-9)
        # A track cannot start before its landmark's appearance frame.
        assert np.all(appear[tracks.source_index[ids]] <= t)


# ------------------------------------------------------------------------- stand-in


def test_standin_matches_the_real_drive(standin, standin_paths):
    d = standin
    imu_path, calib_path = standin_paths
    with np.load(imu_path) as f:
        stamps, v, w = f["time_stamps"], f["linear_velocity"], f["angular_velocity"]
    with np.load(calib_path) as f:
        K, b, imu_T_cam = f["K"], f["b"], f["imu_T_cam"]
    assert d.name == "10-standin" and d.label == STANDIN_LABEL
    assert "STAND-IN" in d.label and "not available" in d.label
    assert d.num_frames == 3026
    np.testing.assert_array_equal(d.time_stamps, stamps.ravel())
    np.testing.assert_array_equal(d.ground_truth.linear_velocity, v.T)
    bias = np.array(d.extra["level_gyro_bias"])
    np.testing.assert_allclose(d.ground_truth.angular_velocity + bias, w.T, atol=1e-15)
    assert bias[2] == 0 and np.allclose(bias[:2], w[:2].mean(axis=1))
    np.testing.assert_array_equal(d.K, K)
    np.testing.assert_array_equal(d.imu_T_cam, imu_T_cam)
    assert d.b == float(b)
    assert 12_000 <= d.num_landmarks <= 13_000
    per_frame = np.diff(d.frame_ptr)
    assert 40 <= per_frame.mean() <= 90 and per_frame.max() <= 130
    _assert_valid_store(d)


def test_standin_ground_truth_and_noise(standin):
    d = standin
    g = d.ground_truth
    np.testing.assert_allclose(
        g.world_T_imu, dead_reckon(d.time_stamps, np.hstack([g.linear_velocity, g.angular_velocity])), atol=1e-12)
    np.testing.assert_allclose((d.linear_velocity - g.linear_velocity).std(), 0.2, rtol=0.05)
    gyro_error = d.angular_velocity - g.angular_velocity
    np.testing.assert_allclose(gyro_error.mean(axis=0), d.extra["level_gyro_bias"], atol=3e-4)
    np.testing.assert_allclose((gyro_error - gyro_error.mean(axis=0)).std(), 0.02, rtol=0.05)
    sample = slice(0, None, 50)
    residual = (d.obs_z - _predicted(d))[sample][~g.outlier[d.obs_ids][sample]]
    assert np.median(np.abs(residual)) < 1.5


def test_standin_extrinsic_override(standin_paths):
    _, _, imu_T_cam = default_rig()
    d = standin_dataset10(*standin_paths, seed=1, imu_T_cam=imu_T_cam, num_landmarks=500, **NOISE_FREE)
    np.testing.assert_array_equal(d.imu_T_cam, imu_T_cam)
    assert "given by the caller" in d.source
    np.testing.assert_allclose(d.obs_z, _predicted(d), atol=1e-9)


def _fake_inputs(tmp_path, T=120):
    """A small synthetic IMU-only file and calibration file (not course data)."""
    d = simulate_drive("tiny", seed=9, num_frames=T)
    imu = tmp_path / "imu_only.npz"
    np.savez(imu, time_stamps=d.time_stamps[None], linear_velocity=d.ground_truth.linear_velocity.T,
             angular_velocity=d.ground_truth.angular_velocity.T)
    calib = tmp_path / "calib.npz"
    K, b, imu_T_cam = default_rig()
    np.savez(calib, K=K, b=np.float64(b), imu_T_cam=imu_T_cam)
    return imu, calib, d


def test_standin_pipeline_on_synthetic_files(tmp_path):
    imu, calib, drive = _fake_inputs(tmp_path)
    d = standin_dataset10(imu, calib, seed=0, num_landmarks=300)
    assert d.name == "10-standin" and d.label == STANDIN_LABEL
    np.testing.assert_array_equal(d.time_stamps, drive.time_stamps)
    bias = np.array(d.extra["level_gyro_bias"])
    g = drive.ground_truth
    expected = dead_reckon(drive.time_stamps, np.hstack([g.linear_velocity, g.angular_velocity - bias]))
    np.testing.assert_allclose(d.ground_truth.world_T_imu, expected, atol=1e-12)
    assert 250 <= d.num_landmarks <= 300
    _assert_valid_store(d)


def test_course_standin_takes_a_seed_and_harder_settings_and_keeps_the_file_calibration(tmp_path):
    imu, _, drive = _fake_inputs(tmp_path)
    imu.rename(tmp_path / "10_imu_only.npz")
    save_course_file(drive, tmp_path / "03.npz")
    d = course_standin10(tmp_path, seed=3, num_landmarks=300, outlier_share=0.05, imu_lag=1)
    config = d.extra["config"]
    assert (d.extra["seed"], config.outlier_share, config.imu_lag, d.label) == (3, 0.05, 1, STANDIN_LABEL)
    np.testing.assert_array_equal(d.imu_T_cam, drive.imu_T_cam)
    assert d.extra["simulated_imu_T_cam"].shape == (4, 4)
    assert d.ground_truth.outlier.any()


def test_course_standin_source_says_which_extrinsic_simulated_its_tracks(tmp_path):
    """Not the internal "given by the caller": the user never gave one."""
    imu, _, drive = _fake_inputs(tmp_path)
    imu.rename(tmp_path / "10_imu_only.npz")
    save_course_file(drive, tmp_path / "03.npz")
    d = course_standin10(tmp_path, seed=0, num_landmarks=100)
    assert "03's corrected imu_T_cam (the physical rig" in d.source and "given by the caller" not in d.source


def test_course_standin_errors_name_the_missing_file_and_the_fixed_extrinsic(tmp_path):
    with pytest.raises(FileNotFoundError, match="course_standin10: 10_imu_only.npz and 03.npz not in"):
        course_standin10(tmp_path)
    with pytest.raises(ValueError, match="imu_T_cam is the physical rig's"):
        course_standin10(tmp_path, imu_T_cam=np.eye(4))


def test_standin_input_errors(tmp_path):
    imu_path, calib_path, _ = _fake_inputs(tmp_path, T=20)
    with pytest.raises(FileNotFoundError, match="nowhere.npz"):
        standin_dataset10(tmp_path / "nowhere.npz", calib_path)
    with pytest.raises(FileNotFoundError, match="missing_calib.npz"):
        standin_dataset10(imu_path, tmp_path / "missing_calib.npz")
    partial = tmp_path / "partial.npz"
    np.savez(partial, time_stamps=np.arange(5.0)[None], linear_velocity=np.zeros((3, 5)))
    with pytest.raises(ValueError, match="partial.npz.*angular_velocity"):
        standin_dataset10(partial, calib_path)
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, time_stamps=np.arange(5.0)[None], linear_velocity=np.zeros((3, 4)),
             angular_velocity=np.zeros((3, 5)))
    with pytest.raises(ValueError, match="linear_velocity.*\\(3, 5\\)"):
        standin_dataset10(wrong, calib_path)
    no_k = tmp_path / "no_k.npz"
    np.savez(no_k, b=0.5, imu_T_cam=np.eye(4))
    with pytest.raises(ValueError, match="no_k.npz.*'K'"):
        standin_dataset10(imu_path, no_k)
    no_extrinsic = tmp_path / "no_extrinsic.npz"
    K, b, imu_T_cam = default_rig()
    np.savez(no_extrinsic, K=K, b=b)
    with pytest.raises(ValueError, match="imu_T_cam"):
        standin_dataset10(imu_path, no_extrinsic)
    standin_dataset10(imu_path, no_extrinsic, imu_T_cam=imu_T_cam, num_landmarks=20)  # not needed then
    not_npz = tmp_path / "text.npz"
    not_npz.write_text("not an archive")
    with pytest.raises(ValueError, match="text.npz"):
        standin_dataset10(not_npz, calib_path)
    with pytest.raises(ValueError, match="num_frames"):
        standin_dataset10(imu_path, calib_path, num_frames=10)


def test_standin_calibration_is_checked_like_a_course_file(tmp_path):
    imu_path, _, _ = _fake_inputs(tmp_path, T=20)
    K, b, imu_T_cam = default_rig()
    cases = {
        "lower_K": (dict(K=K + np.tril(np.ones((3, 3)), -1), b=b, imu_T_cam=imu_T_cam), "'K' must be upper triangular"),
        "reflection": (dict(K=K, b=b, imu_T_cam=imu_T_cam @ np.diag([-1.0, 1, 1, 1])), "'imu_T_cam' is not a rigid"),
        "string_b": (dict(K=K, b="0.6", imu_T_cam=imu_T_cam), "'b' must hold real numbers"),
        "zero_b": (dict(K=K, b=0.0, imu_T_cam=imu_T_cam), "'b' .* must be positive"),
    }
    for name, (arrays, message) in cases.items():
        np.savez(tmp_path / f"{name}.npz", **arrays)
        with pytest.raises(ValueError, match=f"{name}.npz: key {message}"):
            standin_dataset10(imu_path, tmp_path / f"{name}.npz")
    np.savez(tmp_path / "b_as_vector.npz", K=K, b=[b], imu_T_cam=imu_T_cam)  # accepted, as before
    d = standin_dataset10(imu_path, tmp_path / "b_as_vector.npz", num_landmarks=20)
    assert d.b == b


def test_simulate_along_drive_checks_the_drive():
    config, rig = make_config("tiny"), default_rig()
    t, v = np.arange(5) * 0.1, np.zeros((5, 3))
    with pytest.raises(ValueError, match=r"angular_velocity must be finite with shape \(5, 3\)"):
        simulate_along_drive(t, v, np.zeros((4, 3)), config, rig, name="x", source="test")
    with pytest.raises(ValueError, match="time_stamps must be strictly increasing"):
        simulate_along_drive(t[::-1], v, v, config, rig, name="x", source="test")
