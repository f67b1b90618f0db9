"""Calibration from the data: what it chooses on every drive, how sure it is, how long it takes.

Usage::

    VISLA_EDU_DATA=/path/to/course/data python benchmarks/bench_calibration.py [--repeats 3] [--quick]

Prints, for the course drives ``03``, ``0022``, ``0020`` (and its noisy twin: 0.5 m/s and
0.05 rad/s of noise added, as the 2020 release did) and the dataset-10 stand-in
(``load("10")``), and for simulated drives with the quirks the checks must survive (5% tracks of
uniformly random pixels, flipped axes in the reported extrinsic, velocities one sample late or
early):

* the settings :func:`visla_edu.diagnostics.calibrate` chooses (extrinsic correction, IMU lag,
  velocity noise), the track-reprojection score of the best candidate and the smallest 95%
  lower bound of a competitor's margin, the odometry's verdicts (extrinsic, lag, gyro bias,
  velocity scale), and, where the truth is known, whether each setting is right, left at its
  default for lack of evidence, or wrong;
* the time of ``calibrate``: cold (a fresh dataset object, ``cache=False``: wall and CPU,
  min over ``--repeats``) and cached (a fresh dataset object reading the JSON file written by
  a first run; the whole script uses a temporary cache folder, never the user's);
* the visual odometry's rotation error against the ground truth of ``0020`` (KITTI odometry
  sequence 06, attached by the loader from ``kitti_odometry_06_poses.txt`` beside the npz) on
  the pairs the checks use (valid, at least 4 inliers) and on all valid pairs.

Absent files are skipped with a line saying so. Nothing here is asserted: the tests are in
tests/test_calibration.py.
"""

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from visla_edu import diagnostics, simulate
from visla_edu.diagnostics import odometry
from visla_edu.diagnostics import CORRECTIONS

NOISY_SEEDS = (0, 1, 2)
LIVELY = dict(linear_velocity_sigma=0.02, angular_velocity_sigma=0.002, yaw_rate_sigma=0.1, yaw_timescale=1.0)


def _fresh(dataset):
    return dataclasses.replace(dataset, extra={})


def _timed(run, repeats):
    """Result of the last ``run()``; min wall and min CPU time over ``repeats`` runs."""
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = run()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return result, min(walls), min(cpus)


def _cached_time(dataset, repeats):
    """Wall time of a cached calibrate (min over repeats), after a first run filled the cache."""
    diagnostics.calibrate(_fresh(dataset), cache=True)
    result, wall, _ = _timed(lambda: diagnostics.calibrate(_fresh(dataset), cache=True), repeats)
    return result, wall


def _settings_line(cal, truth=None):
    """Chosen settings and the evidence behind them, in one line (two when the truth is known)."""
    tracks, vo = cal.tracks, cal.vo
    margins = [lo for _, lo in list(tracks.correction.margins.values()) + list(tracks.lag.margins.values())]
    best = min((s for scores in tracks.scores.values() for s in scores if s is not None), default=None)
    scale = vo.velocity_scale
    scale_text = "n/a" if scale["scale"] is None else f"{scale['scale']:.3f} +- {scale['stderr']:.3f}"
    line = (f"    -> {cal.extrinsic_correction}, lag {cal.imu_lag:+d}, "
            f"sigma_v {np.round(cal.sigma_linear_velocity, 4)} m/s, "
            f"sigma_w {np.round(cal.sigma_angular_velocity, 5)} rad/s\n"
            f"       tracks: {tracks.pairs} pairs, {tracks.landmarks} landmarks, best median "
            f"{'n/a' if best is None else f'{best:.2f} px'}, smallest 95% lower margin "
            f"{'n/a' if not margins else f'{min(margins):+.2f} px'}; correction {tracks.correction.verdict}; "
            f"lag {tracks.lag.verdict} (best {tracks.lag.best})\n"
            f"       odometry: {vo.pairs}/{vo.frame_pairs} pairs, {cal.extrinsic_correction} "
            f"{vo.extrinsic_verdict[cal.extrinsic_correction]}, best lag {vo.lag_best}, gyro bias "
            f"{vo.gyro_bias['verdict']}, velocity scale {scale_text}")
    if truth is not None:
        line += f"\n       truth {truth[0]}, lag {truth[1]:+d}: {_judge(cal, truth)}"
    return line


def _judge(cal, truth):
    """'right', 'kept the default (not enough evidence)' for each setting left at its default, or 'WRONG'."""
    verdicts = []
    for got, want, choice, default in ((cal.extrinsic_correction, truth[0], cal.tracks.correction, "none"),
                                       (cal.imu_lag, truth[1], cal.tracks.lag, 0)):
        if got == want:
            verdicts.append("right")
        elif got == default and choice.chosen is None:
            verdicts.append("default kept (not enough evidence)")
        else:
            verdicts.append("WRONG")
    return f"correction {verdicts[0]}, lag {verdicts[1]}"


def bench_drive(label, dataset, repeats, truth=None):
    cal, wall, cpu = _timed(lambda: diagnostics.calibrate(_fresh(dataset), cache=False), repeats)
    cached, cached_wall = _cached_time(dataset, repeats)
    print(f"  {label}: {dataset.num_frames} frames, {dataset.num_landmarks} landmarks; calibrate cold {wall:.3f} s "
          f"(cpu {cpu:.3f}), cached {cached_wall:.4f} s ({'from the cache' if cached.source != 'computed' else '?'})")
    print(_settings_line(cal, truth))
    return cal


def _noisy(dataset, seed):
    rng = np.random.default_rng(seed)
    v, w = dataset.linear_velocity, dataset.angular_velocity
    return dataclasses.replace(dataset, extra={}, linear_velocity=v + rng.normal(0, 0.5, v.shape),
                               angular_velocity=w + rng.normal(0, 0.05, w.shape))


def odometry_0020(dataset):
    """Rotation error of the odometry against 0020's ground truth (attached by the loader)."""
    truth = dataset.ground_truth
    if truth is None:
        print("  0020 odometry against ground truth: skipped (no ground truth attached: "
              "kitti_odometry_06_poses.txt missing beside 0020.npz?)")
        return
    true = odometry.camera_motion(truth.world_T_imu, dataset.imu_T_cam)
    vo = odometry.visual_odometry(dataset)
    n = len(true)
    for label, used in (("pairs the checks use (>= 4 inliers)", vo.valid[:n] & (vo.inliers[:n] >= 4)),
                        ("all valid pairs", vo.valid[:n])):
        rotation, translation = odometry.motion_errors(vo.cam_T_next[:n][used], true[used])
        print(f"  0020 odometry vs its ground truth (KITTI 06), {label}: {used.sum()} of {n} pairs, rotation median "
              f"{1e3 * np.median(rotation):.2f} mrad, rms {1e3 * np.sqrt(np.mean(rotation**2)):.2f} mrad, "
              f"translation median {np.median(translation):.3f} m")


def bench_course(directory, repeats):
    from visla_edu import data

    print("course drives")
    for name in ("03", "0022", "0020"):
        path = directory / f"{name}.npz"
        if not path.is_file():
            print(f"  {name}: skipped (no {path})")
            continue
        dataset = data.load(path)
        bench_drive(name, dataset, repeats)
        if name == "0020":
            for seed in NOISY_SEEDS:
                bench_drive(f"0020 noisy twin (seed {seed})", _noisy(dataset, seed), 1)
            odometry_0020(dataset)
    if (directory / "10_imu_only.npz").is_file() and (directory / "03.npz").is_file():
        standin = data.load("10", directory)
        bench_drive("10 stand-in", standin, repeats, truth=("flip_yz", 0))
    else:
        print("  10 stand-in: skipped (needs 10_imu_only.npz and 03.npz)")


def bench_simulated(repeats, seeds):
    _, _, rig = simulate.default_rig()
    flip = dict(imu_T_cam=CORRECTIONS["flip_yz"] @ rig, reported_imu_T_cam=rig)
    quirks = dict(outlier_share=0.05, outlier_kind="uniform")
    lively_quirks = dict(**LIVELY, **quirks, **flip)
    cases = [("small, clean velocities, lively yaw, 5% random tracks, flip, lag -1", "small",
              dict(imu_lag=-1, **lively_quirks), ("flip_yz", -1)),
             ("small, clean velocities, lively yaw, 5% random tracks, flip, lag +1", "small",
              dict(imu_lag=1, **lively_quirks), ("flip_yz", 1)),
             ("small, clean velocities, lively yaw, no quirks", "small", dict(**LIVELY), ("none", 0)),
             ("small, default (0.2 m/s, 0.02 rad/s noise)", "small", {}, ("none", 0)),
             ("course, default noise, 5% random tracks, flip, lag +1", "course", dict(imu_lag=1, **quirks, **flip),
              ("flip_yz", 1)),
             ("tiny, ~100 landmarks, flip", "tiny", dict(num_landmarks=100, **flip), ("flip_yz", 0))]
    print(f"simulated drives (seeds {list(seeds)})")
    for label, preset, overrides, truth in cases:
        for seed in seeds:
            bench_drive(f"{label}, seed {seed}", simulate.simulate_drive(preset, seed, **overrides), repeats, truth)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="folder of the course files (default: $VISLA_EDU_DATA)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per drive (min is printed)")
    parser.add_argument("--quick", action="store_true", help="one seed per simulated case")
    args = parser.parse_args()
    folder = args.data or os.environ.get("VISLA_EDU_DATA", "")
    directory = Path(folder).expanduser().resolve() if folder else None
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; calibration version "
          f"{diagnostics.CALIBRATION_VERSION}")
    # a private cache folder: the user's cache is neither read (cold means cold) nor written
    with tempfile.TemporaryDirectory(prefix="bench-calibration-") as cache:
        os.environ["VISLA_EDU_CACHE"] = cache
        if directory is None or not directory.is_dir():
            print("course drives skipped: set VISLA_EDU_DATA (or --data) to the folder with the course files")
        else:
            bench_course(directory, args.repeats)
        bench_simulated(1 if args.quick else args.repeats, (0,) if args.quick else (0, 1, 2))


if __name__ == "__main__":
    main()
