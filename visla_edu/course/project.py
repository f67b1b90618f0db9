"""The course project (summative): the assignment, the drive it is graded on, the measured rubric, the grader.

A submission is one Python file whose ``make_filter(dataset, config)`` returns a
:class:`visla_edu.stepper.SteppableFilter` (PROJECT.md, :func:`assignment_text`). :func:`grade` (TEACHING.md,
section 7) runs each on :func:`prepare_drive`'s view in its own process (:mod:`~visla_edu.course._sandbox`,
:mod:`~visla_edu.course._runner`), scores it (:func:`measure`, :func:`measured_points`) and writes ``_report``'s files.
"""

import dataclasses
import os
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from visla_edu import data, diagnostics, metrics, run
from visla_edu._files import expand_user
from visla_edu.codes import DEADRECKON, SLAM, VIO
from visla_edu.course import _report, _runner, _sandbox
from visla_edu.course._runner import DEFAULT_MEMORY_LIMIT, DEFAULT_TIME_LIMIT
from visla_edu.course._rubric import (ACCURACY_BANDS, COMPLETES_POINTS, CONSISTENCY_BANDS, MEASURED_TOTAL,
                                     measured_points, rubric_table)
from visla_edu.filters import FilterConfig

__all__ = ["ASSIGNMENT", "REFERENCE_MODES", "COMPLETES_POINTS", "ACCURACY_BANDS", "CONSISTENCY_BANDS", "MEASURED_TOTAL",
           "DEFAULT_TIME_LIMIT", "DEFAULT_MEMORY_LIMIT", "LIBRARY_MATCH_METRES", "assignment_text", "rubric_table",
           "GradingDrive", "Measures", "Grade", "prepare_drive", "measure", "measured_points", "grade"]

#: The written assignment, shipped with the package.
ASSIGNMENT = Path(__file__).with_name("PROJECT.md")
#: The library's runs a submission is compared with, best first.
REFERENCE_MODES = (SLAM, VIO, DEADRECKON)
#: A completed trajectory this close to the library's slam or vio at every frame (m) is marked.
LIBRARY_MATCH_METRES = 1e-6


def assignment_text():
    """The project's assignment, ``PROJECT.md`` (Markdown)."""
    return ASSIGNMENT.read_text(encoding="utf-8")


@dataclass
class Measures:
    """How a trajectory compares with the ground truth, and its consistency (:func:`measure`).

    ``seconds``: run time (s); ``evaluation``: :class:`visla_edu.metrics.TrajectoryEvaluation`, None without
    ground truth or for an incomplete run; ``nees_per_dof``: mean pose NEES / 6, ``nis_per_dof``: total NIS /
    total dof (NaN without them); ``position_error`` (m, no alignment) and ``nees`` (NaN where the covariance
    is singular): shape (n,), per frame with ground truth; ``nis``, ``nis_dof``: shape (frames,).
    """

    frames: int
    seconds: float
    evaluation: object
    nees_per_dof: float
    nis_per_dof: float
    position_error: np.ndarray
    nees: np.ndarray
    nis: np.ndarray
    nis_dof: np.ndarray


def measure(world_T_imu, pose_cov, nis, nis_dof, truth, seconds, complete=True):
    """The :class:`Measures` of a run of ``k`` frames against ``truth``.

    Shapes: ``world_T_imu`` (k, 4, 4), ``pose_cov`` (k, 6, 6) of the right perturbation ``[v; w]``
    (:mod:`visla_edu.lie`), ``nis`` and ``nis_dof`` (int) (k,). ``complete=False`` (stopped early): no ATE.
    """
    world_T_imu, nis, nis_dof = np.asarray(world_T_imu, float), np.asarray(nis, float), np.asarray(nis_dof)
    used = (nis_dof > 0) & np.isfinite(nis)
    nis_per_dof = float(nis[used].sum() / nis_dof[used].sum()) if used.any() else np.nan
    n = 0 if truth is None else min(truth.num_frames, len(world_T_imu))
    evaluation, error, nees = None, np.zeros(0), np.zeros(0)
    if n:
        true_poses = truth.world_T_imu[:n]
        error = np.linalg.norm(world_T_imu[:n, :3, 3] - true_poses[:, :3, 3], axis=1)
        nees = metrics.nees(metrics.pose_errors(world_T_imu[:n], true_poses), np.asarray(pose_cov, float)[:n])
        if complete:
            evaluation = metrics.evaluate(world_T_imu, truth.world_T_imu)
    finite = np.isfinite(nees)
    return Measures(frames=len(world_T_imu), seconds=float(seconds), evaluation=evaluation,
                    nees_per_dof=float(nees[finite].mean() / 6) if finite.any() else np.nan, nis_per_dof=nis_per_dof,
                    position_error=error, nees=nees, nis=nis, nis_dof=nis_dof)


@dataclass
class GradingDrive:
    """The drive submissions are graded on, what they get of it, and the library's references.

    ``name``: the drive's, or its file's when given as a path; ``dataset``: as loaded, with ground truth;
    ``view``, ``config``: what a submission gets (:func:`prepare_drive`); ``references``,
    ``reference_measures``: the library's runs on them by mode (:data:`REFERENCE_MODES`), RunResult and
    :class:`Measures`; ``notes``: the calibration's evidence.
    """

    name: str
    dataset: object
    view: object
    config: FilterConfig
    truth: object
    references: dict
    reference_measures: dict
    notes: list = field(default_factory=list)

    @property
    def simulated(self):
        """Whether the ground truth is a simulation's (the consistency band is scored)."""
        return self.truth is not None and self.truth.simulated


def prepare_drive(drive, data_dir=None, ground_truth=None, ground_truth_times=None):
    """Load ``drive``, make a submission's view of it and run the library's references: a :class:`GradingDrive`.

    The view is a copy **without** ground truth, ``extra``, ``source`` or ``label`` (no truth or seed reaches a
    submission), ``imu_T_cam`` corrected once by the measured calibration; the config is
    :func:`visla_edu.run.resolve_config`'s with ``extrinsic_correction="none"``. ``drive``, ``data_dir``: as
    :func:`visla_edu.data.load`; ``ground_truth(_times)``: KITTI files (:func:`visla_edu.data.attach_ground_truth`).
    """
    dataset = data.load(drive, data_dir)
    if ground_truth:
        dataset = data.attach_ground_truth(dataset, ground_truth, ground_truth_times)
    elif ground_truth_times:
        raise ValueError(f"--ground-truth-times {ground_truth_times} needs --ground-truth POSES_FILE too")
    resolved = run.resolve_config(dataset, FilterConfig())
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(dataset, resolved.extrinsic_correction)
    name = Path(str(drive)).name if isinstance(drive, os.PathLike) or str(drive).endswith(".npz") else dataset.name
    view = dataclasses.replace(dataset, name=name, imu_T_cam=np.array(imu_T_cam, dtype=float), ground_truth=None,
                               extra={}, source=f"the grader's copy of {name}", label="")
    config = dataclasses.replace(resolved, extrinsic_correction="none")
    references = {mode: run.run_filter(view, mode, config, progress=False) for mode in REFERENCE_MODES}
    truth = dataset.ground_truth
    reference_measures = {mode: measure(r.world_T_imu, r.pose_cov, r.nis, r.nis_dof, truth, r.step_seconds.sum())
                          for mode, r in references.items()}
    return GradingDrive(name, dataset, view, config, truth, references, reference_measures,
                        [evidence] if evidence else [])


@dataclass
class Grade:
    """One submission's grade.

    ``name``: in the reports (the file's stem, made unique); ``outcome``: a
    :class:`visla_edu.course._runner.ChildOutcome`; ``measures``: None when it ran no frame; ``points``:
    :func:`measured_points`; ``marks``: for a human (:func:`visla_edu.course._sandbox.scan_source`, a library match).
    """

    name: str
    path: Path
    outcome: object
    measures: object
    points: dict
    marks: list

    @property
    def ok(self):
        """Whether it ran every frame with valid records and no hidden call."""
        return self.outcome.status == "ok"

    @property
    def measured(self):
        """The sum of the scored points."""
        return sum(p for p in self.points.values() if p is not None)


def _check_submissions(submissions):
    """The submission files as resolved paths, each an existing ``.py`` file given once."""
    paths = []
    for given in submissions:
        path = expand_user(given)
        if not path.is_file():
            raise FileNotFoundError(f"submission {given}: no such file" if not path.exists() else
                                    f"submission {given} is not a file: give the student's .py file")
        if path.suffix != ".py":
            raise ValueError(f"submission {given}: expected a Python file (.py), got {path.suffix or 'no suffix'}")
        if path.resolve() in paths:
            raise ValueError(f"submission {given} is given twice; give each file once")
        paths.append(path.resolve())
    if not paths:
        raise ValueError("no submission given: give one or more .py files")
    return paths


def _check_out_dir(out_dir, paths):
    """The report folder, created: a new or empty folder, or an earlier grading's (with its grades.csv)."""
    out = expand_user(out_dir).resolve()
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out_dir} is a file; give a folder for the reports")
    inside = [p for p in paths if out == p.parent or out in p.parents]
    if inside:
        raise ValueError(f"--out {out_dir} holds the submission {inside[0]}; give a separate folder for the reports")
    if out.is_dir() and any(out.iterdir()) and not (out / "grades.csv").is_file():
        raise ValueError(f"--out {out_dir} is a folder with other files (not an earlier grading: no grades.csv); "
                         "give a new or empty folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _names(paths):
    """A unique, file-safe report name per submission: the stem, with its folder's name where stems repeat."""
    def safe(text):
        return "".join(c if c.isalnum() or c in "-_." else "_" for c in text).strip(".") or "submission"

    stems = [p.stem for p in paths]
    names = [safe(p.stem if stems.count(p.stem) == 1 else f"{p.parent.name}-{p.stem}") for p in paths]
    for k, name in enumerate(names):
        if names.count(name) > 1 or name in ("summary", "grades"):
            names[k] = f"{name}-{k + 1}"
    return names


def _library_marks(arrays, references):
    """A mark when a trajectory matches the library's slam or vio at every frame."""
    marks = []
    for mode in (SLAM, VIO):
        gap = float(np.abs(arrays["world_T_imu"][:, :3, 3] - references[mode].world_T_imu[:, :3, 3]).max())
        if gap <= LIBRARY_MATCH_METRES:
            marks.append(f"its trajectory matches the library's {mode} to {gap:.1e} m at every frame: look at the "
                         "code (a copy of the library?)")
    return marks


def _grade_one(path, name, prepared, drive_file, work, time_limit, memory_limit):
    """Run, measure and score one submission (its files in ``work/name``); return its :class:`Grade`."""
    folder = work / name
    folder.mkdir()
    T = prepared.view.num_frames
    outcome = _runner.run_submission(path, drive_file, prepared.config, folder, time_limit, memory_limit, T)
    marks = _sandbox.scan_source(path.read_text(encoding="utf-8", errors="replace"))
    measures = None
    if outcome.frames:
        a = outcome.arrays
        measures = measure(a["world_T_imu"], a["pose_cov"], a["nis"], a["nis_dof"], prepared.truth, outcome.seconds,
                           complete=outcome.status == "ok")
    if outcome.status == "ok":
        marks += _library_marks(outcome.arrays, prepared.references)
    points = measured_points(measures, prepared.reference_measures, outcome.status == "ok", prepared.simulated)
    return Grade(name, path, outcome, measures, points, marks)


def grade(submissions, drive, out_dir, ground_truth=None, ground_truth_times=None, time_limit=DEFAULT_TIME_LIMIT,
          memory_limit=DEFAULT_MEMORY_LIMIT, data_dir=None):
    """Grade each submission on ``drive``; write the reports in ``out_dir``; return the :class:`Grade` list.

    Prints a line per submission (stdout if it completed, else stderr). ``submissions``: the ``.py`` files;
    ``out_dir``: new, empty, or an earlier grading's (replaced); the drive arguments as :func:`prepare_drive`;
    the limits per submission as :func:`visla_edu.course._runner.run_submission`.

    FileNotFoundError or ValueError (bad submission, ``out_dir``, drive or ground truth) before any submission runs.
    """
    paths = _check_submissions(submissions)
    out = _check_out_dir(out_dir, paths)
    prepared = prepare_drive(drive, data_dir, ground_truth, ground_truth_times)
    print(_report.drive_line(prepared, len(paths)))
    grades = []
    with tempfile.TemporaryDirectory(prefix="visla-edu-grade-") as work:
        work = Path(work)
        drive_file = data.save(prepared.view, work / "drive.npz")
        for path, name in zip(paths, _names(paths)):
            result = _grade_one(path, name, prepared, drive_file, work, time_limit, memory_limit)
            _report.write_submission(out / name, result, prepared, work / name)
            if result.ok:
                print(_report.grade_line(result))
            else:
                print(f"visla-edu project grade: {_report.grade_line(result)}", file=sys.stderr)
            grades.append(result)
    print(f"wrote {_report.write_summary(out, grades, prepared, time_limit)} and {out / 'grades.csv'}")
    return grades
