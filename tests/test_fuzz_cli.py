"""Fuzz suite of issue 10, command-line side: outputs, lost files, filter failures, settings, work.

Every file is made from a SIMULATED drive (tests/fuzzgen.py). Each case asserts ONE clear line
on stderr with the documented exit status (2 bad input, 1 filter failure, 3 internal error,
130 Ctrl-C) or a finite result, and that no previous result is lost; a few run through a
subprocess to prove there is no traceback. Test ids start with the class of issue 10.
tests/test_fuzz_inputs.py has the corrupted files.
"""

import dataclasses
import errno
import os
import re
import signal
import subprocess
import sys

import numpy as np
import pytest

import fuzzgen as fz  # tests/fuzzgen.py
from visla_edu import data, ekf, motion, run
from visla_edu.run import workload
from visla_edu.course import release
from visla_edu.data import _features
from visla_edu.filters import _state

# ======================================================================= outputs (class 1)


def _same_as_input(tmp_path, path):
    return ["--out", path]


def _symlink_to_input(tmp_path, path):
    (tmp_path / "link.npz").symlink_to(path)
    return ["--out", tmp_path / "link.npz"]


def _relative_to_input(tmp_path, path):
    (tmp_path / "sub").mkdir()
    return ["--out", tmp_path / "sub" / ".." / path.name]


def _hard_link_to_input(tmp_path, path):
    os.link(path, tmp_path / "twin.npz")
    return ["--out", tmp_path / "twin.npz"]


def _out_fifo(tmp_path, path):
    os.mkfifo(tmp_path / "r.npz")
    return ["--out", tmp_path / "r.npz"]


def _folder_is_file(tmp_path, path):
    return ["--out", path / "r.npz"]


#: name -> (class, argv builder(tmp_path, input path), regex)
OUTPUT_CASES = {
    "--out is the input": ("1-results-lost", _same_as_input, r"is the input file .*drive.npz; writing there would"),
    "--out links to the input": ("1-results-lost", _symlink_to_input, r"is the input file"),
    "--out reaches the input through ..": ("1-results-lost", _relative_to_input, r"is the input file"),
    "--out is a hard link of the input": ("1-results-lost", _hard_link_to_input, r"is the input file"),
    "--out is a directory": ("1-results-lost", lambda tmp_path, p: ["--out", tmp_path],
                             r"--out .*: is a directory; give a file name"),
    "--out without .npz": ("1-results-lost", lambda tmp_path, p: ["--out", tmp_path / "result"],
                           r"must end in .npz; e.g. --out .*result.npz"),
    "--out in a missing folder": ("1-results-lost", lambda tmp_path, p: ["--out", tmp_path / "no" / "r.npz"],
                                  r"the folder .*no does not exist"),
    "--out inside a file": ("1-results-lost", _folder_is_file, r"drive.npz is a regular file, not a folder"),
    "--out is a FIFO": ("1-results-lost", _out_fifo, r"is a FIFO \(named pipe\); visla-edu writes a regular file"),
    "--plot with a bad suffix": ("1-results-lost", lambda tmp_path, p: ["--plot", tmp_path / "map.xyz"],
                                 r"--plot .*map.xyz: the file name must end in .png, .pdf, .svg"),
    "--plot equals --out": ("1-results-lost", lambda tmp_path, p: ["--out", tmp_path / "a.npz", "--plot",
                                                                   tmp_path / "a.npz"], r"is also the --plot file"),
    "--plot is the --out file": ("1-results-lost",
                                 lambda tmp_path, p: ["--out", tmp_path / "a.png", "--plot", tmp_path / "a.png"],
                                 r"--out .*a.png: the file name must end in .npz"),
    "--plot is the input": ("1-results-lost", lambda tmp_path, p: ["--plot", p], r"--plot .*drive.npz: the file name "
                                                                                r"must end in .png"),
}


@pytest.mark.parametrize("name", list(OUTPUT_CASES), ids=fz.ids(OUTPUT_CASES))
def test_outputs_are_checked_before_any_work(name, tmp_path, capsys, monkeypatch):
    _, build, pattern = OUTPUT_CASES[name]
    path = fz.course_file(tmp_path)
    before = path.read_bytes()
    argv = build(tmp_path, path)
    monkeypatch.setattr(run, "run_filter", _must_not_run)
    fz.assert_one_line(fz.cli_run(["run", path, *fz.RUN, *argv], capsys, measure=False), 2, pattern)
    assert path.read_bytes() == before


def test_unwritable_folder_is_reported_before_any_work(tmp_path, capsys, monkeypatch):
    """1-results-lost: a folder this user cannot write to (patched os.access)."""
    path = fz.course_file(tmp_path)
    (tmp_path / "ro").mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if str(p).endswith("ro") else real_access(p, mode))
    monkeypatch.setattr(run, "run_filter", _must_not_run)
    argv = ["run", path, *fz.RUN, "--out", tmp_path / "ro" / "r.npz"]
    fz.assert_one_line(fz.cli_run(argv, capsys, measure=False), 2, r"the folder .*ro is not writable by this user")


def _must_not_run(*args, **kwargs):
    raise AssertionError("the filter ran before the output paths were checked")


def test_the_path_printed_is_the_path_written(tmp_path, capsys):
    """1-results-lost: "saved X" names exactly the files written (R.NPZ stays R.NPZ)."""
    path = fz.course_file(tmp_path)
    outcome = fz.cli_run(["run", path, *fz.RUN, "--out", tmp_path / "R.NPZ", "--plot", tmp_path / "map.svg"], capsys,
                      measure=False)
    fz.assert_ok(outcome)
    assert f"saved {tmp_path / 'R.NPZ'}\n" in outcome.out and f"saved {tmp_path / 'map.svg'}\n" in outcome.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["R.NPZ", "drive.npz", "map.svg"]


# ======================================================================= no lost file (class 1)


def _good_result(tmp_path, capsys):
    path = fz.course_file(tmp_path)
    out = tmp_path / "r.npz"
    fz.assert_ok(fz.cli_run(["run", path, *fz.RUN, "--out", out], capsys, measure=False))
    return path, out, out.read_bytes()


def _writer_dies(exception):
    """A ``savez_compressed`` that writes half a file, then raises ``exception``."""
    def savez(file, **arrays):
        file.write(b"PK\x03\x04" + bytes(1000))
        raise exception
    return savez


@pytest.mark.parametrize("exception, code, pattern", [
    (KeyboardInterrupt(), 130, r"interrupted \(Ctrl-C\); files being written were left as they were"),
    (OSError(errno.ENOSPC, "No space left on device"), 1, r"No space left on device"),
    (MemoryError(), 1, r"out of memory"),
], ids=["1-results-lost/killed mid-write", "1-results-lost/disk full mid-write", "1-results-lost/no memory mid-write"])
def test_a_failed_write_keeps_the_previous_result(exception, code, pattern, tmp_path, capsys, monkeypatch):
    path, out, good = _good_result(tmp_path, capsys)
    monkeypatch.setattr(np, "savez_compressed", _writer_dies(exception))
    fz.assert_one_line(fz.cli_run(["run", path, *fz.RUN, "--out", out], capsys, measure=False), code, pattern)
    assert out.read_bytes() == good
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drive.npz", "r.npz"]  # no temporary file left


def test_a_failed_rename_keeps_the_previous_figure(tmp_path, capsys, monkeypatch):
    """1-results-lost: the process dies between writing the new figure and renaming it."""
    path = fz.course_file(tmp_path)
    figure = tmp_path / "map.png"
    fz.assert_ok(fz.cli_run(["run", path, *fz.RUN, "--plot", figure], capsys, measure=False))
    good = figure.read_bytes()

    def dies(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", dies)
    fz.assert_one_line(fz.cli_run(["run", path, *fz.RUN, "--plot", figure], capsys, measure=False), 130, r"interrupted")
    assert figure.read_bytes() == good and sorted(p.name for p in tmp_path.iterdir()) == ["drive.npz", "map.png"]


def test_an_interrupted_dataset_save_keeps_the_previous_file(tmp_path, monkeypatch):
    """1-results-lost: data.save dies midway; the previous dataset file is intact and still loads."""
    target = data.save(fz.drive(), tmp_path / "saved.npz")
    good = target.read_bytes()
    monkeypatch.setattr(np, "savez_compressed", _writer_dies(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        data.save(fz.drive(2), target)
    assert target.read_bytes() == good and [p.name for p in tmp_path.iterdir()] == ["saved.npz"]
    assert data.load(target).num_observations == fz.drive().num_observations


def test_an_interrupted_release_keeps_whole_notebooks(tmp_path, monkeypatch):
    """1-results-lost: a release that dies while writing leaves every student notebook whole."""
    nbformat = pytest.importorskip("nbformat")
    src, dst = tmp_path / "solutions", tmp_path / "notebooks"
    src.mkdir()
    cell = nbformat.v4.new_code_cell("x = 1\n### BEGIN SOLUTION\ny = 2\n### END SOLUTION")
    nb = nbformat.v4.new_notebook(cells=[cell])
    nbformat.write(nb, src / "a.ipynb")
    release.make_student_notebooks(src, dst)
    good = (dst / "a.ipynb").read_bytes()
    nb.cells[0].source = nb.cells[0].source.replace("x = 1", "x = 3")
    nbformat.write(nb, src / "a.ipynb")
    monkeypatch.setattr(os, "fsync", _raise(KeyboardInterrupt))
    with pytest.raises(KeyboardInterrupt):
        release.make_student_notebooks(src, dst)
    assert (dst / "a.ipynb").read_bytes() == good and sorted(p.name for p in dst.iterdir()) == [".release.json",
                                                                                                   "a.ipynb"]


def _raise(exception_type):
    def fail(*args, **kwargs):
        raise exception_type
    return fail


# ======================================================================= failures of the filter (class 2)


def _fail_at_call(n, exception):
    """An ``imu_step`` that raises ``exception`` at its n-th call (frame n)."""
    real, calls = motion.imu_step, []

    def step(*args, **kwargs):
        calls.append(1)
        if len(calls) == n:
            raise exception
        return real(*args, **kwargs)
    return step


def _diverging_dataset(monkeypatch):
    """A dataset that slipped past the loader: a velocity of 1e200 m/s at frame 10 (real divergence)."""
    ds = fz.drive()
    v = ds.linear_velocity.copy()
    v[10, 0] = 1e200
    diverging = dataclasses.replace(ds, linear_velocity=v, extra={})
    monkeypatch.setattr(data, "load", lambda *a, **k: diverging)


FAILURE_CASES = {
    "divergence (velocity 1e200 past the loader)": (
        lambda mp: _diverging_dataset(mp), [], 1,
        r"the filter diverged: .*frame 11.*likely cause: .*'linear_velocity' at frame 10 has magnitude 1e\+200"),
    "singular matrix in the filter": (
        lambda mp: mp.setattr(motion, "imu_step", _fail_at_call(5, np.linalg.LinAlgError("Singular matrix"))), [], 1,
        r"the filter failed: singular .*\(Singular matrix\); the step into frame 5 lasts"),
    "overflow in the filter": (
        lambda mp: mp.setattr(motion, "imu_step", _fail_at_call(7, OverflowError("math range error"))), [], 1,
        r"numerical failure \(OverflowError: math range error\); the step into frame 7"),
    "out of memory in the dense filter": (
        lambda mp: mp.setattr(_state.ActiveSet, "dense", _raise(MemoryError)), ["--mode", "slam", "--dense"], 1,
        r"out of memory .*--landmark-stride"),
    "singular innovation covariance in SLAM": (
        lambda mp: mp.setattr(ekf, "gain_update", _raise(np.linalg.LinAlgError)), ["--mode", "slam"], 1,
        r"the filter diverged: .*innovation covariance not positive definite at frame \d+"),
    "Ctrl-C during the run": (
        lambda mp: mp.setattr(motion, "imu_step", _fail_at_call(9, KeyboardInterrupt())), [], 130,
        r"^visla-edu run: interrupted \(Ctrl-C\)"),
    "internal error": (
        lambda mp: mp.setattr(motion, "imu_step", _fail_at_call(3, KeyError("oops"))), [], 3,
        r"internal error \(KeyError: 'oops'\); this is a bug in visla-edu, please report it with the command "
        r"line and the traceback of --debug"),
}


@pytest.mark.parametrize("name", list(FAILURE_CASES), ids=[f"2-traceback/{n}" for n in FAILURE_CASES])
def test_failures_are_one_line(name, tmp_path, capsys, monkeypatch):
    patch, extra, code, pattern = FAILURE_CASES[name]
    path = fz.course_file(tmp_path)
    patch(monkeypatch)
    argv = ["run", path, *fz.RUN, *extra]
    fz.assert_one_line(fz.cli_run(argv, capsys, measure=False), code, pattern)


@pytest.mark.parametrize("how", ["--debug", "VISLA_EDU_DEBUG=1"])
def test_debug_adds_the_traceback(how, tmp_path, capsys, monkeypatch):
    """2-traceback: the traceback is there when asked for, after the one line."""
    path = fz.course_file(tmp_path)
    monkeypatch.setattr(motion, "imu_step", _fail_at_call(3, KeyError("oops")))
    argv = ["run", path, *fz.RUN]
    if how == "--debug":
        argv.append("--debug")
    else:
        monkeypatch.setenv("VISLA_EDU_DEBUG", "1")
    outcome = fz.cli_run(argv, capsys, measure=False)
    assert outcome.code == 3 and "please report" in outcome.err.splitlines()[0]
    assert "Traceback (most recent call last)" in outcome.err and "KeyError: 'oops'" in outcome.err


def test_absurd_calibration_past_the_loader_is_refused_before_the_filter(tmp_path, capsys, monkeypatch):
    """3-accepted-but-wrong: an in-memory dataset with a focal length of 1e300 never runs (it used to exit 0)."""
    ds = fz.drive()
    K = ds.K.copy()
    K[0, 0] = K[1, 1] = 1e300
    monkeypatch.setattr(data, "load", lambda *a, **k: dataclasses.replace(ds, K=K, extra={}))
    argv = ["run", "sim-tiny", "--mode", "slam", "--quiet", "--set", "extrinsic_correction=none"]
    fz.assert_one_line(fz.cli_run(argv, capsys, measure=False), 2,
                    r"cannot run the filter: .*focal length fsu .* 1e\+300 px is implausible")


# ======================================================================= settings (class 4)


#: name -> (argv after the dataset, exit status, regex or None for success)
SETTING_CASES = {
    "boolean typo": (["--set", "landmark_cross_covariance=Treu"], 2,
                     r"landmark_cross_covariance needs a bool .*'Treu'"),
    "boolean yes": (["--set", "skip_repeated_frames=yes"], 0, None),
    "boolean 0": (["--set", "landmark_cross_covariance=0"], 0, None),
    "imu_lag 5000": (["--set", "imu_lag=5000"], 2, r"imu_lag must be an integer in \[-2, 2\].*got 5000"),
    "imu_lag -2": (["--set", "imu_lag=-2"], 0, None),
    "imu_lag 0.5": (["--set", "imu_lag=0.5"], 2, r"imu_lag needs an int"),
    "stride 2.0": (["--set", "landmark_stride=2.0"], 2, r"landmark_stride needs an int .*'2.0'"),
    "stride 0 (option)": (["--landmark-stride", "0"], 2, r"landmark_stride must be an integer in \[1, 1000000\]"),
    "stride twice": (["--set", "landmark_stride=2", "--landmark-stride", "3"], 2, r"landmark_stride is given twice"),
    "blas threads 0": (["--blas-threads", "0"], 2, r"--blas-threads: expected a positive integer or 'none'"),
    "blas threads none": (["--blas-threads", "none"], 0, None),
    "blas_threads as a setting": (["--set", "blas_threads=none"], 2, r"not a filter setting; use --blas-threads"),
    "huge velocity noise": (["--set", "sigma_linear_velocity=1e300"], 2, r"must be a number in \[0, 50\] m/s"),
    "overflowing literal": (["--set", "sigma_angular_velocity=1e400"], 2, r"needs a float .*'1e400'"),
    "nan noise": (["--set", "sigma_pixel=nan"], 2, r"sigma_pixel needs a float"),
    "negative prior": (["--set", "landmark_prior_sigma=-1"], 2,
                       r"landmark_prior_sigma must be a number in \(0, 10000\]"),
    "gate probability 0": (["--set", "gate_probability=0"], 2, r"gate_probability must be a number in \(0, 1\]"),
    "unknown setting": (["--set", "sigma_pxl=2"], 2, r"unknown setting 'sigma_pxl'; settings are sigma_pixel"),
    "no equals sign": (["--set", "sigma_pixel"], 2, r"expected NAME=VALUE"),
    "unknown correction": (["--set", "extrinsic_correction=flip"], 2, r"extrinsic_correction must be one of 'auto', 'none', 'flip_yz'"),
    "none for a number": (["--set", "sigma_pixel=none"], 2, r"sigma_pixel needs a float"),
    "dense with vio": (["--mode", "vio", "--dense"], 2, r"--dense is the textbook joint filter and needs --mode slam"),
}


@pytest.mark.parametrize("name", list(SETTING_CASES), ids=[f"4-settings/{n}" for n in SETTING_CASES])
def test_settings_are_strict(name, tmp_path, capsys):
    extra, code, pattern = SETTING_CASES[name]
    argv = ["run", fz.course_file(tmp_path), "--mode", "deadreckon", "--quiet", *extra]
    if "extrinsic_correction" not in " ".join(extra):
        argv += ["--set", "extrinsic_correction=none"]
    if "--mode" in extra:
        argv.remove("--mode"), argv.remove("deadreckon")
    outcome = fz.cli_run(argv, capsys, measure=False)
    if pattern is None:
        fz.assert_ok(outcome)
    else:
        fz.assert_one_line(outcome, code, pattern)


def test_port_out_of_range_is_refused(capsys):
    """4-settings: the stepper's port is checked before a server starts."""
    fz.assert_one_line(fz.cli_run(["stepper", "--port", "70000"], capsys), 2, r"TCP port number from 1 to 65535")


# ======================================================================= unbounded work (class 5)


def test_dense_run_past_the_limits_is_refused_then_forced(tmp_path, capsys, monkeypatch):
    """5-unbounded-work: past the limit (shrunk for the tiny drive) refused with a stride; --force runs."""
    path = fz.course_file(tmp_path)
    monkeypatch.setattr(workload, "WORK_LIMIT_BYTES", 2**16)  # the tiny drive's 2 D^2 8 is about 3 MiB
    argv = ["run", path, "--mode", "slam", "--dense", "--quiet", "--set", "extrinsic_correction=none"]
    outcome = fz.cli_run(argv, capsys, measure=False)
    line = fz.assert_one_line(outcome, 2, r"--mode slam --dense on drive with landmark stride 1 would need "
                                          r"[\d.]+ MiB of memory "
                                       r"\(limit 64.0 KiB\); use --landmark-stride \d+ \(or more\).*--force")
    assert "slam (dense): states up to 456 dimensions" in outcome.out and "mode slam" not in outcome.out  # not run
    stride = int(re.search(r"--landmark-stride (\d+)", line).group(1))
    config = run.FilterConfig(landmark_stride=stride)
    assert workload.estimate_work(data.load(path), "slam", config, dense=True).peak_bytes <= 2**16
    fz.assert_ok(fz.cli_run([*argv, "--force"], capsys, measure=False))


@pytest.mark.parametrize("mode", ["slam", "vio"])
def test_a_crowded_drive_is_refused_before_the_run(mode, tmp_path, capsys, monkeypatch):
    """5-unbounded-work: 3000 landmarks in every frame: hours and gigabytes, refused in a moment."""
    path = fz.course_file(tmp_path, fz.crowded_arrays())
    monkeypatch.setattr(run, "run_filter", _must_not_run)
    outcome = fz.cli_run(["run", path, "--mode", mode, "--quiet", "--set", "extrinsic_correction=none"], capsys,
                         measure=False, seconds=10)
    fz.assert_one_line(outcome, 2, rf"--mode {mode} on drive with landmark stride 1 would need .* GiB of memory .* "
                                   r"use --landmark-stride \d+ \(or more\)")
    assert re.search(rf"{mode}: states up to \d+ dimensions, updates up to (9000|12000) rows", outcome.out)


def test_too_many_observations_are_refused_while_reading(tmp_path, capsys, monkeypatch):
    """5-unbounded-work: a file with more observations than the limit stops at the limit."""
    monkeypatch.setattr(_features, "MAX_OBSERVATIONS", 5000)
    fz.assert_one_line(fz.cli_run(["info", fz.course_file(tmp_path, fz.crowded_arrays(200))], capsys), 2,
                       r"holds more than 5000 observations")


def test_a_file_name_too_long_for_the_folder(tmp_path, capsys, monkeypatch):
    """1-results-lost: a name the folder cannot hold (with its temporary file) is refused before the run."""
    monkeypatch.setattr(run, "run_filter", _must_not_run)
    out = tmp_path / ("r" * 250 + ".npz")
    fz.assert_one_line(fz.cli_run(["run", fz.course_file(tmp_path), *fz.RUN, "--out", out], capsys, measure=False), 2,
                       r"the file name is 254 bytes long, more than the \d+ this folder allows")


def test_release_into_a_file_is_refused(tmp_path, capsys):
    """6-paths: release --dst naming a file."""
    (tmp_path / "solutions").mkdir()
    (tmp_path / "notebooks").write_text("not a folder")
    argv = ["release", "--src", tmp_path / "solutions", "--dst", tmp_path / "notebooks"]
    fz.assert_one_line(fz.cli_run(argv, capsys, measure=False), 2, r"notebooks.* not a folder")


def test_dense_estimate_is_printed_and_within_limits_runs(tmp_path, capsys):
    """5-unbounded-work: a dense run within the limits prints its estimate and runs."""
    argv = ["run", fz.course_file(tmp_path), "--mode", "slam", "--dense", "--landmark-stride", "4", "--quiet",
            "--set", "extrinsic_correction=none"]
    outcome = fz.cli_run(argv, capsys, measure=False)
    fz.assert_ok(outcome)
    assert re.search(r"slam \(dense\): states up to \d+ dimensions, updates up to \d+ rows: about [\d.]+ \w+ of "
                     r"memory and \d+ s", outcome.out)


# ======================================================================= through a subprocess: no traceback


def _subprocess(argv, tmp_path, **kwargs):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(_ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "visla_edu", *map(str, argv)], capture_output=True, text=True,
                          timeout=60, env=env, cwd=tmp_path, **kwargs)


_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("case", ["2-traceback/truncated file", "4-settings/boolean typo"])
def test_subprocess_errors_are_one_line(case, tmp_path):
    if case.endswith("truncated file"):
        argv, pattern = ["info", fz.truncated_file(tmp_path, 0.5)], r"truncated, corrupt"
    else:
        argv, pattern = ["run", "sim-tiny", "--set", "vio_refine_landmarks=Flase"], r"needs a bool"
    done = _subprocess(argv, tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and re.search(pattern, done.stderr), done.stderr


#: A child process that runs ``python -m visla_edu`` (its ``__main__``, through runpy) on ``sys.argv[2:]`` and
#: blocks at one moment, ``sys.argv[1]``, after printing ``@@ blocked at MOMENT``: there the test sends a real
#: SIGINT. A blocked child reads its stdin until the test closes it, so no moment depends on the machine's speed.
_INTERRUPTED_CHILD = """
import atexit, importlib.abc, os, runpy, sys
import numpy as np
from visla_edu import run

moment, argv = sys.argv[1], sys.argv[2:]

def block(where=moment):
    print(f"@@ blocked at {where}", flush=True)
    sys.stdin.read()

class BlockImport(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "visla_edu.cli":
            block()

def make_filter(*args, real=run.make_filter, **kwargs):
    flt = real(*args, **kwargs)
    step = flt.step
    flt.step = lambda: (block() if flt.t == 5 else None, step())[1]
    return flt

def savez(file, *args, **kwargs):
    file.write(b"half a result")
    block()

def replace(src, dst, real=os.replace):
    real(src, dst)
    if os.path.basename(dst) == "r.npz":  # the result (not, e.g., a file of the user cache)
        block()

if moment == "import":
    assert "visla_edu.cli" not in sys.modules
    sys.meta_path.insert(0, BlockImport())
elif moment == "parse":
    from visla_edu import cli
    cli.build_parser = lambda real=cli.build_parser: (block(), real())[1]
elif moment == "run":
    run.make_filter = make_filter
elif moment == "save":
    np.savez_compressed = savez
elif moment == "renamed":
    os.replace = replace
elif moment == "exit":
    atexit.register(block)
sys.argv = ["visla-edu", *argv]
runpy.run_module("visla_edu", run_name="__main__", alter_sys=True)
"""

_INTERRUPTED = "interrupted (Ctrl-C); files being written were left as they were"
#: moment -> (exit status, the one line on stderr or None for none, whether --out keeps the previous bytes)
INTERRUPT_MOMENTS = {
    "import": (130, "visla-edu: interrupted (Ctrl-C) while starting; nothing was run", True),
    "parse": (130, f"visla-edu: {_INTERRUPTED}", True),
    "run": (130, f"visla-edu run: {_INTERRUPTED}", True),
    "save": (130, f"visla-edu run: {_INTERRUPTED}", True),
    "renamed": (130, f"visla-edu run: {_INTERRUPTED}", False),  # written whole before the Ctrl-C
    "exit": (0, None, False),  # the command was complete: the Ctrl-C changes nothing
}


def _blocked_child(moment, argv, tmp_path):
    """Start the child blocked at ``moment``; return it once it says so (the lines it printed until then)."""
    tests = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([_ROOT, tests, os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-u", "-c", _INTERRUPTED_CHILD, moment, *map(str, argv)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path)
    lines = []
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("@@ blocked at"):
            break
    return proc, lines


@pytest.mark.parametrize("moment", INTERRUPT_MOMENTS)
def test_ctrl_c_in_a_subprocess_keeps_the_previous_result(moment, tmp_path):
    """1-results-lost: a real SIGINT at each moment of `python -m visla_edu run`: exit 130 and one line, the
    previous result intact (or, once written whole, the new one), no temporary file, never a death by SIGINT."""
    status, line, kept = INTERRUPT_MOMENTS[moment]
    out = tmp_path / "r.npz"
    out.write_bytes(b"the previous result")
    proc, lines = _blocked_child(moment, ["run", "sim-tiny", "--mode", "slam", "--quiet", "--out", out], tmp_path)
    try:
        assert lines and lines[-1] == f"@@ blocked at {moment}\n", (lines, proc.stderr.read())
        proc.send_signal(signal.SIGINT)
        if moment == "exit":  # SIGINT is ignored by now: let the blocked exit handler go on
            proc.stdin.close()
        proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        proc.kill()
    assert proc.returncode == status and "Traceback" not in err, (proc.returncode, err)
    assert err.strip().splitlines() == ([line] if line else []), err
    assert (out.read_bytes() == b"the previous result") == kept
    if not kept:
        assert run.load_result(out).mode == "slam"
    assert [p.name for p in tmp_path.iterdir()] == ["r.npz"]


_DIVERGE = """
import dataclasses, sys
import fuzzgen as fz
from visla_edu import cli, data
ds = fz.drive()
v = ds.linear_velocity.copy()
v[10, 0] = 1e200
data.load = lambda *a, **k: dataclasses.replace(ds, linear_velocity=v, extra={})
sys.exit(cli.main(["run", "sim-tiny", "--mode", "vio", "--quiet", "--set", "extrinsic_correction=none"]))
"""


def test_divergence_in_a_subprocess_is_one_line_without_warnings(tmp_path):
    """2-traceback: a real divergence with numpy's overflow warnings: still one line on stderr, exit 1."""
    tests = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([_ROOT, tests, os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-c", _DIVERGE], capture_output=True, text=True, timeout=60, env=env,
                          cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Warning" not in done.stderr, done.stderr
    assert re.search(r"the filter diverged: sim-tiny: .* at frame 11.*likely cause: .*magnitude 1e\+200", done.stderr)


# ======================================================================= ground-truth inputs, trajectory outputs


def _poses_file(tmp_path, name="poses.txt"):
    from visla_edu import trajectory

    ds = fz.drive()
    return trajectory.write_kitti(tmp_path / name, data.kitti_poses_from_imu(ds.ground_truth.world_T_imu, ds.imu_T_cam))


def _trajectory_over_ground_truth(tmp_path, path):
    poses = _poses_file(tmp_path)
    return ["--ground-truth", poses, "--trajectory-out", poses], r"--trajectory-out .*poses.txt: is the input file"


def _trajectory_over_registered_ground_truth(tmp_path, path):
    registered = path.rename(tmp_path / "0020.npz")
    poses = _poses_file(tmp_path, "kitti_odometry_06_poses.txt")
    return ["--trajectory-out", poses, "--dataset-is", registered], r"is the input file .*kitti_odometry_06_poses.txt"


def _ground_truth_fifo(tmp_path, path):
    return ["--ground-truth", fz.fifo(tmp_path, "poses.txt")], r"poses.txt: KITTI poses.* is a FIFO"


def _ground_truth_folder(tmp_path, path):
    return ["--ground-truth", tmp_path], r"KITTI poses.* is a folder, not a file"


def _trajectory_unknown_format(tmp_path, path):
    return ["--trajectory-out", tmp_path / "t.csv"], r"unknown trajectory format '.csv'"


GROUND_TRUTH_CASES = {
    "--trajectory-out over the --ground-truth file": ("1-results-lost", _trajectory_over_ground_truth),
    "--trajectory-out over a registered ground truth": ("1-results-lost", _trajectory_over_registered_ground_truth),
    "--trajectory-out with an unknown suffix": ("1-results-lost", _trajectory_unknown_format),
    "--ground-truth is a FIFO": ("6-paths", _ground_truth_fifo),
    "--ground-truth is a folder": ("6-paths", _ground_truth_folder),
}


@pytest.mark.parametrize("name", list(GROUND_TRUTH_CASES), ids=fz.ids(GROUND_TRUTH_CASES))
def test_ground_truth_and_trajectory_paths(name, tmp_path, capsys, monkeypatch):
    path = fz.course_file(tmp_path)
    extra, pattern = GROUND_TRUTH_CASES[name][1](tmp_path, path)
    if "--dataset-is" in extra:
        path = extra.pop()
        extra.pop()
    monkeypatch.setattr(run, "run_filter", _must_not_run)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    fz.assert_one_line(fz.cli_run(["run", path, *fz.RUN, *extra], capsys, seconds=10, measure=False), 2, pattern)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before
