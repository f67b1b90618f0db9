"""Dataset.segment: a stretch of frames as a drive of its own, its ground truth re-based."""

import dataclasses

import numpy as np
import pytest

from visla_edu import lie, metrics, motion
from visla_edu.dataset import GroundTruth
from visla_edu.simulate import simulate_drive


@pytest.fixture(scope="module")
def drive():
    return simulate_drive("tiny", 3, outlier_share=0.1)


def test_frames_observations_and_landmark_numbering(drive):
    seg = drive.segment(10, 25)
    assert seg.name == f"{drive.name}[10:25]" and seg.num_frames == 15
    assert np.array_equal(seg.time_stamps, drive.time_stamps[10:25])
    assert np.array_equal(seg.twists, drive.twists[10:25])
    seen = np.unique(drive.obs_ids[drive.frame_ptr[10]:drive.frame_ptr[25]])
    assert seg.num_landmarks == len(seen) < drive.num_landmarks
    for k in range(seg.num_frames):
        ids, z = seg.observations(k)
        ids_full, z_full = drive.observations(10 + k)
        assert np.array_equal(seen[ids], ids_full) and np.array_equal(z, z_full)
    assert np.all(seg.track_lengths() > 0)
    assert seg.extra == {}


def test_ground_truth_is_expressed_in_the_segments_first_frame(drive):
    seg = drive.segment(10, 25)
    truth, full = seg.ground_truth, drive.ground_truth
    assert np.allclose(truth.world_T_imu[0], np.eye(4), atol=1e-12)
    # relative motion is unchanged
    rel = lie.se3_inv(truth.world_T_imu[:-1]) @ truth.world_T_imu[1:]
    rel_full = lie.se3_inv(full.world_T_imu[10:24]) @ full.world_T_imu[11:25]
    assert np.allclose(rel, rel_full, atol=1e-12)
    # a landmark seen from a pose sits at the same place in that IMU frame
    seen = np.unique(drive.obs_ids[drive.frame_ptr[10]:drive.frame_ptr[25]])
    k, full_t = 7, 17
    in_imu = lie.se3_inv(truth.world_T_imu[k]) @ np.c_[truth.landmarks, np.ones(len(seen))].T
    in_imu_full = lie.se3_inv(full.world_T_imu[full_t]) @ np.c_[full.landmarks[seen], np.ones(len(seen))].T
    assert np.allclose(in_imu, in_imu_full, atol=1e-9)
    assert np.array_equal(truth.outlier, full.outlier[seen])
    assert np.array_equal(truth.linear_velocity, full.linear_velocity[10:25])


def test_a_noise_free_segment_dead_reckons_onto_its_ground_truth():
    clean = simulate_drive("tiny", 1, linear_velocity_sigma=0.0, angular_velocity_sigma=0.0)
    seg = clean.segment(20, 40)
    poses = motion.dead_reckon(seg.time_stamps, seg.twists)
    assert metrics.ate(poses, seg.ground_truth.world_T_imu, align=False) < 1e-6


def test_a_shorter_real_ground_truth_is_kept_where_it_exists(drive):
    short = dataclasses.replace(drive, ground_truth=GroundTruth(world_T_imu=drive.ground_truth.world_T_imu[:30]))
    assert short.segment(20, 40).ground_truth.num_frames == 10
    assert short.segment(30, 40).ground_truth is None
    assert dataclasses.replace(drive, ground_truth=None).segment(0, 5).ground_truth is None


@pytest.mark.parametrize("start, stop, words", [
    (-1, 10, "0 <= start"), (5, 6, "at least 2 frames"), (0, 10_000, "<= 60"),
    (2.0, 10, "start must be an integer"), (0, True, "stop must be an integer")])
def test_bad_bounds_are_refused_with_the_rule(drive, start, stop, words):
    assert drive.num_frames == 60
    with pytest.raises(ValueError, match=words):
        drive.segment(start, stop)
