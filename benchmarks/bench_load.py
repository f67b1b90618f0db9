"""Loading speed and memory: prints load time and peak traced memory per course-format file.

Usage::

    VISLA_EDU_DATA=/path/to/course/data python benchmarks/bench_load.py [--full-size-10]

The features of a course file are a dense ``(4, M, T)`` float64 array (165 MB for ``03``,
1.3 GB for the real ``10.npz``); the loader streams it and keeps only the ~1% valid entries.
``--full-size-10`` writes a temporary file of dataset 10's size in the course format (the
stand-in's tracks; nothing is kept) and loads it, to show the memory stays far below the dense
size when a user brings the real file.
"""

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path


def _measure(path):
    from visla_edu import data

    tracemalloc.start()
    start = time.perf_counter()
    dataset = data.load(path)
    seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    dense_mb = 4 * dataset.num_landmarks * dataset.num_frames * 8 / 2**20
    print(f"{dataset.name:12s} T={dataset.num_frames:5d} M={dataset.num_landmarks:6d} "
          f"observations={dataset.num_observations:7d}  load {seconds:6.2f} s  peak traced {peak / 2**20:7.1f} MB  "
          f"(dense features {dense_mb:7.1f} MB)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full-size-10", action="store_true", help="also load a dataset-10-sized file")
    args = parser.parse_args()
    from visla_edu import data

    for name in ("03", "0022", "10"):
        if name in data.available() and (data.data_dir() / f"{name}.npz").is_file():
            _measure(data.data_dir() / f"{name}.npz")
        else:
            print(f"{name:12s} skipped: no {name}.npz in {data.data_dir()}")
    if args.full_size_10:
        standin = data.load("10")
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "standin_as_course_file.npz"
            data.save(standin, path)
            _measure(path)


if __name__ == "__main__":
    main()
