"""The cross-drive benchmark: every mode on every development drive, and the candidate defaults.

Defaults are chosen here, on all drives at once, never on one. The drives (those whose files
are in ``VISLA_EDU_DATA``; the simulated ones always):

* ``0020`` (KITTI odometry 06) and ``0042`` (the first 500 frames of KITTI odometry 01), with
  their KITTI ground truth: GPS-aided velocities, where dead reckoning is already good;
* their noisy twins (N(0, 0.5) m/s and N(0, 0.05) rad/s added to every velocity sample, as the
  2020 course release did; ``--seeds`` seeds each): the camera has to carry the estimate;
* pieces of both (``Dataset.segment``, as ``visla-edu run --frames`` cuts them: 275 frames of
  0020, 250 of 0042), calibrated and judged on their own;
* simulated drives with the real quirks (5% random outlier tracks, dataset 03's flipped axes
  reported, an IMU lag); dense simulated drives with the 2020 release's velocity noise and one
  stale frame in ten (:func:`visla_edu.simulate.with_stale_copies`: the twins of the sparse
  2019 drives cannot stand for the dense 2020 drives); and (without ``--quick``) the
  full-scale dataset-10-like drive.

Part 1 prints, per drive, ATE (RMSE of the IMU position, m; raw: ``world`` is the first IMU
frame; and SE(3)-aligned) and KITTI drift (% over 100-800 m) of dead reckoning, VIO, joint SLAM
and the batch smoother with ``FilterConfig()``. Part 2 prints one line per candidate default:
the worst and the geometric-mean ratio of its SLAM raw ATE to ``min(dead reckoning, VIO)`` over
all drives, and on how many drives it loses (ratio > 1). A default is accepted only when it
loses on no drive; where none does, the line says which drives lose.

Run: ``python benchmarks/bench_accuracy.py [--quick] [--seeds N] [--no-candidates]`` with
``VISLA_EDU_DATA`` set. Calibrations are cached in a new temporary folder (removed at the end)
unless ``VISLA_EDU_CACHE`` names one.
"""

import argparse
import dataclasses
import os
import tempfile
from pathlib import Path

import numpy as np

from visla_edu import data, diagnostics, metrics, motion, run, simulate
from visla_edu.diagnostics import CORRECTIONS
from visla_edu.filters import FilterConfig
from visla_edu.filters._config import pixel_noise_inflation

#: Candidate defaults of part 2: a label and the settings that differ from ``FilterConfig()``.
CANDIDATES = {
    "default": {},
    "stale copies used (the previous default)": {"skip_stale_copies": False},
    "the default before the gyro regime (clones everywhere, r^2 alone)": {"msckf_window": 20, "inflation_power": 2.0},
    "clones everywhere (msckf_window=20)": {"msckf_window": 20},
    "no clones anywhere (the joint EKF of notebook 08)": {"msckf_window": 0},
    "r^2 alone (no track correlation)": {"inflation_power": 2.0},
    "no inflation": {"pixel_noise_inflation": 1.0},
    "r^1 alone": {"inflation_power": 1.0},
    "r^3 alone": {"inflation_power": 3.0},
    "msckf_window=10": {"msckf_window": 10},
    "msckf_window=30": {"msckf_window": 30},
    "track_gate_probability=0.99": {"track_gate_probability": 0.99},
    "track_gate_probability=0.999": {"track_gate_probability": 0.999},
}
PIECES = {"0020": 275, "0042": 250}


def noisy_twin(ds, seed, sigma_v=0.5, sigma_w=0.05):
    """``ds`` with white noise added to every velocity sample (its ground truth kept)."""
    rng = np.random.default_rng(seed)
    return dataclasses.replace(
        ds, name=f"{ds.name}-noisy{seed}", extra={},
        linear_velocity=ds.linear_velocity + rng.normal(0, sigma_v, ds.linear_velocity.shape),
        angular_velocity=ds.angular_velocity + rng.normal(0, sigma_w, ds.angular_velocity.shape))


def segments(ds, length):
    """``ds`` cut into consecutive drives of ``length`` frames, as far as its ground truth goes."""
    covered = ds.ground_truth.num_frames
    return [ds.segment(start, start + length) for start in range(0, covered - length + 1, length)]


def quirky_drive(seed, lag):
    """A simulated drive with 5% random outlier tracks, 03's flipped axes reported, and an IMU lag."""
    _, _, imu_T_cam = simulate.default_rig()
    return simulate.simulate_drive("small", seed, outlier_share=0.05, outlier_kind="uniform", imu_lag=lag,
                                   reported_imu_T_cam=CORRECTIONS["flip_yz"] @ imu_T_cam)


def dense_stale_drive(seed):
    """A simulated drive as dense as the 2020 course release (0022: 73 observations a frame), with its
    velocity noise (0.5 m/s, 0.05 rad/s), 5% random outlier tracks and one stale frame in ten."""
    ds = simulate.simulate_drive("course", seed, linear_velocity_sigma=0.5, angular_velocity_sigma=0.05,
                                 outlier_share=0.05, outlier_kind="uniform")
    return simulate.with_stale_copies(ds, 0.1, seed)


def standin_like(data_dir, noise):
    """Dataset 10's real IMU drive with simulated tracks, 03's flipped axes and 5% random outlier tracks."""
    directory = Path(data.data_dir(data_dir))
    reported = data.load(directory / "03.npz")
    physical_imu_T_cam, _ = diagnostics.resolve_extrinsics(reported, "auto")
    ds = data.standin_dataset10(directory / "10_imu_only.npz", directory / "03.npz", seed=1, outlier_share=0.05,
                                outlier_kind="uniform", linear_velocity_sigma=noise[0],
                                angular_velocity_sigma=noise[1], imu_T_cam=physical_imu_T_cam)
    ds.imu_T_cam = reported.imu_T_cam.copy()
    return ds


def drives(args):
    """The benchmark's drives, by label."""
    available = data.available(args.data_dir)
    out = {}
    for name, length in PIECES.items():
        if name not in available:
            continue
        ds = data.load(name, args.data_dir)
        out[name] = ds
        for seed in range(args.seeds):
            out[f"{name} noisy{seed}"] = noisy_twin(ds, seed)
        for i, part in enumerate(segments(ds, length)):
            out[f"{name} piece {i} [{part.name.split('[')[-1]}"] = part
    for seed in range(1 if args.quick else 2):
        for lag in (-1, 1):
            out[f"sim seed {seed} lag {lag:+d}"] = quirky_drive(seed, lag)
    for seed in range(1 if args.quick else 3):
        out[f"sim dense 2020-like seed {seed}, stale frames"] = dense_stale_drive(seed)
    if not args.quick and "10" in available:
        out["dataset-10-like (0.2 m/s, 0.02 rad/s)"] = standin_like(args.data_dir, (0.2, 0.02))
    return out


def _config(ds, settings):
    """``FilterConfig`` of a candidate; ``inflation_power`` resolves ``pixel_noise_inflation`` as ``max(1, r)^power``
    alone (no track correlation)."""
    settings = dict(settings)
    power = settings.pop("inflation_power", None)
    if power is None:
        return FilterConfig(**settings)
    measured = run.resolve_config(ds, FilterConfig(pixel_noise_inflation=1.0, **settings))
    inflation = pixel_noise_inflation(measured.sigma_pixel, ds.K[0, 0], measured.sigma_angular_velocity,
                                      float(np.median(ds.time_steps)), power)
    return FilterConfig(pixel_noise_inflation=inflation, **settings)


def _figures(est, ds):
    gt = ds.ground_truth.world_T_imu
    e = metrics.evaluate(est[:len(gt)], gt)
    return e.ate_raw, e.ate_aligned, e.drift_translation


def evaluate(ds, smoother=True):
    """Figures ``(raw, aligned, drift %)`` of every mode on ``ds`` with the defaults."""
    config = FilterConfig()
    lag = run.resolve_config(ds, config).imu_lag
    rows = {"deadreckon": _figures(motion.dead_reckon(ds.time_stamps, ds.twists, lag=lag), ds)}
    for mode in ("vio", "slam"):
        rows[mode] = _figures(run.run_filter(ds, mode, config, progress=False).world_T_imu, ds)
    if smoother:
        rows["smooth"] = _figures(run.run_smoother(ds, "smooth", config, progress=False).world_T_imu, ds)
    return rows


def print_table(label, rows):
    dr = rows["deadreckon"][0]
    print(f"\n{label}")
    print(f"  {'mode':11s} {'ATE raw':>8s} {'aligned':>8s} {'drift %':>8s} {'vs DR':>6s}")
    for mode, (raw, aligned, drift) in rows.items():
        drift_text = f"{drift:8.2f}" if drift is not None else f"{'-':>8s}"
        print(f"  {mode:11s} {raw:8.2f} {aligned:8.2f} {drift_text} {raw / dr:6.2f}")


def candidate_line(label, settings, sets, yardstick):
    """One line of part 2: the candidate's SLAM raw ATE over ``min(dead reckoning, VIO)`` on every drive."""
    ratios = {}
    for name, ds in sets.items():
        est = run.run_filter(ds, "slam", _config(ds, settings), progress=False).world_T_imu
        ratios[name] = _figures(est, ds)[0] / yardstick[name]
    r = np.array(list(ratios.values()))
    losing = [name for name, ratio in ratios.items() if ratio > 1]
    verdict = "accepted: loses on no drive" if not losing else f"loses on {len(losing)}: " + ", ".join(
        f"{name} {ratios[name]:.2f}" for name in losing)
    print(f"  {label:42s} worst {r.max():5.2f}  geometric mean {np.exp(np.mean(np.log(r))):5.2f}  {verdict}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", default=None)
    parser.add_argument("--quick", action="store_true", help="one simulated seed, no dataset-10-like drive")
    parser.add_argument("--seeds", type=int, default=6, help="noisy twins of each drive (default 6)")
    parser.add_argument("--no-candidates", action="store_true", help="part 1 only")
    parser.add_argument("--candidates", default="", metavar="TEXT",
                        help="only the candidates whose label contains TEXT (the default always runs)")
    args = parser.parse_args(argv)
    if "VISLA_EDU_CACHE" in os.environ:
        run_benchmark(args)
        return
    with tempfile.TemporaryDirectory(prefix="visla-edu-bench-cache-") as cache:  # removed afterwards
        os.environ["VISLA_EDU_CACHE"] = cache
        try:
            run_benchmark(args)
        finally:
            del os.environ["VISLA_EDU_CACHE"]


def run_benchmark(args):
    """Part 1 (every mode on every drive) and part 2 (the candidate defaults)."""
    sets = drives(args)
    yardstick = {}
    for name, ds in sets.items():
        rows = evaluate(ds, smoother="dataset-10" not in name)
        yardstick[name] = min(rows["deadreckon"][0], rows["vio"][0])
        print_table(f"{name}: {ds.num_frames} frames", rows)
    if args.no_candidates:
        return
    print("\ncandidate defaults: SLAM raw ATE / min(dead reckoning, VIO) over all drives above")
    for label, settings in CANDIDATES.items():
        if label == "default" or args.candidates in label:
            candidate_line(label, settings, sets, yardstick)


if __name__ == "__main__":
    main()
