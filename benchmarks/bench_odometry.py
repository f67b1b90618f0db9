"""Stereo visual odometry: accuracy against ground truth, robustness to outliers, coverage, speed.

Usage::

    VISLA_EDU_DATA=/path/to/course/data python benchmarks/bench_odometry.py [--repeats 5]

Measures :func:`visla_edu.diagnostics.odometry.visual_odometry` (RANSAC + Gauss-Newton on SE(3)), the
odometry the diagnostics use, and prints (the Kabsch odometry it replaced is gone; its figures
are in the history of this file, commit 22f67b5):

* ``0020`` against KITTI odometry sequence 06 (attached by the loader from
  ``kitti_odometry_06_poses.txt`` beside it; the npz has 3 extra frames, the first 1100 pairs
  are compared): share of valid pairs, rotation
  error (mrad per frame) and translation error (m per frame), median and RMS over valid pairs;
  NEES of the stated covariance; coverage (stale pairs, tracked points, error by inlier count);
  the forward translation against the truth (scale); what a rotation from bearings alone
  would give on the sparse pairs.
* simulated drives (``simulate_drive("small", seed)``, truth from ``ground_truth.world_T_imu``
  and ``imu_T_cam``): no outliers, 5% outlier tracks (the simulator's 20-60 px offsets), 5% with
  100-400 px offsets, 5% tracks of uniformly random pixels (made here), 30% outlier tracks.
* course drives ``03`` and ``0022`` (no ground truth): valid share, inlier share, rms
  reprojection error, stale pairs, runtime (min and median of ``--repeats`` runs).

The calibration built on it (track reprojection, slopes, lag, gyro bias, velocity scale) is
measured by ``bench_calibration.py``.

A file that is absent is skipped with a line saying so. Nothing here is asserted: the tests
are in tests/test_odometry.py.
"""

import argparse
import dataclasses
import os
import time
from pathlib import Path

import numpy as np

from visla_edu import lie, simulate
from visla_edu.diagnostics import odometry
from visla_edu.metrics import chi2_bounds

SEEDS = (0, 1, 2)


def _errors_line(cam_T_next, valid, true):
    """Valid share, rotation (mrad) and translation (m) error: median and RMS over valid pairs."""
    valid = np.asarray(valid[:len(true)], bool)
    return f"valid {valid.mean():6.1%}  {_error_figures(cam_T_next, valid, true)}"


def _error_figures(cam_T_next, valid, true):
    if not valid.any():
        return "(no valid pair)"
    rot, trans = odometry.motion_errors(cam_T_next[:len(true)][valid], true[valid])
    return (f"rotation median {1e3 * np.median(rot):6.2f} rms {1e3 * _rms(rot):7.2f} mrad/frame  "
            f"translation median {np.median(trans):6.3f} rms {_rms(trans):6.3f} m/frame")


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def _nees_line(vo, true):
    """Mean NEES of the 6-dof motion error under the stated covariance, and the share inside 95%."""
    n = len(true)
    valid = vo.valid[:n]
    error = lie.se3_log(lie.se3_inv(vo.cam_T_next[:n][valid]) @ true[valid])
    nees = np.einsum("pi,pi->p", error, np.linalg.solve(vo.covariance[:n][valid], error[..., None])[..., 0])
    low, high = chi2_bounds(6, 0.95)
    inside = np.mean((nees > low) & (nees < high))
    return f"NEES mean {nees.mean():7.2f} median {np.median(nees):6.2f} (6 expected), {inside:5.1%} inside chi2_6 95%"


def _timed(run, repeats):
    """Result of ``run()`` and the min and median wall time of ``repeats`` runs."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return result, min(times), float(np.median(times))


# ------------------------------------------------------------------------ 0020 with ground truth


def bench_0020(directory, repeats):
    from visla_edu import data

    path = directory / "0020.npz"
    dataset = data.load(path) if path.is_file() else None
    if dataset is None or dataset.ground_truth is None:
        print(f"0020: skipped (need {path} and its ground truth kitti_odometry_06_poses.txt beside it)")
        return
    true = odometry.camera_motion(dataset.ground_truth.world_T_imu, dataset.imu_T_cam)
    vo, best, median = _timed(lambda: odometry.visual_odometry(dataset), repeats)
    print(f"0020 against KITTI 06 ground truth, first {len(true)} pairs; runtime {best:.3f} s (median {median:.3f})")
    print(f"  RANSAC + GN                {_errors_line(vo.cam_T_next, vo.valid, true)}")
    print(f"  {_nees_line(vo, true)}")
    strict = odometry.visual_odometry(dataset, min_inliers=4)
    print(f"  min_inliers=4              {_errors_line(strict.cam_T_next, strict.valid, true)}")
    _coverage_0020(vo, true)
    _scale_0020(vo, true)
    _bearing_rotation_0020(dataset, true)


def _coverage_0020(vo, true):
    n = len(true)
    tracked, valid, inliers = vo.tracked[:n], vo.valid[:n], vo.inliers[:n]
    print(f"  coverage: {np.mean(vo.stale[:n] > 0):.1%} of pairs are stale copies (every pixel repeated), "
          f"tracked points per pair 0/1/2/>=3: {np.mean(tracked == 0):.1%} / {np.mean(tracked == 1):.1%} / "
          f"{np.mean(tracked == 2):.1%} / {np.mean(tracked >= 3):.1%}; valid {valid.mean():.1%}")
    for label, chosen in (("3", inliers == 3), ("4", inliers == 4), ("5", inliers == 5), (">=6", inliers >= 6)):
        chosen &= valid
        rot, trans = odometry.motion_errors(vo.cam_T_next[:n][chosen], true[chosen])
        print(f"    {label:>3} inliers: {chosen.sum():4d} pairs, rotation median {1e3 * np.median(rot):5.2f} "
              f"rms {1e3 * _rms(rot):6.2f} mrad, translation median {np.median(trans):.3f} m")


def _scale_0020(vo, true):
    """Forward translation of the odometry against the truth (pairs with >= 4 inliers)."""
    chosen = vo.valid[:len(true)] & (vo.inliers[:len(true)] >= 4)
    ratio = vo.cam_T_next[:len(true)][chosen, 2, 3] / true[chosen, 2, 3]
    print(f"  scale: forward translation / truth, median {np.median(ratio):.3f} over {chosen.sum()} pairs "
          f"with >= 4 inliers (simulated drives: see below)")


def _bearing_rotation_0020(dataset, true):
    """Rotation from left-image bearings alone (Wahba), per number of points: the far-point idea."""
    K_inv = np.linalg.inv(dataset.K)

    def bearings(z):
        b = np.c_[z[:, :2], np.ones(len(z))] @ K_inv.T
        return b / np.linalg.norm(b, axis=1, keepdims=True)

    errors = {2: [], 3: [], 4: []}
    for t in range(len(true)):
        (ids_prev, z_prev), (ids_next, z_next) = dataset.observations(t), dataset.observations(t + 1)
        _, i, j = np.intersect1d(ids_prev, ids_next, return_indices=True)
        keep = ~np.all(z_prev[i] == z_next[j], axis=1)  # stale copies measure nothing
        i, j = i[keep], j[keep]
        if len(i) < 2:
            continue
        U, _, Vt = np.linalg.svd(bearings(z_next[j]).T @ bearings(z_prev[i]))
        R = Vt.T @ np.diag([1.0, 1.0, np.linalg.det(Vt.T @ U.T)]) @ U.T
        errors[min(len(i), 4)].append(np.linalg.norm(lie.so3_log(R.T @ true[t, :3, :3])))
    parts = [f"{k if k < 4 else '>=4'} points: {1e3 * np.median(v):5.2f} mrad median ({len(v)} pairs)"
             for k, v in errors.items() if v]
    print("  rotation from bearings alone (no translation), " + ", ".join(parts))


# ------------------------------------------------------------------------ simulated drives


def _random_pixel_tracks(dataset, share, rng):
    """``dataset`` with the pixels of ``share`` of its tracks uniformly random in the image (uL > uR)."""
    width, height = dataset.extra["config"].image_size
    seen = np.flatnonzero(dataset.track_lengths() > 0)
    chosen = rng.choice(seen, size=int(round(share * len(seen))), replace=False)
    hit = np.isin(dataset.obs_ids, chosen)
    u = np.sort(rng.uniform(0, width, (hit.sum(), 2)), axis=1)[:, ::-1]
    z = dataset.obs_z.copy()
    z[hit] = np.column_stack([u[:, 0], rng.uniform(0, height, hit.sum()), u[:, 1], rng.uniform(0, height, hit.sum())])
    return dataclasses.replace(dataset, obs_z=z, extra=dict(dataset.extra))


SIMULATED_CASES = {
    "no outliers": dict(outlier_share=0.0),
    "5% outlier tracks, 20-60 px": dict(outlier_share=0.05),
    "5% outlier tracks, 100-400 px": dict(outlier_share=0.05, outlier_offset_range=(100.0, 400.0)),
    "5% random-pixel tracks": dict(outlier_share=0.0),
    "30% outlier tracks, 20-60 px": dict(outlier_share=0.3),
}


def bench_simulated():
    print(f"simulated drives (preset small, 300 frames, seeds {SEEDS}), errors pooled over the seeds")
    for label, overrides in SIMULATED_CASES.items():
        runs, truths = [], []
        for seed in SEEDS:
            dataset = simulate.simulate_drive("small", seed=seed, **overrides)
            if "random" in label:
                dataset = _random_pixel_tracks(dataset, 0.05, np.random.default_rng(100 + seed))
            truths.append(odometry.camera_motion(dataset.ground_truth.world_T_imu, dataset.imu_T_cam))
            runs.append(odometry.visual_odometry(dataset))
        true = np.concatenate(truths)
        vo = _concatenate(runs)
        print(f"  {label}")
        print(f"    {_errors_line(vo.cam_T_next, vo.valid, true)}")
        print(f"    {_nees_line(vo, true)}; scale {_forward_ratio(vo, true):.4f}")


def _concatenate(results):
    """One :class:`~visla_edu.diagnostics.odometry.VisualOdometry` with the pairs of several drives."""
    arrays = {f.name: np.concatenate([getattr(r, f.name) for r in results])
              for f in dataclasses.fields(odometry.VisualOdometry) if f.name != "settings"}
    return odometry.VisualOdometry(**arrays, settings=results[0].settings)


def _forward_ratio(vo, true):
    return float(np.median(vo.cam_T_next[vo.valid, 2, 3] / true[vo.valid, 2, 3]))


# ------------------------------------------------------------------------ course drives without ground truth


def bench_course(directory, name, repeats):
    from visla_edu import data

    path = directory / f"{name}.npz"
    if not path.is_file():
        print(f"{name}: skipped (no {path})")
        return
    dataset = data.load(path)
    start = time.process_time()
    vo, best, median = _timed(lambda: odometry.visual_odometry(dataset), repeats)
    cpu = (time.process_time() - start) / repeats
    valid = vo.valid
    print(f"{name}: {dataset.num_frames - 1} pairs, {vo.tracked.mean():.1f} tracked points per pair; "
          f"runtime {best:.3f} s (median {median:.3f}, cpu {cpu:.3f}) over {repeats} runs")
    print(f"  valid {valid.mean():.1%}, inlier share {vo.inliers.sum() / max(vo.tracked[valid].sum(), 1):.1%} "
          f"of the tracked points of valid pairs, rms reprojection median {np.median(vo.rms_px[valid]):.2f} px "
          f"(90%: {np.percentile(vo.rms_px[valid], 90):.2f}), stale pairs {(vo.stale > 0).sum()}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="folder of the course files (default: $VISLA_EDU_DATA)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per course drive")
    args = parser.parse_args()
    folder = args.data or os.environ.get("VISLA_EDU_DATA", "")
    directory = Path(folder).expanduser().resolve() if folder else None
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if directory is None or not directory.is_dir():
        print("course drives skipped: set VISLA_EDU_DATA (or --data) to the folder with the course files")
    else:
        bench_0020(directory, args.repeats)
        for name in ("03", "0022"):
            bench_course(directory, name, args.repeats)
    bench_simulated()


if __name__ == "__main__":
    main()
