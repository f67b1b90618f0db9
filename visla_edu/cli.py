"""Command line: ``visla-edu {info,run,stepper,release} ...`` (also ``python -m visla_edu``).

Examples::

    visla-edu info 03                       # summary and diagnostics of a course file
    visla-edu run sim --plot sim.png        # joint SLAM on the built-in simulated drive
    visla-edu run 03 --mode mapping --out map.npz
    visla-edu run 03 --dense --landmark-stride 20
    visla-edu run 03 --blas-threads none      # leave numpy's BLAS threads alone (default: 1)
    visla-edu run 0020                      # ATE and drift against its KITTI ground truth (found beside it)
    visla-edu run X --ground-truth poses.txt --ground-truth-times times.txt --trajectory-out slam.tum
    visla-edu stepper --port 8866           # the filter stepper page (Voila)
    visla-edu release                       # regenerate notebooks/ from solutions/
"""

import argparse
import dataclasses
import sys
from pathlib import Path

from visla_edu.codes import MODES, SLAM

__all__ = ["main", "build_parser"]


def build_parser():
    """The argument parser of ``visla-edu``."""
    parser = argparse.ArgumentParser(
        prog="visla-edu", description="Visual-inertial SLAM with an EKF: datasets, filters, course tools.")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--data-dir", default=None,
                        help="folder with the course files (default: $VISLA_EDU_DATA, else ./data)")
    sub = parser.add_subparsers(dest="command", required=True)

    info = sub.add_parser("info", parents=[common], help="summarise a dataset and diagnose its problems")
    info.add_argument("dataset", help="03, 0022, 10, sim, sim-small, sim-tiny or a path to an .npz file")
    info.add_argument("--no-diagnostics", action="store_true", help="skip the visual-odometry diagnostics")

    run = sub.add_parser("run", parents=[common], help="run a filter over a dataset")
    run.add_argument("dataset", help="03, 0022, 10, sim, sim-small, sim-tiny or a path to an .npz file")
    run.add_argument("--mode", default=SLAM, choices=MODES)
    run.add_argument("--dense", action="store_true", help="textbook dense joint EKF (slam only; use a stride)")
    run.add_argument("--landmark-stride", type=int, default=None, help="use every N-th landmark only")
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                     help="override a FilterConfig setting, e.g. --set sigma_pixel=2 (repeatable)")
    run.add_argument("--out", default=None, help="save the result (.npz)")
    run.add_argument("--plot", default=None, help="save a top-down figure of trajectory and map (.png)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--blas-threads", type=_blas_threads, default=1, metavar="N",
                     help="BLAS threads while the filter runs (default 1, fastest for its small matrices; "
                          "'none' leaves numpy's setting alone)")
    run.add_argument("--ground-truth", default=None, metavar="FILE",
                     help="KITTI odometry poses (poses/NN.txt: left-camera poses, row i = frame i) to report ATE and "
                          "drift against (automatic for a registered drive such as 0020)")
    run.add_argument("--ground-truth-times", default=None, metavar="FILE",
                     help="KITTI times.txt of the ground truth, checked against the dataset's time stamps")
    run.add_argument("--trajectory-out", default=None, metavar="FILE",
                     help="write the estimated trajectory: .kitti or .txt (KITTI, 12 numbers per row) or .tum "
                          "(TUM: t x y z qx qy qz qw)")

    stepper = sub.add_parser("stepper", parents=[common], help="serve the interactive filter stepper with Voila")
    stepper.add_argument("--port", type=int, default=8866)
    stepper.add_argument("--open", action="store_true", help="open a browser")

    release = sub.add_parser("release", help="generate the student notebooks from the solutions")
    release.add_argument("--src", default=None, help="solutions folder (default: the project's solutions/)")
    release.add_argument("--dst", default=None, help="student folder (default: the project's notebooks/)")
    release.add_argument("--check", action="store_true", help="only report notebooks that drifted")
    return parser


def _blas_threads(text):
    """``--blas-threads`` value: a positive integer or ``none``."""
    if text.strip().lower() == "none":
        return None
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer or 'none', got {text!r}")
    return n


def _parse_settings(pairs):
    """``["sigma_pixel=2", ...]`` -> FilterConfig keyword arguments, typed like the defaults."""
    from visla_edu.filters import FilterConfig

    fields = {f.name: f for f in dataclasses.fields(FilterConfig)}
    defaults = FilterConfig()
    out = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        if not sep or name not in fields:
            raise SystemExit(f"--set {pair!r}: expected NAME=VALUE with NAME one of {', '.join(fields)}")
        kind = type(getattr(defaults, name))
        try:
            out[name] = (value.lower() in ("1", "true", "yes")) if kind is bool else kind(value)
        except ValueError:
            raise SystemExit(f"--set {pair!r}: {name} needs a {kind.__name__}, got {value!r}") from None
    return out


def _cmd_info(args):
    from visla_edu import data, diagnostics

    dataset = data.load(args.dataset, args.data_dir)
    print(data.format_summary(dataset))
    if not args.no_diagnostics and dataset.num_observations:
        print()
        print(diagnostics.diagnose(dataset))


def _cmd_run(args):
    from visla_edu import data, plotting, run
    from visla_edu.filters import FilterConfig

    settings = _parse_settings(args.set)
    if args.landmark_stride is not None:
        settings["landmark_stride"] = args.landmark_stride
    config = FilterConfig(**settings)
    _check_run_outputs(args)
    dataset = _load_with_ground_truth(args)
    if dataset.label:
        print(dataset.label)
    result = run.run_filter(dataset, args.mode, config, dense=args.dense,
                            progress=False if args.quiet else None, verbose=True, blas_threads=args.blas_threads)
    print(result.summary())
    if dataset.ground_truth is not None:
        _print_evaluation(run.evaluate_result(result, dataset.ground_truth), dataset.ground_truth, args.mode)
    if args.out:
        run.save_result(result, args.out)
        print(f"saved {Path(args.out).resolve()}")
    if args.trajectory_out:
        from visla_edu import trajectory

        print(f"saved {trajectory.write_trajectory(args.trajectory_out, result.time_stamps, result.world_T_imu)}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        plotting.plot_result(result, args.plot, ground_truth=dataset.ground_truth,
                             title=f"{dataset.name}: {args.mode}{' (dense)' if args.dense else ''}")
        print(f"saved {Path(args.plot).resolve()}")


def _check_run_outputs(args):
    """Problems with the output and ground-truth options, found before the run starts."""
    if args.trajectory_out:
        from visla_edu import trajectory

        trajectory.trajectory_format(args.trajectory_out)
    if args.ground_truth_times and not args.ground_truth:
        raise ValueError(f"--ground-truth-times {args.ground_truth_times} needs --ground-truth POSES_FILE too")


def _load_with_ground_truth(args):
    """The dataset of ``args``, with the ground truth of ``--ground-truth`` when given."""
    from visla_edu import data

    dataset = data.load(args.dataset, args.data_dir)
    if args.ground_truth:
        dataset = data.attach_ground_truth(dataset, args.ground_truth, args.ground_truth_times)
    return dataset


def _print_evaluation(evaluations, ground_truth, mode):
    """The lines ``visla-edu run`` prints about the ground truth, estimate and dead reckoning."""
    source = Path(ground_truth.source).name if ground_truth.source else "the simulation"
    print(f"ATE against ground truth ({source}, {ground_truth.num_frames} frames), drift over 100-800 m segments:")
    rows = {f"{mode} estimate": evaluations["estimate"], "dead reckoning": evaluations["dead_reckoning"]}
    width = max(map(len, rows)) + 2
    for label, evaluation in rows.items():
        print(f"  {label:{width}s}{evaluation.summary()}")


def _cmd_stepper(args):
    from visla_edu.stepper import app

    print(f"serving the filter stepper on http://localhost:{args.port}/ (Ctrl-C to stop)")
    app.serve(port=args.port, open_browser=args.open, data_dir=args.data_dir, wait=True)


def _cmd_release(args):
    from visla_edu import release

    root = Path(__file__).resolve().parent.parent
    src = Path(args.src) if args.src else root / "solutions"
    dst = Path(args.dst) if args.dst else root / "notebooks"
    if not src.is_dir():
        raise SystemExit(f"release: solutions folder {src} not found (run from a source checkout or pass --src)")
    teaching = src.resolve().parent / "TEACHING.md"
    if args.check:
        drifted = release.check_in_sync(src, dst)
        if teaching.is_file() and release.update_points_table(src, teaching, check=True):
            drifted.append(teaching.name)
        print("\n".join(f"drifted: {name}" for name in drifted) or "notebooks/ is in sync with solutions/")
        raise SystemExit(1 if drifted else 0)
    release.make_student_notebooks(src, dst)
    print(f"wrote student notebooks to {dst}")
    if teaching.is_file() and release.update_points_table(src, teaching):
        print(f"updated the points table in {teaching}")


def main(argv=None):
    """Entry point of the ``visla-edu`` console script."""
    args = build_parser().parse_args(argv)
    handlers = {"info": _cmd_info, "run": _cmd_run, "stepper": _cmd_stepper, "release": _cmd_release}
    try:
        handlers[args.command](args)
    except (FileNotFoundError, ValueError) as err:
        print(f"visla-edu {args.command}: {err}", file=sys.stderr)
        return 2
    return 0
