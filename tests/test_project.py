"""The course project's grader: ``visla-edu project grade`` runs students' filters with the library hidden.

One grading of many submissions on ``sim-tiny`` (module fixture): a filter written outside the
library (``project_fixtures/numpy_vio.py``, numpy only), PROJECT.md's own starting point, one
submission that calls the library's filter, two that go around the hiding, and one per failure
(raise, NaN, not SE(3), wrong type, import error, syntax error). Each failure is one line on
stderr and the next submission is still graded. A second grading with a 1 s time limit stops a
submission that hangs. Each grading starts a process per submission (about 1-2 s each).
"""

import contextlib
import csv
import importlib.util
import io
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from visla_edu import cli, data, metrics
from visla_edu.course import _rubric, _runner, _sandbox, project

ROOT = Path(__file__).resolve().parents[1]
NUMPY_VIO = ROOT / "tests" / "project_fixtures" / "numpy_vio.py"


def _starter():
    """The runnable starting point PROJECT.md shows (its first Python block)."""
    return re.search(r"```python\n(.*?)```", project.assignment_text(), flags=re.S).group(1)


_RECORD = """
import numpy as np
from visla_edu.filters import StepRecord


def record(t, pose):
    e = np.zeros((0, 4))
    return StepRecord(t=t, world_T_imu=pose, pose_cov=np.eye(6), ids=np.zeros(0, dtype=int), z=e, z_pred=e,
                      status=np.zeros(0, dtype=int), nis=np.nan, nis_dof=0, active_ids=np.zeros(0, dtype=int),
                      active_means=np.zeros((0, 3)), active_covs=np.zeros((0, 3, 3)))


class Filter:
    def __init__(self, dataset, config):
        self.config, self.t = config, -1

    def step(self):
        self.t += 1
        return record(self.t, self.pose(self.t))

    def pose(self, t):
        return np.eye(4)
"""

#: name -> (source, status, words the one line must hold)
FAILURES = {
    "raises": (_RECORD + """
class Broken(Filter):
    def pose(self, t):
        scale = 1 / (5 - t)
        return np.eye(4) if scale else None

def make_filter(dataset, config):
    return Broken(dataset, config)
""", "raised", ["ZeroDivisionError: division by zero (line ", "of raises.py) in step() at frame 5"]),
    "returns_nan": (_RECORD + """
class Nan(Filter):
    def pose(self, t):
        return np.full((4, 4), np.nan) if t == 3 else np.eye(4)

def make_filter(dataset, config):
    return Nan(dataset, config)
""", "non-finite", ["non-finite", "frame 3"]),
    "not_rigid": (_RECORD + """
class Scaled(Filter):
    def pose(self, t):
        return np.diag([2.0, 2.0, 2.0, 1.0]) if t == 2 else np.eye(4)

def make_filter(dataset, config):
    return Scaled(dataset, config)
""", "not-se3", ["not in SE(3)", "frame 2"]),
    "wrong_type": (_RECORD + """
class Dicts(Filter):
    def step(self):
        self.t += 1
        return {"t": self.t}

def make_filter(dataset, config):
    return Dicts(dataset, config)
""", "wrong-type", ["returned a dict", "StepRecord"]),
    "import_error": ("import numpy as np\nimport a_module_nobody_has\n\ndef make_filter(dataset, config):\n    pass\n",
                     "import-error", ["ModuleNotFoundError", "a_module_nobody_has", "line 2"]),
    "syntax_error": ("def make_filter(dataset, config:\n    return None\n", "syntax-error",
                     ["not valid Python", "line 1"]),
    "calls_library": ("from visla_edu import run\n\ndef make_filter(dataset, config):\n"
                      "    return run.make_filter(dataset, 'slam', config)\n",
                      "refused", ["run.make_filter", "hidden", "in make_filter"]),
    "catches_hidden": (_RECORD + """
import visla_edu.filters

def make_filter(dataset, config):
    try:
        return visla_edu.filters.JointSlam(dataset, dataset.camera, config)
    except Exception:
        return Filter(dataset, config)
""", "refused", ["filters.JointSlam.__init__", "went on when it raised"]),
    "reloads": (_RECORD + """
import importlib
import visla_edu.run

def make_filter(dataset, config):
    try:
        fresh = importlib.reload(visla_edu.run)
        return fresh.make_filter(dataset, "slam", config)
    except ImportError:
        return Filter(dataset, config)
""", "refused", ["import visla_edu.run"]),
}
#: The submissions that complete, graded after the failures.
GOOD = ("starter", "numpy_vio")


def _grade(argv):
    """``visla-edu`` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as stop:  # argparse's errors
            code = stop.code
    return code, out.getvalue(), err.getvalue()


def _csv(out_dir):
    with open(out_dir / "grades.csv", newline="") as f:
        return {row["submission"]: row for row in csv.DictReader(f)}


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("submissions")
    files = []
    for name, (source, _, _) in FAILURES.items():
        (folder / f"{name}.py").write_text(source)
        files.append(folder / f"{name}.py")
    (folder / "starter.py").write_text(_starter())
    files += [folder / "starter.py", NUMPY_VIO]
    out_dir = tmp_path_factory.mktemp("grading") / "out"
    code, out, err = _grade(["project", "grade", *map(str, files), "--drive", "sim-tiny", "--out", str(out_dir)])
    return {"code": code, "out": out, "err": err, "dir": out_dir, "rows": _csv(out_dir)}


def test_each_failure_is_one_line_and_the_next_submission_is_still_graded(graded):
    assert graded["code"] == 0, graded["err"]
    lines = graded["err"].strip().splitlines()
    assert "Traceback" not in graded["err"]
    assert len(lines) == len(FAILURES), lines
    for (name, (_, status, words)), line in zip(FAILURES.items(), lines):
        assert line.startswith(f"visla-edu project grade: {name}.py: {status}: "), line
        for word in words:
            assert word in line, f"{name}: {word!r} not in {line!r}"
        assert graded["rows"][name]["status"] == status
        report = (graded["dir"] / name / "report.md").read_text()
        assert f"**{status}**" in report and graded["rows"][name]["message"] in report
    for name in GOOD:  # graded after every failure
        assert graded["rows"][name]["status"] == "ok"
        assert re.search(rf"^{name}\.py: ok, 60 frames", graded["out"], flags=re.M)


def test_a_filter_written_outside_the_library_is_graded_with_its_own_ate(graded):
    row, folder = graded["rows"]["numpy_vio"], graded["dir"] / "numpy_vio"
    with np.load(folder / "estimate.npz") as saved:
        estimate, covariance = saved["world_T_imu"], saved["pose_cov"]
    truth = data.load("sim-tiny").ground_truth.world_T_imu
    ate_aligned, ate_raw = metrics.ate(estimate, truth), metrics.ate(estimate, truth, align=False)
    assert float(row["ate_aligned_m"]) == ate_aligned and float(row["ate_raw_m"]) == ate_raw
    report = (folder / "report.md").read_text()
    assert f"| **numpy_vio** | {ate_raw:.3f} | {ate_aligned:.3f} |" in report
    for figure in ("trajectory.png", "errors.png", "consistency.png"):
        assert (folder / figure).read_bytes()[:4] == b"\x89PNG" and f"({figure})" in report
    # the trajectory is that file's filter on the inputs the grader gives it (no ground truth)
    prepared = project.prepare_drive("sim-tiny")
    assert prepared.view.ground_truth is None and prepared.config.resolved
    spec = importlib.util.spec_from_file_location("numpy_vio_here", NUMPY_VIO)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    flt = module.make_filter(prepared.view, prepared.config)
    records = [flt.step() for _ in range(prepared.view.num_frames)]
    np.testing.assert_allclose(estimate, [r.world_T_imu for r in records], rtol=0, atol=1e-10)
    nees = metrics.nees(metrics.pose_errors(estimate, truth), covariance)
    assert float(row["nees_per_dof"]) == pytest.approx(np.nanmean(nees) / 6, rel=1e-12)
    measures = project.measure(estimate, covariance, np.zeros(60), np.zeros(60), prepared.truth, 0.0)
    points = _rubric.measured_points(measures, prepared.reference_measures, True, True)
    assert [row[f"points_{k}"] for k in points] == ["" if v is None else str(v) for v in points.values()]
    assert int(row["points_measured"]) == sum(v or 0 for v in points.values()) and points["completes"] == 10


def test_the_starter_of_project_md_earns_the_dead_reckoning_band_and_steps_in_the_stepper(graded):
    row = graded["rows"]["starter"]
    scored = not _rubric.accuracy_unscored(project.prepare_drive("sim-tiny").reference_measures)
    assert (row["points_completes"], row["points_accuracy"], row["points_consistency"]) == ("10", "10" if scored else "",
                                                                                        "0")
    assert row["nees_per_dof"] == ""  # its covariance is zero: no NEES
    blocks = re.findall(r"```python\n(.*?)```", project.assignment_text(), flags=re.S)
    namespace = {}
    exec(blocks[0], namespace)  # noqa: S102 - the starting point
    exec(blocks[1].replace('"sim-small"', '"sim-tiny"'), namespace)  # noqa: S102 - how to step it
    record = namespace["stepper"].goto(10)
    with np.load(graded["dir"] / "starter" / "estimate.npz") as saved:
        np.testing.assert_allclose(record.world_T_imu, saved["world_T_imu"][10], rtol=0, atol=1e-12)


def test_a_submission_using_the_library_is_refused_and_marked(graded):
    for name in ("calls_library", "catches_hidden", "reloads"):
        row = graded["rows"][name]
        assert row["points_measured"] == "0" and row["status"] == "refused"
    marks = graded["rows"]["calls_library"]["marks"]
    assert "run.make_filter" in marks and "line 1: imports visla_edu.run, which is hidden" in marks
    assert "imports importlib" in graded["rows"]["reloads"]["marks"]
    report = (graded["dir"] / "calls_library" / "report.md").read_text()
    assert "hidden library call: `run.make_filter`" in report


def test_the_summary_lists_every_submission(graded):
    summary = (graded["dir"] / "summary.md").read_text()
    for name in [*FAILURES, *GOOD]:
        assert f"[{name}]({name}/report.md)" in summary
    assert "| library slam |" in summary and "**timeout**" not in summary


def test_submissions_that_hang_or_take_too_much_memory_are_stopped(tmp_path):
    folder = tmp_path / "class"
    folder.mkdir()
    (folder / "hangs.py").write_text("import time\n\ndef make_filter(dataset, config):\n    time.sleep(120)\n")
    (folder / "hog.py").write_text(_starter() + "\n\ndef make_filter(dataset, config):\n"
                                   "    buffer = np.empty(2 * 2**30, dtype=np.uint8)  # 2 GiB, never touched\n"
                                   "    return DeadReckoning(dataset, config)\n")
    (folder / "starter.py").write_text(_starter())
    files = [str(folder / name) for name in ("hangs.py", "hog.py", "starter.py")]
    code, out, err = _grade(["project", "grade", *files, "--drive", "sim-tiny", "--out", str(tmp_path / "out"),
                             "--time-limit", "1", "--memory-limit", "1"])
    assert code == 0
    hangs, hog = err.strip().splitlines()
    assert hangs == ("visla-edu project grade: hangs.py: timeout: ran past the time limit of 1 s (in make_filter); "
                     "0 measured point(s)")
    assert hog.startswith("visla-edu project grade: hog.py: out-of-memory: ran out of memory in make_filter "
                          "(MemoryError: ") and "of hog.py)" in hog
    assert re.search(r"^starter\.py: ok, 60 frames", out, flags=re.M)  # graded after both, within both limits


def test_a_process_that_ends_without_an_outcome_is_named_by_how_it_ended(tmp_path):
    (tmp_path / "output.txt").write_text("some output\n")
    (tmp_path / "progress").write_text("frame 12")
    killed = _runner.read_outcome(tmp_path, -9, False, 10.0, 60)
    assert (killed.status, killed.message) == ("crashed", "was killed (SIGKILL: often the system running out of memory)")
    (tmp_path / "progress").write_text("import")
    exited = _runner.read_outcome(tmp_path, 0, False, 10.0, 60)
    assert exited.status == "crashed" and "ended with exit status 0" in exited.message
    assert "while importing it" in exited.message and exited.output == "some output\n" and exited.frames == 0
    (tmp_path / "progress").unlink()
    with pytest.raises(RuntimeError, match="failed before the submission ran .* its last line: some output"):
        _runner.read_outcome(tmp_path, 1, False, 10.0, 60)


@pytest.mark.parametrize("argv, message", [
    (["missing.py"], "submission missing.py: no such file"),
    (["notes.txt"], "expected a Python file (.py)"),
    (["a.py", "a.py"], "is given twice"),
    (["a.py", "--out", "busy"], "is a folder with other files"),
    (["a.py", "--out", "."], "holds the submission"),
    (["a.py", "--time-limit", "0"], "expected a positive number of seconds"),
])
def test_bad_input_is_one_line_before_any_submission_runs(tmp_path, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a.py").write_text("")
    (tmp_path / "notes.txt").write_text("")
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "thesis.tex").write_text("")
    argv = argv if "--out" in argv else [*argv, "--out", "reports"]
    code, out, err = _grade(["project", "grade", *argv, "--drive", "sim-tiny"])
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "reports").exists() and sorted(p.name for p in (tmp_path / "busy").iterdir()) == [
        "thesis.tex"]


def test_project_md_holds_the_measured_rubric_and_the_defaults():
    text = project.assignment_text()
    assert _rubric.rubric_table() in text
    assert f"time limit ({project.DEFAULT_TIME_LIMIT:g} s by default)" in text
    assert f"memory limit ({project.DEFAULT_MEMORY_LIMIT / 2**30:g} GiB)" in text
    assert '"course/PROJECT.md"' in (ROOT / "pyproject.toml").read_text()  # shipped with the package
    for name in _sandbox.ALLOWED_MODULES[1:8]:
        assert f"`{name}`" in text
    code, out, _ = _grade(["project", "show"])
    assert code == 0 and out == text


def test_the_source_scan_marks_hidden_imports_and_tricks_but_not_the_interface():
    allowed = ("import numpy as np\nfrom visla_edu.filters import FilterConfig, StepRecord\n"
               "from visla_edu import lie, camera\nfrom visla_edu.codes import OBS_USED\nimport visla_edu.lie\n"
               "from visla_edu.filters._base import StepRecord\n")
    assert _sandbox.scan_source(allowed) == []
    marks = _sandbox.scan_source("from visla_edu.filters import JointSlam, StepRecord\nimport visla_edu.ekf\n"
                                 "from visla_edu.run import make_filter\nimport sys\nx = sys.modules\n"
                                 "exec('1')\nf = open('truth.txt')\nimport subprocess\n")
    assert marks == ["line 1: imports visla_edu.filters.JointSlam, which is hidden while it is graded",
                     "line 2: imports visla_edu.ekf, which is hidden while it is graded",
                     "line 3: imports visla_edu.run.make_filter, which is hidden while it is graded",
                     "line 5: uses modules (reaches into sys.modules)",
                     "line 6: calls exec (runs code built at run time)",
                     "line 7: calls open (reads or writes a file)",
                     "line 8: imports subprocess"]
    assert _sandbox.scan_source("def broken(:\n") == []


def test_hiding_leaves_the_geometry_and_the_interface_working():
    """In a process of its own (hiding lasts): the filters raise, lie, camera and the types work."""
    code = """
import numpy as np
from visla_edu import camera, data, lie, run
from visla_edu.course import _sandbox
from visla_edu.filters import FilterConfig, StepRecord
ds = data.load("sim-tiny")
count = _sandbox.hide_library()
_sandbox.block_imports()
config = FilterConfig(sigma_pixel=2.0)
assert config.gate_threshold > 0 and lie.se3_exp(np.ones(6)).shape == (4, 4)
assert ds.camera.predict(np.eye(4), np.array([[0.0, 0.0, 10.0]])).shape == (1, 4) and ds.observations(3)
StepRecord(0, np.eye(4), np.eye(6), *[np.zeros(0)] * 4, 0.0, 0, *[np.zeros(0)] * 3)
for call in (lambda: run.make_filter(ds), lambda: data.load("sim-tiny"), lambda: __import__("visla_edu.stepper")):
    try:
        call()
    except (_sandbox.SubmissionUsedLibrary, ImportError) as err:
        print(type(err).__name__, err.args[0].split(" is hidden")[0])
print(count > 300, _sandbox.HIDDEN_CALLS)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.splitlines() == ["SubmissionUsedLibrary run.make_filter", "SubmissionUsedLibrary data.load",
                                "ImportError visla_edu.stepper",
                                "True ['run.make_filter', 'data.load', 'import visla_edu.stepper']"]


def test_measured_points_follow_the_bands():
    class Evaluation:
        def __init__(self, ate):
            self.ate_aligned = ate

    class Measures:
        def __init__(self, ate, nees=1.0):
            self.evaluation, self.nees_per_dof = Evaluation(ate), nees

    references = {"slam": Measures(1.0), "vio": Measures(2.0), "deadreckon": Measures(4.0)}
    for ate, expected in ((1.25, 25), (1.3, 18), (2.5, 18), (4.2, 10), (4.3, 0)):
        assert _rubric.measured_points(Measures(ate), references, True, False)["accuracy"] == expected
    assert [_rubric.measured_points(Measures(1.0, nees), references, True, True)["consistency"]
            for nees in (0.01, 0.05, 1.0, 3.0, 9.0, 11.0, np.nan)] == [0, 2, 5, 5, 2, 0, 0]
    assert _rubric.measured_points(None, references, False, True) == {"completes": 0, "accuracy": 0,
                                                                      "consistency": 0}
    close = {**references, "deadreckon": Measures(1.2)}  # dead reckoning alone earns the top band
    assert _rubric.measured_points(Measures(1.0), close, True, True) == {"completes": 10, "accuracy": None,
                                                                         "consistency": 5}
    assert "dead reckoning alone earns the top band" in _rubric.accuracy_unscored(close)
    no_truth = {mode: type("M", (), {"evaluation": None})() for mode in references}
    assert _rubric.measured_points(Measures(1.0), no_truth, True, False) == {
        "completes": 10, "accuracy": None, "consistency": None}


@pytest.mark.data
@pytest.mark.slow
@pytest.mark.parametrize("name", ["0020"])
def test_accuracy_is_not_scored_where_dead_reckoning_is_as_good_as_slam(require_data, name):
    """PROJECT.md says so of 0020, a KITTI drive of the 2019 release (nearly noise-free velocities)."""
    require_data(name)
    prepared = project.prepare_drive(name)
    assert prepared.truth is not None and not prepared.simulated
    assert "dead reckoning alone earns the top band" in _rubric.accuracy_unscored(prepared.reference_measures)
    assert prepared.reference_measures["slam"].nees_per_dof > 10  # "a pose NEES in the tens", not scored
    assert f"`{name}`" in project.assignment_text()


def test_a_trajectory_equal_to_the_librarys_is_marked_for_a_human():
    prepared = project.prepare_drive("sim-tiny")
    slam = prepared.references["slam"].world_T_imu
    marks = project._library_marks({"world_T_imu": slam.copy()}, prepared.references)
    assert len(marks) == 1 and marks[0].startswith("its trajectory matches the library's slam to 0.0e+00 m")
    nearby = slam.copy()
    nearby[:, 0, 3] += 1e-4  # a tenth of a millimetre: an own implementation's difference
    assert project._library_marks({"world_T_imu": nearby}, prepared.references) == []
