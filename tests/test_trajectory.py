"""Trajectory files (KITTI, TUM): round trips, bad input, atomic writes, and evo's ATE equals ours."""

import os

import numpy as np
import pytest

from visla_edu import lie, metrics, trajectory
from visla_edu._files import atomic_write


def _poses(n=30, seed=0):
    rng = np.random.default_rng(seed)
    steps = lie.se3_exp(np.column_stack([1 + 0.1 * rng.standard_normal((n, 3)), 0.1 * rng.standard_normal((n, 3))]))
    poses = np.empty((n, 4, 4))
    poses[0] = np.eye(4)
    for t in range(1, n):
        poses[t] = poses[t - 1] @ steps[t]
    return poses


def test_kitti_round_trip_is_exact(tmp_path):
    poses = _poses()
    path = trajectory.write_kitti(tmp_path / "est.kitti", poses)
    assert path == (tmp_path / "est.kitti").resolve() and len(path.read_text().splitlines()) == 30
    assert len(path.read_text().splitlines()[3].split()) == 12
    back, times = trajectory.read_kitti(path)
    assert times is None
    np.testing.assert_array_equal(back, poses)


def test_tum_round_trip(tmp_path):
    poses, times = _poses(), 1.3e9 + 0.1 * np.arange(30)
    path = trajectory.write_tum(tmp_path / "est.tum", times, poses)
    first = path.read_text().splitlines()[0].split()
    assert len(first) == 8 and float(first[0]) == times[0]
    read_times, back = trajectory.read_tum(path)
    np.testing.assert_array_equal(read_times, times)
    np.testing.assert_array_equal(back[:, :3, 3], poses[:, :3, 3])
    np.testing.assert_allclose(back, poses, atol=1e-14)
    quaternion = np.array(first[4:], dtype=float)  # scalar last, unit
    assert quaternion[3] == pytest.approx(1.0) and np.linalg.norm(quaternion) == pytest.approx(1.0)


@pytest.mark.parametrize("name, fmt", [("a.kitti", "kitti"), ("a.txt", "kitti"), ("A.TUM", "tum")])
def test_format_from_suffix_and_dispatch(tmp_path, name, fmt):
    assert trajectory.trajectory_format(name) == fmt
    poses, times = _poses(5), np.arange(5.0)
    trajectory.write_trajectory(tmp_path / name, times, poses)
    read_times, back = trajectory.read_trajectory(tmp_path / name)
    np.testing.assert_allclose(back, poses, atol=1e-14)
    assert (read_times is None) == (fmt == "kitti")


@pytest.mark.parametrize("name", ["a.csv", "a", "a.npz"])
def test_unknown_suffix_is_an_error(name):
    with pytest.raises(ValueError, match=r"unknown trajectory format .* use .kitti or .txt .* or .tum"):
        trajectory.trajectory_format(name)


@pytest.mark.parametrize("text, pattern", [
    ("# only a comment\n", "no rows: the file is empty"),
    ("0 0 0 0 0 0 0 1 9\n", r"line 1 has 9 numbers, expected 8"),
    ("0 0 0 0 0 0 0 2\n", r"line 1: quaternion .* has norm 2"),
    ("# t x y z qx qy qz qw\n1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", r"line 3: time 1.0 does not increase"),
])
def test_bad_tum_files(tmp_path, text, pattern):
    path = tmp_path / "bad.tum"
    path.write_text(text)
    with pytest.raises(ValueError, match=pattern):
        trajectory.read_tum(path)


def test_bad_poses_are_not_written(tmp_path):
    poses = _poses(5)
    poses[3, 1, 3] = np.inf
    with pytest.raises(ValueError, match="pose of frame 3 is not finite"):
        trajectory.write_kitti(tmp_path / "x.kitti", poses)
    with pytest.raises(ValueError, match=r"shape \(T, 4, 4\)"):
        trajectory.write_kitti(tmp_path / "x.kitti", np.eye(4))
    with pytest.raises(ValueError, match="5 finite numbers"):
        trajectory.write_tum(tmp_path / "x.tum", np.arange(4.0), _poses(5))
    assert not list(tmp_path.iterdir())


def test_atomic_write_keeps_the_old_file_when_the_block_fails(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old\n")
    with pytest.raises(RuntimeError):
        with atomic_write(path) as f:
            f.write("half")
            raise RuntimeError("interrupted")
    assert path.read_text() == "old\n" and os.listdir(tmp_path) == ["out.txt"]
    with atomic_write(path, "wb") as f:
        f.write(b"new\n")
    assert path.read_bytes() == b"new\n" and os.listdir(tmp_path) == ["out.txt"]
    with pytest.raises(FileNotFoundError, match="folder .*nowhere does not exist"):
        with atomic_write(tmp_path / "nowhere" / "x.txt"):
            pass
    with pytest.raises(ValueError, match="is a folder, not a file"):
        with atomic_write(tmp_path):
            pass


# ----------------------------------------------------------------------------- evo


def test_evo_computes_the_same_ate(tmp_path):
    pytest.importorskip("evo", reason="evo (the trajectory-evaluation package; dev extra) is not installed")
    from evo.core import metrics as evo_metrics
    from evo.tools import file_interface

    truth = _poses(200, seed=1)
    rng = np.random.default_rng(2)
    estimate = lie.se3_exp(np.concatenate([0.5 * rng.standard_normal(3), 0.05 * rng.standard_normal(3)])) @ truth
    estimate = estimate @ lie.se3_exp(0.05 * rng.standard_normal((200, 6)))
    times = 100.0 + 0.1 * np.arange(200)
    trajectory.write_tum(tmp_path / "truth.tum", times, truth)
    trajectory.write_tum(tmp_path / "est.tum", times, estimate)

    def evo_ate(align):
        ref = file_interface.read_tum_trajectory_file(str(tmp_path / "truth.tum"))
        est = file_interface.read_tum_trajectory_file(str(tmp_path / "est.tum"))
        if align:
            est.align(ref, correct_scale=False)
        ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
        ape.process_data((ref, est))
        return ape.get_statistic(evo_metrics.StatisticsType.rmse)

    raw, aligned = metrics.ate(estimate, truth, align=False), metrics.ate(estimate, truth, align=True)
    assert aligned < raw
    assert evo_ate(align=False) == pytest.approx(raw, rel=1e-9)
    assert evo_ate(align=True) == pytest.approx(aligned, rel=1e-9)
