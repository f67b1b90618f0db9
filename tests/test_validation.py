"""Tests of visla_edu.validation, the one home of the calibration and rigidity checks: each check
refuses what it names, and every caller (camera, loaders, metrics, trajectory files) gets the
same verdict from it."""

import numpy as np
import pytest

from visla_edu import camera, lie, metrics, validation

K = np.array([[552.5, 0.0, 682.0], [0.0, 552.5, 238.8], [0.0, 0.0, 1.0]])


def test_nonrigid_frames_flags_each_way_a_pose_leaves_se3():
    rng = np.random.default_rng(3)
    poses = lie.se3_exp(rng.normal(size=(5, 6)))
    poses[1, :3, :3] *= 1.01                      # not orthonormal
    poses[2, :3, 0] *= -1                         # a reflection (det -1, still orthonormal)
    poses[3, 3, 3] = 1.01                         # last row
    poses[4, :3, :3] += 1e-4                      # within the tolerance
    bad, orthogonality = validation.nonrigid_frames(poses, 1e-3)
    assert bad.tolist() == [False, True, True, True, False]
    assert orthogonality[1] > 0.02 and orthogonality[0] < 1e-12


def test_an_exact_last_row_can_be_asked_for():
    pose = lie.se3_exp(np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3]))
    pose[3, 3] = 1 + 1e-9
    assert not validation.nonrigid_frames(pose[None], 1e-6)[0][0]
    assert validation.nonrigid_frames(pose[None], 1e-6, last_row_tolerance=0.0)[0][0]
    with pytest.raises(ValueError, match=r"^x: key 'T' is not a rigid transform: last row is .*expected \[0, 0, 0, 1\]"):
        validation.check_rigid(pose, "x: key 'T'")


@pytest.mark.parametrize("edit, message", [
    (lambda T: T[:3, :3].__imul__(1.0001), r"max \|R\^T R - I\| = 0.0002 > 1e-06; rounded entries\?"),
    (lambda T: T[:3, :3].__imul__(1.1), r"max \|R\^T R - I\| = 0.21 > 1e-06$"),
    (lambda T: T[:3, 0].__imul__(-1), r"det\(R\) = -1, expected \+1 \(a reflection\?\)"),
])
def test_check_rigid_says_what_is_wrong(edit, message):
    T = lie.se3_exp(np.array([0.5, 0.0, 0.1, 0.0, 0.3, 0.0]))
    validation.check_rigid(T, "x")  # rigid: no error
    edit(T)
    with pytest.raises(ValueError, match="^x is not a rigid transform: " + message):
        validation.check_rigid(T, "x")


def test_the_metrics_and_the_poses_check_name_the_same_frame():
    truth = lie.se3_exp(np.random.default_rng(0).normal(size=(6, 6)))
    poses = truth.copy()
    poses[4, :3, :3] *= 1.01
    with pytest.raises(ValueError, match=r"^gt: the pose of frame 4 is not a rigid transform \(max \|R\^T R - I\| = "
                                         r"0.0201, det R = 1.03, last row \[0.0, 0.0, 0.0, 1.0\]; expected "):
        validation.check_rigid_poses(poses, "gt: the pose")
    with pytest.raises(ValueError, match=r"the ground truth's pose of frame 4 is not a rigid transform \(max"):
        metrics.ate(truth, poses)


@pytest.mark.parametrize("edit, message", [
    (lambda K: K.__setitem__((1, 0), 3.0), r"must be upper triangular with K\[2, 2\] = 1"),
    (lambda K: K.__setitem__((2, 2), 2.0), r"must be upper triangular with K\[2, 2\] = 1"),
    (lambda K: K.__setitem__((0, 0), -1.0), r"needs positive focal lengths, got fsu = -1.0, fsv = 552.5"),
    (lambda K: K.__setitem__((0, 1), 2.5), r"has a skew K\[0, 1\] = 2.5, but the stereo camera model has none"),
    (lambda K: K.__setitem__((0, 2), np.nan), r"needs finite entries"),
])
def test_the_camera_and_the_loader_refuse_the_same_intrinsics_in_the_same_words(edit, message):
    bad = K.copy()
    edit(bad)
    with pytest.raises(ValueError, match=r"^stereo_matrix: K " + message):
        camera.stereo_matrix(bad, 0.6)
    with pytest.raises(ValueError, match=r"^f.npz: key 'K' " + message):
        validation.check_intrinsics(bad, "f.npz: key 'K'")
    np.testing.assert_array_equal(validation.check_intrinsics(K, "x"), K)


@pytest.mark.parametrize("b, message", [(0.0, "must be positive, got 0.0"), (-0.5, "must be positive, got -0.5"),
                                        (np.inf, "must be a finite number, got inf"),
                                        (np.nan, "must be a finite number, got nan")])
def test_a_baseline_must_be_a_positive_number(b, message):
    with pytest.raises(ValueError, match=r"^triangulate_disparity: b \(stereo baseline, metres\) " + message):
        camera.triangulate_disparity(np.array([[700.0, 240.0, 650.0, 240.0]]), K, b)
    assert validation.check_baseline(np.array(0.6), "x") == 0.6


def test_plausible_calibration_names_the_key_and_the_fix():
    with pytest.raises(ValueError, match=r"^f: key 'b': the stereo baseline is 600 m, outside the plausible .* "
                                         r"It looks like millimetres: divide by 1000.$"):
        validation.check_plausible_calibration(K, 600.0, "f")
    pose = np.eye(4)
    pose[:3, 3] = [25.0, 0.0, 0.0]
    with pytest.raises(ValueError, match=r"^f: key 'cam_T_imu': the camera-IMU translation \|t\| is 25 m"):
        validation.check_plausible_calibration(K, 0.6, "f", pose, "cam_T_imu")
    validation.check_plausible_calibration(K, 0.6, "f", np.eye(4))


def test_magnitude_does_not_overflow():
    assert validation.magnitude([1e200, 1e200, 0.0]) == pytest.approx(np.sqrt(2) * 1e200)
    np.testing.assert_allclose(validation.magnitude(np.array([[3.0, 4.0, 12.0], [0.0, 0.0, 0.0]])), [13.0, 0.0])
