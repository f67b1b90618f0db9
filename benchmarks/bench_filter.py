"""Speed and memory of the filters: prints wall time, peak memory and per-step latency.

Usage::

    VISLA_EDU_DATA=/path/to/course/data python benchmarks/bench_filter.py [--dense-stride 20]

Each case runs in its own process so that its peak resident memory (ru_maxrss) is its own,
``--repeat`` times (wall time reported as the median and the best: this machine's timing
varies by +-15% from run to run; the per-step latencies are from the last run).
Cases: full-landmark SLAM (active set) on ``03`` and on dataset 10 (the real file or its
stand-in), the dense textbook SLAM on a landmark stride of ``03``, dead reckoning on ``03``,
and the simulated drive (always available). Course-data cases are skipped, with a note,
when the data directory lacks the files.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time

CASES = [
    ("sim", "slam", False, 1),
    ("03", "slam", False, 1),
    ("10", "slam", False, 1),
    ("03", "slam", True, None),
    ("03", "deadreckon", False, 1),
]


def _measure(name, mode, dense, stride, repeat):
    """Run one case ``repeat`` times in this process and return its figures (in a child process)."""
    import numpy as np

    from visla_edu import data, run
    from visla_edu.filters import FilterConfig

    dataset = data.load(name)
    config = FilterConfig(landmark_stride=stride)
    run.make_filter(dataset, mode, config, dense)  # warm-up: extrinsic check and caches
    walls = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = run.run_filter(dataset, mode, config, dense=dense, progress=False)
        walls.append(time.perf_counter() - start)
    wall = float(np.median(walls))
    steps = result.step_seconds
    return {
        "dataset": dataset.name, "mode": mode + (" dense" if dense else ""), "stride": stride,
        "frames": dataset.num_frames, "landmarks_used": int(np.isfinite(result.landmarks[:, 0]).sum()),
        "wall_s": wall, "wall_min_s": min(walls), "median_step_ms": 1e3 * float(np.median(steps)),
        "p95_step_ms": 1e3 * float(np.percentile(steps, 95)), "max_step_ms": 1e3 * float(steps.max()),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def _available(name):
    from visla_edu import data

    return name.startswith("sim") or name in data.available()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dense-stride", type=int, default=20, help="landmark stride of the dense case")
    parser.add_argument("--repeat", type=int, default=3, help="runs per case (wall time: median and best)")
    parser.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        name, mode, dense, stride, repeat = args.child
        print(json.dumps(_measure(name, mode, dense == "1", int(stride), int(repeat))))
        return
    print(f"{'dataset':11s} {'mode':12s} {'stride':>6s} {'frames':>6s} {'landmarks':>9s} {'wall s':>7s} {'best s':>7s} "
          f"{'median ms':>9s} {'p95 ms':>7s} {'max ms':>7s} {'peak MB':>8s}")
    for name, mode, dense, stride in CASES:
        stride = args.dense_stride if stride is None else stride
        if not _available(name):
            print(f"{name:11s} {mode:12s} skipped: not in the data directory ({os.environ.get('VISLA_EDU_DATA')})")
            continue
        child = subprocess.run(
            [sys.executable, __file__, "--child", name, mode, "1" if dense else "0", str(stride), str(args.repeat)],
            capture_output=True, text=True, check=True)
        r = json.loads(child.stdout.strip().splitlines()[-1])
        print(f"{r['dataset']:11s} {r['mode']:12s} {r['stride']:6d} {r['frames']:6d} {r['landmarks_used']:9d} "
              f"{r['wall_s']:7.2f} {r['wall_min_s']:7.2f} {r['median_step_ms']:9.2f} {r['p95_step_ms']:7.2f} {r['max_step_ms']:7.1f} "
              f"{r['peak_rss_mb']:8.0f}")


if __name__ == "__main__":
    main()
