"""The command line as a user types it: info, run (with --out/--plot/--set), errors."""

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


def test_missing_dataset_is_a_clear_error(tmp_path, capsys):
    assert cli.main(["info", "03", "--data-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "03" in err and "VISLA_EDU_DATA" in err


def test_info_prints_summary_and_diagnostics(capsys):
    assert cli.main(["info", "sim-small"]) == 0
    text = capsys.readouterr().out
    for word in ("frames", "landmarks", "disparity", "extrinsic check", "time alignment", "gyro bias"):
        assert word in text


def test_python_dash_m_works():
    done = subprocess.run([sys.executable, "-m", "visla_edu", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "info" in done.stdout and "run" in done.stdout
