"""Ground truth of real drives: KITTI poses read, checked, converted, attached and drawn."""

import dataclasses

import numpy as np
import pytest

from visla_edu import data, lie, metrics, plotting, simulate, trajectory
from visla_edu.dataset import GroundTruth


@pytest.fixture(scope="module")
def tiny():
    """A 60-frame simulated drive with its ground truth."""
    return simulate.simulate_drive("tiny", seed=0)


def _write_kitti_truth(tmp_path, ds, frames=None, name="poses.txt", times=True):
    """The drive's true IMU poses as KITTI camera poses (and KITTI's %e times); their paths."""
    n = frames or ds.num_frames
    cam0_T_cam = data.kitti_poses_from_imu(ds.ground_truth.world_T_imu[:n], ds.imu_T_cam)
    poses = trajectory.write_kitti(tmp_path / name, cam0_T_cam)
    if not times:
        return poses, None
    times_path = tmp_path / f"times_{name}"
    np.savetxt(times_path, ds.time_stamps[:n] - ds.time_stamps[0], fmt="%e")  # KITTI's 7 digits
    return poses, times_path


# ----------------------------------------------------------------------------- conversion


def test_simulated_truth_through_kitti_camera_poses_and_back(tmp_path, tiny):
    poses, times = _write_kitti_truth(tmp_path, tiny)
    truth = data.load_ground_truth(tiny, poses, times)
    assert truth.num_frames == tiny.num_frames and not truth.simulated and truth.source == str(poses.resolve())
    np.testing.assert_allclose(truth.world_T_imu, tiny.ground_truth.world_T_imu, rtol=0, atol=1e-12)


def test_conversion_is_the_stated_formula(tiny):
    rng = np.random.default_rng(3)
    world_T_imu = lie.se3_exp(rng.standard_normal((5, 6)))
    cam_T_imu = lie.se3_inv(tiny.imu_T_cam)
    P = data.kitti_poses_from_imu(world_T_imu, tiny.imu_T_cam)
    np.testing.assert_allclose(lie.se3_inv(cam_T_imu) @ P @ cam_T_imu, world_T_imu, atol=1e-12)
    np.testing.assert_allclose(data.imu_poses_from_kitti(P, tiny.imu_T_cam), world_T_imu, atol=1e-12)
    # 1 m along the camera's optical axis z is 1 m along the IMU's forward axis x
    forward = np.eye(4)[None].copy()
    forward[0, 2, 3] = 1.0
    moved = data.imu_poses_from_kitti(forward, tiny.imu_T_cam)[0, :3, 3]
    np.testing.assert_allclose(moved, tiny.imu_T_cam[:3, 2], atol=1e-15)
    assert moved[0] > 0.99


def test_thirteen_column_file_and_fewer_poses_than_frames(tmp_path, tiny):
    cam0_T_cam = data.kitti_poses_from_imu(tiny.ground_truth.world_T_imu[:50], tiny.imu_T_cam)
    rows = np.column_stack([tiny.time_stamps[:50] - tiny.time_stamps[0], cam0_T_cam[:, :3].reshape(50, 12)])
    np.savetxt(tmp_path / "p13.txt", rows)
    truth = data.load_ground_truth(tiny, tmp_path / "p13.txt")
    assert truth.num_frames == 50
    np.testing.assert_allclose(truth.world_T_imu, tiny.ground_truth.world_T_imu[:50], atol=1e-12)
    est = tiny.ground_truth.world_T_imu.copy()
    est[50:, 0, 3] += 100.0  # frames the ground truth does not cover are not compared
    result = metrics.evaluate(est, truth.world_T_imu)
    assert (result.frames, result.total_frames) == (50, 60) and result.ate_raw < 1e-9


def test_attach_replaces_the_ground_truth_and_shares_the_arrays(tmp_path, tiny):
    poses, _ = _write_kitti_truth(tmp_path, tiny, frames=40, times=False)
    attached = data.attach_ground_truth(tiny, poses)
    assert attached.ground_truth.num_frames == 40 and attached.ground_truth.landmarks is None
    assert attached.obs_z is tiny.obs_z and tiny.ground_truth.num_frames == 60


# ----------------------------------------------------------------------------- bad input


def _kitti_rows(n=3):
    return np.tile(np.eye(4)[:3].ravel(), (n, 1)) + np.column_stack([np.zeros((n, 3)), np.arange(n), np.zeros((n, 8))])


@pytest.mark.parametrize("text, pattern", [
    ("", r"no rows: the file is empty"),
    ("1 0 0 0 0 1 0 0 0 0 1\n", r"line 1 has 11 numbers, expected 12 or 13"),
    ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0 5\n", r"line 2 has 13 numbers, expected 12 like line 1"),
    ("1 0 0 0 0 1 0 0 0 0 1 x\n", r"line 1, column 12: 'x' is not a number"),
    ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 nan 0 1 0 0 0 0 1 0\n", r"line 2, column 4: non-finite value nan"),
    ("1 0 0 0 0 1 0 0 0 0 1.01 0\n", r"line 1: rotation is not orthonormal .* 0.0201 > 0.001"),
    ("1 0 0 0 0 1 0 0 0 0 -1 0\n", r"line 1: rotation has determinant -1"),
    ("0.2 1 0 0 0 0 1 0 0 0 0 1 0\n0.1 1 0 0 0 0 1 0 0 0 0 1 0\n", r"line 2: time 0.1 does not increase"),
    ("1,0,0,0,0,1,0,0,0,0,1,0\n", r"line 1 has 1 numbers, expected 12 or 13 .*; separated by commas\? use spaces"),
])
def test_bad_pose_files_name_file_line_and_value(tmp_path, tiny, text, pattern):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(ValueError, match=pattern) as err:
        data.load_ground_truth(tiny, path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("scale, pattern", [
    (1000.0, r"frame 1 is 643.3\d* m from frame 0's.* at most 55.9\d* m .*looks like millimetres"),
    (1e200, r"frame 1 is 6.43\d*e\+199 m from frame 0's.* at most 55.9\d* m away"),
])
def test_poses_farther_than_the_drive_can_go_are_refused(tmp_path, tiny, scale, pattern):
    """Positions in millimetres, or so large that the ATE overflows to inf, are refused when read."""
    cam0_T_cam = data.kitti_poses_from_imu(tiny.ground_truth.world_T_imu, tiny.imu_T_cam)
    cam0_T_cam[:, :3, 3] *= scale
    path = trajectory.write_kitti(tmp_path / "poses.txt", cam0_T_cam)
    with pytest.raises(ValueError, match=pattern) as err:
        data.load_ground_truth(tiny, path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_missing_and_binary_files(tmp_path, tiny):
    with pytest.raises(FileNotFoundError, match="nothere.txt: KITTI poses.* file not found"):
        data.load_ground_truth(tiny, tmp_path / "nothere.txt")
    (tmp_path / "bin.txt").write_bytes(b"\x89PNG\x00\xff\xfe")
    with pytest.raises(ValueError, match="not a text file"):
        data.load_ground_truth(tiny, tmp_path / "bin.txt")


def test_a_sequence_longer_than_the_drive_gives_its_first_rows(tmp_path, tiny):
    """A course file that is the first part of a KITTI sequence (0042: 500 of 1101 frames) uses the first rows."""
    head = tiny.segment(0, 40)
    poses, times = _write_kitti_truth(tmp_path, tiny)  # 60 poses and times for a 40-frame drive
    for times_path in (times, None):
        truth = data.load_ground_truth(head, poses, times_path)
        assert truth.num_frames == 40 and truth.file_rows == 60 and truth.rows_text == "rows 0-39 of 60"
        np.testing.assert_allclose(truth.world_T_imu, head.ground_truth.world_T_imu, atol=1e-12)
    attached = data.attach_ground_truth(dataclasses.replace(head, ground_truth=None), poses, times)
    assert "KITTI poses of every frame (rows 0-39 of 60 of " in data.format_summary(attached)
    assert data.load_ground_truth(tiny, poses, times).rows_text == ""  # every row used: nothing to say


def test_a_longer_sequence_whose_times_differ_is_refused(tmp_path, tiny):
    """The times tell a sequence that starts with this drive from another drive's poses."""
    head = tiny.segment(0, 40)
    poses, times = _write_kitti_truth(tmp_path, tiny)
    shifted = np.loadtxt(times)
    shifted[5:] += 0.05
    np.savetxt(times, shifted, fmt="%e")
    with pytest.raises(ValueError, match=r"row 5 \(frame 5\) has time .*another drive"):
        data.load_ground_truth(head, poses, times)


@pytest.mark.parametrize("rows", [1, 2])
def test_too_few_poses_for_an_ate_is_an_error(tmp_path, tiny, rows):
    np.savetxt(tmp_path / "short.txt", _kitti_rows(rows))
    with pytest.raises(ValueError, match=rf"short.txt: {rows} pose\(s\); an ATE .* needs at least 3"):
        data.load_ground_truth(tiny, tmp_path / "short.txt")


@pytest.mark.parametrize("tolerance", [float("nan"), -1.0, float("inf")])
def test_a_times_tolerance_that_checks_nothing_is_refused(tmp_path, tiny, tolerance):
    poses, times = _write_kitti_truth(tmp_path, tiny)
    with pytest.raises(ValueError, match="tolerance must be a finite number of seconds >= 0"):
        data.load_ground_truth(tiny, poses, times, tolerance=tolerance)


def test_check_times_with_more_times_than_frames_names_both_counts():
    with pytest.raises(ValueError, match=r"x.txt: 70 times but the dataset has only 60 frames"):
        data.check_times(np.zeros(70), np.arange(60) * 0.1, "x.txt")


def test_times_are_checked_against_the_time_stamps(tmp_path, tiny):
    poses, times = _write_kitti_truth(tmp_path, tiny)
    relative = np.loadtxt(times)
    relative[17] += 0.002
    np.savetxt(times, relative, fmt="%e")
    with pytest.raises(ValueError, match=r"row 17 \(frame 17\) has time .* time_stamps\[17\] - time_stamps\[0\] is "
                                         r".* > 0.001 s"):
        data.load_ground_truth(tiny, poses, times)
    assert data.load_ground_truth(tiny, poses, times, tolerance=0.01).num_frames == 60
    np.savetxt(times, relative[:-1], fmt="%e")
    with pytest.raises(ValueError, match=r"59 times but .* has 60 poses"):
        data.load_ground_truth(tiny, poses, times)



def test_absolute_times_are_named_as_such(tmp_path, tiny):
    """Unix times (or any offset) that match once the first is subtracted: say so, not 'another drive'."""
    with pytest.raises(ValueError, match=r"x.txt: the times start at 1317384506.500000 s, not 0, .*\(subtract the "
                                         r"first time"):
        data.check_times(1317384506.5 + tiny.time_stamps - tiny.time_stamps[0], tiny.time_stamps, "x.txt")
    with pytest.raises(ValueError, match=r"row 3 \(frame 3\)"):  # not an offset: the row that differs
        data.check_times(np.r_[0, 0.1, 0.2, 0.9], np.arange(4) * 0.1, "x.txt")

# ----------------------------------------------------------------------------- registry


def test_registered_drive_finds_its_ground_truth_in_the_data_dir(tmp_path, tiny):
    drive = dataclasses.replace(tiny, name="0020", ground_truth=None)
    data.save(drive, tmp_path / "0020.npz")
    assert data.load("0020", data_dir=tmp_path).ground_truth is None  # no pose file: no ground truth
    assert "0020" in data.available(tmp_path)
    files = data.REGISTRY["0020"]["ground_truth"]
    _write_kitti_truth(tmp_path, tiny, frames=57, name=files["poses"])
    (tmp_path / f"times_{files['poses']}").rename(tmp_path / files["times"])
    loaded = data.load("0020", data_dir=tmp_path)
    assert loaded.ground_truth.num_frames == 57 and loaded.ground_truth.source.endswith(files["poses"])
    np.testing.assert_allclose(loaded.ground_truth.world_T_imu, tiny.ground_truth.world_T_imu[:57], atol=1e-12)
    assert "attached: KITTI poses of frames 0-56, 57 of 60 frames" in data.format_summary(loaded)
    assert data.load(tmp_path / "0020.npz").ground_truth.num_frames == 57  # by path too
    (tmp_path / "elsewhere").mkdir()
    data.save(loaded, tmp_path / "elsewhere" / "copy.npz")  # a real drive's poses are not written into the npz
    assert data.load(tmp_path / "elsewhere" / "copy.npz").ground_truth is None


def test_simulated_ground_truth_keeps_every_field(tiny):
    g = tiny.ground_truth
    assert g.simulated and g.num_frames == tiny.num_frames
    assert g.landmarks.shape == (tiny.num_landmarks, 3) and g.outlier.shape == (tiny.num_landmarks,)
    assert "yes (poses, landmarks, velocities, outliers)" in data.format_summary(tiny)


@pytest.mark.data
def test_course_drive_0020_has_its_kitti_ground_truth(require_data):
    path = require_data("0020")
    if not (path.parent / data.REGISTRY["0020"]["ground_truth"]["poses"]).is_file():
        pytest.skip("kitti_odometry_06_poses.txt not found beside 0020.npz")
    ds = data.load("0020", data_dir=path.parent)
    g = ds.ground_truth
    assert (ds.num_frames, g.num_frames) == (1104, 1101) and not g.simulated
    np.testing.assert_allclose(g.world_T_imu[0], np.eye(4), atol=1e-9)
    # the IMU (x forward) drives forward: dead reckoning with the next sample follows the truth
    from visla_edu import motion

    result = metrics.evaluate(motion.dead_reckon(ds.time_stamps, ds.twists, lag=1), g.world_T_imu)
    assert result.path_length == pytest.approx(1241, abs=5) and result.drift_segments > 500
    assert result.ate_raw < 15 and result.drift_translation < 4


@pytest.mark.data
def test_course_drive_0042_uses_the_first_rows_of_its_longer_sequence(require_data):
    """0042.npz is the first 500 frames of KITTI odometry 01; its poses file has all 1101 rows."""
    path = require_data("0042")
    if not (path.parent / data.REGISTRY["0042"]["ground_truth"]["poses"]).is_file():
        pytest.skip("kitti_odometry_01_poses.txt not found beside 0042.npz")
    ds = data.load("0042", data_dir=path.parent)
    g = ds.ground_truth
    assert (ds.num_frames, g.num_frames, g.file_rows) == (500, 500, 1101) and g.rows_text == "rows 0-499 of 1101"
    from visla_edu import motion

    result = metrics.evaluate(motion.dead_reckon(ds.time_stamps, ds.twists, lag=1), g.world_T_imu)
    assert result.path_length == pytest.approx(1171, abs=5) and result.ate_raw < 10


# ----------------------------------------------------------------------------- drawing


def test_ground_truth_is_drawn_unlike_estimate_dead_reckoning_and_landmarks(tiny):
    import matplotlib

    matplotlib.use("Agg")
    from visla_edu import run

    result = run.run_filter(tiny, "deadreckon", progress=False)
    result.mode = "slam"  # draw the dead-reckoning reference too
    truth = GroundTruth(world_T_imu=tiny.ground_truth.world_T_imu[:40])
    ax = plotting.plot_result(result, ground_truth=truth).axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}
    gt = lines["ground truth"]
    assert len(gt.get_xdata()) == 40
    styles = {label: (matplotlib.colors.to_hex(line.get_color()), line.get_linestyle())
              for label, line in lines.items() if not label.startswith("_")}
    assert len(set(styles.values())) == len(styles) == 3, styles  # estimate, dead reckoning, truth
    landmark_colors = {matplotlib.colors.to_hex(c) for c in ax.collections[0].get_facecolors()}
    assert styles["ground truth"][0] not in landmark_colors
    assert "ground truth" in [t.get_text() for t in ax.get_legend().get_texts()]
    matplotlib.pyplot.close("all")
