"""Plausible time stamps, velocities and observed pixels of a drive, and why.

The drive's counterpart of the calibration's plausible ranges (:mod:`visla_edu.validation` says what
*plausible* means): a well-formed file with time stamps in nanoseconds, a gap of 1e6 s, velocities in
km/h or a 'missing' marker other than -1 is refused.

========================  ====================  ============================================
quantity                  plausible             why
========================  ====================  ============================================
principal point cu, cv    among the observed    it lies near the image centre, inside the
                          pixels                region where features are seen
off-axis angle of pixels  < 85 deg              a pinhole camera sees less than 170 deg
observed pixels           >= -10 px             inside the image, give or take a tracker's
                                                sub-pixel slack; not a 'missing' marker
median frame step         2 ms .. 10 s          cameras run at 0.1 to 500 frames per second
largest frame step        <= max(10 s, 100      dead reckoning carries one velocity sample
                          median steps)         across a gap: 1e6 s at 10 m/s is 10,000 km
speed                     <= 343 m/s            no vehicle carrying a stereo rig is supersonic
angular rate              <= 35 rad/s           2000 deg/s, a MEMS gyro's full-scale range
ground-truth position     <= 343 m/s x elapsed  the drive cannot outrun sound either (20 m of
                          time + 20 m           slack for the camera-IMU lever arm)
========================  ====================  ============================================

Every check raises ``ValueError`` naming the file, the key, the value and the plausible range;
:func:`dataset_problems` and :func:`calibration_problems` return the messages for an in-memory Dataset
(the filter driver refuses a dataset that fails the latter).
"""

import numpy as np

from visla_edu.camera import right_in_left_pixels
from visla_edu.validation import MAX_EXTRINSIC_TRANSLATION, check_plausible_calibration, magnitude

__all__ = [
    "MAX_OFF_AXIS_DEG",
    "FRAME_STEP_RANGE",
    "MAX_GAP_SECONDS",
    "MAX_GAP_STEPS",
    "MAX_SPEED",
    "MAX_ANGULAR_RATE",
    "check_time_stamps",
    "check_velocities",
    "check_ground_truth_reach",
    "check_observations",
    "check_track_layout",
    "calibration_problems",
    "dataset_problems",
]

MAX_OFF_AXIS_DEG = 85.0
FRAME_STEP_RANGE = (2e-3, 10.0)  # s, the median step
MAX_GAP_SECONDS = 10.0
MAX_GAP_STEPS = 100
MAX_SPEED = 343.0  # m/s
MAX_ANGULAR_RATE = 35.0  # rad/s

#: Pixels below this are outside any image (a tracker reports at most a pixel or so beyond the border).
MIN_PIXEL = -10.0
#: More identical ``[x, x, x, x]`` observations than this count and share are a 'missing' marker.
_MARKER_MIN_COUNT, _MARKER_SHARE = 10, 0.01
#: The principal point must lie in the box of the observed left pixels, widened by this
#: share of its size on every side, once a file has at least this many observations.
_BOX_MARGIN, _BOX_MIN_OBSERVATIONS = 0.25, 50
#: With at least this many observations, more than this share with ``uL - uR <= 0`` means the
#: left and right columns are swapped (dataset 03 has about 1%: the quirk).
_SWAP_MIN_OBSERVATIONS, _SWAP_SHARE = 20, 0.5
#: A typical frame step (10 Hz), to choose between units that all give a plausible step.
_TYPICAL_STEP = 0.1
#: Units time stamps are sometimes stored in: factor to seconds, name, the fix.
_TIME_UNITS = ((1e-3, "milliseconds", "/ 1e3"), (1e-6, "microseconds", "/ 1e6"), (1e-9, "nanoseconds", "/ 1e9"),
               (60.0, "minutes", "* 60"), (3600.0, "hours", "* 3600"))


def check_time_stamps(stamps, path, key="time_stamps", index="[0, {}]"):
    """Seconds, at a camera's frame rate, without long gaps (``stamps`` (T,), increasing; fewer than 2 pass).

    The median step must lie in :data:`FRAME_STEP_RANGE` (else the message suggests the unit, milliseconds to
    hours, that would fit); no step may exceed ``max(MAX_GAP_SECONDS, MAX_GAP_STEPS * median)``. ``path`` may
    be a dataset's name; ``key`` and ``index`` as in :func:`~visla_edu.data._format.check_increasing`.
    """
    if len(stamps) < 2:
        return
    steps = np.diff(stamps)
    median = float(np.median(steps))
    low, high = FRAME_STEP_RANGE
    if not low <= median <= high:
        fits = [(unit, name, fix) for unit, name, fix in _TIME_UNITS if low <= median * unit <= high]
        guess = min(fits, key=lambda f: abs(np.log10(median * f[0] / _TYPICAL_STEP)), default=None)
        hint = (f"; they look like {guess[1]} ({median * guess[0]:.4g} s per frame): store seconds, "
                f"{key} {guess[2]}") if guess else "; store the time stamps in seconds"
        raise ValueError(f"{path}: key '{key}': the median step between frames is {median:.6g}, but a camera "
                         f"frame comes every {low:g} to {high:g} s{hint}")
    limit = max(MAX_GAP_SECONDS, MAX_GAP_STEPS * median)
    gaps = np.flatnonzero(steps > limit)
    if gaps.size:
        i = int(gaps[0])
        raise ValueError(
            f"{path}: key '{key}' has a gap of {steps[i]:.6g} s between frames {i} and {i + 1} "
            f"({key}{index.format(i)} = {float(stamps[i])!r}, {key}{index.format(i + 1)} = {float(stamps[i + 1])!r}; "
            f"the median step is {median:.4g} s, the most allowed {limit:.4g} s): dead reckoning would carry one "
            f"velocity sample across it. Split the drive at frame {i + 1}, or fix the stamp")


def check_velocities(linear, angular, keys, path):
    """Speeds <= :data:`MAX_SPEED`, angular rates <= :data:`MAX_ANGULAR_RATE` (``(3, T)`` each, m/s and rad/s)."""
    for values, key, limit, unit, hint in (
        (linear, keys[0], MAX_SPEED, "m/s", "the speed of sound; are they in km/h, mm/s or another unit?"),
        (angular, keys[1], MAX_ANGULAR_RATE, "rad/s", "2000 deg/s, a gyro's full range; are they in deg/s?"),
    ):
        norms = magnitude(np.asarray(values, dtype=float).T)
        bad = np.flatnonzero(norms > limit)
        if bad.size:
            t = int(bad[0])
            raise ValueError(f"{path}: key '{key}' at frame {t} has magnitude {norms[t]:.6g} {unit}, more than "
                             f"the plausible {limit:g} {unit} ({hint})")


def check_ground_truth_reach(world_T_imu, time_stamps, what, path):
    """Each ground-truth position within ``MAX_SPEED * (t_i - t_0) + MAX_EXTRINSIC_TRANSLATION`` of the first.

    ``world_T_imu`` (n, 4, 4), finite; ``time_stamps`` (T,) in s, ``T >= n``; ``what`` names the poses' key or
    file. Refuses poses in another unit (the message says when millimetres would fit) or overflowing ones.
    """
    positions = np.asarray(world_T_imu, dtype=float)[:, :3, 3]
    distance = magnitude(positions - positions[:1])
    elapsed = np.asarray(time_stamps, dtype=float)[: len(positions)] - float(time_stamps[0])
    reach = MAX_SPEED * elapsed + MAX_EXTRINSIC_TRANSLATION
    bad = np.flatnonzero(distance > reach)
    if not bad.size:
        return
    t = int(bad[0])
    mm = " It looks like millimetres: divide the positions by 1000." if distance[t] / 1000 <= reach[t] else ""
    raise ValueError(f"{path}: {what}: the ground-truth pose of frame {t} is {distance[t]:.6g} m from frame 0's, but "
                     f"{elapsed[t]:.6g} s into the drive it can be at most {reach[t]:.6g} m away ({MAX_SPEED:g} m/s, "
                     f"the speed of sound, plus {MAX_EXTRINSIC_TRANSLATION:g} m); is it the ground truth of another "
                     f"drive, or in another unit?{mm}")


def check_observations(K, obs_z, path, K_right=None, K_key="K"):
    """The pixels ``obs_z`` (N, 4) fit ``K``: principal point among them, angles below :data:`MAX_OFF_AXIS_DEG`.

    With ``K_right`` (when it differs from ``K``) the right pixels are checked in the left camera's
    (:func:`visla_edu.camera.right_in_left_pixels`).
    """
    if len(obs_z) == 0:
        return
    _check_marker(obs_z, path)
    obs_z = right_in_left_pixels(obs_z, K, K_right)
    _check_disparity_sign(obs_z, path)
    f = np.array([K[0, 0], K[1, 1]])
    c = np.array([K[0, 2], K[1, 2]])
    pixels = np.concatenate([obs_z[:, 0:2], obs_z[:, 2:4]])
    low, high = pixels.min(axis=0), pixels.max(axis=0)
    angle = np.degrees(np.arctan(np.max(np.abs(pixels - c), axis=0) / f))
    for axis, name in enumerate(("u (cu, fsu)", "v (cv, fsv)")):
        if angle[axis] > MAX_OFF_AXIS_DEG:
            raise ValueError(
                f"{path}: key '{K_key}': observed pixels lie up to {np.max(np.abs(pixels[:, axis] - c[axis])):.6g} px "
                f"from the principal point along {name}, {angle[axis]:.2f} deg off the optical axis with focal "
                f"length {f[axis]:.6g} px; a camera sees less than {2 * MAX_OFF_AXIS_DEG:g} deg, so the focal "
                "length is too small (another unit?) or the principal point is wrong")
    if len(obs_z) < _BOX_MIN_OBSERVATIONS:
        return
    margin = _BOX_MARGIN * (high - low)
    for axis, name in enumerate(("cu", "cv")):
        if not low[axis] - margin[axis] <= c[axis] <= high[axis] + margin[axis]:
            raise ValueError(
                f"{path}: key '{K_key}': the principal point {name} = {c[axis]:.6g} px lies outside the observed "
                f"pixels ({low[axis]:.6g} to {high[axis]:.6g} px, {len(obs_z)} observations); it should be near the "
                "image centre. Are cu and cv swapped, or K from another camera?")


def _check_marker(obs_z, path):
    """Refuse pixels far left of or above the image, and a repeated ``[x, x, x, x]``: another 'missing' marker."""
    low = obs_z.min(axis=0)
    if np.any(low < MIN_PIXEL):
        i, plane = (int(v) for v in np.argwhere(obs_z == low.min())[0])
        raise ValueError(
            f"{path}: key 'features': an observation has {('uL', 'vL', 'uR', 'vR')[plane]} = {low.min():.6g} px, far "
            f"outside the image (pixels are >= 0; the course marks 'not observed' with -1 in all four). Is another "
            "marker used for missing observations?")
    same = obs_z[np.all(obs_z == obs_z[:, :1], axis=1), 0]
    if len(same):
        values, counts = np.unique(same, return_counts=True)
        if counts.max() > max(_MARKER_MIN_COUNT, _MARKER_SHARE * len(obs_z)):
            raise ValueError(
                f"{path}: key 'features': {counts.max()} observations are [x, x, x, x] with x = "
                f"{values[counts.argmax()]:.6g}, which looks like a marker for 'not observed' (a real stereo "
                "observation has u != v); the course marks 'not observed' with -1 in all four")


def _check_disparity_sign(obs_z, path):
    """Refuse features whose disparity ``uL - uR`` is mostly <= 0: the file stores ``[uR, vR, uL, vL]``."""
    nonpositive = np.count_nonzero(obs_z[:, 0] - obs_z[:, 2] <= 0)
    if len(obs_z) >= _SWAP_MIN_OBSERVATIONS and nonpositive > _SWAP_SHARE * len(obs_z):
        raise ValueError(
            f"{path}: key 'features': {100 * nonpositive / len(obs_z):.1f}% of the {len(obs_z)} observations have "
            "uL - uR <= 0 (no depth; a few are a known quirk): are the left and right columns swapped? The course "
            "stores [uL, vL, uR, vR]; fix with features[[2, 3, 0, 1]]")


def check_track_layout(frame_ptr, obs_ids, num_landmarks, path):
    """When M = T, refuse features whose landmark and frame axes are swapped, if the tracks say so.

    A tracker follows a landmark over contiguous frames, so swapped, every "frame" sees one contiguous run of
    ids. Refused when every frame's ids are contiguous and more than half of the landmarks seen at least twice
    have gaps (gaps alone are allowed). ``obs_ids`` (N,) is frame-major.
    """
    T = len(frame_ptr) - 1
    if num_landmarks != T or len(obs_ids) == 0:
        return
    per_frame = np.diff(frame_ptr)
    frames = np.repeat(np.arange(T), per_frame)
    seen = per_frame > 0
    id_span = obs_ids[frame_ptr[1:][seen] - 1] - obs_ids[frame_ptr[:-1][seen]] + 1
    frames_contiguous = np.all(id_span == per_frame[seen]) and np.any(per_frame > 1)
    count = np.bincount(obs_ids, minlength=T)
    lo = np.full(T, T)
    hi = np.full(T, -1)
    np.minimum.at(lo, obs_ids, frames)
    np.maximum.at(hi, obs_ids, frames)
    tracked = count > 1
    gappy = int(np.sum(hi[tracked] - lo[tracked] + 1 != count[tracked]))
    if frames_contiguous and gappy > 0.5 * max(1, int(tracked.sum())):
        raise ValueError(
            f"{path}: key 'features' looks transposed: M = T = {T}, and {gappy} of {int(tracked.sum())} landmarks "
            "are seen in frames with gaps while every frame sees one contiguous run of landmark ids, the pattern "
            "of a (4, T, M) array (a tracker follows a landmark over contiguous frames). Store it as (4, M, T), "
            "e.g. features.transpose(0, 2, 1)")


def calibration_problems(dataset):
    """Messages (list of str) of the failed :func:`~visla_edu.validation.check_plausible_calibration` (K, K_right)."""
    checks = [lambda: check_plausible_calibration(np.asarray(dataset.K, dtype=float), float(dataset.b), dataset.name,
                                                  np.asarray(dataset.imu_T_cam, dtype=float))]
    if dataset.K_right is not None:
        checks.append(lambda: check_plausible_calibration(np.asarray(dataset.K_right, dtype=float), float(dataset.b),
                                                          dataset.name, K_key="K_r"))
    return _problems(checks)


def dataset_problems(dataset):
    """Messages (list of str) of the checks (calibration, time stamps, velocities, pixels) a Dataset fails."""
    name = dataset.name
    return calibration_problems(dataset) + _problems([
        lambda: check_time_stamps(np.asarray(dataset.time_stamps, dtype=float), name),
        lambda: check_velocities(np.asarray(dataset.linear_velocity).T, np.asarray(dataset.angular_velocity).T,
                                 ("linear_velocity", "angular_velocity"), name),
        lambda: check_observations(np.asarray(dataset.K, dtype=float), dataset.obs_z, name, dataset.K_right),
    ])


def _problems(checks):
    problems = []
    for check in checks:
        try:
            check()
        except (ValueError, ArithmeticError) as err:
            problems.append(str(err))
    return problems
