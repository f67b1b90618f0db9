"""What the project grader writes: a report per submission with its figures, the summary, the table.

``DIR/<name>/``: ``report.md``, ``trajectory.png``, ``errors.png``, ``consistency.png``, ``estimate.npz``,
``output.txt`` and ``traceback.txt`` (when it raised); ``DIR/summary.md`` and ``DIR/grades.csv``. Figures
are :class:`matplotlib.figure.Figure` objects (no pyplot state); every file is written atomically.
"""

import csv
import datetime
import io
import shutil

import numpy as np

from visla_edu import __version__, metrics, plotting
from visla_edu._files import atomic_write
from visla_edu.codes import DEADRECKON, SLAM, VIO
from visla_edu.course import _grader_child, _rubric, _runner

__all__ = ["STATUSES", "CSV_COLUMNS", "drive_line", "grade_line", "write_submission", "write_summary"]

#: Every status a submission can get, with its meaning.
STATUSES = {**_grader_child.STATUSES, **_runner.EXIT_STATUSES}
#: The columns of ``grades.csv`` (numbers at full precision; empty where not measured).
CSV_COLUMNS = ("submission", "file", "status", "message", "frames", "seconds", "ate_raw_m", "ate_aligned_m",
               "drift_translation_percent", "drift_rotation_deg_per_100m", "nees_per_dof", "nis_per_dof",
               "points_completes", "points_accuracy", "points_consistency", "points_measured", "marks")
#: Bytes of a submission's output kept in its report folder (the end of it).
OUTPUT_LIMIT = 2**20
#: The fields of a TrajectoryEvaluation in the tables, in column order.
_EVALUATION_FIELDS = ("ate_raw", "ate_aligned", "drift_translation", "drift_rotation")
_REFERENCE_LABELS = {SLAM: "library slam", VIO: "library vio", DEADRECKON: "dead reckoning"}
_STYLES = {SLAM: {"color": plotting.PALETTE["reddish_purple"], "linestyle": ":", "linewidth": 2.0},
           VIO: {"color": plotting.PALETTE["orange"], "linestyle": (0, (6, 2, 1, 2)), "linewidth": 1.4},
           DEADRECKON: plotting.STYLES["dead_reckoning"]}


def _number(value, digits=3):
    return "—" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def drive_line(prepared, count):
    """One line: what is graded, on which drive, with the library's aligned ATE when there is a truth."""
    view = prepared.view
    truth = "no ground truth (accuracy not scored)" if prepared.truth is None else \
        f"ground truth of {prepared.truth.num_frames} frames"
    refs = "; ".join(f"{_REFERENCE_LABELS[m]} ATE {_number(r.evaluation.ate_aligned)} m aligned"
                     for m, r in prepared.reference_measures.items() if r.evaluation is not None)
    unscored = _rubric.accuracy_unscored(prepared.reference_measures) if prepared.truth is not None else ""
    return f"grading {count} submission(s) on {prepared.name} ({view.num_frames} frames, {truth})" + \
        (f"; {refs}" if refs else "") + (f"; accuracy not scored: {unscored}" if unscored else "")


def grade_line(grade):
    """One line about a graded submission: its file, status and message, and the points."""
    measured = f"; {grade.measured} measured point(s)"
    if not grade.ok:
        return f"{grade.path.name}: {grade.outcome.status}: {grade.outcome.message}{measured}"
    evaluation = grade.measures.evaluation
    ate = "" if evaluation is None else f", ATE {evaluation.ate_aligned:.3f} m aligned ({evaluation.ate_raw:.3f} m raw)"
    marks = f"; {len(grade.marks)} mark(s) for a human" if grade.marks else ""
    ran = f"{grade.outcome.frames} frames in {grade.outcome.seconds:.2f} s"
    return f"{grade.path.name}: ok, {ran}{ate}{measured}{marks}"


# ----------------------------------------------------------------------------- figures

def _series(grade, prepared):
    """``[(label, world_T_imu, style)]``: the submission first, then the references."""
    rows = [(f"{grade.name} (submission)", grade.outcome.arrays["world_T_imu"], plotting.STYLES["estimate"])]
    return rows + [(_REFERENCE_LABELS[m], r.world_T_imu, _STYLES[m]) for m, r in prepared.references.items()]


def _trajectory_figure(grade, prepared):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 6), layout="constrained")
    ax = fig.add_subplot()
    if prepared.truth is not None:
        p = prepared.truth.world_T_imu[:, :3, 3]
        ax.plot(p[:, 0], p[:, 1], label="ground truth", **plotting.GROUND_TRUTH_STYLE)
    for label, poses, style in reversed(_series(grade, prepared)):
        ax.plot(poses[:, 0, 3], poses[:, 1, 3], label=label, **style)
    ax.plot([0], [0], label="start", **plotting.STYLES["start"])
    ax.set_aspect("equal", adjustable="datalim")
    ax.set(xlabel="x (m)", ylabel="y (m)", title=f"{prepared.name}: top-down, world = first IMU frame")
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, alpha=0.3)
    return fig


def _errors_figure(grade, prepared):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 3.5), layout="constrained")
    ax = fig.add_subplot()
    times = prepared.view.time_stamps - prepared.view.time_stamps[0]
    rows = [(f"{grade.name} (submission)", grade.measures, plotting.STYLES["estimate"])]
    rows += [(_REFERENCE_LABELS[m], prepared.reference_measures[m], _STYLES[m]) for m in prepared.references]
    for label, measures, style in reversed(rows):
        ax.plot(times[:len(measures.position_error)], measures.position_error, label=label, **style)
    ax.set(xlabel="time (s)", ylabel="position error (m)", title="|p_est - p_true| per frame (no alignment)")
    ax.legend(loc="upper left", fontsize="small")
    ax.grid(True, alpha=0.3)
    return fig


def _consistency_figure(grade, prepared):
    from matplotlib.figure import Figure

    with_truth = prepared.truth is not None
    fig = Figure(figsize=(8, 6 if with_truth else 3.2), layout="constrained")
    axes = fig.subplots(2 if with_truth else 1, 1, squeeze=False)[:, 0]
    times = (prepared.view.time_stamps - prepared.view.time_stamps[0])[:grade.measures.frames]
    if with_truth:
        ax = axes[0]
        lower, upper = metrics.chi2_bounds(6)
        ax.axhspan(lower, upper, color=plotting.PALETTE["bluish_green"], alpha=0.25, lw=0,
                   label="95% band of chi2(6)")
        library = prepared.reference_measures[SLAM].nees
        all_times = prepared.view.time_stamps - prepared.view.time_stamps[0]
        ax.plot(all_times[:len(library)], library, label="library slam", **_STYLES[SLAM])
        ax.plot(times[:len(grade.measures.nees)], grade.measures.nees, ".-", ms=3, lw=0.8,
                color=plotting.PALETTE["blue"], label=f"{grade.name}: pose NEES")
        ax.set(yscale="log", xlabel="time (s)", ylabel="pose NEES (6 dof)",
               title=f"pose NEES: mean per dof {_number(grade.measures.nees_per_dof, 2)}")
        ax.legend(loc="upper left", fontsize="small")
        ax.grid(True, alpha=0.3)
    if np.any(grade.measures.nis_dof > 0):
        plotting.plot_nis(grade.measures.nis, grade.measures.nis_dof, time=times, ax=axes[-1])
    else:
        axes[-1].set_title("no NIS: the submission reported no update (nis_dof 0 at every frame)", fontsize="medium")
    return fig


def _write_figures(folder, grade, prepared):
    """The figures of a submission that ran at least two frames; their file names."""
    if grade.measures is None or grade.measures.frames < 2:
        return []
    figures = [("trajectory.png", _trajectory_figure)]
    if prepared.truth is not None:
        figures.append(("errors.png", _errors_figure))
    figures.append(("consistency.png", _consistency_figure))
    for name, draw in figures:
        plotting.save_figure(draw(grade, prepared), folder / name)
    return [name for name, _ in figures]


# ----------------------------------------------------------------------------- the report

def _points_rows(grade, prepared):
    """The rows of the measured-points table, with why each criterion got its points."""
    refs = prepared.reference_measures
    why = {"completes": grade.outcome.message}
    if grade.points["accuracy"] is None:
        why["accuracy"] = f"not scored: {_rubric.accuracy_unscored(refs)}"
    elif grade.ok:
        ate = grade.measures.evaluation.ate_aligned
        bands = ", ".join(f"{p} for <= {f:g} x {m} = {f * refs[m].evaluation.ate_aligned:.3f} m"
                          for p, m, f in _rubric.ACCURACY_BANDS)
        why["accuracy"] = f"aligned ATE {ate:.3f} m (bands: {bands})"
    if grade.points["consistency"] is None:
        why["consistency"] = "not scored: reported on real drives only (the truth and the noise are not the model's)"
    elif grade.ok:
        why["consistency"] = f"mean pose NEES per dof {_number(grade.measures.nees_per_dof, 2)}"
    best = {"completes": _rubric.COMPLETES_POINTS, "accuracy": _rubric.ACCURACY_BANDS[0][0],
            "consistency": _rubric.CONSISTENCY_BANDS[0][0]}
    return [f"| {k} | {'—' if p is None else p} / {best[k]} | {why.get(k, 'did not complete')} |"
            for k, p in grade.points.items()]


def _measure_row(label, measures):
    if measures is None:
        return f"| {label} | — | — | — | — | — | — | — |"
    ev = measures.evaluation
    cells = [_number(None if ev is None else getattr(ev, key)) for key in _EVALUATION_FIELDS]
    cells += [_number(measures.nees_per_dof, 2), _number(measures.nis_per_dof, 2), _number(measures.seconds, 2)]
    return f"| {label} | " + " | ".join(cells) + " |"


def _comparison(grade, prepared):
    """The table of the submission (none: ``grade`` None) and the references against the ground truth."""
    rows = ["| | ATE raw (m) | ATE aligned (m) | drift (%) | drift (deg/100 m) | NEES/dof | NIS/dof | time (s) |",
            "|---|---|---|---|---|---|---|---|"]
    if grade is not None:
        rows.append(_measure_row(f"**{grade.name}**", grade.measures if grade.ok else None))
    return rows + [_measure_row(_REFERENCE_LABELS[m], prepared.reference_measures[m]) for m in prepared.references]


def _report_text(grade, prepared, figures, has_traceback):
    outcome = grade.outcome
    lines = [f"# Project: {grade.name} on {prepared.name}", "",
             f"**{outcome.status}**: {outcome.message}", "",
             f"Submission `{grade.path}`; graded {datetime.datetime.now().astimezone():%Y-%m-%d %H:%M %Z} by visla-edu "
             f"{__version__} on {prepared.name} ({prepared.view.num_frames} frames).", "",
             f"## Measured points: {grade.measured}", "",
             "| criterion | points | why |", "|---|---|---|", *_points_rows(grade, prepared), "",
             "The grader measures these; the report (the rest of the rubric) is graded by a human: see PROJECT.md, "
             "'Rubric'.", ""]
    if grade.marks or outcome.hidden_calls or outcome.notes:
        lines += ["## For a human to look at", ""]
        lines += [f"- hidden library call: `{call}`" for call in outcome.hidden_calls]
        lines += [f"- {mark}" for mark in grade.marks] + [f"- grader: {note}" for note in outcome.notes] + [""]
    lines += ["## Against the ground truth and the library", "", *_comparison(grade, prepared), "",
              "ATE aligned: after the best rigid alignment; drift: KITTI's, over 100-800 m segments; NEES per dof: "
              "should be near 1 (pose errors against the covariance); NIS per dof: near 1. The library's filters ran "
              "on the same inputs the submission got.", ""]
    lines += [f"![{name[:-4]}]({name})" for name in figures] + ([""] if figures else [])
    if has_traceback:
        lines += ["The submission's traceback is in [traceback.txt](traceback.txt).", ""]
    if outcome.output.strip():
        lines += ["## What it printed (the end)", "", "```text", outcome.output.rstrip(), "```", ""]
    return "\n".join(lines)


def write_submission(folder, grade, prepared, work):
    """Write ``folder/report.md`` and its figures, ``estimate.npz``, ``output.txt`` and ``traceback.txt``."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, limit in (("estimate.npz", None), ("output.txt", OUTPUT_LIMIT)):
        if (work / name).is_file():
            with atomic_write(folder / name, "wb") as f, open(work / name, "rb") as src:
                if limit is not None and src.seek(0, 2) > limit:
                    src.seek(-limit, 2)
                    f.write(f"[... the beginning is cut: the output had more than {limit // 2**20} MiB ...]\n".encode())
                else:
                    src.seek(0)
                shutil.copyfileobj(src, f)
    has_traceback = bool(grade.outcome.traceback)
    if has_traceback:
        with atomic_write(folder / "traceback.txt") as f:
            f.write(grade.outcome.traceback)
    figures = _write_figures(folder, grade, prepared)
    with atomic_write(folder / "report.md") as f:
        f.write(_report_text(grade, prepared, figures, has_traceback))
    return folder / "report.md"


# ----------------------------------------------------------------------------- the summary

def _csv_row(grade):
    m = grade.measures if grade.ok else None  # a run that stopped early is not measured
    ev = None if m is None else m.evaluation
    values = [grade.name, str(grade.path), grade.outcome.status, grade.outcome.message, grade.outcome.frames,
              grade.outcome.seconds, *(None if ev is None else getattr(ev, k) for k in _EVALUATION_FIELDS),
              None if m is None else m.nees_per_dof, None if m is None else m.nis_per_dof,
              grade.points["completes"], grade.points["accuracy"], grade.points["consistency"], grade.measured,
              "; ".join(grade.outcome.hidden_calls[:3] + grade.marks)]
    return ["" if v is None or (isinstance(v, float) and not np.isfinite(v)) else repr(v) if isinstance(v, float)
            else v for v in values]


def _summary_row(grade):
    """A submission's row of the summary: link, status, frames, time, ATE, NEES, points, marks."""
    measures = grade.measures if grade.ok else None
    ate = None if measures is None or measures.evaluation is None else measures.evaluation.ate_aligned
    marks = len(grade.marks) + len(grade.outcome.hidden_calls)
    return (f"| [{grade.name}]({grade.name}/report.md) | {grade.outcome.status} | {grade.outcome.frames} | "
            f"{_number(grade.outcome.seconds, 2)} | {_number(ate)} | "
            f"{_number(None if measures is None else measures.nees_per_dof, 2)} | {grade.measured} | {marks or ''} |")


def _summary_text(grades, prepared, time_limit):
    seen = dict.fromkeys(g.outcome.status for g in grades)
    return "\n".join([
        f"# Project grades on {prepared.name}", "",
        drive_line(prepared, len(grades)) + ".", "",
        f"Time limit {time_limit:g} s per submission; graded {datetime.datetime.now().astimezone():%Y-%m-%d %H:%M %Z} "
        f"by visla-edu {__version__}.", *[f"Calibration: {note}" for note in prepared.notes], "",
        "## The library on the same inputs", "", *_comparison(None, prepared), "",
        "## Submissions", "",
        "| submission | status | frames | time (s) | ATE aligned (m) | NEES/dof | measured points | marks |",
        "|---|---|---|---|---|---|---|---|", *(_summary_row(g) for g in grades), "",
        *[f"- **{status}**: {STATUSES[status]}" for status in seen], "",
        "Measured points are the grader's part of the rubric (PROJECT.md); a human grades the report and looks at "
        "every submission with marks.", ""])


def write_summary(out, grades, prepared, time_limit):
    """Write ``out/summary.md`` and ``out/grades.csv``; return the summary's path."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    writer.writerows(_csv_row(g) for g in grades)
    with atomic_write(out / "grades.csv") as f:
        f.write(text.getvalue())
    with atomic_write(out / "summary.md") as f:
        f.write(_summary_text(grades, prepared, time_limit))
    return out / "summary.md"
