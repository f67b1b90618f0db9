"""Accuracy of every mode with the default settings, against ground truth (issue 8's table).

Prints, per drive: ATE (RMSE of the IMU position, m; raw = ``world`` is the first IMU frame, and
SE(3)-aligned) and KITTI-style drift (% over 100-800 m segments) of dead reckoning, VIO, SLAM
(the invariant EKF), the batch smoother and the sliding window, all with ``FilterConfig()``:
one setting for every drive, the noise and the IMU lag measured from each drive's data.

Drives:

* ``0020`` (KITTI odometry 06, with its ground truth) and its noisy twin (N(0, 0.5) m/s and
  N(0, 0.05) rad/s added to every velocity sample, as the 2020 course release did; seeded);
* ``0020`` cut into four drives of 275 frames (about 300 m each, :meth:`Dataset.segment`), each
  calibrated and run on its own, its ground truth starting at its first frame: more drives
  with ground truth than one, so that a setting is not judged on a single drive;
* simulated drives with 5% uniformly random outlier tracks, flipped camera axes and an IMU lag;
* a full-scale dataset-10-like drive with dataset 03's flipped axes and 5% random outlier
  tracks (the stand-in's real IMU drive, two IMU noise levels);
* for the course files without ground truth (03, 0022) the gated share and the runtime.

Run: ``python benchmarks/bench_accuracy.py [--quick] [--only {0020,segments,sim,standin,course}]``
with ``VISLA_EDU_DATA`` set (drives whose files are absent are skipped). Calibrations are cached
in a new temporary folder (removed at the end), unless ``VISLA_EDU_CACHE`` names one.
"""

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from visla_edu import data, diagnostics, metrics, motion, run, simulate
from visla_edu.diagnostics import CORRECTIONS
from visla_edu.filters import FilterConfig

FILTER_MODES = ("vio", "slam")
SMOOTHER_MODES = ("smooth", "window")


def noisy_twin(ds, seed, sigma_v=0.5, sigma_w=0.05):
    """``ds`` with white noise added to every velocity sample (its ground truth kept)."""
    rng = np.random.default_rng(seed)
    return dataclasses.replace(
        ds, name=f"{ds.name}-noisy{seed}", extra={},
        linear_velocity=ds.linear_velocity + rng.normal(0, sigma_v, ds.linear_velocity.shape),
        angular_velocity=ds.angular_velocity + rng.normal(0, sigma_w, ds.angular_velocity.shape))


def segments(ds, length=275):
    """``ds`` cut into consecutive drives of ``length`` frames, as far as its ground truth goes."""
    covered = ds.ground_truth.num_frames
    return [ds.segment(start, start + length) for start in range(0, covered - length + 1, length)]


def quirky_drive(seed, lag):
    """A simulated drive with 5% random outlier tracks, 03's flipped axes reported, and an IMU lag."""
    _, _, imu_T_cam = simulate.default_rig()
    return simulate.simulate_drive("small", seed, outlier_share=0.05, outlier_kind="uniform", imu_lag=lag,
                                   reported_imu_T_cam=CORRECTIONS["flip_yz"] @ imu_T_cam)


def standin_like(data_dir, noise):
    """Dataset 10's real IMU drive with simulated tracks, 03's flipped axes and 5% random outlier tracks.

    As the registered stand-in does, the cameras are simulated with 03's corrected extrinsic (the
    physical rig) and the dataset reports the file's uncorrected one, so the calibration has to
    find the flip.
    """
    directory = Path(data.data_dir(data_dir))
    reported = data.load(directory / "03.npz")
    physical_imu_T_cam, _ = diagnostics.resolve_extrinsics(reported, "auto")
    ds = data.standin_dataset10(directory / "10_imu_only.npz", directory / "03.npz", seed=1, outlier_share=0.05,
                                outlier_kind="uniform", linear_velocity_sigma=noise[0],
                                angular_velocity_sigma=noise[1], imu_T_cam=physical_imu_T_cam)
    ds.imu_T_cam = reported.imu_T_cam.copy()
    return ds


def evaluate(ds, modes):
    """Rows ``(mode, ATE raw, ATE aligned, drift %, seconds)`` of each mode, and the calibration."""
    gt = ds.ground_truth.world_T_imu
    n = len(gt)
    calibration = diagnostics.calibrate(ds)
    config = FilterConfig()
    lag = run.resolve_config(ds, config).imu_lag
    rows = [("deadreckon",) + _figures(motion.dead_reckon(ds.time_stamps, ds.twists, lag=lag)[:n], gt) + (0.0,)]
    for mode in modes:
        start = time.perf_counter()
        if mode in SMOOTHER_MODES:
            result = run.run_smoother(ds, mode, config, progress=False)
        else:
            result = run.run_filter(ds, mode, config, progress=False)
        rows.append((mode,) + _figures(result.world_T_imu[:n], gt) + (time.perf_counter() - start,))
    return rows, calibration


def _path_length(ds):
    """Length (m) of the drive's true path."""
    positions = ds.ground_truth.world_T_imu[:, :3, 3]
    return float(np.sum(np.linalg.norm(np.diff(positions, axis=0), axis=1)))


def _figures(est, gt):
    e = metrics.evaluate(est, gt)
    return e.ate_raw, e.ate_aligned, e.drift_translation


def print_table(label, rows, calibration):
    print(f"\n{label}: correction {calibration.extrinsic_correction!r}, lag {calibration.imu_lag:+d}, "
          f"sigma_v {np.round(calibration.sigma_linear_velocity, 3)} m/s, "
          f"sigma_w {np.round(calibration.sigma_angular_velocity, 4)} rad/s")
    print(f"  {'mode':11s} {'ATE raw':>8s} {'aligned':>8s} {'drift %':>8s} {'vs DR':>6s} {'time s':>7s}")
    dr = rows[0][1]
    for mode, raw, aligned, drift, seconds in rows:
        drift_text = f"{drift:8.2f}" if drift is not None else f"{'-':>8s}"
        print(f"  {mode:11s} {raw:8.2f} {aligned:8.2f} {drift_text} {raw / dr:6.2f} {seconds:7.1f}")


def gated_and_time(name, data_dir):
    """Gated share and whole-run time of SLAM with the defaults on a course file without ground truth."""
    ds = data.load(name, data_dir)
    start = time.perf_counter()
    result = run.run_filter(ds, "slam", FilterConfig(), progress=False)
    seconds = time.perf_counter() - start
    totals = result.status_totals()
    share = totals["gated"] / max(totals["gated"] + totals["used"], 1)
    print(f"  {name:6s} gated {100 * share:5.1f}% of the observations, SLAM (with calibration) {seconds:5.1f} s, "
          f"config lag {result.config['imu_lag']:+d}, correction {diagnostics.calibrate(ds).extrinsic_correction!r}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", default=None)
    parser.add_argument("--quick", action="store_true", help="one noisy twin, one quirky seed, no stand-in")
    parser.add_argument("--only", choices=("0020", "segments", "sim", "standin", "course"), default=None,
                        help="run one group of drives")
    args = parser.parse_args(argv)
    if "VISLA_EDU_CACHE" in os.environ:
        run_groups(args)
        return
    with tempfile.TemporaryDirectory(prefix="visla-edu-bench-cache-") as cache:  # removed afterwards
        os.environ["VISLA_EDU_CACHE"] = cache
        try:
            run_groups(args)
        finally:
            del os.environ["VISLA_EDU_CACHE"]


def run_groups(args):
    """Print the tables of the groups ``args.only`` selects (all by default)."""
    available = data.available(args.data_dir)
    all_modes = FILTER_MODES + SMOOTHER_MODES
    if "0020" in available and args.only in (None, "0020"):
        ds = data.load("0020", args.data_dir)
        print_table("0020 (KITTI odometry 06)", *evaluate(ds, all_modes))
        for seed in range(1 if args.quick else 3):
            print_table(f"0020 noisy twin (seed {seed})", *evaluate(noisy_twin(ds, seed), all_modes))
    if "0020" in available and args.only in (None, "segments"):
        for part in segments(data.load("0020", args.data_dir)):
            print_table(f"{part.name}, {_path_length(part):.0f} m", *evaluate(part, all_modes))
    for seed in range(0 if args.only not in (None, "sim") else 1 if args.quick else 2):
        for lag in (-1, 1):
            print_table(f"simulated small drive, seed {seed}: 5% random outlier tracks, flipped axes, lag {lag:+d}",
                        *evaluate(quirky_drive(seed, lag), all_modes))
    if not args.quick and "10" in available and args.only in (None, "standin"):
        for noise in ((0.2, 0.02), (0.05, 0.005)):
            print_table(f"dataset-10-like (3026 frames), 03's flipped axes, 5% random outlier tracks, IMU noise {noise}",
                        *evaluate(standin_like(args.data_dir, noise), ("slam", "smooth")))
    course = [name for name in ("03", "0022") if name in available and args.only in (None, "course")]
    if course:
        print("\ncourse files without ground truth:")
    for name in course:
        gated_and_time(name, args.data_dir)


if __name__ == "__main__":
    main()
