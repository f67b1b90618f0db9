"""Corrupted course files for the fuzz suite (tests/test_fuzz.py), made from SIMULATED drives only.

Every file starts from a small simulated drive (:func:`drive`) written in the 2021+ course
layout (:func:`course_arrays`); a case changes the arrays (:data:`ARRAY_CASES`) or the bytes
of the archive (:func:`write_zip` writes zip archives by hand, so a test can forge what
numpy and zipfile would never write: a key stored twice, a header that declares 7 TiB, a
member whose zip entry inflates to 1 GiB).

Each array case is ``(issue class, change, expected message regex)``. The classes follow
issue 10: ``1-results-lost``, ``2-traceback``, ``3-accepted-but-wrong``, ``4-settings``,
``5-unbounded-work``, ``6-paths``.

The harness at the end runs the command line in process (:func:`cli_run`: exit status,
output, peak traced memory, wall time, under a time limit) and checks the one-line error
(:func:`assert_one_line`).
"""

import contextlib
import functools
import io
import os
import re
import signal
import struct
import time
import tracemalloc
import zlib
from dataclasses import dataclass

import numpy as np

from visla_edu import cli, lie, simulate

#: Unix time of the first frame (course files store Unix seconds).
T0 = 1.37e9


@functools.cache
def drive(seed=0):
    """A tiny simulated drive (60 frames, ~150 landmarks) with Unix-time stamps."""
    dataset = simulate.simulate_drive("tiny", seed=seed)
    dataset.time_stamps = dataset.time_stamps + T0
    return dataset


def course_arrays(dataset=None, fmt="2021+"):
    """The arrays of a course file of ``dataset`` (default :func:`drive`), fresh copies."""
    ds = dataset if dataset is not None else drive()
    arrays = {
        "time_stamps": np.array(ds.time_stamps, dtype=float)[None, :],
        "features": ds.to_dense_features(),
        "linear_velocity": np.array(ds.linear_velocity, dtype=float).T.copy(),
        "angular_velocity": np.array(ds.angular_velocity, dtype=float).T.copy(),
        "K": np.array(ds.K, dtype=float),
        "b": np.array(float(ds.b)),
        "imu_T_cam": np.array(ds.imu_T_cam, dtype=float),
    }
    if fmt == "2019":
        arrays["rotational_velocity"] = arrays.pop("angular_velocity")
        arrays["cam_T_imu"] = lie.se3_inv(arrays.pop("imu_T_cam"))
    return arrays


def write_npz(path, arrays, compressed=False):
    """``arrays`` as an ``.npz`` at ``path`` (numpy's own writer); returns ``path``."""
    with open(path, "wb") as f:
        (np.savez_compressed if compressed else np.savez)(f, **arrays)
    return path


def npy_bytes(array):
    """The ``.npy`` file of ``array`` as bytes (C or Fortran order as the array is)."""
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def npy_header(shape, dtype=np.float64, fortran_order=False):
    """Only the magic string and header of an ``.npy`` declaring ``shape`` (no data)."""
    buffer = io.BytesIO()
    header = {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": fortran_order,
              "shape": tuple(shape)}
    np.lib.format.write_array_header_1_0(buffer, header)
    return buffer.getvalue()


@dataclass
class Raw:
    """A zip member given as its stored bytes: ``data`` (compressed if ``method`` is 8), sizes, CRC."""

    data: bytes
    file_size: int
    crc: int = 0
    method: int = 8


def deflated(payload):
    """A :class:`Raw` deflate member of ``payload`` (bytes), with its true size and CRC."""
    c = zlib.compressobj(6, zlib.DEFLATED, -15)
    return Raw(c.compress(payload) + c.flush(), len(payload), zlib.crc32(payload))


@functools.cache
def inflating_member(header, total=2**30):
    """A deflate member that starts with ``header`` and inflates to ``total`` bytes (zeros after it).

    Built from one compressed block of 16 MiB of zeros repeated (a full flush resets the
    compressor, so every block compresses to the same bytes): about 1 MB on disk, 1 GiB
    inflated. The CRC is not computed (the loader must refuse the member before reading it).
    """
    block = 2**24
    assert total % block == 0
    c = zlib.compressobj(6, zlib.DEFLATED, -15)
    first = c.compress(header + bytes(block - len(header))) + c.flush(zlib.Z_FULL_FLUSH)
    zeros = c.compress(bytes(block)) + c.flush(zlib.Z_FULL_FLUSH)
    return Raw(first + zeros * (total // block - 1) + c.flush(), total)


def write_zip(path, members):
    """A zip archive written by hand: ``members`` is a list of ``(name, bytes or Raw)``.

    Names may repeat (a key stored twice). Sizes of 4 GiB and more get zip64 extra fields,
    so an entry may declare any uncompressed size. Returns ``path``.
    """
    out, central = io.BytesIO(), []
    for name, member in members:
        raw = member if isinstance(member, Raw) else Raw(member, len(member), zlib.crc32(member), 0)
        offset = out.tell()
        extra, csize, usize = _zip64_extra(raw)
        out.write(struct.pack("<IHHHHHIIIHH", 0x04034B50, 45, 0, raw.method, 0, 0x21, raw.crc, csize, usize,
                              len(name), len(extra)) + name.encode() + extra + raw.data)
        central.append(struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 45, 45, 0, raw.method, 0, 0x21, raw.crc, csize,
                                   usize, len(name), len(extra), 0, 0, 0, 0, offset) + name.encode() + extra)
    start = out.tell()
    directory = b"".join(central)
    out.write(directory)
    out.write(struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(central), len(central), len(directory), start, 0))
    path.write_bytes(out.getvalue())
    return path


def _zip64_extra(raw):
    if raw.file_size < 2**32 - 1 and len(raw.data) < 2**32 - 1:
        return b"", len(raw.data), raw.file_size
    return struct.pack("<HHQQ", 1, 16, raw.file_size, len(raw.data)), 0xFFFFFFFF, 0xFFFFFFFF


def zip_of(arrays, replace=None, append=()):
    """Members of ``arrays`` as ``(name, npy bytes)``, with members replaced or appended."""
    members = [(f"{k}.npy", (replace or {}).get(k, npy_bytes(v))) for k, v in arrays.items()]
    return members + list(append)


# --------------------------------------------------------------------------- changes of the arrays


def _set(key, value):
    def change(arrays):
        arrays[key] = np.asarray(value(arrays[key]) if callable(value) else value)
    return change


def _entry(key, index, value):
    def change(arrays):
        arrays[key] = arrays[key].copy()
        arrays[key][index] = value
    return change


def _scale_stamps(factor):
    def change(arrays):
        stamps = arrays["time_stamps"]
        arrays["time_stamps"] = (stamps - stamps[0, 0]) * factor + stamps[0, 0] * factor
    return change


def _gap(seconds, frame=30):
    def change(arrays):
        arrays["time_stamps"] = arrays["time_stamps"].copy()
        arrays["time_stamps"][0, frame:] += seconds
    return change


def _translation(key, t):
    def change(arrays):
        arrays[key] = arrays[key].copy()
        arrays[key][:3, 3] = t
    return change


def _focal(f):
    def change(arrays):
        arrays["K"] = arrays["K"].copy()
        arrays["K"][0, 0] = arrays["K"][1, 1] = f
    return change


def square_drive_arrays():
    """Course arrays of a drive cut to M = T (the first T landmarks seen), contiguous tracks."""
    arrays = course_arrays(drive(1))
    T = arrays["features"].shape[2]
    seen = np.flatnonzero((arrays["features"][0] != -1).any(axis=1))
    arrays["features"] = np.ascontiguousarray(arrays["features"][:, seen[:T], :])
    return arrays


def crowded_arrays(num_landmarks=3000):
    """Course arrays where every one of ``num_landmarks`` landmarks is seen in every frame (plausible pixels)."""
    arrays = course_arrays()
    T = arrays["features"].shape[2]
    rng = np.random.default_rng(5)
    uL, v = rng.uniform(100, 1300, (num_landmarks, T)), rng.uniform(50, 400, (num_landmarks, T))
    arrays["features"] = np.stack([uL, v, uL - rng.uniform(1, 50, (num_landmarks, T)), v])
    return arrays


def _marker(value):
    def change(arrays):
        arrays["features"] = np.where(arrays["features"] == -1, value, arrays["features"])
    return change


def _swap_square(arrays):
    square = square_drive_arrays()
    arrays.update(square)
    arrays["features"] = np.ascontiguousarray(square["features"].transpose(0, 2, 1))


#: name -> (issue class, change of the course arrays, regex the one-line error must match)
ARRAY_CASES = {
    # time units, gaps and order: the messages the issue asks for
    "stamps in milliseconds": ("2-traceback", _scale_stamps(1e3), r"look like milliseconds.*time_stamps / 1e3"),
    "stamps in nanoseconds": ("2-traceback", _scale_stamps(1e9), r"look like nanoseconds"),
    "stamps in microseconds": ("2-traceback", _scale_stamps(1e6), r"look like microseconds"),
    "gap of 1e6 s": ("2-traceback", _gap(1e6), r"gap of 1e\+06 s between frames 29 and 30.*Split the drive"),
    "gap of 60 s": ("2-traceback", _gap(60.0, 10), r"gap of 60.1\d* s between frames 9 and 10"),
    "nan stamp": ("2-traceback", _entry("time_stamps", (0, 7), np.nan), r"non-finite value nan at index \(0, 7\)"),
    "repeated stamp": ("2-traceback", _set("time_stamps", lambda s: np.insert(s[:, :-1], 7, s[0, 6], axis=1)),
                       r"time_stamps\[0, 7\] = .* is not after time_stamps\[0, 6\]"),
    "stamps backwards": ("2-traceback", _set("time_stamps", lambda s: s[:, ::-1].copy()), r"strictly increasing"),
    "nan velocity": ("2-traceback", _entry("linear_velocity", (2, 9), np.nan), r"'linear_velocity'.*nan.*\(2, 9\)"),
    "speed 1e4 m/s": ("2-traceback", _entry("linear_velocity", (0, 12), 1e4), r"frame 12 .*343 m/s.*km/h"),
    "angular rate 1e3 rad/s": ("2-traceback", _entry("angular_velocity", (2, 3), 1e3), r"frame 3 .*35 rad/s"),
    "velocity T mismatch": ("2-traceback", _set("linear_velocity", lambda v: v[:, :-1]), r"expected shape \(3, 60\)"),
    # accepted but wrong, before issue 10
    "uint16 features": ("3-accepted-but-wrong", _set("features", lambda f: np.clip(f, 0, None).astype(np.uint16)),
                        r"dtype uint16, which cannot hold -1"),
    "boolean features": ("3-accepted-but-wrong", _set("features", lambda f: f > 0),
                         r"dtype bool, which cannot hold -1"),
    "uint8 features": ("3-accepted-but-wrong", _set("features", lambda f: np.clip(f, 0, 255).astype(np.uint8)),
                       r"cannot hold -1"),
    "complex features": ("3-accepted-but-wrong", _set("features", lambda f: f.astype(complex)), r"real numbers"),
    "skewed K": ("3-accepted-but-wrong", _entry("K", (0, 1), 2.5), r"skew K\[0, 1\] = 2.5.*has none"),
    "focal 1e300": ("3-accepted-but-wrong", _focal(1e300), r"focal length fsu = K\[0, 0\] = 1e\+300 px is implausible"),
    "focal 1e-12": ("3-accepted-but-wrong", _focal(1e-12), r"focal length .* 1e-12 px is implausible"),
    "focal in mm (4.7)": ("3-accepted-but-wrong", _focal(4.7), r"off the optical axis.*focal length is too small"),
    "aspect 10": ("3-accepted-but-wrong", _entry("K", (1, 1), 5500.0), r"fsv / fsu = 10 is implausible"),
    "principal point 1e9": ("3-accepted-but-wrong", _entry("K", (0, 2), 1e9),
                            r"principal point cu .* outside any image"),
    "principal point off the pixels": ("3-accepted-but-wrong", _entry("K", (1, 2), 15000.0),
                                       r"(principal point cv = 15000 px lies outside the observed pixels"
                                       r"|off the optical axis)"),
    "principal point below the image": ("3-accepted-but-wrong", _entry("K", (1, 2), 2000.0),
                                        r"principal point cv = 2000 px lies outside the observed pixels"),
    "baseline 600 m": ("3-accepted-but-wrong", _set("b", 600.0), r"baseline is 600 m.*millimetres"),
    "baseline 1e-300": ("3-accepted-but-wrong", _set("b", 1e-300), r"baseline is 1e-300 m, outside"),
    "extrinsic 1e9 m": ("3-accepted-but-wrong", _translation("imu_T_cam", [1e9, 0, 0]),
                        r"'imu_T_cam': the camera-IMU translation \|t\| is 1e\+09 m"),
    "extrinsic in mm": ("3-accepted-but-wrong", _translation("imu_T_cam", [1500.0, 0, -600.0]), r"millimetres"),
    "swapped axes M = T": ("3-accepted-but-wrong", _swap_square, r"looks transposed: M = T = 60"),
    "swapped axes M != T": ("3-accepted-but-wrong", _set("features", lambda f: f.transpose(0, 2, 1).copy()),
                            r"axes look swapped"),
    "nan pixel": ("3-accepted-but-wrong", _entry("features", (1, 3, 5), np.inf), r"non-finite value inf"),
    "missing marked -999": ("3-accepted-but-wrong", _marker(-999.0), r"uL = -999 px, far outside the image"),
    "missing marked 0": ("3-accepted-but-wrong", _marker(0.0), r"observations are \[x, x, x, x\] with x = 0, which "
                                                               r"looks like a marker"),
    "missing marked 5000": ("3-accepted-but-wrong", _marker(5000.0), r"(marker|off the optical axis)"),
    "negative pixel": ("3-accepted-but-wrong", _entry("features", (0, 0, 0), -50.0),
                       r"(uL = -50 px, far outside the image|partly observed)"),
}


# --------------------------------------------------------------------------- the harness


MEMORY_BUDGET = 96 * 2**20
NO_READ_BUDGET = 8 * 2**20
TIME_LIMIT = 20.0
#: A deadreckoning run without the extrinsic check: the fastest full run of the CLI.
RUN = ("--mode", "deadreckon", "--quiet", "--set", "extrinsic_correction=none")


class _Timeout(BaseException):
    """Raised by the alarm (a BaseException, so the CLI's boundary cannot swallow it)."""


@dataclass
class Outcome:
    """What one in-process command line run did."""

    code: int
    out: str
    err: str
    peak_bytes: int
    seconds: float


@contextlib.contextmanager
def alarm(seconds):
    """Raise :class:`_Timeout` in the main thread after ``seconds`` (SIGALRM)."""
    def expire(signum, frame):
        raise _Timeout(f"the case ran longer than {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def cli_run(argv, capsys, seconds=TIME_LIMIT, measure=True):
    """``cli.main(argv)`` in process: exit status, output, peak traced memory, wall time.

    ``measure=False`` skips tracemalloc (it slows imports and plotting several times over);
    the peak is then reported as 0.
    """
    if measure:
        tracemalloc.start()
    start = time.perf_counter()
    try:
        with alarm(seconds):
            try:
                code = cli.main([str(a) for a in argv])
            except SystemExit as exc:
                code = exc.code
        peak = tracemalloc.get_traced_memory()[1] if measure else 0
    finally:
        if measure:
            tracemalloc.stop()
    out, err = capsys.readouterr()
    return Outcome(code, out, err, peak, time.perf_counter() - start)


def assert_one_line(outcome, code, pattern, budget=MEMORY_BUDGET):
    """Exit status ``code``, exactly one line on stderr matching ``pattern``, no traceback, within budget."""
    lines = outcome.err.strip().splitlines()
    assert outcome.code == code, f"exit {outcome.code}, expected {code}: {outcome.err}"
    assert len(lines) == 1 and "Traceback" not in outcome.err, outcome.err
    assert re.search(pattern, lines[0]), lines[0]
    assert outcome.peak_bytes < budget, f"peak memory {outcome.peak_bytes / 2**20:.1f} MiB"
    return lines[0]


def assert_ok(outcome):
    """Exit status 0, no traceback, within the memory budget."""
    assert outcome.code == 0, outcome.err
    assert "Traceback" not in outcome.err and outcome.peak_bytes < MEMORY_BUDGET


def course_file(tmp_path, arrays=None, name="drive.npz", compressed=False):
    """A course file of :func:`course_arrays` (or ``arrays``) in ``tmp_path``."""
    return write_npz(tmp_path / name, course_arrays() if arrays is None else arrays, compressed)


def ids(cases):
    """Test ids ``<class>/<name>`` of a case table whose values start with the class."""
    return [f"{case[0]}/{name}" for name, case in cases.items()]


def write_bytes(path, raw):
    """``raw`` to ``path``; returns ``path``."""
    path.write_bytes(raw)
    return path


def truncated_file(tmp_path, share):
    """A compressed course file of the drive cut to ``share`` of its bytes."""
    path = course_file(tmp_path, compressed=True)
    raw = path.read_bytes()
    return write_bytes(path, raw[: int(len(raw) * share)])


def fifo(tmp_path, name="drive.npz"):
    """A FIFO (named pipe) where a course file is expected."""
    path = tmp_path / name
    os.mkfifo(path)
    return path
