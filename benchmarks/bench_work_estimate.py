"""The work estimate of ``visla-edu run`` against measured runs: time and peak memory.

Usage::

    VISLA_EDU_DATA=/path/to/course/data python benchmarks/bench_work_estimate.py [--frames 60]

For each case, :func:`visla_edu.run.workload.estimate_work` is computed for the first ``--frames``
frames of the drive, then the filter runs over those frames in its own process (one BLAS
thread, as the CLI runs it), and the table prints estimated and measured seconds and the
estimated peak bytes against the measured growth of the resident memory (ru_maxrss after the
run minus before it). The estimate is a model for refusing runs that would take hours or
gigabytes, so the ratio matters to a factor of a few, not to percent. Cases: dense SLAM at
several landmark strides (simulated course drive; dataset 03 when the data directory has
it), active-set SLAM and VIO on a crowded simulated drive (about 700 landmarks in view at
every frame), and active-set SLAM on the simulated course drive.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time

CASES = [
    # dataset, mode, dense, landmark stride
    ("sim", "slam", True, 8),
    ("sim", "slam", True, 4),
    ("sim", "slam", True, 2),
    ("03", "slam", True, 8),
    ("03", "slam", True, 4),
    ("crowded", "slam", False, 1),
    ("crowded", "vio", False, 1),
    ("sim", "slam", False, 1),
]


def _dataset(name, frames):
    from visla_edu import data, simulate

    if name != "crowded":
        ds = data.load(name)
    else:  # about 700 landmarks in view at every frame, consistent tracks (so they are used, not gated)
        ds = simulate.simulate_drive("tiny", num_landmarks=3000, max_observations_per_frame=5000)
    return _first_frames(ds, frames)


def _first_frames(ds, frames):
    """The dataset cut to its first ``frames`` frames (same landmarks)."""
    import dataclasses

    T = min(frames, ds.num_frames)
    end = ds.frame_ptr[T]
    return dataclasses.replace(ds, time_stamps=ds.time_stamps[:T], linear_velocity=ds.linear_velocity[:T],
                               angular_velocity=ds.angular_velocity[:T], frame_ptr=ds.frame_ptr[: T + 1],
                               obs_ids=ds.obs_ids[:end], obs_z=ds.obs_z[:end], ground_truth=None, extra={})


def _measure(name, mode, dense, stride, frames):
    from visla_edu import run
    from visla_edu.run import workload
    from visla_edu.filters import FilterConfig

    ds = _dataset(name, frames)
    config = FilterConfig(landmark_stride=stride, extrinsic_correction="none")
    estimate = workload.estimate_work(ds, mode, config, dense)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    start = time.perf_counter()
    run.run_filter(ds, mode, config, dense=dense, progress=False)
    seconds = time.perf_counter() - start
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - before
    return {"dataset": ds.name, "mode": mode + (" dense" if dense else ""), "stride": stride, "frames": ds.num_frames,
            "state_dim": estimate.state_dim, "rows": estimate.max_rows, "est_s": estimate.seconds, "s": seconds,
            "est_mb": estimate.peak_bytes / 2**20, "mb": grown / 2**20}


def _available(name):
    from visla_edu import data

    return name.startswith("sim") or name == "crowded" or name in data.available()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="frames of each drive to run")
    parser.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        name, mode, dense, stride, frames = args.child
        print(json.dumps(_measure(name, mode, dense == "1", int(stride), int(frames))))
        return
    print(f"{'dataset':9s} {'mode':11s} {'stride':>6s} {'frames':>6s} {'max D':>6s} {'rows':>5s} {'est s':>7s} "
          f"{'run s':>7s} {'ratio':>6s} {'est MB':>7s} {'run MB':>7s}")
    for name, mode, dense, stride in CASES:
        if not _available(name):
            print(f"{name:9s} {mode:11s} skipped: not in the data directory ({os.environ.get('VISLA_EDU_DATA')})")
            continue
        child = subprocess.run([sys.executable, __file__, "--child", name, mode, "1" if dense else "0", str(stride),
                                str(args.frames)], capture_output=True, text=True, check=True)
        r = json.loads(child.stdout.strip().splitlines()[-1])
        print(f"{r['dataset']:9s} {r['mode']:11s} {r['stride']:6d} {r['frames']:6d} {r['state_dim']:6d} {r['rows']:5d} "
              f"{r['est_s']:7.2f} {r['s']:7.2f} {r['est_s'] / r['s']:6.2f} {r['est_mb']:7.1f} {r['mb']:7.1f}")


if __name__ == "__main__":
    main()
