"""``visla-edu project show|grade``: the parser of the project's command; the work is :mod:`visla_edu.course.project`.

Apart from the grader so that :mod:`visla_edu.cli` builds its parser without importing it.
"""

import argparse

from visla_edu.course._runner import DEFAULT_MEMORY_LIMIT, DEFAULT_TIME_LIMIT

__all__ = ["add_parser", "run"]


def _seconds(text):
    """``--time-limit``: a positive number of seconds."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 < value < 1e7:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _gibibytes(text):
    """``--memory-limit``: GiB of address space, 0 for no limit; returned in bytes (or None)."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 <= value <= 1e6 or 0 < value < 0.25:
        raise argparse.ArgumentTypeError(f"expected GiB of memory, at least 0.25 (or 0 for no limit), got {text!r}")
    return int(value * 2**30) or None


def add_parser(sub, common, debug, path):
    """Add ``project`` (with ``show`` and ``grade``) to the ``visla-edu`` subcommands ``sub``.

    ``common`` and ``debug`` are the other commands' parent parsers (``--data-dir`` and ``--debug``;
    ``--debug``); ``path`` is the ``type=`` for a path (:func:`visla_edu.cli.options.path`).
    """
    project = sub.add_parser("project", parents=[debug], help="the course project: print the assignment, grade "
                                                              "submissions (see PROJECT.md)")
    actions = project.add_subparsers(dest="project_command", required=True, metavar="{show,grade}")
    actions.add_parser("show", parents=[debug], help="print the assignment (PROJECT.md); e.g. > PROJECT.md")
    grade = actions.add_parser("grade", parents=[common], help="run students' filters on a drive, with the library "
                               "hidden and a time limit; write a report per submission and a summary")
    grade.add_argument("submissions", nargs="+", type=path, metavar="SUBMISSION.py",
                       help="the students' files, each defining make_filter(dataset, config)")
    grade.add_argument("--drive", required=True,
                       help="03, 0022, 0020, 0042, 10, sim, sim-small, sim-tiny or a path to an .npz file (e.g. a "
                            "simulated drive the students never had)")
    grade.add_argument("--ground-truth", default=None, type=path, metavar="FILE",
                       help="KITTI odometry poses to grade against (automatic for a registered drive such as 0020)")
    grade.add_argument("--ground-truth-times", default=None, type=path, metavar="FILE",
                       help="KITTI times.txt of the ground truth, checked against the drive's time stamps")
    grade.add_argument("--out", required=True, type=path, metavar="DIR",
                       help="folder for the reports: new, empty, or an earlier grading's")
    grade.add_argument("--time-limit", type=_seconds, default=DEFAULT_TIME_LIMIT, metavar="SECONDS",
                       help="wall time per submission: import, make_filter and every step (default "
                            f"{DEFAULT_TIME_LIMIT:g})")
    grade.add_argument("--memory-limit", type=_gibibytes, default=DEFAULT_MEMORY_LIMIT, metavar="GIB",
                       help=f"address space per submission in GiB (default {DEFAULT_MEMORY_LIMIT / 2**30:g}; 0: no "
                            "limit; Linux and macOS)")


def run(args):
    """The ``project`` command: print the assignment, or grade the submissions."""
    from visla_edu.course import project

    if args.project_command == "show":
        print(project.assignment_text(), end="")
        return
    project.grade(args.submissions, args.drive, args.out, ground_truth=args.ground_truth,
                  ground_truth_times=args.ground_truth_times, time_limit=args.time_limit,
                  memory_limit=args.memory_limit, data_dir=args.data_dir)
