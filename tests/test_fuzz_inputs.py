"""Fuzz suite of issue 10, input side: corrupted and forged course files, bad paths, random bytes.

Every file is made from a SIMULATED drive (tests/fuzzgen.py), never from course data. Each
case runs the command line in process and asserts either ONE clear line on stderr (no
traceback, exit status 2) or a finite result equal to the file's contents, within a time
limit and a memory budget (tracemalloc); the cases that must not read a huge member get a
budget of a few MiB. Test ids start with the class of issue 10 (``3-accepted-but-wrong/...``),
so ``pytest tests/test_fuzz_inputs.py tests/test_fuzz_cli.py --collect-only -q`` counts them
per class. tests/test_fuzz_cli.py has the output, settings and failure side.
"""

import os
import re
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fuzzgen as fz  # tests/fuzzgen.py
from visla_edu import data, run
from visla_edu.data import _features

# ======================================================================= corrupted arrays (classes 2, 3)


@pytest.mark.parametrize("name", list(fz.ARRAY_CASES), ids=fz.ids(fz.ARRAY_CASES))
def test_corrupted_arrays(name, tmp_path, capsys):
    _, change, pattern = fz.ARRAY_CASES[name]
    arrays = fz.course_arrays()
    change(arrays)
    path = fz.course_file(tmp_path, arrays)
    line = fz.assert_one_line(fz.cli_run(["info", path, "--no-diagnostics"], capsys), 2, pattern)
    assert str(path) in line  # the file is named


def _forged_2019_translation(tmp_path):
    arrays = fz.course_arrays(fmt="2019")
    arrays["cam_T_imu"] = arrays["cam_T_imu"].copy()
    arrays["cam_T_imu"][:3, 3] = [0.0, 2e4, 0.0]
    return fz.course_file(tmp_path, arrays)


def _zip(replace=None, append=()):
    return lambda tmp_path: fz.write_zip(tmp_path / "drive.npz", fz.zip_of(fz.course_arrays(), replace, append))


def _stored(header, declared_data_bytes):
    """A stored member: ``header`` and 64 bytes, whose zip entry declares the header's full size."""
    data = header + bytes(64)
    return fz.Raw(data, len(header) + declared_data_bytes, zlib.crc32(data), 0)


_TIB7_M = 7 * 2**40 // (4 * 60 * 8)  # M of a (4, M, 60) float64 array of 7 TiB
_K = fz.course_arrays()["K"]

#: name -> (class, builder(tmp_path) -> path, regex, memory budget)
ARCHIVE_CASES = {
    "K appended twice": ("3-accepted-but-wrong", _zip(append=[("K.npy", fz.npy_bytes(_K * 2))]),
                         r"key 'K' appears twice in the archive", fz.MEMORY_BUDGET),
    "K stored as K and K.npy": ("3-accepted-but-wrong", _zip(append=[("K", fz.npy_bytes(_K))]),
                                r"key 'K' appears twice", fz.MEMORY_BUDGET),
    "2019 extrinsic 20 km": ("3-accepted-but-wrong", _forged_2019_translation,
                             r"'cam_T_imu': the camera-IMU translation \|t\| is 20000 m", fz.MEMORY_BUDGET),
    "features header declares 7 TiB": ("5-unbounded-work", _zip({"features": fz.npy_header((4, _TIB7_M, 60))}),
                                       r"declares a \(4, \d+, 60\) float64 array \(7.0 TiB\) but its zip entry "
                                       r"holds only", fz.NO_READ_BUDGET),
    "features header and zip64 entry declare 7 TiB": (
        "5-unbounded-work", _zip({"features": _stored(fz.npy_header((4, _TIB7_M, 60)), 4 * _TIB7_M * 60 * 8)}),
        r"'features' declares .* of 7.0 TiB, more than the 4.0 GiB", fz.NO_READ_BUDGET),
    "K inflates to 1 GiB": ("5-unbounded-work", _zip({"K": fz.inflating_member(fz.npy_header((3, 3)))}),
                            r"'K': its zip entry inflates to 1.0 GiB but its .npy header declares a \(3, 3\)",
                            fz.NO_READ_BUDGET),
    "time_stamps declares 1e9 frames": ("5-unbounded-work", _zip({"time_stamps": _stored(
        fz.npy_header((1, 10**9)), 8 * 10**9)}), r"declares T = 1000000000 frames, more than", fz.NO_READ_BUDGET),
    "npy version 3.0": ("2-traceback", _zip({"b": b"\x93NUMPY\x03\x00" + fz.npy_bytes(np.array(0.6))[8:]}),
                        r"'b' is not a readable numpy array \(ValueError: .npy format version 3.0", fz.MEMORY_BUDGET),
    "object array": ("2-traceback", _zip({"K": fz.npy_header((3, 3), object) + b"x" * 9}),
                     r"'K' is not a readable numpy array \(dtype object holds Python objects", fz.MEMORY_BUDGET),
    "member is not npy": ("2-traceback", _zip({"K": b"these are not the bytes"}),
                          r"'K' is not a readable numpy array", fz.MEMORY_BUDGET),
    "unknown compression": ("2-traceback", _zip({"b": fz.Raw(b"\0" * 16, 136, 0, 99)}),
                            r"'b' uses zip compression method 99", fz.MEMORY_BUDGET),
    "empty archive": ("2-traceback", lambda tmp_path: fz.write_zip(tmp_path / "drive.npz", []),
                      r"matches neither course format", fz.MEMORY_BUDGET),
    "zero bytes": ("2-traceback", lambda tmp_path: fz.write_bytes(tmp_path / "drive.npz", b""),
                   r"not a valid .npz \(zip\) archive", fz.MEMORY_BUDGET),
    "text file": ("2-traceback", lambda tmp_path: fz.write_bytes(tmp_path / "drive.npz", b"time,vx\n0,1\n"),
                  r"not a valid .npz \(zip\) archive", fz.MEMORY_BUDGET),
    "single npy": ("2-traceback", lambda tmp_path: fz.write_bytes(tmp_path / "drive.npz", fz.npy_bytes(_K)),
                   r"single .npy array, not an .npz archive", fz.MEMORY_BUDGET),
    "truncated archive": ("2-traceback", lambda tmp_path: fz.truncated_file(tmp_path, 0.6),
                          r"truncated, corrupt, or not an .npz", fz.MEMORY_BUDGET),
}


@pytest.mark.parametrize("name", list(ARCHIVE_CASES), ids=fz.ids(ARCHIVE_CASES))
def test_forged_archives(name, tmp_path, capsys):
    _, build, pattern, budget = ARCHIVE_CASES[name]
    path = build(tmp_path)
    outcome = fz.cli_run(["info", path, "--no-diagnostics"], capsys, seconds=10)
    fz.assert_one_line(outcome, 2, pattern, budget)
    assert outcome.seconds < 5


# ======================================================================= valid variants load correctly (3, 5)


def _fortran(arrays):
    arrays["features"] = np.asfortranarray(arrays["features"])


def _float32(arrays):
    arrays["features"] = arrays["features"].astype(np.float32)


def _int16(arrays):
    arrays["features"] = np.round(arrays["features"]).astype(np.int16)


def _big_endian(arrays):
    arrays["features"] = arrays["features"].astype(">f8")


def _square(arrays):
    arrays.update(fz.square_drive_arrays())


#: name -> (class, change); the file must load to exactly the arrays numpy reads from it.
VALID_CASES = {
    "Fortran-order features": ("5-unbounded-work", _fortran),
    "float32 features": ("3-accepted-but-wrong", _float32),
    "signed int16 features": ("3-accepted-but-wrong", _int16),
    "big-endian features": ("3-accepted-but-wrong", _big_endian),
    "M = T, landmark-major as it should be": ("3-accepted-but-wrong", _square),
}


@pytest.mark.parametrize("name", list(VALID_CASES), ids=fz.ids(VALID_CASES))
def test_valid_variants_give_the_file_contents(name, tmp_path, capsys):
    arrays = fz.course_arrays()
    VALID_CASES[name][1](arrays)
    path = fz.course_file(tmp_path, arrays)
    out = tmp_path / "result.npz"
    fz.assert_ok(fz.cli_run(["run", path, *fz.RUN, "--out", out], capsys, measure=False))
    ds = data.load(path)
    with np.load(path) as f:  # an independent reader of the same file
        np.testing.assert_array_equal(ds.to_dense_features(), f["features"].astype(float))
        np.testing.assert_array_equal(ds.linear_velocity, f["linear_velocity"].T)
    result = run.load_result(out)
    assert np.all(np.isfinite(result.world_T_imu)) and np.all(np.isfinite(result.pose_cov))


@pytest.mark.parametrize("order", ["C", "F"])
def test_large_features_are_streamed_with_bounded_memory(order, tmp_path, capsys, monkeypatch):
    """5-unbounded-work: a 36 MiB dense array (few observations) loads within 12 MiB, in either memory order."""
    monkeypatch.setattr(_features, "_CHUNK_BYTES", 2**20)
    arrays = fz.course_arrays()
    T = arrays["features"].shape[2]
    dense = np.full((4, 20_000, T), -1.0, order=order)
    dense[:, : arrays["features"].shape[1]] = arrays["features"]
    arrays["features"] = dense
    path = fz.course_file(tmp_path, arrays)
    assert dense.nbytes > 36 * 2**20
    outcome = fz.cli_run(["info", path, "--no-diagnostics"], capsys)
    assert outcome.code == 0 and outcome.peak_bytes < 12 * 2**20, (outcome.err, outcome.peak_bytes)
    assert data.load(path).num_observations == fz.drive().num_observations


# ======================================================================= paths (class 6)


def _broken_link(tmp_path):
    path = tmp_path / "drive.npz"
    path.symlink_to(tmp_path / "gone.npz")
    return [path]


def _data_dir_is_file(tmp_path):
    return ["03", "--data-dir", fz.course_file(tmp_path)]


def _fifo_in_data_dir(tmp_path):
    os.mkfifo(tmp_path / "03.npz")
    return ["03", "--data-dir", tmp_path]


#: name -> (class, argv after the command, regex)
def _fifo_case(tmp_path):
    return [fz.fifo(tmp_path)]


PATH_CASES = {
    "directory": ("6-paths", lambda tmp_path: [tmp_path], r"is a directory, not a file"),
    "FIFO": ("6-paths", _fifo_case, r"is a FIFO \(named pipe\), not a regular file"),
    "FIFO named like a course file": ("6-paths", _fifo_in_data_dir, r"03.npz: is a FIFO"),
    "broken symbolic link": ("6-paths", _broken_link, r"a broken symbolic link \(it points to"),
    "missing file": ("6-paths", lambda tmp_path: [tmp_path / "nothere.npz"], r"not found at .*VISLA_EDU_DATA"),
    "course name, empty data dir": ("6-paths", lambda tmp_path: ["03", "--data-dir", tmp_path],
                                    r"course file 03.npz not found in"),
    "data dir is a file": ("6-paths", _data_dir_is_file, r"is a regular file, not a folder"),
}


@pytest.mark.parametrize("command", ["info", "run"])
@pytest.mark.parametrize("name", list(PATH_CASES), ids=fz.ids(PATH_CASES))
def test_bad_paths(name, command, tmp_path, capsys):
    _, build, pattern = PATH_CASES[name]
    extra = ["--no-diagnostics"] if command == "info" else list(fz.RUN)
    fz.assert_one_line(fz.cli_run([command, *build(tmp_path), *extra], capsys, seconds=10), 2, pattern)


def test_unreadable_file_is_not_reported_as_missing(tmp_path, capsys, monkeypatch):
    """6-paths: an unreadable file is named as such (access refused by a patched os.access)."""
    path = fz.course_file(tmp_path)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if str(p) == str(path) else real_access(p, mode))
    fz.assert_one_line(fz.cli_run(["info", path], capsys), 2, r"permission denied \(this user cannot read it\)")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their permissions")
def test_unreadable_file_for_real(tmp_path, capsys):
    """6-paths: the same with real permissions (skipped as root)."""
    path = fz.course_file(tmp_path)
    path.chmod(0)
    fz.assert_one_line(fz.cli_run(["info", path], capsys), 2, r"permission denied")


# ======================================================================= random bytes (hypothesis)


@pytest.fixture(scope="module")
def stored_file(tmp_path_factory):
    """A stored (uncompressed) course file of the simulated drive, its bytes and its dataset."""
    path = fz.course_file(tmp_path_factory.mktemp("fuzz"))
    return path.read_bytes(), data.load(path)


_HYPOTHESIS = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                       suppress_health_check=[HealthCheck.function_scoped_fixture])


def _check_random_file(path, reference, capsys):
    """Random damage: one clear line (exit 2), or exit 0 with exactly the reference drive."""
    outcome = fz.cli_run(["info", path, "--no-diagnostics"], capsys, seconds=10)
    if outcome.code == 0:
        ds = data.load(path)
        for key in ("time_stamps", "linear_velocity", "angular_velocity", "K", "imu_T_cam", "obs_z", "obs_ids"):
            np.testing.assert_array_equal(getattr(ds, key), getattr(reference, key))
        return
    fz.assert_one_line(outcome, 2, re.escape(str(path)))


@_HYPOTHESIS
@given(edits=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.binary(min_size=1, max_size=8)),
                      min_size=1, max_size=4))
def test_random_bytes_overwritten(stored_file, edits, tmp_path, capsys):
    """byte-level: random bytes overwritten anywhere in a stored archive."""
    raw, reference = stored_file
    damaged = bytearray(raw)
    for where, new in edits:
        start = int(where * len(raw))
        damaged[start:start + len(new)] = new
    path = fz.write_bytes(tmp_path / "random.npz", bytes(damaged[: len(raw)]))
    _check_random_file(path, reference, capsys)


@_HYPOTHESIS
@given(share=st.floats(0, 1, exclude_max=True))
def test_random_truncation(stored_file, share, tmp_path, capsys):
    """byte-level: the archive cut at a random length."""
    raw, reference = stored_file
    path = fz.write_bytes(tmp_path / "cut.npz", raw[: int(share * len(raw))])
    fz.assert_one_line(fz.cli_run(["info", path, "--no-diagnostics"], capsys, seconds=10), 2, re.escape(str(path)))


@settings(_HYPOTHESIS, max_examples=25)
@given(key=st.sampled_from(sorted(fz.course_arrays())), where=st.integers(0, 10**6), new=st.binary(min_size=1,
                                                                                                    max_size=8))
def test_random_member_bytes_in_a_valid_archive(key, where, new, tmp_path, capsys):
    """byte-level: damage inside one ``.npy`` member with valid CRCs: a clear line, or the file's own contents."""
    arrays = fz.course_arrays()
    member = bytearray(fz.npy_bytes(arrays[key]))
    start = where % len(member)
    member[start:start + len(new)] = new
    path = fz.write_zip(tmp_path / "member.npz", fz.zip_of(arrays, replace={key: bytes(member)}))
    outcome = fz.cli_run(["run", path, *fz.RUN, "--out", tmp_path / "r.npz"], capsys, seconds=10, measure=False)
    if outcome.code != 0:
        fz.assert_one_line(outcome, 2, re.escape(str(path)))
        return
    result = run.load_result(tmp_path / "r.npz")
    assert np.all(np.isfinite(result.world_T_imu)) and np.all(np.isfinite(result.pose_cov))
    with np.load(path) as f:  # correct: what numpy itself reads from the damaged file
        np.testing.assert_array_equal(data.load(path).to_dense_features(), f["features"].astype(float))


