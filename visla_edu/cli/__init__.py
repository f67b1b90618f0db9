"""Command line: ``visla-edu {info,run,stepper,release,student,project,book} ...`` (also ``python -m visla_edu``).

Examples: the README's "Command line" section. :func:`main` is the one error boundary: whatever a user can get
wrong is reported as ONE line on stderr that names the file, key, value, setting or frame and what to try, never
a traceback (``--debug`` or ``VISLA_EDU_DEBUG=1`` adds it). Every file is written atomically, so an error or
Ctrl-C never leaves a half-written file where a good one was. Exit status:

* 0 - done;
* 1 - the filter (or the diagnostics) failed on valid input: divergence, a singular matrix, numerical overflow,
  out of memory (the line names the frame and the likely cause), or an error marked ``failed = True`` (its
  ``hint``, like any error's, ends the line);
* 2 - bad input: a command-line error, a bad ``--set`` value, a missing, unreadable or invalid file, an output
  path that cannot or must not be written (checked before any work);
* 3 - an internal error (a bug): one line asking to report it;
* 130 - interrupted (Ctrl-C), at any moment after the process starts (``visla_edu.__main__``).
"""

import argparse
import errno
import os
import sys
import traceback
import warnings
from pathlib import Path

from visla_edu.cli import options as _options
from visla_edu.codes import RUN_MODES, RUN_MODES_HELP, SLAM, SMOOTHER_MODES
from visla_edu.course import commands as _project_commands

__all__ = ["main", "build_parser", "EXIT_FAILED", "EXIT_BAD_INPUT", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "DEBUG_ENV"]

EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED = 1, 2, 3, 130
#: Environment variable that makes every error print its traceback too (like ``--debug``).
DEBUG_ENV = "VISLA_EDU_DEBUG"
#: errno values of an OSError that mean a bad path given by the user (exit 2); others are system failures (exit 1).
_PATH_ERRNOS = {errno.ENOENT, errno.EACCES, errno.EPERM, errno.EISDIR, errno.ENOTDIR, errno.EEXIST, errno.ENAMETOOLONG,
                errno.EROFS, errno.ELOOP, errno.ENXIO}


class _UsageExit(SystemExit):
    """A command-line error: exit status 2 (as argparse), the message as its text for in-process callers."""

    def __init__(self, message):
        super().__init__(EXIT_BAD_INPUT)
        self.message = message

    def __str__(self):
        return self.message


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (no usage block) that points to ``--help``."""

    def error(self, message):
        line = _one_line(f"{self.prog}: error: {message} (see {self.prog} --help)")
        print(line, file=sys.stderr)
        raise _UsageExit(line)

    def format_help(self):
        if callable(self.epilog):  # run's list of settings: imports the filters, so only when asked
            self.epilog = self.epilog()
        return super().format_help()


#: What the dataset argument of ``info`` and ``run`` accepts.
_DATASET_HELP = "03, 0022, 0020, 0042, 10, datasetNN, sim, sim-small, sim-tiny, or a path to an .npz or 2025+ .npy file"


def build_parser():
    """The ``argparse.ArgumentParser`` of ``visla-edu``; its usage errors are one line and status 2 (:class:`_Parser`).

    The subcommand (required) is stored as ``command``; ``--debug`` goes before or after it, ``--data-dir`` after
    ``info``, ``run``, ``stepper``; values are checked while parsing (:mod:`visla_edu.cli.options`).
    """
    parser = _Parser(prog="visla-edu",
                     description="Visual-inertial SLAM with an EKF: datasets, filters, course tools.")
    debug_help = f"print tracebacks of errors (also {DEBUG_ENV}=1)"
    parser.add_argument("--debug", action="store_true", help=debug_help)
    debug = _Parser(add_help=False)
    debug.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=debug_help)
    common = _Parser(add_help=False, parents=[debug])
    common.add_argument("--data-dir", default=None, type=_options.path,
                        help="folder with the course files (default: $VISLA_EDU_DATA, else ./data)")
    sub = parser.add_subparsers(dest="command", required=True)

    info = sub.add_parser("info", parents=[common], help="summarise a dataset and diagnose its problems")
    info.add_argument("dataset", help=_DATASET_HELP)
    info.add_argument("--no-diagnostics", action="store_true", help="skip the visual-odometry diagnostics")
    _add_frames_option(info)

    _add_run_parser(sub, common)

    stepper = sub.add_parser("stepper", parents=[common], help="serve the interactive filter stepper with Voila")
    stepper.add_argument("--port", type=_options.port, default=8866, help="TCP port of the page (default 8866)")
    stepper.add_argument("--open", action="store_true", help="open a browser")

    release = sub.add_parser("release", parents=[debug], help="generate the student notebooks from the solutions")
    release.add_argument("--src", default=None, type=_options.path, help="solutions folder (default: the project's solutions/)")
    release.add_argument("--dst", default=None, type=_options.path,
                         help="student edition folder (default: the package's visla_edu/course/notebooks/)")
    release.add_argument("--check", action="store_true", help="only report notebooks that drifted")
    release.add_argument("--force", action="store_true", help="also replace student notebooks edited by hand")
    student = sub.add_parser("student", parents=[debug], help="create a student's folder, or add the new notebooks")
    student.add_argument("folder", type=_options.path, help="the student's folder (created if missing; files "
                                                            "already there are never replaced)")
    _project_commands.add_parser(sub, common, debug, _options.path)

    book = sub.add_parser("book", parents=[debug], help="build the course site (the student edition, executed) in DIR")
    book.add_argument("dir", type=_options.path, metavar="DIR", help="the site's folder: new, empty or a former site")
    book.add_argument("--src", default=None, type=_options.path, help="solutions folder (default: the project's)")
    book.add_argument("--no-course-data", action="store_true", help="run without VISLA_EDU_DATA, as on Binder")
    book.add_argument("--repository", default=None, metavar="URL",
                      help="https://github.com/OWNER/NAME: Binder and Colab buttons on each page")
    book.add_argument("--branch", default="main", help="the branch those buttons open (default: main)")
    return parser


def _add_run_parser(sub, common):
    run = sub.add_parser("run", parents=[common], help="run a filter over a dataset", epilog=_options.settings_help,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("dataset", help=_DATASET_HELP)
    run.add_argument("--mode", default=SLAM, choices=RUN_MODES, help=RUN_MODES_HELP)
    run.add_argument("--dense", action="store_true", help="textbook dense joint EKF (slam only; use a stride)")
    run.add_argument("--force", action="store_true",
                     help="run even when the estimated memory or time exceeds the limits (2 GiB, 15 min)")
    run.add_argument("--landmark-stride", type=_options.stride, default=None, metavar="N",
                     help="use every N-th landmark only (default 1: all; as --set landmark_stride=N)")
    run.add_argument("--set", action="append", default=[], type=_options.setting, metavar="NAME=VALUE",
                     help="override a FilterConfig setting, e.g. --set sigma_pixel=2 (repeatable); "
                          "booleans are true/false (or 1/0, yes/no), ranges are enforced")
    run.add_argument("--smoother-set", action="append", default=[], type=_options.smoother_setting,
                     metavar="NAME=VALUE",
                     help="with --mode smooth or window: a smoother setting of its own, e.g. window_size=40 (repeatable)")
    run.add_argument("--out", default=None, type=_options.path, help="save the result (.npz)")
    run.add_argument("--plot", default=None, type=_options.path,
                     help="save a top-down figure of trajectory and map (.png, .pdf, .svg or another matplotlib format)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--blas-threads", type=_options.blas_threads, default=1, metavar="N",
                     help="BLAS threads while the filter runs (default 1, fastest for its small matrices; "
                          "'none' leaves numpy's setting alone)")
    run.add_argument("--ground-truth", default=None, type=_options.path, metavar="FILE",
                     help="KITTI odometry poses (poses/NN.txt: left-camera poses, row i = frame i) to report ATE and "
                          "drift against (automatic for a registered drive such as 0020)")
    run.add_argument("--ground-truth-times", default=None, type=_options.path, metavar="FILE",
                     help="KITTI times.txt of the ground truth, checked against the dataset's time stamps")
    run.add_argument("--trajectory-out", default=None, type=_options.path, metavar="FILE",
                     help="write the estimated trajectory: .kitti or .txt (KITTI, 12 numbers per row) or .tum "
                          "(TUM: t x y z qx qy qz qw)")
    _add_frames_option(run)


def _add_frames_option(parser):
    parser.add_argument("--frames", default=None, type=_options.frames, metavar="START:STOP",
                        help="use frames START..STOP-1 only, as a drive of their own (its ground truth starts at "
                             "frame START); either end may be left out, e.g. 0:300 or 500:")


def _select_frames(dataset, frames, truth_option=None):
    """``dataset`` cut to ``frames``, ``--frames (start, stop)`` (stop None: the end), or unchanged.

    A range outside the drive is a ValueError; too few ground-truth poses left: :func:`_segment_truth_checked`
    (``truth_option``: the user's ``--ground-truth`` file).
    """
    if frames is None:
        return dataset
    start, stop = frames
    stop = dataset.num_frames if stop is None else stop
    if not start + 2 <= stop <= dataset.num_frames:
        raise ValueError(f"--frames {start}:{stop}: {dataset.name} has frames 0..{dataset.num_frames - 1}; give "
                         f"0 <= START, START + 2 <= STOP <= {dataset.num_frames} (STOP is excluded)")
    return _segment_truth_checked(dataset, dataset.segment(start, stop), start, stop, truth_option)


def _segment_truth_checked(dataset, segment, start, stop, truth_option):
    """``segment``, refused (``--ground-truth`` given) or without its ground truth when it keeps too few poses."""
    import dataclasses

    from visla_edu.data import MIN_POSES

    if dataset.ground_truth is None:
        return segment
    kept = 0 if segment.ground_truth is None else segment.ground_truth.num_frames
    if kept >= MIN_POSES:
        return segment
    covered = dataset.ground_truth.num_frames
    what = (f"the ground truth ({Path(dataset.ground_truth.source).name if dataset.ground_truth.source else 'simulated'}) "
            f"covers frames 0..{covered - 1}, so frames {start}..{stop - 1} keep {kept} of its poses and an ATE "
            f"needs at least {MIN_POSES}")
    if truth_option:
        raise ValueError(f"--frames {start}:{stop}: --ground-truth {truth_option}: {what}; give START <= "
                         f"{covered - MIN_POSES} and STOP >= START + {MIN_POSES}, or leave out --ground-truth")
    print(f"note: --frames {start}:{stop}: {what}; running without ground truth (no ATE)")
    return dataclasses.replace(segment, ground_truth=None)


def _cmd_info(args):
    from visla_edu import data, diagnostics

    dataset = _select_frames(data.load(args.dataset, args.data_dir), args.frames)
    print(data.format_summary(dataset))
    if not args.no_diagnostics and dataset.num_observations:
        print()
        try:
            print(diagnostics.calibrate(dataset).report(dataset.name))
        except (ArithmeticError, ValueError, MemoryError) as err:
            err.hint = "the file loaded fine; rerun with --no-diagnostics to skip the diagnostics"
            err.failed = True  # a failure of the diagnostics on a valid file: exit 1, not 2
            raise


def _cmd_run(args):
    import numpy as np

    from visla_edu import run
    from visla_edu.run import workload
    from visla_edu.filters import FilterDivergedError

    config = _run_config(args)
    outputs = _check_outputs(args, _run_inputs(args))
    dataset = _load_with_ground_truth(args)
    if dataset.label:
        print(dataset.label)
    _check_work(dataset, args, config)
    try:
        progress = False if args.quiet else None
        if args.mode in SMOOTHER_MODES:
            result = run.run_smoother(dataset, args.mode, config, progress=progress, verbose=True,
                                      blas_threads=args.blas_threads, smoother_settings=dict(args.smoother_set))
        else:
            result = run.run_filter(dataset, args.mode, config, dense=args.dense, progress=progress,
                                    verbose=True, blas_threads=args.blas_threads)
    except (FilterDivergedError, np.linalg.LinAlgError, ArithmeticError, MemoryError) as err:
        err.hint = workload.divergence_hint(dataset, config, getattr(err, "frame", None))
        raise
    print(result.summary())
    if dataset.ground_truth is not None:
        _print_evaluation(run.evaluate_result(result, dataset.ground_truth), dataset.ground_truth, args.mode,
                          result.start_mode)
    if args.out:
        print(f"saved {run.save_result(result, outputs['--out'])}")
    if args.trajectory_out:
        from visla_edu import trajectory

        written = trajectory.write_trajectory(outputs["--trajectory-out"], result.time_stamps, result.world_T_imu)
        print(f"saved {written}")
    if args.plot:
        _save_plot(result, dataset, args, outputs["--plot"])


def _run_config(args):
    """The FilterConfig of ``--set`` and ``--landmark-stride`` (each setting given once), checked."""
    from visla_edu.filters import FilterConfig

    if args.dense and args.mode != SLAM:
        raise ValueError(f"--dense is the textbook joint filter and needs --mode slam, got --mode {args.mode}")
    names = [name for name, _ in args.smoother_set]
    if names and args.mode not in SMOOTHER_MODES:
        raise ValueError(f"--smoother-set {names[0]}: smoother settings need --mode smooth or window, got --mode {args.mode}")
    if len(set(names)) < len(names):
        raise ValueError(f"--smoother-set: {max(names, key=names.count)} is given twice; give each setting once")
    _check_window_settings(args)  # the smoother's own settings are checked by run.run_smoother
    settings = {}
    pairs = list(args.set) + ([("landmark_stride", args.landmark_stride)] if args.landmark_stride else [])
    for name, value in pairs:
        if name in settings:
            raise ValueError(f"--set: {name} is given twice (or both --set landmark_stride and --landmark-stride); "
                             "give each setting once")
        settings[name] = value
    return FilterConfig(**settings)


def _check_window_settings(args):
    """Refuse a ``--set`` that ``--mode window`` would ignore (an EKF-only setting such as the gate)."""
    if args.mode != "window":
        return
    from visla_edu.smoother import FILTER_SETTINGS

    used = (*FILTER_SETTINGS, "extrinsic_correction", "landmark_stride")
    for name, _ in args.set:
        if name not in used:
            raise ValueError(f"--set {name}: --mode window does not use it (a setting of the EKF); the window reads "
                             f"{', '.join(used[:-1])} and its own --smoother-set settings")


def _run_inputs(args):
    """Every file ``run`` reads: the dataset, its registered ground truth, ``--ground-truth`` files."""
    from visla_edu import data

    if args.ground_truth_times and not args.ground_truth:
        raise ValueError(f"--ground-truth-times {args.ground_truth_times} needs --ground-truth POSES_FILE too")
    given = [args.ground_truth, args.ground_truth_times]
    return data.input_files(args.dataset, args.data_dir) + [Path(p) for p in given if p and Path(p).exists()]


def _check_outputs(args, inputs):
    """``{"--out": path, "--plot": path, "--trajectory-out": path}``, checked before any work (check_output_path)."""
    from visla_edu._files import check_output_path

    given = {"--out": args.out, "--plot": args.plot, "--trajectory-out": args.trajectory_out}
    outputs = {}
    for option, path in given.items():
        if not path:
            continue
        others = [(o, p) for o, p in given.items() if o != option and p]
        outputs[option] = check_output_path(path, _suffixes(option, path), option, inputs, others)
    return outputs


def _suffixes(option, path):
    """The suffixes allowed for an output option (the trajectory's format is checked by its own rule)."""
    if option == "--out":
        return (".npz",)
    if option == "--plot":
        from visla_edu.plotting import figure_suffixes

        return figure_suffixes()
    from visla_edu import trajectory

    trajectory.trajectory_format(path)
    return tuple(trajectory.FORMATS)


def _check_work(dataset, args, config):
    """Print the estimated cost of a dense (or a heavy) run; refuse one past the limits unless ``--force``."""
    import dataclasses

    from visla_edu.run import workload

    estimate = workload.estimate_work(dataset, args.mode, config, args.dense)
    over = estimate.over_limits()
    if args.dense or over:
        print(estimate.summary())
    if not over:
        return
    if args.force:
        print(f"--force: running anyway ({' and '.join(over)})")
        return
    stride = config.landmark_stride
    while stride < dataset.num_landmarks and workload.estimate_work(
            dataset, args.mode, dataclasses.replace(config, landmark_stride=stride), args.dense).over_limits():
        stride *= 2
    dense = " --dense" if args.dense else ""
    alternative = "the active set (drop --dense, same trajectory), " if args.dense else ""
    raise ValueError(f"--mode {args.mode}{dense} on {dataset.name} with landmark stride {config.landmark_stride} would "
                     f"need {' and '.join(over)}; use --landmark-stride {stride} (or more), or {alternative}or --force "
                     "to run it anyway")


def _save_plot(result, dataset, args, path):
    import matplotlib

    matplotlib.use("Agg")
    from visla_edu import plotting

    figure = plotting.plot_result(result, ground_truth=dataset.ground_truth,
                                  title=f"{dataset.name}: {args.mode}{' (dense)' if args.dense else ''}")
    print(f"saved {plotting.save_figure(figure, path)}")


def _load_with_ground_truth(args):
    """The dataset of ``args``, with the ground truth of ``--ground-truth`` when given, cut to ``--frames``."""
    from visla_edu import data

    dataset = data.load(args.dataset, args.data_dir)
    if args.ground_truth:
        dataset = data.attach_ground_truth(dataset, args.ground_truth, args.ground_truth_times)
    return _select_frames(dataset, args.frames, args.ground_truth)


def _print_evaluation(evaluations, ground_truth, mode, start_mode=""):
    """The lines ``visla-edu run`` prints about the ground truth, estimate and dead reckoning."""
    source = Path(ground_truth.source).name if ground_truth.source else "the simulation"
    rows = f", {ground_truth.rows_text}" if ground_truth.rows_text else ""
    print(f"ATE against ground truth ({source}, {ground_truth.num_frames} frames{rows}), "
          "drift over 100-800 m segments:")
    rows = {f"{mode} estimate": evaluations["estimate"]}
    if "start" in evaluations:
        start = {"slam": "slam (EKF)", "vio": "vio", "deadreckon": "dead reckoning"}.get(start_mode, start_mode or "start")
        rows[f"{start} it started from"] = evaluations["start"]
    rows["dead reckoning"] = evaluations["dead_reckoning"]
    width = max(map(len, rows)) + 2
    for label, evaluation in rows.items():
        print(f"  {label:{width}s}{evaluation.summary()}")


def _cmd_stepper(args):
    from visla_edu.stepper import app

    print(f"serving the filter stepper on http://localhost:{args.port}/ (Ctrl-C to stop)")
    app.serve(port=args.port, open_browser=args.open, data_dir=args.data_dir, wait=True)


def _cmd_release(args):
    from visla_edu.course import release
    from visla_edu.course import STUDENT_NOTEBOOKS

    src = Path(args.src) if args.src else release.SOLUTIONS
    dst = Path(args.dst) if args.dst else STUDENT_NOTEBOOKS
    if not src.is_dir():
        raise FileNotFoundError(f"solutions folder {src} not found (run from a source checkout or pass --src)")
    if dst.exists() and not dst.is_dir():
        raise NotADirectoryError(f"release: --dst {dst} is a file, not a folder; give the folder of the student "
                                 "notebooks")
    teaching = src.resolve().parent / "TEACHING.md"
    if args.check:
        drifted = release.check_in_sync(src, dst)
        if teaching.is_file() and release.update_points_table(src, teaching, check=True):
            drifted.append(teaching.name)
        print("\n".join(f"drifted: {name}" for name in drifted) or f"{dst} is in sync with {src}")
        raise SystemExit(1 if drifted else 0)
    release.make_student_notebooks(src, dst, force=args.force)
    print(f"wrote student notebooks to {dst}")
    if teaching.is_file() and release.update_points_table(src, teaching):
        print(f"updated the points table in {teaching}")


def _cmd_student(args):
    from visla_edu.course import student

    print(student.make_student_folder(args.folder).report())


def _cmd_book(args):
    from visla_edu.course import book

    index = book.build_book(args.dir, args.src, not args.no_course_data, args.repository, args.branch)
    print(f"wrote the course site: {index}")


_HANDLERS = {"info": _cmd_info, "run": _cmd_run, "stepper": _cmd_stepper, "release": _cmd_release,
             "student": _cmd_student, "book": _cmd_book, "project": _project_commands.run}


def main(argv=None):
    """The one error boundary of the commands: parse ``argv``, run the command, return its exit status.

    ``argv`` (list of str): the arguments after ``visla-edu``, default ``sys.argv[1:]``. Numerical warnings
    (numpy's ``RuntimeWarning``) are collected: a failure is reported by its one line, a success by one line
    counting them; ``--debug`` prints them as they happen. ``visla_edu.__main__.console_main`` also covers
    loading this module and the moments after this function returns.

    Returns
    -------
    int
        The module docstring's status; 130 for Ctrl-C at any moment from parsing to the last line printed.

    Raises
    ------
    SystemExit
        For a usage error (status 2), ``--help`` (0) and ``release --check`` finding notebooks that drifted (1).
    """
    command, debug = None, os.environ.get(DEBUG_ENV, "").strip() not in ("", "0")
    try:
        args = build_parser().parse_args(argv)
        command, debug = args.command, debug or getattr(args, "debug", False)
        return _run_command(args, debug)
    except KeyboardInterrupt:
        _report(command, "interrupted (Ctrl-C); files being written were left as they were", debug)
        return EXIT_INTERRUPTED


def _run_command(args, debug):
    """Run the command of ``args`` inside :func:`main`'s boundary: its exit status (a KeyboardInterrupt propagates)."""
    with warnings.catch_warnings(record=not debug) as caught:
        if not debug:
            warnings.simplefilter("default", RuntimeWarning)  # once per place: bounded
        try:
            _HANDLERS[args.command](args)
        except BrokenPipeError:  # the reader of our output went away (e.g. `| head`): stop quietly
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return EXIT_FAILED
        except Exception as err:  # noqa: BLE001 - the boundary: every error becomes one line and a status
            code, message = _describe(err, args)
            _report(args.command, message, debug)
            return code
    _note_warnings(args.command, caught or [])
    return 0


def _note_warnings(command, caught):
    """One line on stderr for the numerical warnings of a successful run, the rest re-issued."""
    numeric = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    for w in caught:
        if not issubclass(w.category, RuntimeWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if numeric:
        first = str(numeric[0].message)
        print(f"visla-edu {command}: note: numerical warnings at {len(numeric)} place(s), e.g. {first!r} "
              "(rerun with --debug to see them)", file=sys.stderr)


def _report(command, message, debug):
    """``message`` as one line on stderr, after ``visla-edu COMMAND:`` (``visla-edu:`` before parsing)."""
    print(_one_line(f"visla-edu{' ' + command if command else ''}: {message}"), file=sys.stderr)
    if debug:
        traceback.print_exc()


def _one_line(text):
    return " ".join(str(text).split())


def _describe(err, args):
    """``(exit status, message)`` of an exception that reached the boundary (statuses: the module docstring)."""
    import numpy as np

    from visla_edu.filters import FilterDivergedError

    hint = getattr(err, "hint", "")
    hint = f"; {hint}" if hint else ""
    if getattr(err, "failed", False):
        return EXIT_FAILED, f"{type(err).__name__}: {err}{hint}"
    if isinstance(err, FilterDivergedError):
        return EXIT_FAILED, f"the filter diverged: {err}{hint}"
    if isinstance(err, np.linalg.LinAlgError):
        return EXIT_FAILED, f"the filter failed: singular or not positive definite matrix ({err}){hint}"
    if isinstance(err, ArithmeticError):
        return EXIT_FAILED, f"numerical failure ({type(err).__name__}: {err}){hint}"
    if isinstance(err, MemoryError):
        return EXIT_FAILED, f"out of memory ({err or 'MemoryError'}); {_memory_hint(args)}"
    if isinstance(err, OSError) and (err.errno in _PATH_ERRNOS or err.errno is None):
        return EXIT_BAD_INPUT, _os_message(err)
    if isinstance(err, OSError):
        return EXIT_FAILED, f"{_os_message(err)} (a system error: check the disk and the paths)"
    if isinstance(err, ValueError):
        return EXIT_BAD_INPUT, f"{err}{hint}"
    return EXIT_INTERNAL, (f"internal error ({type(err).__name__}: {err}); this is a bug in visla-edu, please report "
                           "it with the command line and the traceback of --debug")


def _os_message(err):
    """An OSError as text: our own messages as they are, the system's as 'file: reason'."""
    if err.filename is None:
        return str(err)
    return f"{err.filename}: {(err.strerror or str(err)).lower()}"


def _memory_hint(args):
    if getattr(args, "dense", False):
        return ("the dense filter keeps a covariance over every landmark: use a larger --landmark-stride, "
                "or the active set (drop --dense)")
    return "close other programs or use a smaller dataset"
