"""The 2025+ course format (``datasetNN/datasetNN.npy``, a pickled dict) and the general stereo rig.

No such course file is available, so every file here is written by the tests from a simulated
drive (:func:`visla_edu.data.save_course2025`), in each convention the format may use: the
extrinsics camera->IMU or IMU->camera, in the optical or the "regular" camera frame, the
velocities (T, 3) or (3, T). What is checked:

* a file in each convention loads and runs every mode to the trajectory of the same drive in
  the 2021+ format (``K_l = K_r``), with the convention found by the diagnostics;
* a rig with ``K_l != K_r`` runs every mode and tracks its simulated ground truth;
* a pickle that would run code is refused with one line naming the file, and never runs;
* bad files are refused with one line naming the file, the key and the shape or value;
* a file without features loads for dead reckoning, and the other modes say why they cannot run;
* ``visla-edu info`` prints the rig and the evidence for the extrinsics' direction and frame.
"""

import pickle
from pathlib import Path

import numpy as np
import pytest

from visla_edu import cli, data, diagnostics, lie, metrics, run, simulate
from visla_edu.course.capstone import CapstoneFilter, Steps, library_parts
from visla_edu.filters import FilterConfig

MODES = ("deadreckon", "mapping", "vio", "slam", "smooth", "window")
CONVENTIONS = [("camera->IMU", "regular", "T x 3"), ("camera->IMU", "optical", "3 x T"),
               ("IMU->camera", "regular", "3 x T"), ("IMU->camera", "optical", "T x 3")]
#: A right camera with intrinsics of its own: focal lengths 4% and 3% longer, principal point moved.
K_LEFT = np.asarray(simulate.default_rig()[0], dtype=float)
K_RIGHT = K_LEFT @ np.array([[1.04, 0.0, 0.02], [0.0, 1.03, -0.03], [0.0, 0.0, 1.0]])


def _run_all(dataset):
    """``{mode: world_T_imu}`` of every mode with the default (auto) settings."""
    out = {}
    for mode in MODES:
        runner = run.run_smoother if mode in ("smooth", "window") else run.run_filter
        out[mode] = runner(dataset, mode, FilterConfig(), progress=False).world_T_imu
    return out


@pytest.fixture(scope="module")
def drive():
    """A 120-frame simulated drive (long enough for the track evidence) and its runs in the 2021+ format."""
    ds = simulate.simulate_drive("tiny", 0, num_frames=120)
    folder = Path(__import__("tempfile").mkdtemp(prefix="visla-edu-2021-"))
    reference = data.load(str(data.save(ds, folder / "drive.npz")))
    return ds, _run_all(reference)


def _write(ds, folder, direction="camera->IMU", frame="regular", layout="T x 3", features=True, name="dataset01"):
    (folder / name).mkdir(parents=True, exist_ok=True)
    return data.save_course2025(ds, folder / name / f"{name}.npy", direction, frame, layout, features)


# ----------------------------------------------------------------------------- every convention, every mode


@pytest.mark.parametrize("direction, frame, layout", CONVENTIONS)
def test_each_convention_runs_every_mode_as_the_2021_format(drive, tmp_path, direction, frame, layout):
    ds, reference = drive
    loaded = data.load(str(_write(ds, tmp_path, direction, frame, layout)))
    assert loaded.extra["format"] == data.FORMAT_2025 and loaded.K_right is not None
    np.testing.assert_allclose(loaded.imu_T_cam, ds.imu_T_cam, atol=1e-14)
    assert loaded.b == pytest.approx(ds.b, rel=1e-14)
    np.testing.assert_array_equal(loaded.linear_velocity, ds.linear_velocity)
    np.testing.assert_array_equal(loaded.obs_z, ds.obs_z)
    calibration = diagnostics.calibrate(loaded)
    convention = f"{direction}, {frame}"
    assert calibration.reading.chosen == convention
    assert calibration.reading.track.chosen == convention  # the motion alone finds it too
    np.testing.assert_allclose(calibration.imu_T_cam, ds.imu_T_cam, atol=1e-14)
    runs = _run_all(loaded)
    for mode in MODES:
        assert np.abs(runs[mode][:, :3, 3] - reference[mode][:, :3, 3]).max() < 1e-9, mode
        assert np.abs(runs[mode][:, :3, :3] - reference[mode][:, :3, :3]).max() < 1e-9, mode


def test_a_rig_with_two_intrinsics_runs_every_mode_and_tracks_its_ground_truth(tmp_path):
    ds = simulate.simulate_drive("tiny", 0, K_right=K_RIGHT)
    loaded = data.load(str(_write(ds, tmp_path, "IMU->camera", "optical")))
    np.testing.assert_array_equal(loaded.K_right, K_RIGHT)
    assert not loaded.camera.same_intrinsics
    runs, in_memory = _run_all(loaded), _run_all(ds)
    truth = ds.ground_truth.world_T_imu
    dead_reckoning = metrics.ate(runs["deadreckon"], truth)
    for mode in MODES:
        assert np.abs(runs[mode] - in_memory[mode]).max() < 1e-9, mode  # the file changes nothing
        error = metrics.ate(runs[mode], truth)
        assert error < 0.3, (mode, error)  # tens of centimetres over the drive's 73 m
        if mode not in ("deadreckon", "mapping"):  # the camera corrects the pose in these modes
            assert error < dead_reckoning, (mode, error, dead_reckoning)
    with pytest.raises(ValueError, match="two intrinsics.*save_course2025"):
        data.save(loaded, tmp_path / "two.npz")
    with pytest.raises(ValueError, match="two intrinsics"):
        CapstoneFilter(loaded, run.resolve_config(loaded, FilterConfig()), library_parts(), Steps(None, None, None))


# ----------------------------------------------------------------------------- the pickle is never run


def _npy_with_payload(path, payload):
    """An .npy file declaring a 0-d object array, followed by ``payload`` (raw pickle bytes)."""
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "|O", "fortran_order": False, "shape": ()})
        f.write(payload)
    return path


class _RunsCode:
    """Pickles as a call of os.system: unpickling it with np.load(allow_pickle=True) would run the command."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        import os
        return os.system, (f"touch {self.marker}",)


@pytest.mark.parametrize("how", ["reduce", "protocol 0", "builtins eval"])
def test_a_pickle_that_would_run_code_is_refused_and_never_runs(tmp_path, capsys, how):
    marker = tmp_path / "ran"
    path = tmp_path / "dataset66.npy"
    if how == "reduce":
        contents = np.empty((), dtype=object)
        contents[()] = {"v_t": _RunsCode(marker), "timestamps": np.arange(3.0)}
        np.save(path, contents, allow_pickle=True)  # writing pickles the call, it does not run it
    elif how == "protocol 0":
        _npy_with_payload(path, pickle.dumps(_RunsCode(marker), protocol=0))
    else:
        _npy_with_payload(path, b"cbuiltins\neval\n(V__import__('os').system('touch " + str(marker).encode()
                          + b"')\ntR.")
    with pytest.raises(ValueError) as err:
        data.load(str(path))
    message = str(err.value)
    assert "\n" not in message and str(path) in message and "nothing from the file was run" in message
    assert "never needs" in message
    assert cli.main(["info", str(path)]) == 2
    assert str(path) in capsys.readouterr().err
    assert not marker.exists()


def test_plain_arrays_numbers_and_none_are_read(tmp_path):
    """The restricted unpickler reads what np.save writes of plain data: arrays of any layout, scalars, None."""
    from visla_edu.data._pickle import read_pickled_dict

    stored = {"a": np.arange(6.0).reshape(2, 3), "f": np.asfortranarray(np.ones((3, 4), np.float32)),
              "i": np.int64(4), "x": 1.5, "none": None, "text": "hi", "list": [1, 2], "b": np.array([True, False])}
    np.save(tmp_path / "plain.npy", stored, allow_pickle=True)
    _, got = read_pickled_dict(tmp_path / "plain.npy")
    assert set(got) == set(stored) and got["none"] is None and got["text"] == "hi" and got["list"] == [1, 2]
    for key in ("a", "f", "b"):
        np.testing.assert_array_equal(got[key], stored[key])
        assert got[key].dtype == stored[key].dtype
    assert got["i"] == 4 and got["x"] == 1.5


# ----------------------------------------------------------------------------- bad files, one line each


def _contents(ds):
    return {"timestamps": ds.time_stamps.copy(), "v_t": ds.linear_velocity.copy(), "w_t": ds.angular_velocity.copy(),
            "features": ds.to_dense_features(), "K_l": K_LEFT.copy(), "K_r": K_LEFT.copy(),
            "extL_T_imu": ds.imu_T_cam.copy(),
            "extR_T_imu": ds.imu_T_cam @ np.array([[1, 0, 0, ds.b], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])}


def _rotated_right(c):
    c["extR_T_imu"] = c["extR_T_imu"] @ lie.se3_exp([0, 0, 0, 0, 0.1, 0])


@pytest.mark.parametrize("change, message", [
    (lambda c: c.pop("K_r"), r"needs key\(s\) \['K_r'\]"),
    (lambda c: c.update(v_t=c["v_t"][:, :2]), r"key 'v_t' expected shape \(60, 3\) or \(3, 60\).*got \(60, 2\)"),
    (lambda c: c.update(w_t=list(c["w_t"])), "key 'w_t' must be a numpy array, got list"),
    (lambda c: c.update(timestamps=c["timestamps"][::-1].copy()), "key 'timestamps' must be strictly increasing"),
    (lambda c: c.update(timestamps=c["timestamps"] * 1e3), "key 'timestamps'.*milliseconds"),
    (lambda c: c.update(v_t=c["v_t"] * 100), "key 'v_t' at frame .* m/s"),
    (lambda c: c.update(K_l=c["K_l"] + [[0, 1.0, 0], [0, 0, 0], [0, 0, 0]]), "key 'K_l' has a skew K_l"),
    (lambda c: c.update(K_r=c["K_r"] * [[1e-3, 1, 1], [1, 1e-3, 1], [1, 1, 1]]), "key 'K_r': focal length"),
    (lambda c: c.update(extL_T_imu=c["extL_T_imu"] * 1.1), "key 'extL_T_imu' is not a rigid transform"),
    (_rotated_right, r"rectified stereo pair under no reading.*rotated 5\.73 deg"),
    (lambda c: c.update(features=c["features"][:, :, :-1]), r"key 'features' expected shape \(4, M, T\) with T = 60"),
    (lambda c: c.update(features=c["features"][[2, 3, 0, 1]]), "left and right columns swapped"),
])
def test_a_bad_file_is_refused_naming_the_key(tmp_path, change, message):
    contents = _contents(simulate.simulate_drive("tiny", 0))
    change(contents)
    path = tmp_path / "dataset02.npy"
    np.save(path, contents, allow_pickle=True)
    with pytest.raises(ValueError, match=message) as err:
        data.load(str(path))
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_three_frames_are_refused_as_ambiguous_velocities(tmp_path):
    ds = simulate.simulate_drive("tiny", 0).segment(0, 3)
    with pytest.raises(ValueError, match=r"key 'v_t' has shape \(3, 3\) with T = 3 frames .*cannot say whether rows"):
        data.load(str(_write(ds, tmp_path)))


@pytest.mark.parametrize("write, message", [
    (lambda p: np.save(p, np.zeros((3, 3))), r"an \.npy file of a \(3, 3\) float64 array, but a 2025\+ course"),
    (lambda p: p.write_bytes(b"PK\x03\x04 not an npy"), "not a readable .npy file"),
    (lambda p: np.save(p, np.array([{"a": 1}, {"b": 2}], dtype=object), allow_pickle=True), r"\(2,\) object"),
    (lambda p: np.save(p, np.array(["x"], dtype=object), allow_pickle=True), "holds a str, but a 2025"),
])
def test_a_file_that_is_not_a_course_dict_says_what_it_is(tmp_path, write, message):
    path = tmp_path / "dataset03.npy"
    write(path)
    with pytest.raises(ValueError, match=message):
        data.load(str(path))


# ----------------------------------------------------------------------------- a dataset shipped with images


def test_a_file_without_features_runs_dead_reckoning_and_says_why_the_rest_cannot(drive, tmp_path, capsys):
    ds, reference = drive
    path = _write(ds, tmp_path, features=False, name="dataset04")
    loaded = data.load(str(path))
    assert loaded.num_observations == 0 and "dataset04_imgs.npy" in loaded.extra[data.NO_FEATURES]
    result = run.run_filter(loaded, "deadreckon", FilterConfig(), progress=False)
    assert np.abs(result.world_T_imu - reference["deadreckon"]).max() < 1e-9
    for mode in MODES[1:]:
        runner = run.run_smoother if mode in ("smooth", "window") else run.run_filter
        with pytest.raises(ValueError, match=f"mode {mode} needs stereo observations.*no feature tracks.*deadreckon"):
            runner(loaded, mode, FilterConfig(), progress=False)
    assert cli.main(["run", str(path), "--mode", "slam", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "dataset04_imgs.npy" in err
    assert cli.main(["info", str(path)]) == 0
    assert "tracks        none: dataset04.npy has no feature tracks" in capsys.readouterr().out


# ----------------------------------------------------------------------------- names, info


def test_course_names_resolve_in_the_data_dir(tmp_path):
    ds = simulate.simulate_drive("tiny", 0)
    nested = _write(ds, tmp_path, name="dataset07")  # the course's layout: dataset07/dataset07.npy
    flat = data.save_course2025(ds, tmp_path / "dataset08.npy")
    assert data.load("dataset07", tmp_path).source == str(nested)
    assert data.load("dataset08", tmp_path).source == str(flat)
    assert data.input_files("dataset07", tmp_path) == [nested]
    assert data.available(tmp_path) == ["dataset07", "dataset08", "sim"]
    with pytest.raises(FileNotFoundError, match=r"dataset09/dataset09\.npy \(or dataset09\.npy\) not found"):
        data.load("dataset09", tmp_path)


def test_info_prints_the_rig_and_the_evidence_for_the_extrinsics(tmp_path, capsys):
    ds = simulate.simulate_drive("tiny", 0, num_frames=120, K_right=K_RIGHT)
    path = _write(ds, tmp_path, "IMU->camera", "regular")
    assert cli.main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    for expected in (f"left  K_l fsu {K_LEFT[0, 0]:.2f}", f"right K_r fsu {K_RIGHT[0, 0]:.2f}",
                     "(differs from K_l", "baseline 0.6000 m", "IMU->camera, regular   [+0.600, -0.000, +0.000]",
                     "a rectified pair  <- the loader's", "track reprojection among the readings: best 'IMU->camera, "
                     "regular', chosen", "read as 'IMU->camera, regular'", "track reprojection confirms it"):
        assert expected in text, expected
    for name in ("camera->IMU, optical", "camera->IMU, regular", "IMU->camera, optical"):
        assert text.count(name) >= 2  # in the rig geometry and in the motion evidence


@pytest.fixture(scope="module")
def turning_drive():
    """300 frames with turns: enough for the visual odometry's slopes."""
    return simulate.simulate_drive("small", 0)


def test_the_odometry_agrees_with_the_right_reading_only(turning_drive, tmp_path):
    loaded = data.load(str(_write(turning_drive, tmp_path, "camera->IMU", "optical")))
    reading = diagnostics.calibrate(loaded).reading
    assert reading.chosen == reading.track.chosen == "camera->IMU, optical" and reading.warning == ""
    assert reading.vo_verdict["camera->IMU, optical"] == "agrees"
    assert reading.vo_verdict["camera->IMU, regular"] == reading.vo_verdict["IMU->camera, regular"] == "disagrees"


def test_extrinsics_that_match_no_reading_get_a_clear_warning(turning_drive, tmp_path, capsys):
    """The file's extrinsics are those of a camera rolled 90 deg about its optical axis: a rectified pair, but
    not this drive's rig. The loader reads them; the diagnostics warn, and so do info and run."""
    rolled = turning_drive.imu_T_cam @ lie.se3_exp([0, 0, 0, 0, 0, np.pi / 2])
    import dataclasses
    wrong = dataclasses.replace(turning_drive, imu_T_cam=rolled, extra={})
    path = _write(wrong, tmp_path, "camera->IMU", "regular")
    loaded = data.load(str(path))
    reading = diagnostics.calibrate(loaded).reading
    assert reading.chosen == "camera->IMU, regular"  # the only rectified reading
    assert reading.warning.startswith("warning: the extrinsics match n")
    assert reading.warning in diagnostics.resolve_extrinsics(loaded)[1]
    assert cli.main(["info", str(path)]) == 0
    assert reading.warning in capsys.readouterr().out
