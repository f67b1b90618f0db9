"""The command line as a user types it: info, run (with --out/--plot/--set), errors."""

import re
import subprocess
import sys

import numpy as np
import pytest

from visla_edu import cli, run


def test_run_writes_result_and_figure(tmp_path, capsys):
    out, fig = tmp_path / "r.npz", tmp_path / "r.png"
    assert cli.main(["run", "sim-tiny", "--mode", "slam", "--out", str(out), "--plot", str(fig), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "mode slam" in text and "ATE against ground truth" in text
    result = run.load_result(out)
    assert result.world_T_imu.shape == (60, 4, 4) and result.mode == "slam"
    np.testing.assert_allclose(result.world_T_imu[0], np.eye(4))
    assert fig.stat().st_size > 10_000  # a real PNG, not an empty file


def test_run_settings_reach_the_filter(tmp_path):
    out = tmp_path / "r.npz"
    argv = ["run", "sim-tiny", "--mode", "mapping", "--set", "sigma_pixel=2.5", "--landmark-stride", "2",
            "--out", str(out), "--quiet"]
    assert cli.main(argv) == 0
    result = run.load_result(out)
    assert result.config["sigma_pixel"] == 2.5 and result.config["landmark_stride"] == 2
    assert np.isnan(result.landmarks[1::2, 0]).all()  # odd landmarks skipped by the stride


def test_bad_setting_names_the_problem():
    with pytest.raises(SystemExit, match="sigma_pxl"):
        cli.main(["run", "sim-tiny", "--set", "sigma_pxl=2"])
    with pytest.raises(SystemExit, match="needs a float"):
        cli.main(["run", "sim-tiny", "--set", "sigma_pixel=big"])



def test_smoother_settings_reach_the_smoother_and_the_result_file(tmp_path, capsys):
    out = tmp_path / "r.npz"
    argv = ["run", "sim-tiny", "--mode", "window", "--smoother-set", "window_size=5", "--smoother-set",
            "loss=Huber", "--out", str(out), "--quiet"]
    assert cli.main(argv) == 0
    result = run.load_result(out)
    assert result.config["smoother_window_size"] == 5 and result.config["smoother_loss"] == "huber"


@pytest.mark.parametrize("argv, message", [
    (["--mode", "slam", "--smoother-set", "window_size=5"], "smoother settings need --mode smooth or window"),
    (["--mode", "window", "--smoother-set", "window_size=5", "--smoother-set", "window_size=6"],
     "window_size is given twice"),
    (["--mode", "smooth", "--smoother-set", "window_size=5"], "window_size: mode smooth does not use it"),
])
def test_smoother_settings_are_refused_where_they_cannot_apply(argv, message, capsys):
    assert cli.main(["run", "sim-tiny", *argv, "--quiet"]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("value, message", [
    ("window_size=1", "window_size must be an integer >= 2"),
    ("window_size=big", "window_size needs an int (an integer >= 2"),
    ("sigma_pixel=2", "comes from the filter's settings: use --set"),
    ("imu_lag=1", "comes from the filter's settings: use --set imu_lag=VALUE"),
    ("min_disparity=5", "use --set min_init_disparity=VALUE"),
    ("windowsize=5", "'windowsize' is not a smoother setting"),
    ("blas_threads=2", "'blas_threads' is not a smoother setting"),
    ("window_size", "expected NAME=VALUE; the smoother's settings are loss, loss_scale"),
])
def test_a_bad_smoother_setting_is_an_argparse_error(value, message, capsys):
    with pytest.raises(SystemExit):
        cli.main(["run", "sim-tiny", "--mode", "window", "--smoother-set", value])
    assert message in capsys.readouterr().err

@pytest.mark.parametrize("value", ["none", "None", "2"])
def test_blas_threads_option(value, capsys):
    assert cli.main(["run", "sim-tiny", "--mode", "deadreckon", "--blas-threads", value, "--quiet"]) == 0
    assert "mode deadreckon" in capsys.readouterr().out


@pytest.mark.parametrize("value", ["0", "-1", "two"])
def test_bad_blas_threads_names_the_option(value, capsys):
    with pytest.raises(SystemExit):
        cli.main(["run", "sim-tiny", "--blas-threads", value])
    err = capsys.readouterr().err
    assert "--blas-threads" in err and "positive integer or 'none'" in err


@pytest.mark.parametrize("option", ["--out", "--plot", "--trajectory-out", "--ground-truth", "--data-dir"])
def test_an_empty_path_is_refused_not_ignored(option, capsys):
    with pytest.raises(SystemExit):
        cli.main(["run", "sim-tiny", "--quiet", option, ""])
    err = capsys.readouterr().err
    assert f"argument {option}: empty path" in err and len(err.strip().splitlines()) == 1


_NO_USER = "~visla-edu-no-such-user-4711"


@pytest.mark.parametrize("argv, env", [
    (["run", "sim-tiny", "--out", f"{_NO_USER}/r.npz"], {}),
    (["run", "sim-tiny", "--plot", f"{_NO_USER}/r.png"], {}),
    (["run", "sim-tiny", "--trajectory-out", f"{_NO_USER}/r.tum"], {}),
    (["run", "sim-tiny", "--ground-truth", f"{_NO_USER}/poses.txt"], {}),
    (["info", f"{_NO_USER}/drive.npz"], {}),
    (["info", "03", "--data-dir", _NO_USER], {}),
    (["info", "03"], {"VISLA_EDU_DATA": f"{_NO_USER}/data"}),
], ids=["out", "plot", "trajectory-out", "ground-truth", "dataset", "data-dir", "VISLA_EDU_DATA"])
def test_a_path_of_an_unknown_user_is_bad_input_not_a_bug(argv, env, capsys, monkeypatch):
    """``~name/...`` of no such user: Path.expanduser's RuntimeError was reported as an internal error (exit 3)."""
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert cli.main([*argv, "--quiet"] if argv[0] == "run" else [*argv, "--no-diagnostics"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"cannot expand '{_NO_USER}': no such user or home folder on this system; give the full path" in err


def test_a_result_file_given_as_the_dataset_is_named_as_such(tmp_path, capsys):
    """It was 'looks like the 2021+ course format but is missing key(s) [...]' and 40 keys."""
    out = tmp_path / "r.npz"
    assert cli.main(["run", "sim-tiny", "--mode", "deadreckon", "--quiet", "--out", str(out)]) == 0
    capsys.readouterr()
    for command in (["info", str(out), "--no-diagnostics"], ["run", str(out), "--quiet"]):
        assert cli.main(command) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "course format" not in err
        assert f"{out}: is a result file of 'visla-edu run --out'" in err and "run.load_result" in err


def test_missing_dataset_is_a_clear_error(tmp_path, capsys):
    assert cli.main(["info", "03", "--data-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "03" in err and "VISLA_EDU_DATA" in err


def test_info_prints_summary_and_diagnostics(capsys):
    assert cli.main(["info", "sim-small"]) == 0
    text = capsys.readouterr().out
    for word in ("frames", "landmarks", "disparity", "extrinsic check", "time alignment", "gyro bias"):
        assert word in text


def _help(capsys, *command):
    with pytest.raises(SystemExit) as exit_info:
        cli.main([*command, "--help"])
    assert exit_info.value.code == 0
    return " ".join(capsys.readouterr().out.split())  # argparse's line breaks undone


def test_run_help_names_every_mode_and_every_setting_with_its_default(capsys):
    """What the README and the error lines ("see visla-edu run --help") send a user to."""
    import dataclasses

    from visla_edu import smoother
    from visla_edu.codes import RUN_MODES
    from visla_edu.filters import FilterConfig

    def shown(value):  # as --set would take it
        if isinstance(value, bool):
            return str(value).lower()
        return f"{value:g}" if isinstance(value, (int, float)) else str(value)

    text = _help(capsys, "run")
    for mode in RUN_MODES:
        assert f"{mode} (" in text, mode
    assert "slam (joint EKF, the default)" in text and cli.build_parser().parse_args(["run", "x"]).mode == "slam"
    filter_defaults, smoother_defaults = FilterConfig(), smoother.SmootherConfig()
    for name in [field.name for field in dataclasses.fields(FilterConfig)]:
        assert f"{name}={shown(getattr(filter_defaults, name))}" in text, name
    for name in smoother.OWN_SETTINGS:
        assert f"{name}={shown(getattr(smoother_defaults, name))}" in text, name
    assert "every N-th landmark only (default 1" in text


def test_run_help_says_what_each_setting_accepts_and_which_mode_reads_it(capsys):
    """Each setting's line of the epilog: its default, then its declaration's description."""
    from visla_edu import settings, smoother
    from visla_edu.filters import FilterConfig

    with pytest.raises(SystemExit):
        cli.main(["run", "--help"])
    lines = capsys.readouterr().out.splitlines()
    own = {name: spec for name, spec in settings.specs(smoother.SmootherConfig).items() if name in smoother.OWN_SETTINGS}
    for name, spec in [*settings.specs(FilterConfig).items(), *own.items()]:
        line = next(line for line in lines if line.startswith(f"  {name}="))
        assert line.split()[0] == f"{name}={settings.format_value(spec.default)}", line
        assert spec.describe() in line, line
        assert ("(window only)" in line) == (name in smoother.WINDOW_ONLY), line
        assert ("(smooth only)" in line) == (name in smoother.BATCH_ONLY), line


def test_stepper_help_states_the_default_port(capsys):
    assert "(default 8866)" in _help(capsys, "stepper")
    assert cli.build_parser().parse_args(["stepper"]).port == 8866


def test_python_dash_m_works():
    done = subprocess.run([sys.executable, "-m", "visla_edu", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "info" in done.stdout and "run" in done.stdout


# ----------------------------------------------------------------------------- ground truth, trajectories


@pytest.fixture(scope="module")
def real_like_drive(tmp_path_factory):
    """A small simulated drive saved WITHOUT its truth, plus that truth as KITTI poses and times."""
    import dataclasses

    from visla_edu import data, simulate, trajectory

    folder = tmp_path_factory.mktemp("drive")
    ds = simulate.simulate_drive("tiny", seed=3)
    path = data.save(dataclasses.replace(ds, name="drive", label="", ground_truth=None), folder / "drive.npz")
    cam0_T_cam = data.kitti_poses_from_imu(ds.ground_truth.world_T_imu[:55], ds.imu_T_cam)
    poses = trajectory.write_kitti(folder / "poses.txt", cam0_T_cam)
    times = folder / "times.txt"
    np.savetxt(times, ds.time_stamps[:55] - ds.time_stamps[0], fmt="%e")
    return path, poses, times, ds


def test_run_with_ground_truth_prints_saves_and_exports(real_like_drive, tmp_path, capsys):
    from visla_edu import metrics, trajectory

    path, poses, times, ds = real_like_drive
    out, tum = tmp_path / "r.npz", tmp_path / "slam.tum"
    argv = ["run", str(path), "--ground-truth", str(poses), "--ground-truth-times", str(times), "--out", str(out),
            "--trajectory-out", str(tum), "--quiet"]
    assert cli.main(argv) == 0
    text = capsys.readouterr().out
    assert "ATE against ground truth (poses.txt, 55 frames)" in text
    assert "slam estimate" in text and "dead reckoning" in text and text.count("drift unavailable") == 2
    result = run.load_result(out)
    truth = ds.ground_truth.world_T_imu[:55]
    assert result.evaluation["estimate_ate_raw"] == pytest.approx(metrics.ate(result.world_T_imu[:55], truth, False))
    assert result.evaluation["dead_reckoning_ate_aligned"] == pytest.approx(
        metrics.ate(result.dead_reckoning[:55], truth, True))
    assert result.evaluation["estimate_frames"] == 55 and result.evaluation["ground_truth_source"] == str(poses)
    assert f"{result.evaluation['estimate_ate_raw']:.3f} m raw" in text
    times_read, exported = trajectory.read_tum(tum)
    np.testing.assert_array_equal(times_read, result.time_stamps)
    np.testing.assert_allclose(exported, result.world_T_imu, atol=1e-12)


def test_trajectory_out_in_kitti_format(real_like_drive, tmp_path):
    from visla_edu import trajectory

    path, _, _, _ = real_like_drive
    assert cli.main(["run", str(path), "--mode", "deadreckon", "--trajectory-out", str(tmp_path / "dr.kitti"),
                     "--out", str(tmp_path / "r.npz"), "--quiet"]) == 0
    poses, _ = trajectory.read_kitti(tmp_path / "dr.kitti")
    np.testing.assert_array_equal(poses, run.load_result(tmp_path / "r.npz").world_T_imu)


@pytest.mark.parametrize("extra, message", [
    (["--trajectory-out", "est.csv"], "unknown trajectory format '.csv'"),
    (["--ground-truth-times", "times.txt"], "--ground-truth-times times.txt needs --ground-truth"),
    (["--ground-truth", "missing_poses.txt"], "missing_poses.txt: KITTI poses.* file not found"),
])
def test_ground_truth_and_trajectory_errors_come_before_the_run(real_like_drive, capsys, extra, message):
    path, _, _, _ = real_like_drive
    assert cli.main(["run", str(path), "--quiet", *extra]) == 2
    captured = capsys.readouterr()
    assert re.search(message, captured.err) and "mode slam" not in captured.out


def test_a_registered_ground_truth_beside_a_renamed_drive_is_never_overwritten(real_like_drive, tmp_path, capsys):
    """0020 copied as drive20.npz still reads kitti_odometry_06_poses.txt (it is known by its content)."""
    import shutil

    from visla_edu import data

    path, poses, _, _ = real_like_drive
    drive = shutil.copy(path, tmp_path / "drive20.npz")
    truth = tmp_path / "kitti_odometry_06_poses.txt"
    shutil.copy(poses, truth)
    before = truth.read_bytes()
    assert truth in data.input_files(str(drive))
    assert cli.main(["run", str(drive), "--mode", "deadreckon", "--quiet", "--trajectory-out", str(truth)]) == 2
    assert "is the input file" in capsys.readouterr().err and truth.read_bytes() == before


@pytest.mark.data
def test_info_and_run_0020_with_its_ground_truth(require_data, capsys):
    path = require_data("0020")
    if not (path.parent / "kitti_odometry_06_poses.txt").is_file():
        pytest.skip("kitti_odometry_06_poses.txt not found beside 0020.npz")
    assert cli.main(["info", "0020", "--data-dir", str(path.parent), "--no-diagnostics"]) == 0
    assert "ground truth  attached: KITTI poses of frames 0-1100, 1101 of 1104 frames" in capsys.readouterr().out
    assert cli.main(["run", "0020", "--data-dir", str(path.parent), "--mode", "deadreckon", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "ATE against ground truth (kitti_odometry_06_poses.txt, 1101 frames)" in text
    assert "first 1101 of 1104 frames" in text and "segments of 100-800 m" in text


# ----------------------------------------------------------------------------- --frames


def test_frames_runs_a_segment_against_its_own_ground_truth(real_like_drive, tmp_path, capsys):
    from visla_edu import lie, metrics

    path, poses, times, ds = real_like_drive
    out = tmp_path / "r.npz"
    argv = ["run", str(path), "--ground-truth", str(poses), "--ground-truth-times", str(times),
            "--frames", "20:45", "--mode", "deadreckon", "--out", str(out), "--quiet"]
    assert cli.main(argv) == 0
    text = capsys.readouterr().out
    assert "frames 20..44 of" in text and "ATE against ground truth (poses.txt, 25 frames)" in text
    result = run.load_result(out)
    assert result.name == "drive[20:45]" and result.world_T_imu.shape == (25, 4, 4)
    np.testing.assert_array_equal(result.time_stamps, ds.time_stamps[20:45])
    truth = lie.se3_inv(ds.ground_truth.world_T_imu[20]) @ ds.ground_truth.world_T_imu[20:45]
    assert result.evaluation["estimate_ate_raw"] == pytest.approx(metrics.ate(result.world_T_imu, truth, False))


@pytest.mark.parametrize("value, kept", [("56:60", 0), ("53:60", 2), ("20:22", 2)])
def test_frames_past_the_given_ground_truth_are_refused_before_the_run(real_like_drive, value, kept, capsys):
    """--ground-truth with --frames where it keeps fewer than 3 poses: no silent drop, no ATE of 1-2 poses."""
    path, poses, _, _ = real_like_drive
    argv = ["run", str(path), "--ground-truth", str(poses), "--frames", value, "--mode", "deadreckon", "--quiet"]
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert "mode deadreckon" not in captured.out  # refused before the run
    err = captured.err.strip()
    assert len(err.splitlines()) == 1
    assert f"--frames {value}: --ground-truth {poses}: the ground truth (poses.txt) covers frames 0..54" in err
    assert f"keep {kept} of its poses and an ATE needs at least 3; give START <= 52" in err


def test_frames_keeping_too_little_automatic_ground_truth_run_without_it(capsys):
    assert cli.main(["run", "sim-tiny", "--frames", "0:2", "--mode", "deadreckon", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "note: --frames 0:2: the ground truth (simulated) covers frames 0..59, so frames 0..1 keep 2" in out
    assert "running without ground truth (no ATE)" in out and "ATE against" not in out


def test_frames_open_ends_and_info(capsys):
    assert cli.main(["run", "sim-tiny", "--frames", "50:", "--mode", "deadreckon", "--quiet"]) == 0
    assert "sim-tiny[50:60]: mode deadreckon, 10 frames" in capsys.readouterr().out
    assert cli.main(["info", "sim-tiny", "--frames", ":20", "--no-diagnostics"]) == 0
    assert "sim-tiny[0:20]: frames 0..19 of" in capsys.readouterr().out


@pytest.mark.parametrize("value", ["3", "a:b", "-1:5", "1:2:3"])
def test_a_malformed_frames_option_is_an_argparse_error(value, capsys):
    with pytest.raises(SystemExit):
        cli.main(["run", "sim-tiny", "--quiet", f"--frames={value}"])
    err = capsys.readouterr().err
    assert "argument --frames: expected START:STOP" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("value", ["58:70", "30:31", "40:20"])
def test_frames_outside_the_drive_are_refused_before_the_run(value, capsys):
    assert cli.main(["run", "sim-tiny", "--quiet", "--frames", value]) == 2
    err = capsys.readouterr().err.strip()
    assert f"--frames {value}: sim-tiny has frames 0..59" in err and len(err.splitlines()) == 1
