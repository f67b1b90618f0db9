"""Tests of visla_edu.data: loading both course formats, validation, save/load, summaries.

Unit tests build tiny course files in tmp_path; tests marked ``data`` use the real
course files from VISLA_EDU_DATA and are skipped when it is unset.
"""

import re
import sys
import time
import tracemalloc
import types

import numpy as np
import pytest

import visla_edu
from visla_edu import data, lie
from visla_edu.data import _features, _npz, _standin
from visla_edu.dataset import Dataset, GroundTruth, frame_major_order

T, M = 12, 9


# --------------------------------------------------------------------------- synthetic course files


def course_dict(fmt="2021+", T=T, M=M, seed=0):
    """A valid course-format dict: contiguous tracks, positive disparity, rigid extrinsics."""
    rng = np.random.default_rng(seed)
    features = np.full((4, M, T), -1.0)
    for m in range(M - 1):  # the last landmark is never observed
        start = int(rng.integers(0, T - 1))
        stop = int(rng.integers(start + 1, T + 1))
        n = stop - start
        uL, v, disparity = rng.uniform(50, 1200, n), rng.uniform(20, 350, n), rng.uniform(0.5, 60, n)
        features[:, m, start:stop] = [uL, v, uL - disparity, v]
    imu_T_cam = np.eye(4)
    imu_T_cam[:3, :3] = lie.so3_exp(rng.normal(size=3))
    imu_T_cam[:3, 3] = rng.normal(size=3)
    arrays = {
        "time_stamps": (1.6e9 + np.cumsum(rng.uniform(0.09, 0.11, T)))[None, :],
        "features": features,
        "linear_velocity": rng.normal(size=(3, T)),
        "angular_velocity": rng.normal(scale=0.1, size=(3, T)),
        "K": np.array([[552.5, 0.0, 682.0], [0.0, 552.5, 238.7], [0.0, 0.0, 1.0]]),
        "b": np.array(0.6),
        "imu_T_cam": imu_T_cam,
    }
    if fmt == "2019":
        arrays["rotational_velocity"] = arrays.pop("angular_velocity")
        arrays["cam_T_imu"] = lie.se3_inv(arrays.pop("imu_T_cam"))
    return arrays


def write(tmp_path, arrays, name="drive.npz", compressed=True):
    path = tmp_path / name
    (np.savez_compressed if compressed else np.savez)(path, **arrays)
    return path


def observed_entry(features, skip=0):
    """``(landmark, frame)`` of an observed entry."""
    m, t = np.argwhere(features[0] != -1)[skip]
    return int(m), int(t)


def assert_same_dataset(a, b, exact_pose=True):
    for key in ("time_stamps", "linear_velocity", "angular_velocity", "K", "frame_ptr", "obs_ids", "obs_z"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    assert a.b == b.b and a.num_landmarks == b.num_landmarks
    if exact_pose:
        np.testing.assert_array_equal(a.imu_T_cam, b.imu_T_cam)
    else:
        np.testing.assert_allclose(a.imu_T_cam, b.imu_T_cam, rtol=0, atol=1e-14)


# --------------------------------------------------------------------------- loading valid files


def test_both_formats_load_to_the_same_dataset(tmp_path):
    new = data.load(write(tmp_path, course_dict("2021+"), "new.npz"))
    old = data.load(write(tmp_path, course_dict("2019"), "old.npz"))
    assert_same_dataset(new, old, exact_pose=False)
    assert (new.extra["format"], old.extra["format"]) == ("2021+", "2019/2020")
    np.testing.assert_allclose(old.camera.cam_T_imu, course_dict("2019")["cam_T_imu"], atol=1e-14)


def test_arrays_are_time_major(tmp_path):
    arrays = course_dict()
    ds = data.load(write(tmp_path, arrays))
    assert ds.time_stamps.shape == (T,) and ds.linear_velocity.shape == (T, 3)
    np.testing.assert_array_equal(ds.time_stamps, arrays["time_stamps"][0])
    np.testing.assert_array_equal(ds.angular_velocity, arrays["angular_velocity"].T)
    assert ds.linear_velocity.flags.c_contiguous and isinstance(ds.b, float)


@pytest.mark.parametrize("rows_per_chunk", [None, 1, 2, 4])
def test_sparse_store_equals_dense_input(tmp_path, monkeypatch, rows_per_chunk):
    if rows_per_chunk is not None:
        monkeypatch.setattr(_features, "_CHUNK_BYTES", rows_per_chunk * T * 8)
    arrays = course_dict(seed=3)
    ds = data.load(write(tmp_path, arrays))
    np.testing.assert_array_equal(ds.to_dense_features(), arrays["features"])
    reference = Dataset.from_dense(arrays["features"], **{k: None for k in _OTHER_FIELDS})
    for key in ("frame_ptr", "obs_ids", "obs_z"):
        np.testing.assert_array_equal(getattr(ds, key), getattr(reference, key), err_msg=key)
    assert ds.track_lengths()[M - 1] == 0  # the never-observed landmark is kept


_OTHER_FIELDS = ("name", "source", "time_stamps", "linear_velocity", "angular_velocity", "K", "b", "imu_T_cam")


def test_frame_major_order_sorts_by_frame_then_id():
    rng = np.random.default_rng(7)
    pairs = rng.permutation([(m, t) for m in range(6) for t in range(5) if rng.random() < 0.6])
    ids, frames = pairs[:, 0], pairs[:, 1]
    order, frame_ptr = frame_major_order(ids, frames, 7)  # frames 5 and 6 have no observations
    assert [tuple(p) for p in zip(frames[order], ids[order])] == sorted(zip(frames, ids))
    np.testing.assert_array_equal(np.diff(frame_ptr), np.bincount(frames, minlength=7))
    assert frame_ptr[0] == 0 and frame_ptr.dtype == np.int64
    with pytest.raises(ValueError, match=r"frames must lie in \[0, 4\)"):
        frame_major_order(ids, frames, 4)
    with pytest.raises(ValueError, match="same shape"):
        frame_major_order(ids, frames[:-1], 7)


@pytest.mark.parametrize(
    "variant",
    ["stored", "fortran", "float32"],
)
def test_other_encodings_of_features(tmp_path, variant):
    arrays = course_dict(seed=4)
    if variant == "fortran":
        arrays["features"] = np.asfortranarray(arrays["features"])
    if variant == "float32":
        arrays["features"] = arrays["features"].astype(np.float32)
    ds = data.load(write(tmp_path, arrays, compressed=variant != "stored"))
    np.testing.assert_array_equal(ds.to_dense_features(), arrays["features"].astype(float))
    assert ds.obs_z.dtype == np.float64


def test_no_landmarks_and_frames_without_observations(tmp_path):
    arrays = course_dict()
    arrays["features"] = np.full((4, 0, T), -1.0)
    ds = data.load(write(tmp_path, arrays))
    assert ds.num_landmarks == 0 and ds.num_observations == 0
    np.testing.assert_array_equal(ds.frame_ptr, np.zeros(T + 1))


def test_source_name_and_unknown_label(tmp_path):
    path = write(tmp_path, course_dict(), "mydrive.npz")
    ds = data.load(str(path))
    assert ds.source == str(path.resolve()) and ds.name == "mydrive"
    assert "not a known course file" in ds.label
    assert len(ds.extra["sha256"]) == 64 and ds.extra["known_file"] is None


def test_known_file_recognised_by_sha256(tmp_path, monkeypatch):
    path = write(tmp_path, course_dict(), "renamed.npz")
    sha = _npz.file_sha256(path)
    entry = {"sha256": sha, "format": "2021+", "description": "dataset 99: a test drive"}
    monkeypatch.setitem(data.REGISTRY, "99", entry)
    ds = data.load(path)
    assert (ds.name, ds.label, ds.extra["known_file"]) == ("99", "dataset 99: a test drive", "99")


def test_known_name_with_other_hash_says_so(tmp_path):
    ds = data.load(write(tmp_path, course_dict(), "03.npz"))
    assert ds.name == "03" and "sha256 differs" in ds.label


# --------------------------------------------------------------------------- bad files


def _set(key, value):
    def change(arrays):
        arrays[key] = np.asarray(value) if not callable(value) else value(arrays[key])

    return change


def _drop(*keys):
    def change(arrays):
        for key in keys:
            del arrays[key]

    return change


def _set_entry(key, index, value):
    def change(arrays):
        arrays[key] = arrays[key].copy()
        arrays[key][index] = value

    return change


def _partial_observed(arrays):
    m, t = observed_entry(arrays["features"], skip=5)
    arrays["features"][2, m, t] = -1


def _partial_unobserved(arrays):
    m, t = np.argwhere(arrays["features"][0] == -1)[0]
    arrays["features"][1, m, t] = 100.0


def _scaled_rotation(T_):
    out = T_.copy()
    out[:3, :3] *= 1.01
    return out


def _reflection(T_):
    out = T_.copy()
    out[:3, 0] *= -1
    return out


def _bad_last_row(T_):
    out = T_.copy()
    out[3, 2] = 0.1
    return out


_SHAPE = r"expected shape"
BAD_CASES = {
    "missing K": (_drop("K"), r"2021\+ course format but is missing key\(s\) \['K'\]"),
    "missing features": (_drop("features"), r"missing key\(s\) \['features'\]"),
    "neither format": (_drop("angular_velocity", "imu_T_cam"), r"matches neither course format.*found keys"),
    "extra key": (_set("foo", 1.0), r"unexpected key\(s\) \['foo'\]"),
    "velocity T mismatch": (
        _set("linear_velocity", lambda a: a[:, :-1]),
        r"'linear_velocity' expected shape \(3, 12\) \(T = 12 from time_stamps\), got \(3, 11\)",
    ),
    "angular wrong rows": (_set("angular_velocity", lambda a: a[:2]), r"'angular_velocity' expected shape \(3, 12\)"),
    "time_stamps 1-d": (_set("time_stamps", lambda a: a[0]), r"'time_stamps' expected shape \(1, T\).*got \(12,\)"),
    "time_stamps empty": (_set("time_stamps", np.zeros((1, 0))), r"'time_stamps' expected shape \(1, T\) with T >= 1"),
    "features T mismatch": (
        _set("features", lambda a: a[:, :, :-1]),
        r"'features' expected shape \(4, M, T\) with T = 12 from time_stamps, got \(4, 9, 11\)",
    ),
    "features 3 planes": (_set("features", lambda a: a[:3]), r"'features' expected shape \(4, M, T\).*got \(3, 9, 12\)"),
    "K shape": (_set("K", np.eye(3, 4)), r"'K' expected shape \(3, 3\), got \(3, 4\)"),
    "b shape": (_set("b", [0.6]), r"'b' expected shape \(\), got \(1,\)"),
    "pose shape": (_set("imu_T_cam", np.eye(4)[:3]), r"'imu_T_cam' expected shape \(4, 4\), got \(3, 4\)"),
    "nan velocity": (_set_entry("linear_velocity", (1, 5), np.nan), r"'linear_velocity' has a non-finite value nan at index \(1, 5\)"),
    "inf time": (_set_entry("time_stamps", (0, 3), np.inf), r"'time_stamps' has a non-finite value inf at index \(0, 3\)"),
    "nan K": (_set_entry("K", (0, 2), np.nan), r"'K' has a non-finite value nan at index \(0, 2\)"),
    "nan features": (
        _set_entry("features", (3, 4, 7), np.nan),
        r"'features' has a non-finite value nan at index \(3, 4, 7\) \(vR of landmark 4 at frame 7\)",
    ),
    "time not increasing": (
        _set("time_stamps", lambda a: np.concatenate([a[:, :5], a[:, 4:5], a[:, 6:]], axis=1)),
        r"strictly increasing, but time_stamps\[0, 5\] = .* is not after time_stamps\[0, 4\]",
    ),
    "partial observed": (_partial_observed, r"landmark \d+ at frame \d+ is partly observed: it is observed .*uR"),
    "partial unobserved": (_partial_unobserved, r"landmark 0 at frame 0 is partly observed: it is not observed.*vL = features\[1, 0, 0\] = 100"),
    "K lower": (_set_entry("K", (1, 0), 3.0), r"'K' must be upper triangular"),
    "K scale": (_set_entry("K", (2, 2), 2.0), r"'K' must be upper triangular with K\[2, 2\] = 1"),
    "K focal": (_set_entry("K", (1, 1), -552.5), r"'K' needs positive focal lengths, got fsu = 552.5, fsv = -552.5"),
    "b zero": (_set("b", 0.0), r"'b' \(stereo baseline, metres\) must be positive, got 0.0"),
    "b negative": (_set("b", -0.6), r"must be positive, got -0.6"),
    "not orthogonal": (_set("imu_T_cam", _scaled_rotation), r"'imu_T_cam' is not a rigid transform: max \|R\^T R - I\| = 0.0201"),
    "reflection": (_set("imu_T_cam", _reflection), r"'imu_T_cam' is not a rigid transform: det\(R\) = -1"),
    "last row": (_set("imu_T_cam", _bad_last_row), r"last row is \[0.0, 0.0, 0.1, 1.0\], expected \[0, 0, 0, 1\]"),
    "string K": (_set("K", np.array([["a"] * 3] * 3)), r"'K' must hold real numbers, got dtype <U1"),
    "object K": (_set("K", np.array([None] * 9, dtype=object).reshape(3, 3)), r"'K' is not a readable numpy array"),
    "string features": (_set("features", lambda a: a.astype(str)), r"'features' must hold real numbers"),
    "partial ground truth": (_set("ground_truth_landmarks", np.zeros((M, 3))), r"ground-truth key.*missing"),
}


@pytest.mark.parametrize("case", list(BAD_CASES))
def test_bad_2021_file_raises_a_clear_value_error(tmp_path, case):
    change, message = BAD_CASES[case]
    arrays = course_dict()
    change(arrays)
    path = write(tmp_path, arrays)
    with pytest.raises(ValueError, match=message) as info:
        data.load(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    "change, message",
    [
        (_set("cam_T_imu", _scaled_rotation), r"'cam_T_imu' is not a rigid transform"),
        (_drop("cam_T_imu"), r"2019/2020 course format but is missing key\(s\) \['cam_T_imu'\]"),
        (_set("rotational_velocity", lambda a: a[:, 1:]), r"'rotational_velocity' expected shape \(3, 12\)"),
        (_set("angular_velocity", np.zeros((3, T))), r"unexpected key\(s\) \['angular_velocity'\] in a 2019/2020"),
    ],
)
def test_bad_2019_file_raises_a_clear_value_error(tmp_path, change, message):
    arrays = course_dict("2019")
    change(arrays)
    with pytest.raises(ValueError, match=message):
        data.load(write(tmp_path, arrays))


def test_partial_observation_found_in_a_later_chunk(tmp_path, monkeypatch):
    monkeypatch.setattr(_features, "_CHUNK_BYTES", 2 * T * 8)
    arrays = course_dict()
    m, t = observed_entry(arrays["features"], skip=-1)
    arrays["features"][3, m, t] = -1
    with pytest.raises(ValueError, match=rf"landmark {m} at frame {t} is partly observed.*vR"):
        data.load(write(tmp_path, arrays))


def test_missing_file_says_where_it_looked(tmp_path):
    with pytest.raises(FileNotFoundError, match=rf"{re.escape(str(tmp_path))}.*VISLA_EDU_DATA"):
        data.load(tmp_path / "nothere.npz")
    where = re.escape(str(tmp_path))
    message = rf"course file 03.npz not found in {where} \(the data directory from the data_dir argument\). Set VISLA_EDU"
    with pytest.raises(FileNotFoundError, match=message):
        data.load("03", data_dir=tmp_path)


def test_not_an_npz(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("these are not the files you are looking for")
    with pytest.raises(ValueError, match=rf"{re.escape(str(text))}: not a valid .npz \(zip\) archive"):
        data.load(text)
    single = tmp_path / "single.npz"
    with open(single, "wb") as f:
        np.save(f, np.zeros(3))
    with pytest.raises(ValueError, match=r"single .npy array, not an .npz archive"):
        data.load(single)


def test_truncated_file(tmp_path):
    path = write(tmp_path, course_dict())
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match=r"truncated, corrupt, or not an .npz"):
        data.load(path)


@pytest.mark.parametrize("compressed", [True, False])
def test_corrupt_features_are_reported_as_a_damaged_file(tmp_path, compressed):
    arrays = course_dict(T=40, M=30)
    path = write(tmp_path, arrays, compressed=compressed)
    raw = bytearray(path.read_bytes())
    start = raw.find(b"features.npy") + 400  # inside the features member's data
    raw[start:start + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"truncated, corrupt, or not an .npz file \((BadZipFile|error)"):
        data.load(path)


def test_imu_only_file_points_to_the_standin(tmp_path):
    arrays = course_dict()
    imu_only = {k: arrays[k] for k in ("time_stamps", "linear_velocity", "angular_velocity")}
    with pytest.raises(ValueError, match=r"missing key\(s\) \['features', 'K', 'b', 'imu_T_cam'\].*load\('10'\)"):
        data.load(write(tmp_path, imu_only, "10_imu_only.npz"))


# --------------------------------------------------------------------------- save / load


def _dataset_with_ground_truth(seed=5):
    arrays = course_dict(seed=seed)
    rng = np.random.default_rng(seed)
    gt = GroundTruth(
        world_T_imu=lie.se3_exp(rng.normal(size=(T, 6))),
        landmarks=rng.normal(size=(M, 3)),
        linear_velocity=rng.normal(size=(T, 3)),
        angular_velocity=rng.normal(size=(T, 3)),
        outlier=rng.random(M) < 0.3,
    )
    return Dataset.from_dense(
        arrays["features"],
        name="sim-test",
        source="simulated for a test",
        time_stamps=arrays["time_stamps"][0],
        linear_velocity=arrays["linear_velocity"].T.copy(),
        angular_velocity=arrays["angular_velocity"].T.copy(),
        K=arrays["K"],
        b=0.6,
        imu_T_cam=arrays["imu_T_cam"],
        ground_truth=gt,
        label="a simulated drive (test)",
    )


def test_save_load_round_trip_with_ground_truth(tmp_path):
    original = _dataset_with_ground_truth()
    path = data.save(original, tmp_path / "saved")
    assert path == (tmp_path / "saved.npz").resolve()
    loaded = data.load(path)
    assert_same_dataset(original, loaded)
    for key in ("world_T_imu", "landmarks", "linear_velocity", "angular_velocity", "outlier"):
        a, b = getattr(original.ground_truth, key), getattr(loaded.ground_truth, key)
        np.testing.assert_array_equal(a, b, err_msg=key)
        assert a.dtype == b.dtype
    assert (loaded.name, loaded.label, loaded.source) == ("sim-test", "a simulated drive (test)", str(path))
    assert not list(tmp_path.glob(".*tmp"))


def test_save_load_round_trip_without_ground_truth(tmp_path):
    original = data.load(write(tmp_path, course_dict("2019"), "old.npz"))
    loaded = data.load(data.save(original, tmp_path / "new.npz"))
    assert_same_dataset(original, loaded)
    assert loaded.ground_truth is None and loaded.extra["format"] == "2021+"
    with np.load(tmp_path / "new.npz") as f:  # the file is in the 2021+ course layout
        assert f["features"].shape == (4, M, T) and f["linear_velocity"].shape == (3, T)


def _scale_rotations(poses):
    poses[5, :3, :3] *= 2.0


def _last_row(poses):
    poses[7, 3] = [0.0, 0.0, 0.0, 0.0]


def _millimetres(poses):
    poses[:, :3, 3] *= 1000.0


@pytest.mark.parametrize("change, pattern", [
    (_scale_rotations, r"the pose of frame 5 is not a rigid transform \(max \|R\^T R - I\| = 3"),
    (_last_row, r"the pose of frame 7 is not a rigid transform .*last row \[0.0, 0.0, 0.0, 0.0\]"),
    (_millimetres, r"the ground-truth pose of frame \d+ is .* m from frame 0's.*looks like millimetres"),
])
def test_saved_ground_truth_poses_are_checked_when_loaded(tmp_path, change, pattern):
    """Ground-truth poses a run cannot evaluate against are refused by the loader, not after the run."""
    path = data.save(_dataset_with_ground_truth(), tmp_path / "saved.npz")
    with np.load(path) as f:
        arrays = {key: f[key] for key in f.files}
    change(arrays["ground_truth_world_T_imu"])
    write(tmp_path, arrays, "saved.npz")
    with pytest.raises(ValueError, match=pattern) as err:
        data.load(path)
    assert "'ground_truth_world_T_imu'" in str(err.value) and str(path) in str(err.value)


# --------------------------------------------------------------------------- data directory and names


def test_data_dir_argument_beats_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("VISLA_EDU_DATA", str(tmp_path / "env"))
    assert data.data_dir(tmp_path / "arg") == tmp_path / "arg"
    assert data.data_dir() == tmp_path / "env"


def test_data_dir_default_is_absolute_cwd_data(tmp_path, monkeypatch):
    monkeypatch.delenv("VISLA_EDU_DATA", raising=False)
    monkeypatch.chdir(tmp_path)
    assert data.data_dir() == (tmp_path / "data").resolve()
    monkeypatch.setenv("VISLA_EDU_DATA", "  ")
    assert data.data_dir() == (tmp_path / "data").resolve()
    assert data.data_dir("rel").is_absolute()


def test_load_by_name_from_argument_or_environment(tmp_path, monkeypatch):
    write(tmp_path, course_dict(), "0022.npz")
    monkeypatch.setenv("VISLA_EDU_DATA", str(tmp_path))
    assert data.load("0022").name == "0022"
    monkeypatch.setenv("VISLA_EDU_DATA", str(tmp_path / "elsewhere"))
    assert data.load("0022", data_dir=tmp_path).num_frames == T
    assert data.load("0022.npz", data_dir=tmp_path).num_frames == T  # a bare file name, found in the data dir
    with pytest.raises(FileNotFoundError, match=r"from VISLA_EDU_DATA="):
        data.load("0022")


def test_bad_names(tmp_path):
    with pytest.raises(TypeError, match="name or a path"):
        data.load(3)
    with pytest.raises(ValueError, match="empty dataset name"):
        data.load(" ")


@pytest.fixture
def fake_simulate(monkeypatch):
    """Stand-ins for visla_edu.simulate and the dataset-10 stand-in builder that record their calls."""
    calls = []
    module = types.ModuleType("visla_edu.simulate")
    module.simulate_drive = lambda **kw: calls.append(("simulate_drive", kw)) or "drive"
    def standin_dataset10(*args, **kwargs):
        calls.append(("standin_dataset10", args))
        return types.SimpleNamespace(imu_T_cam=kwargs["imu_T_cam"], extra={}, name="standin")

    monkeypatch.setattr(_standin, "standin_dataset10", standin_dataset10)
    monkeypatch.setitem(sys.modules, "visla_edu.simulate", module)
    monkeypatch.setattr(visla_edu, "simulate", module, raising=False)
    return calls


@pytest.mark.parametrize("name, preset", [("sim", "course"), ("sim-small", "small"), ("sim-tiny", "tiny")])
def test_sim_names_call_the_simulator(fake_simulate, name, preset):
    assert data.load(name) == "drive"
    assert fake_simulate == [("simulate_drive", {"preset": preset, "seed": 0})]


def test_dataset10_real_file_then_standin_then_error(tmp_path, fake_simulate):
    with pytest.raises(FileNotFoundError, match=r"10.npz is not in .* 10_imu_only.npz and 03.npz are missing"):
        data.load("10", data_dir=tmp_path)
    write(tmp_path, course_dict(), "03.npz")
    with pytest.raises(FileNotFoundError, match=r"but 10_imu_only.npz is missing"):
        data.load("10", data_dir=tmp_path)
    write(tmp_path, {"time_stamps": np.zeros((1, 2))}, "10_imu_only.npz")
    standin = data.load("10", data_dir=tmp_path)
    assert standin.name == "standin"
    assert fake_simulate == [("standin_dataset10", (tmp_path / "10_imu_only.npz", tmp_path / "03.npz"))]
    # simulated with the physical (diagnosed) rig, reported with the file's calibration like 10.npz
    np.testing.assert_array_equal(standin.imu_T_cam, data.load("03", data_dir=tmp_path).imu_T_cam)
    assert standin.extra["simulated_imu_T_cam"].shape == (4, 4)
    write(tmp_path, course_dict(), "10.npz")
    real = data.load("10", data_dir=tmp_path)
    assert real.name == "10" and "not on record" in real.label


def test_available(tmp_path):
    assert data.available(tmp_path) == ["sim"]
    write(tmp_path, course_dict(), "0022.npz")
    write(tmp_path, course_dict(), "03.npz")
    assert data.available(tmp_path) == ["03", "0022", "sim"]
    write(tmp_path, {"time_stamps": np.zeros((1, 2))}, "10_imu_only.npz")
    assert data.available(tmp_path) == ["03", "10", "0022", "sim"]


# --------------------------------------------------------------------------- summary


def _quirky_dataset():
    """Frame 3 repeats frame 2; landmark 0 has a gap; landmark 4 seen once; odd disparities."""
    rng = np.random.default_rng(1)
    features = np.full((4, 6, 8), -1.0)
    for m, frames in enumerate([[0, 1, 4], [1, 2, 3], [2, 3], [5, 6, 7], [6], []]):
        for t in frames:
            u, v = rng.uniform(100, 900), rng.uniform(50, 300)
            features[:, m, t] = [u, v, u - rng.uniform(2, 50), v]
    features[:, :, 3] = features[:, :, 2]  # repeat frame 2 exactly (landmark 1 and 2 in both)
    features[2, 3, 5] = features[0, 3, 5] + 1.0  # negative disparity
    features[2, 3, 6] = features[0, 3, 6]  # zero disparity
    features[2, 3, 7] = features[0, 3, 7] - 0.5  # tiny disparity
    return Dataset.from_dense(
        features, name="quirky", source="test", time_stamps=np.arange(8) * 0.1,
        linear_velocity=np.tile([3.0, 4.0, 0.0], (8, 1)), angular_velocity=np.zeros((8, 3)),
        K=np.diag([500.0, 500.0, 1.0]), b=0.5, imu_T_cam=np.eye(4),
    )


def test_summarize_reports_the_quirks():
    s = data.summarize(_quirky_dataset())
    assert s["repeated_frames"] == [3]
    assert (s["nonpositive_disparity"], s["tiny_disparity"], s["tiny_disparity_depth_m"]) == (2, 1, 250.0)
    assert not s["tracks_contiguous"] and s["noncontiguous_landmarks"] == 1
    assert (s["landmarks_seen_once"], s["landmarks_never_observed"]) == (1, 1)
    assert s["track_length_frames"] == {"min": 1, "median": 3.0, "max": 3}
    assert s["speed_m_s"]["mean"] == pytest.approx(5.0) and s["distance_m"] == pytest.approx(3.5)
    assert s["frames"] == 8 and s["ground_truth"] is False


def test_format_summary_is_readable():
    text = data.format_summary(_quirky_dataset())
    assert "frame 3 repeats the features of frame 2" in text
    assert "1 tracks have gaps" in text and "uL - uR <= 0" in text and "ground truth  none" in text


# --------------------------------------------------------------------------- real course files


@pytest.fixture(scope="module")
def dataset03(require_data):
    return data.load(require_data("03"))


@pytest.mark.data
def test_03_loads_with_the_known_counts(dataset03):
    ds = dataset03
    assert (ds.num_frames, ds.num_landmarks, ds.num_observations) == (1010, 5105, 66353)
    assert ds.name == "03" and ds.label.startswith("dataset 3: KITTI-360 drive")
    assert ds.extra["sha256"] == data.REGISTRY["03"]["sha256"] and ds.extra["format"] == "2021+"


@pytest.mark.data
def test_03_summary(dataset03):
    s = data.summarize(dataset03)
    assert s["repeated_frames"] == [1008]
    assert s["nonpositive_disparity"] == 621 and s["tracks_contiguous"]
    assert "frame 1008 repeats" in data.format_summary(dataset03)


@pytest.mark.data
def test_03_dense_window_matches_numpy(dataset03, require_data):
    with np.load(require_data("03")) as f:
        window = f["features"][:, :, 500:540]
        np.testing.assert_array_equal(dataset03.linear_velocity, f["linear_velocity"].T)
        np.testing.assert_array_equal(dataset03.imu_T_cam, f["imu_T_cam"])
    np.testing.assert_array_equal(dataset03.to_dense_features(frames=slice(500, 540)), window)


@pytest.mark.data
def test_03_load_time_and_peak_memory(require_data):
    path = require_data("03")
    dense_bytes = 4 * 5105 * 1010 * 8
    tracemalloc.start()
    try:
        start = time.perf_counter()
        data.load(path)
        seconds = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    print(f"03: loaded in {seconds:.2f} s (under tracemalloc), peak {peak / 1e6:.1f} MB")
    assert peak < dense_bytes / 2


@pytest.mark.data
def test_0022_loads_in_the_old_format(require_data):
    path = require_data("0022")
    ds = data.load(path)
    assert (ds.num_frames, ds.num_landmarks, ds.name) == (800, 3220, "0022")
    assert ds.extra["format"] == "2019/2020" and ds.label.startswith("KITTI raw")
    with np.load(path) as f:
        np.testing.assert_allclose(ds.imu_T_cam @ f["cam_T_imu"], np.eye(4), atol=1e-6)
        np.testing.assert_array_equal(ds.angular_velocity, f["rotational_velocity"].T)


@pytest.mark.data
def test_imu_only_file_of_dataset10_is_recognised(require_data):
    with pytest.raises(ValueError, match=r"missing key\(s\).*load\('10'\)"):
        data.load(require_data("10_imu_only"))


# --------------------------------------------------------------------------- plausibility (issue 10)


def test_square_features_with_gappy_tracks_load():
    """M = T is refused as transposed only on evidence (tests/fuzzgen.py has a transposed drive refused)."""
    from visla_edu.data import _plausible

    rng = np.random.default_rng(2)
    observed = rng.random((20, 20)) < 0.3  # (landmark, frame): neither rows nor columns contiguous
    ids, frames = np.nonzero(observed)
    order, frame_ptr = frame_major_order(ids, frames, 20)
    _plausible.check_track_layout(frame_ptr, ids[order], 20, "x")  # no error: the data do not say "swapped"


@pytest.mark.parametrize("scale, unit", [(1 / 60, "minutes"), (1 / 3600, "hours")])
def test_time_stamps_in_other_units_are_named(tmp_path, scale, unit):
    arrays = course_dict()
    stamps = arrays["time_stamps"]
    arrays["time_stamps"] = (stamps - stamps[0, 0]) * scale
    with pytest.raises(ValueError, match=rf"they look like {unit}"):
        data.load(write(tmp_path, arrays))


@pytest.mark.parametrize("key, value", [("b", 0.005), ("b", 5.0), ("K00", 4.0), ("t", 20.0)])
def test_calibration_at_the_edges_of_the_plausible_ranges_loads(tmp_path, key, value):
    from visla_edu import validation

    arrays = course_dict()
    if key == "b":
        arrays["b"] = np.array(value)
        data.load(write(tmp_path, arrays))
        return
    if key == "K00":
        K = arrays["K"].copy()
        K[0, 0] = K[1, 1] = value
        validation.check_plausible_calibration(K, 0.6, "x")
        return
    arrays["imu_T_cam"][:3, 3] = [value, 0.0, 0.0]
    data.load(write(tmp_path, arrays))


@pytest.mark.parametrize("index", [(0, 2), (1, 2)])
def test_principal_point_at_zero_is_refused_and_at_the_upper_edge_accepted(index):
    from visla_edu import validation

    K = course_dict()["K"].copy()
    K[index] = 0.0
    with pytest.raises(ValueError, match=r"= 0 px is outside any image \(it lies near the image centre, above 0 "
                                         r"and at most 20000 px\)"):
        validation.check_plausible_calibration(K, 0.6, "x")
    K[index] = validation.PRINCIPAL_POINT_RANGE[1]
    validation.check_plausible_calibration(K, 0.6, "x")


def test_swapped_left_and_right_columns_are_named(tmp_path):
    arrays = course_dict()
    swapped = dict(arrays, features=arrays["features"][[2, 3, 0, 1]].copy())
    with pytest.raises(ValueError, match=r"key 'features': 100.0% of the .* observations have uL - uR <= 0 .* are the "
                                         r"left and right columns swapped\? .* features\[\[2, 3, 0, 1\]\]"):
        data.load(write(tmp_path, swapped))
    assert data.load(write(tmp_path, arrays, "fine.npz")).num_observations > 0


def test_nan_as_the_missing_marker_and_rounded_extrinsics_get_a_fix(tmp_path):
    arrays = course_dict()
    features = arrays["features"].copy()
    features[features == -1] = np.nan
    with pytest.raises(ValueError, match=r"key 'features' has a non-finite value nan .* marks 'not observed' with -1 "
                                         r"in all four: features = np.nan_to_num\(features, nan=-1\)"):
        data.load(write(tmp_path, dict(arrays, features=features), "nan.npz"))
    rounded = dict(arrays, imu_T_cam=np.round(arrays["imu_T_cam"], 4))
    with pytest.raises(ValueError, match=r"key 'imu_T_cam' is not a rigid transform: .* rounded entries\? store full "
                                         r"precision, or re-orthonormalise R"):
        data.load(write(tmp_path, rounded, "rounded.npz"))


def test_a_name_that_is_a_file_in_the_current_folder_gets_the_path_suggested(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, course_dict(), "mydrive.npz")
    (tmp_path / "data").mkdir()
    with pytest.raises(FileNotFoundError, match=r"--data-dir on the command line.* A file mydrive.npz is in the "
                                                r"current folder: give it as a path, ./mydrive.npz"):
        data.load("mydrive", tmp_path / "data")


def test_summary_of_a_drive_without_observations_says_so():
    import dataclasses

    from visla_edu import simulate

    ds = simulate.simulate_drive("tiny", seed=0)
    empty = dataclasses.replace(ds, obs_ids=ds.obs_ids[:0], obs_z=ds.obs_z[:0], frame_ptr=np.zeros_like(ds.frame_ptr))
    text = data.format_summary(empty)
    assert "tracks        none: no landmark is observed (every feature is -1)" in text and "None" not in text
