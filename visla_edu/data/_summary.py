"""What a student should know about a drive before filtering it.

:func:`summarize` collects the facts as a dict, :func:`format_summary` as the text that
``visla-edu info DATASET`` prints.
"""

import numpy as np

from visla_edu.dataset import repeated_frames

__all__ = ["summarize", "format_summary"]


def _stats(values):
    """``{"min", "median", "max"}`` of an array (None entries when empty)."""
    values = np.asarray(values)
    if values.size == 0:
        return {"min": None, "median": None, "max": None}
    cast = int if values.dtype.kind in "iu" else float
    return {"min": cast(values.min()), "median": float(np.median(values)), "max": cast(values.max())}


def summarize(dataset):
    """Facts (a dict) about a dataset a student should know before running a filter on it.

    Its keys are built below, units in their names; ``time_step_s`` and ``speed_m_s`` are ``{"mean", "min",
    "max"}``, ``observations_per_frame`` and ``track_length_frames`` (over observed landmarks) ``{"min",
    "median", "max"}``. ``ground_truth_frames``: frames its poses cover, or None; ``ground_truth_rows``:
    :attr:`~visla_edu.dataset.GroundTruth.rows_text`; ``K``, ``K_right``: nested lists (``K_right`` None for
    one intrinsics); ``extrinsic_readings``: for a 2025+ file, name -> ``{"offset", "rotation_deg", "problem"}``
    of each reading of its extrinsics, else None; ``no_features``: why a file has no feature tracks, or ``""``.
    """
    ds = dataset
    steps = ds.time_steps
    per_frame = np.diff(ds.frame_ptr)
    lengths = ds.track_lengths()
    observed = lengths > 0
    spans = ds.track_spans()
    gaps = (spans[:, 1] - spans[:, 0] + 1 != lengths) & observed
    disparity = ds.disparity()
    nonpositive = int(np.count_nonzero(disparity <= 0))
    speed = np.linalg.norm(ds.linear_velocity, axis=1)
    return {
        "name": ds.name,
        "label": ds.label,
        "source": ds.source,
        "frames": ds.num_frames,
        "duration_s": float(ds.time_stamps[-1] - ds.time_stamps[0]),
        "time_step_s": _mean_min_max(steps),
        "landmarks": ds.num_landmarks,
        "landmarks_never_observed": int(np.count_nonzero(~observed)),
        "observations": ds.num_observations,
        "observations_per_frame": _stats(per_frame),
        "frames_without_observations": int(np.count_nonzero(per_frame == 0)),
        "track_length_frames": _stats(lengths[observed]),
        "landmarks_seen_once": int(np.count_nonzero(lengths == 1)),
        "nonpositive_disparity": nonpositive,
        "nonpositive_disparity_share": nonpositive / max(1, ds.num_observations),
        "tiny_disparity": int(np.count_nonzero((disparity > 0) & (disparity < 1))),
        "tiny_disparity_depth_m": float(ds.K[0, 0] * ds.b),
        "repeated_frames": repeated_frames(ds),
        "tracks_contiguous": not gaps.any(),
        "noncontiguous_landmarks": int(np.count_nonzero(gaps)),
        "speed_m_s": _mean_min_max(speed),
        "distance_m": float(np.sum(speed[:-1] * steps)),
        **_ground_truth_facts(ds.ground_truth),
        **_rig_facts(ds),
    }


def _rig_facts(ds):
    readings = ds.extrinsic_readings
    return {
        "K": np.asarray(ds.K, dtype=float).tolist(),
        "K_right": None if ds.K_right is None else np.asarray(ds.K_right, dtype=float).tolist(),
        "baseline_m": float(ds.b),
        "extrinsic_readings": None if not readings else {
            r.name: {"offset": [float(x) for x in r.offset], "rotation_deg": float(np.degrees(r.rotation)),
                     "problem": r.problem} for r in readings},
        "extrinsic_reading": ds.extra.get("extrinsic_reading"),
        "no_features": ds.extra.get("no_features", ""),
        "ignored_keys": list(ds.extra.get("ignored_keys", [])),
    }


def _ground_truth_facts(gt):
    return {
        "ground_truth": gt is not None,
        "ground_truth_frames": None if gt is None else gt.num_frames,
        "ground_truth_simulated": gt is not None and gt.simulated,
        "ground_truth_source": "" if gt is None else gt.source,
        "ground_truth_rows": "" if gt is None else gt.rows_text,
    }


def _mean_min_max(values):
    if len(values) == 0:
        return {"mean": None, "min": None, "max": None}
    return {"mean": float(np.mean(values)), "min": float(np.min(values)), "max": float(np.max(values))}


def _shorten(text, limit=160):
    """``text`` cut to ``limit`` characters (a simulated drive's source lists its whole config)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def format_summary(dataset):
    """The readable text (str) of :func:`summarize`, what ``visla-edu info DATASET`` prints."""
    s = summarize(dataset)
    lines = [f"{s['name']}: {s['label']}" if s["label"] else s["name"], f"  source        {_shorten(s['source'])}"]
    lines += _rig_lines(s) + _time_lines(s) + _observation_lines(s) + _track_lines(s) + _disparity_lines(s)
    lines += _motion_lines(s)
    return "\n".join(lines)


def _intrinsics_text(K):
    return f"fsu {K[0][0]:.2f}, fsv {K[1][1]:.2f}, cu {K[0][2]:.2f}, cv {K[1][2]:.2f} px"


def _rig_lines(s):
    """Both intrinsics, the baseline and the readings of the extrinsics: for a file that gives two cameras (2025+)."""
    if s["K_right"] is None and s["extrinsic_readings"] is None:
        return []
    same = s["K_right"] is None or s["K_right"] == s["K"]
    lines = [f"  rig           left  K_l {_intrinsics_text(s['K'])}",
             f"                right K_r {_intrinsics_text(s['K_right'] or s['K'])}"
             + (" (the same as K_l)" if same else " (differs from K_l: each image is modelled with its own)"),
             f"                baseline {s['baseline_m']:.4f} m (the distance between the two cameras of extL_T_imu, "
             "extR_T_imu)"]
    if s["extrinsic_readings"]:
        lines.append("  extrinsics    the right camera in the left camera frame (m) under each reading of extL_T_imu, "
                     "extR_T_imu:")
        for name, g in s["extrinsic_readings"].items():
            offset = "[" + ", ".join(f"{x:+.3f}" for x in g["offset"]) + "]"
            verdict = "a rectified pair" if not g["problem"] else "not rectified"
            mark = "  <- the loader's" if name == s["extrinsic_reading"] else ""
            lines.append(f"                {name:22s} {offset}, rotated {g['rotation_deg']:.2f} deg: {verdict}{mark}")
        lines.append("                the diagnostics decide the reading from the data (the calibration below shows "
                     "the evidence)")
    if s["ignored_keys"]:
        lines.append(f"  ignored keys  {', '.join(s['ignored_keys'])} (not part of the format visla-edu reads)")
    return lines


def _fmt_stats(stats, unit=""):
    def num(x):
        return f"{x:g}" if isinstance(x, float) else str(x)

    return f"min {num(stats['min'])} / median {num(stats['median'])} / max {num(stats['max'])}{unit}"


def _time_lines(s):
    step = s["time_step_s"]
    if step["mean"] is None:
        return [f"  frames        {s['frames']} (a single time stamp)"]
    return [
        f"  frames        {s['frames']} over {s['duration_s']:.1f} s; time step mean {step['mean']:.4f} s "
        f"(min {step['min']:.4f}, max {step['max']:.4f}): use each step's own tau, not a constant"
    ]


def _observation_lines(s):
    never = s["landmarks_never_observed"]
    lines = [f"  landmarks     {s['landmarks']}" + (f" ({never} never observed)" if never else " (every one observed)")]
    lines.append(f"  observations  {s['observations']} in total; per frame {_fmt_stats(s['observations_per_frame'])}")
    if s["frames_without_observations"]:
        lines.append(f"                {s['frames_without_observations']} frames have no observations "
                     "(prediction only)")
    return lines


def _track_lines(s):
    if s["no_features"]:
        return [f"  tracks        none: {s['no_features']}; dead reckoning only (--mode deadreckon)"]
    if s["track_length_frames"]["max"] is None:
        return ["  tracks        none: no landmark is observed (every feature is -1)"]
    lines = [
        f"  tracks        length {_fmt_stats(s['track_length_frames'], ' frames')}; "
        f"{s['landmarks_seen_once']} landmarks seen only once"
    ]
    if s["tracks_contiguous"]:
        lines.append("                every track is one contiguous run of frames: a landmark can leave the "
                     "filter after its last observation")
    else:
        lines.append(f"                {s['noncontiguous_landmarks']} tracks have gaps (landmark seen again after "
                     "missing frames): keep them in the filter until their last observation")
    for t in s["repeated_frames"]:
        lines.append(f"  repeated      frame {t} repeats the features of frame {t - 1} exactly "
                     "(duplicated camera frame; the IMU keeps moving)")
    return lines


def _disparity_lines(s):
    return [
        f"  disparity     {s['nonpositive_disparity']} observations ({100 * s['nonpositive_disparity_share']:.2f}%) "
        "have uL - uR <= 0: no depth, skip them when initialising landmarks",
        f"                {s['tiny_disparity']} observations have 0 < uL - uR < 1 px: depth beyond "
        f"{s['tiny_disparity_depth_m']:.0f} m, very uncertain",
    ]


def _motion_lines(s):
    speed = s["speed_m_s"]
    return [
        f"  speed         mean {speed['mean']:.2f} m/s (min {speed['min']:.2f}, max {speed['max']:.2f}); "
        f"about {s['distance_m']:.0f} m driven",
        f"  ground truth  {_truth_text(s)}",
    ]


def _truth_text(s):
    if not s["ground_truth"]:
        return "none (real data)"
    if s["ground_truth_simulated"]:
        return "yes (poses, landmarks, velocities, outliers)"
    n, T = s["ground_truth_frames"], s["frames"]
    cover = "every frame" if n == T else f"frames 0-{n - 1}, {n} of {T} frames"
    rows = f"{s['ground_truth_rows']} of " if s["ground_truth_rows"] else ""
    return f"attached: KITTI poses of {cover} ({rows}{_shorten(s['ground_truth_source'], 100)})"
