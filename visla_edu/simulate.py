"""Simulated stereo-inertial drives with ground truth, and the stand-in for dataset 10.

Two entry points build a :class:`~visla_edu.dataset.Dataset` with a
:class:`~visla_edu.dataset.GroundTruth`:

* :func:`simulate_drive` invents a car-like drive (smooth speed, curves and turns),
  places landmarks along the road and simulates stereo feature tracks and IMU noise.
* :func:`standin_dataset10` takes the real IMU drive of course dataset 10 (whose feature
  file is not available) as the true motion and simulates the feature tracks on it.

Both share one pipeline, usable on its own for any true trajectory::

    world_T_imu = integrate_poses(time_stamps, v_true, w_true)     # (T, 4, 4)
    landmarks, appear = place_landmarks(world_T_imu, n, config, rng, time_stamps)
    tracks = simulate_tracks(world_T_imu, landmarks, K, b, imu_T_cam, config, rng,
                             appear=appear, max_landmarks=config.num_landmarks)

Conventions are the library's: twist ``u = [v; w]`` (linear first), motion
``T_{t+1} = T_t @ se3_exp(tau_t u_t)``, ``world`` = IMU frame at the first time stamp
(x forward, y left, z up), camera optical frame x right, y down, z forward.

How the tracks are made (all of it vectorised; a loop runs over track *age*, not frames):

1. Every landmark has an *appearance frame* (the frame its placement was anchored to):
   the detector may pick it up from then on. Anchors are spread along the drive in
   proportion to the *scene change* per step, distance travelled plus
   ``scene_speed_floor`` times elapsed time, with a burst at frame 0 (the detector
   starts with a full image).
2. A track starts at the first frame, at most ``max_start_delay`` frames after the
   appearance frame, in which the landmark is visible (depth within ``depth_range``,
   inside both images), and lasts while it stays visible, but not beyond a random
   lifetime: the detector loses it with probability about ``track_loss_probability``
   per frame of average scene change (so a stopped car keeps its tracks longer, and the
   number of tracked features stays about constant). Each track is one contiguous run.
3. Tracks shorter than ``min_track_length`` are dropped; a random subset keeps
   ``num_landmarks`` of them; frames with more than ``max_observations_per_frame``
   observations lose their farthest ones (a track keeps its longest remaining run).
4. Ids are assigned by first observation frame. Pixels are ``Ks pi(q)`` plus white
   noise on each of ``[uL, vL, uR, vR]`` (so ``vR`` equals ``vL`` plus noise: the pair is
   rectified); a share of tracks are gross outliers, and a share of observations get a
   non-positive disparity (noise on far points, topped up by forced ones).
"""

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d

from visla_edu import lie
from visla_edu.camera import StereoCamera, projection
from visla_edu.dataset import Dataset, GroundTruth

__all__ = [
    "SimulationConfig",
    "SimulatedTracks",
    "PRESETS",
    "STANDIN_LABEL",
    "STANDIN_NUM_LANDMARKS",
    "make_config",
    "default_rig",
    "simulate_motion",
    "integrate_poses",
    "add_imu_noise",
    "place_landmarks",
    "simulate_tracks",
    "simulate_drive",
    "standin_dataset10",
]

#: Label of the dataset-10 stand-in (shown wherever the dataset is named).
STANDIN_LABEL = (
    "STAND-IN for dataset 10: real IMU drive of dataset 10, simulated stereo tracks "
    "(the real 10.npz features are not available)"
)
#: Default number of landmarks of the stand-in, about the size of the real dataset 10.
STANDIN_NUM_LANDMARKS = 13_000


@dataclass
class SimulationConfig:
    """Every parameter of a simulated drive (defaults: the ``"course"`` preset).

    Lengths in metres, times in seconds, angles in radians, pixels in pixels.
    Pairs ``(lo, hi)`` are ranges sampled uniformly unless said otherwise.

    Attributes
    ----------
    num_frames : int
        T, number of time stamps (ignored by the stand-in: the file decides).
    time_step, time_step_jitter : float
        Mean step between time stamps and the standard deviation of its jitter.
    start_time : float
        First time stamp.
    speed_range : (float, float)
        Forward speed band; the speed is ``mid + half_width * tanh(smooth noise)``.
    speed_timescale : float
        Correlation time of the speed changes.
    yaw_rate_sigma, yaw_timescale : float
        Gentle curves: smooth yaw-rate noise, its standard deviation and correlation time.
    turn_interval : float
        One turn per this much drive time (a 100 s drive has 4 at 25 s).
    turn_angle_range, turn_duration_range : (float, float)
        Heading change of a turn (either direction) and its duration.
    roll_pitch_amplitude, roll_pitch_timescale : float
        Roll and pitch angles are smooth noise of this amplitude; their rates are tiny.
    side_velocity_sigma : float
        Smooth lateral and vertical body velocity (a car barely slips).
    linear_velocity_sigma, angular_velocity_sigma : float
        White noise added to the true velocities to give the measured IMU velocities.
    gyro_bias : (float, float, float)
        Constant bias added to the measured angular velocity.
    K, b, imu_T_cam : ndarray (3, 3), float, ndarray (4, 4), or None
        Calibration; None means :func:`default_rig` (stand-in: the calibration file).
    image_size : (int, int)
        Image width and height in pixels.
    num_landmarks : int
        Target number of landmark tracks M (the per-frame cap may remove a few).
    candidate_factor : float
        Landmarks placed per wanted track (some are never seen, or only once).
    imu_height : float
        Height of the IMU above the road.
    ahead_range : (float, float)
        Roadside landmarks sit this far along the road ahead of their anchor pose...
    lateral_range : (float, float)
        ...this far to the left or right of the path...
    height_range : (float, float)
        ...and this high above the road.
    far_share : float
        Share of far landmarks (buildings, trees, hills): tiny disparity.
    far_range, far_height_range : (float, float)
        Far landmarks: distance from the anchor pose, height above the road.
    far_bearing : float
        Largest bearing (left or right of straight ahead) of a far landmark.
    scene_speed_floor : float
        The scene changes by ``distance + floor * time`` per step: new landmarks appear
        and tracks are lost in proportion to it.
    depth_range : (float, float)
        A landmark is visible only at depths within this range (m, camera z).
    track_loss_probability : float
        Probability that the detector loses a track per frame of average scene change
        (exponential lifetimes in scene-change units, mean ``1 / p`` frames, plus
        ``min_track_length`` guaranteed frames).
    min_track_length : int
        Shorter tracks are dropped.
    max_start_delay : int
        Frames after its appearance a landmark may become visible, else it is dropped.
    max_observations_per_frame : int
        Cap on the observations of one frame; the farthest are dropped.
    pixel_sigma : float
        Standard deviation of the pixel noise on each of ``[uL, vL, uR, vR]``.
    outlier_share : float
        Share of landmark tracks that are gross outliers.
    outlier_offset_range : (float, float)
        Size of an outlier's constant offset: both images (wrong feature), or the right
        image's u only (wrong stereo match), half of the outliers each.
    nonpositive_disparity_share : float
        Share of observations with ``uL - uR <= 0``: noise on far points, topped up by
        forcing the farthest inlier observations to disparities in ``(-1, 0]``.
    """

    num_frames: int = 1010
    time_step: float = 0.1046
    time_step_jitter: float = 1e-4
    start_time: float = 0.0
    speed_range: tuple = (5.0, 15.0)
    speed_timescale: float = 8.0
    yaw_rate_sigma: float = 0.02
    yaw_timescale: float = 4.0
    turn_interval: float = 25.0
    turn_angle_range: tuple = (0.4, 1.6)
    turn_duration_range: tuple = (6.0, 12.0)
    roll_pitch_amplitude: float = 0.01
    roll_pitch_timescale: float = 2.0
    side_velocity_sigma: float = 0.02
    linear_velocity_sigma: float = 0.2
    angular_velocity_sigma: float = 0.02
    gyro_bias: tuple = (0.0, 0.0, 0.0)
    K: object = None
    b: object = None
    imu_T_cam: object = None
    image_size: tuple = (1400, 500)
    num_landmarks: int = 5000
    candidate_factor: float = 1.6
    imu_height: float = 1.0
    ahead_range: tuple = (3.0, 70.0)
    lateral_range: tuple = (2.0, 30.0)
    height_range: tuple = (0.0, 4.0)
    far_share: float = 0.1
    far_range: tuple = (40.0, 80.0)
    far_height_range: tuple = (0.0, 10.0)
    far_bearing: float = 0.7
    scene_speed_floor: float = 3.0
    depth_range: tuple = (1.5, 80.0)
    track_loss_probability: float = 0.055
    min_track_length: int = 2
    max_start_delay: int = 10
    max_observations_per_frame: int = 130
    pixel_sigma: float = 1.0
    outlier_share: float = 0.01
    outlier_offset_range: tuple = (20.0, 60.0)
    nonpositive_disparity_share: float = 0.01

    def validate(self):
        """Raise ``ValueError`` naming the first field with an impossible value."""
        _require(self.num_frames >= 2, "num_frames", self.num_frames, ">= 2")
        _require(self.num_landmarks >= 0, "num_landmarks", self.num_landmarks, ">= 0")
        _require(self.time_step > 0, "time_step", self.time_step, "> 0")
        for name in ("time_step_jitter", "linear_velocity_sigma", "angular_velocity_sigma",
                     "pixel_sigma", "side_velocity_sigma", "roll_pitch_amplitude",
                     "yaw_rate_sigma", "scene_speed_floor", "max_start_delay"):
            _require(getattr(self, name) >= 0, name, getattr(self, name), ">= 0")
        for name in ("far_share", "outlier_share", "nonpositive_disparity_share"):
            _require(0 <= getattr(self, name) <= 1, name, getattr(self, name), "in [0, 1]")
        _require(0 < self.track_loss_probability <= 1, "track_loss_probability",
                 self.track_loss_probability, "in (0, 1]")
        _require(self.min_track_length >= 1, "min_track_length", self.min_track_length, ">= 1")
        _require(self.max_observations_per_frame >= 1, "max_observations_per_frame",
                 self.max_observations_per_frame, ">= 1")
        _require(self.candidate_factor >= 1, "candidate_factor", self.candidate_factor, ">= 1")
        _require(0 < self.depth_range[0] < self.depth_range[1], "depth_range",
                 self.depth_range, "0 < near < far")
        for name in ("speed_range", "turn_angle_range", "turn_duration_range", "ahead_range",
                     "lateral_range", "height_range", "far_range", "far_height_range",
                     "outlier_offset_range"):
            lo, hi = getattr(self, name)
            _require(lo <= hi, name, getattr(self, name), "(lo, hi) with lo <= hi")
        return self

    def describe(self):
        """One line ``name=value, ...``; arrays are shown by shape."""
        parts = []
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value = f"array{value.shape}"
            parts.append(f"{f.name}={value}")
        return "SimulationConfig(" + ", ".join(parts) + ")"


def _require(ok, name, value, expected):
    if not ok:
        raise ValueError(f"SimulationConfig.{name} must be {expected}, got {value!r}")


#: Overrides of the :class:`SimulationConfig` defaults for each preset.
PRESETS = {
    "tiny": {"num_frames": 60, "num_landmarks": 150},
    "small": {"num_frames": 300, "num_landmarks": 1000},
    "course": {},
}
_PRESET_NAMES = {"tiny": "sim-tiny", "small": "sim-small", "course": "sim"}


def make_config(preset="course", **overrides):
    """The configuration of a preset with some fields replaced.

    Parameters
    ----------
    preset : {"tiny", "small", "course"}
        ``"tiny"``: 60 frames, ~150 landmarks (unit tests); ``"small"``: 300 frames,
        ~1000 landmarks; ``"course"``: dataset-3 scale, 1010 frames, ~5000 landmarks.
    **overrides
        Any :class:`SimulationConfig` field.

    Returns
    -------
    SimulationConfig
    """
    if preset not in PRESETS:
        raise ValueError(f"make_config: unknown preset {preset!r}; choose one of {sorted(PRESETS)}")
    names = {f.name for f in dataclasses.fields(SimulationConfig)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ValueError(f"make_config: unknown SimulationConfig field(s) {unknown}; "
                         f"valid fields: {sorted(names)}")
    return SimulationConfig(**{**PRESETS[preset], **overrides}).validate()


def default_rig():
    """A KITTI-like stereo rig (made up for visla-edu, not taken from any course file).

    Left camera: ``fsu = fsv = 550`` px, principal point ``(680, 240)``, 1400x500 images,
    baseline 0.6 m, mounted 1.5 m ahead of and 0.6 m above the IMU, looking forward
    (camera x = -IMU y, camera y = -IMU z, camera z = IMU x) with a ~1 degree misalignment.

    Returns
    -------
    K : ndarray, shape (3, 3)
    b : float
    imu_T_cam : ndarray, shape (4, 4)
    """
    K = np.array([[550.0, 0.0, 680.0], [0.0, 550.0, 240.0], [0.0, 0.0, 1.0]])
    imu_R_cam_nominal = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    imu_T_cam = np.eye(4)
    imu_T_cam[:3, :3] = imu_R_cam_nominal @ lie.so3_exp(np.array([0.01, -0.012, 0.006]))
    imu_T_cam[:3, 3] = [1.5, 0.0, 0.6]
    return K, 0.6, imu_T_cam


# --------------------------------------------------------------------------- motion


def _smooth_noise(rng, n, step, timescale):
    """Gaussian-filtered white noise with unit stationary standard deviation, shape (n,)."""
    white = rng.standard_normal(n)
    sigma = timescale / step
    if sigma < 0.3:
        return white
    x = np.arange(-int(4.0 * sigma + 0.5), int(4.0 * sigma + 0.5) + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    kernel /= kernel.sum()  # the kernel of gaussian_filter1d (truncate=4)
    return gaussian_filter1d(white, sigma, mode="reflect") / np.sqrt(np.sum(kernel**2))


def _rates_of(angle, time_stamps):
    """Piecewise-constant rates that step ``angle`` from sample to sample, shape (T,)."""
    rates = np.diff(angle) / np.diff(time_stamps)
    return np.append(rates, rates[-1])


def _turn_yaw_rates(time_stamps, config, rng):
    """Yaw rates of a few raised-cosine turns, each turning by its angle, shape (T,)."""
    t0, duration = time_stamps[0], time_stamps[-1] - time_stamps[0]
    n_turns = int(duration // config.turn_interval) if config.turn_interval > 0 else 0
    if n_turns == 0:
        return np.zeros_like(time_stamps)
    centres = t0 + (np.arange(n_turns) + 0.5 + rng.uniform(-0.25, 0.25, n_turns)) * duration / n_turns
    angles = rng.choice([-1.0, 1.0], n_turns) * rng.uniform(*config.turn_angle_range, n_turns)
    lengths = rng.uniform(*config.turn_duration_range, n_turns)
    phase = (time_stamps[None, :] - centres[:, None]) / lengths[:, None] + 0.5
    inside = (phase >= 0) & (phase <= 1)
    bumps = (angles / lengths)[:, None] * (1 - np.cos(2 * np.pi * phase))
    return np.sum(np.where(inside, bumps, 0.0), axis=0)


def _time_stamps(config, rng):
    """Slightly jittered, strictly increasing time stamps, shape (T,)."""
    steps = config.time_step + config.time_step_jitter * rng.standard_normal(config.num_frames - 1)
    steps = np.maximum(steps, 0.1 * config.time_step)
    return config.start_time + np.concatenate([[0.0], np.cumsum(steps)])


def simulate_motion(config, rng):
    """True time stamps and body velocities of a car-like drive.

    Forward speed varies smoothly within ``speed_range``; the yaw rate is smooth noise
    plus a few turns; roll and pitch stay within about ``roll_pitch_amplitude``; lateral
    and vertical velocities are near zero (body x forward, y left, z up).

    Parameters
    ----------
    config : SimulationConfig
    rng : numpy.random.Generator

    Returns
    -------
    time_stamps : ndarray, shape (T,)
    linear_velocity, angular_velocity : ndarray, shape (T, 3)
        Constant over each step ``[t_k, t_{k+1})``; the last row is unused by the poses.
    """
    n, step = config.num_frames, config.time_step
    t = _time_stamps(config, rng)
    lo, hi = config.speed_range
    speed = 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.tanh(_smooth_noise(rng, n, step, config.speed_timescale))
    lateral = config.side_velocity_sigma * _smooth_noise(rng, n, step, 1.0)
    vertical = config.side_velocity_sigma * _smooth_noise(rng, n, step, 1.0)
    roll, pitch = (config.roll_pitch_amplitude * _smooth_noise(rng, n, step, config.roll_pitch_timescale)
                   for _ in range(2))
    yaw_rate = config.yaw_rate_sigma * _smooth_noise(rng, n, step, config.yaw_timescale)
    yaw_rate = yaw_rate + _turn_yaw_rates(t, config, rng)
    linear = np.stack([speed, lateral, vertical], axis=1)
    angular = np.stack([_rates_of(roll, t), _rates_of(pitch, t), yaw_rate], axis=1)
    return t, linear, angular


def integrate_poses(time_stamps, linear_velocity, angular_velocity):
    """Poses from body velocities: ``T_0 = I``, ``T_{k+1} = T_k @ se3_exp(tau_k [v_k; w_k])``.

    Parameters
    ----------
    time_stamps : array_like, shape (T,)
    linear_velocity, angular_velocity : array_like, shape (T, 3)

    Returns
    -------
    ndarray, shape (T, 4, 4)
        ``world_T_imu`` with ``world`` the IMU frame at the first time stamp.
    """
    tau = np.diff(np.asarray(time_stamps, dtype=float))
    twists = np.concatenate([linear_velocity, angular_velocity], axis=1)[:-1] * tau[:, None]
    steps = lie.se3_exp(twists)
    poses = np.empty((len(tau) + 1, 4, 4))
    poses[0] = np.eye(4)
    for k, step in enumerate(steps):
        poses[k + 1] = poses[k] @ step
    return poses


def add_imu_noise(linear_velocity, angular_velocity, config, rng):
    """Measured IMU velocities: true + white noise (+ constant gyro bias).

    Parameters
    ----------
    linear_velocity, angular_velocity : ndarray, shape (T, 3)
    config : SimulationConfig
        ``linear_velocity_sigma``, ``angular_velocity_sigma``, ``gyro_bias``.
    rng : numpy.random.Generator

    Returns
    -------
    linear_velocity, angular_velocity : ndarray, shape (T, 3)
    """
    noise_v = config.linear_velocity_sigma * rng.standard_normal(np.shape(linear_velocity))
    noise_w = config.angular_velocity_sigma * rng.standard_normal(np.shape(angular_velocity))
    bias = np.asarray(config.gyro_bias, dtype=float).reshape(1, 3)
    return linear_velocity + noise_v, angular_velocity + noise_w + bias


# ------------------------------------------------------------------------ landmarks


def _scene_change(world_T_imu, time_stamps, config):
    """How much the view changes per step: distance + ``scene_speed_floor`` * time, shape (T-1,).

    Normalised to mean 1 (uniform if the car never moves). New features appear and
    tracks are lost at rates proportional to it, so a stopped car keeps its features.
    """
    step_len = np.linalg.norm(np.diff(world_T_imu[:, :3, 3], axis=0), axis=1)
    change = step_len + config.scene_speed_floor * np.diff(time_stamps)
    return change / change.mean() if change.sum() > 0 else np.ones_like(change)


def _default_time_stamps(time_stamps, T, config):
    if time_stamps is None:
        return config.time_step * np.arange(T)
    stamps = np.asarray(time_stamps, dtype=float)
    if stamps.shape != (T,):
        raise ValueError(f"simulate: time_stamps must have shape ({T},), got {stamps.shape}")
    return stamps


def _anchor_frames(change, n, config, rng):
    """Appearance frames, drawn in proportion to the scene change, shape (n,)."""
    weight = change.copy()
    # The detector starts with a full image: about one mean lifetime of anchors at frame 0.
    weight[0] += 1.0 / config.track_loss_probability
    return rng.choice(len(weight), size=n, p=weight / weight.sum())


def _roadside_points(world_T_imu, arc, anchor, config, rng):
    """Points beside the road ahead of the anchor poses, shape (n, 3)."""
    n = len(anchor)
    s = arc[anchor] + rng.uniform(*config.ahead_range, n)
    k = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 1)
    side = rng.choice([-1.0, 1.0], n)
    offset = np.stack([
        s - arc[k],  # beyond the last pose the road continues straight
        side * rng.uniform(*config.lateral_range, n),
        rng.uniform(*config.height_range, n) - config.imu_height,
    ], axis=1)
    return np.einsum("nij,nj->ni", world_T_imu[k, :3, :3], offset) + world_T_imu[k, :3, 3]


def _far_points(world_T_imu, anchor, config, rng):
    """Far points in front of the anchor poses, shape (n, 3)."""
    n = len(anchor)
    distance = rng.uniform(*config.far_range, n)
    bearing = rng.uniform(-config.far_bearing, config.far_bearing, n)
    offset = np.stack([
        distance * np.cos(bearing),
        distance * np.sin(bearing),
        rng.uniform(*config.far_height_range, n) - config.imu_height,
    ], axis=1)
    pose = world_T_imu[anchor]
    return np.einsum("nij,nj->ni", pose[:, :3, :3], offset) + pose[:, :3, 3]


def place_landmarks(world_T_imu, num_landmarks, config, rng, time_stamps=None):
    """Place landmarks along a true trajectory.

    Each landmark gets an anchor frame (spread over the drive in proportion to distance
    travelled plus ``scene_speed_floor`` times elapsed time, with a burst of about one
    mean track lifetime's worth at frame 0).
    A share ``1 - far_share`` stands beside the road ``ahead_range`` metres along the path
    ahead of its anchor pose, ``lateral_range`` to the left or right, ``height_range``
    above the road (the road is ``imu_height`` below the IMU, in the local body frame);
    the rest are far points ``far_range`` metres in front of the anchor pose.

    Parameters
    ----------
    world_T_imu : array_like, shape (T, 4, 4)
        True IMU poses.
    num_landmarks : int
        n, the number of landmarks to place.
    config : SimulationConfig
    rng : numpy.random.Generator
    time_stamps : array_like, shape (T,), optional
        Default: uniform steps of ``config.time_step``.

    Returns
    -------
    landmarks : ndarray, shape (n, 3)
        World positions.
    appear : ndarray of int, shape (n,)
        Anchor frames: a landmark's track may start at this frame or a few later.
    """
    world_T_imu = _check_poses(world_T_imu, "place_landmarks")
    time_stamps = _default_time_stamps(time_stamps, len(world_T_imu), config)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(world_T_imu[:, :3, 3], axis=0), axis=1))])
    change = _scene_change(world_T_imu, time_stamps, config)
    anchor = _anchor_frames(change, num_landmarks, config, rng)
    far = rng.random(num_landmarks) < config.far_share
    landmarks = np.empty((num_landmarks, 3))
    landmarks[~far] = _roadside_points(world_T_imu, arc, anchor[~far], config, rng)
    landmarks[far] = _far_points(world_T_imu, anchor[far], config, rng)
    return landmarks, anchor.astype(np.int64)


def _check_poses(world_T_imu, where):
    poses = np.asarray(world_T_imu, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) < 2:
        raise ValueError(f"{where}: world_T_imu must have shape (T, 4, 4) with T >= 2, got {poses.shape}")
    return poses


# --------------------------------------------------------------------------- tracks


@dataclass
class SimulatedTracks:
    """Stereo tracks in the sparse layout of :class:`~visla_edu.dataset.Dataset`.

    Attributes
    ----------
    landmarks : ndarray, shape (M, 3)
        True positions of the tracked landmarks, id order (by first observation frame).
    source_index : ndarray of int, shape (M,)
        Row of each landmark in the ``landmarks`` given to :func:`simulate_tracks`.
    frame_ptr : ndarray of int, shape (T + 1,)
    obs_ids : ndarray of int, shape (N,)
    obs_z : ndarray, shape (N, 4)
        Measured pixels ``[uL, vL, uR, vR]``, frame-major, ids increasing within a frame.
    outlier : ndarray of bool, shape (M,)
        Tracks corrupted on purpose.
    """

    landmarks: np.ndarray
    source_index: np.ndarray
    frame_ptr: np.ndarray
    obs_ids: np.ndarray
    obs_z: np.ndarray
    outlier: np.ndarray


def _visible(q, Ks, config):
    """Depth within ``depth_range`` and pixels inside both images, shape (n,)."""
    depth = q[:, 2]
    near, far = config.depth_range
    ok = (depth >= near) & (depth <= far)
    safe = np.where(ok, depth, 1.0)
    uL = Ks[0, 0] * q[:, 0] / safe + Ks[0, 2]
    vL = Ks[1, 1] * q[:, 1] / safe + Ks[1, 2]
    uR = uL + Ks[2, 3] / safe
    width, height = config.image_size
    return ok & (uR >= 0) & (uL < width) & (uL >= 0) & (uR < width) & (vL >= 0) & (vL < height)


def _march(cam_T_world, landmarks, appear, clock, budget, Ks, config):
    """Follow every landmark from its appearance frame until its track ends.

    A track ends when the landmark is no longer visible, or (after ``min_track_length``
    frames) when the detector ``clock`` (T,) has advanced by the track's ``budget`` (n,).
    Returns the observations as ``(landmark row, frame, q)``, shapes (N,), (N,), (N, 3).
    """
    T = len(cam_T_world)
    start = np.full(len(landmarks), -1)
    length = np.zeros(len(landmarks), dtype=np.int64)
    alive = np.flatnonzero(appear < T)
    rows, frames, points = [], [], []
    age = 0
    while alive.size:
        t = appear[alive] + age
        alive, t = alive[t < T], t[t < T]
        q = np.einsum("nij,nj->ni", cam_T_world[t, :3, :3], landmarks[alive]) + cam_T_world[t, :3, 3]
        vis = _visible(q, Ks, config)
        waiting = start[alive] < 0
        start[alive[waiting & vis]] = t[waiting & vis]
        lost = (length[alive] >= config.min_track_length) & (
            clock[t] - clock[np.maximum(start[alive], 0)] >= budget[alive])
        seen = vis & (start[alive] >= 0) & ~lost
        rows.append(alive[seen])
        frames.append(t[seen])
        points.append(q[seen])
        length[alive[seen]] += 1
        stop = (~waiting & ~seen) | (waiting & ~vis & (age >= config.max_start_delay))
        alive = alive[~stop]
        age += 1
    if not rows:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    return np.concatenate(rows), np.concatenate(frames), np.concatenate(points)


def _longest_runs(rows, frames, keep, min_length):
    """Keep each landmark's longest run of consecutive kept frames if long enough, shape (N,)."""
    if len(rows) == 0:
        return keep.copy()
    order = np.lexsort((frames, rows))
    r, f, k = rows[order], frames[order], keep[order]
    follows = np.r_[False, (r[1:] == r[:-1]) & (f[1:] == f[:-1] + 1) & k[:-1]]
    new_run = k & ~follows
    run_id = np.cumsum(new_run) - 1
    run_len = np.bincount(run_id[k], minlength=new_run.sum())
    run_row = r[new_run]
    by_row = np.lexsort((-run_len, run_row))
    first = np.r_[True, run_row[by_row][1:] != run_row[by_row][:-1]]
    best = np.zeros(len(run_len), dtype=bool)
    best[by_row[first]] = True
    best &= run_len >= min_length
    result = np.zeros(len(rows), dtype=bool)
    result[order] = k & best[np.maximum(run_id, 0)]
    return result


def _cap_per_frame(rows, frames, depth, config):
    """Drop the farthest observations of crowded frames, keeping tracks contiguous, shape (N,)."""
    order = np.lexsort((depth, frames))
    f_sorted = frames[order]
    rank = np.arange(len(order)) - np.searchsorted(f_sorted, f_sorted, side="left")
    keep = np.empty(len(order), dtype=bool)
    keep[order] = rank < config.max_observations_per_frame
    return _longest_runs(rows, frames, keep, config.min_track_length)


def _select_tracks(rows, frames, q, n_candidates, max_landmarks, config, rng):
    """Drop short tracks, keep at most ``max_landmarks``, apply the per-frame cap, shape (N,)."""
    length = np.bincount(rows, minlength=n_candidates)
    survivors = np.flatnonzero(length >= config.min_track_length)
    if max_landmarks is not None and len(survivors) > max_landmarks:
        survivors = rng.choice(survivors, size=max_landmarks, replace=False)
    chosen = np.zeros(n_candidates, dtype=bool)
    chosen[survivors] = True
    keep = chosen[rows]
    keep[keep] = _cap_per_frame(rows[keep], frames[keep], q[keep, 2], config)
    return keep


def _outlier_offsets(num_landmarks, config, rng):
    """Outlier tracks and their constant pixel offsets.

    Half are a wrong feature (the same offset in both images), half a wrong stereo match
    (the right image's u shifted along the epipolar line).

    Returns
    -------
    offsets : ndarray, shape (M, 4)
        Zero rows for inliers.
    outlier : ndarray of bool, shape (M,)
    """
    outlier = np.zeros(num_landmarks, dtype=bool)
    n_out = int(round(config.outlier_share * num_landmarks))
    outlier[rng.choice(num_landmarks, size=n_out, replace=False)] = True
    size = rng.uniform(*config.outlier_offset_range, num_landmarks)
    angle = rng.uniform(0.0, 2 * np.pi, num_landmarks)
    wrong_match = rng.random(num_landmarks) < 0.5
    du, dv = size * np.cos(angle), size * np.sin(angle)
    zero = np.zeros(num_landmarks)
    offsets = np.where(wrong_match[:, None],
                       np.stack([zero, zero, np.copysign(size, du), zero], axis=1),
                       np.stack([du, dv, du, dv], axis=1))
    return np.where(outlier[:, None], offsets, 0.0), outlier


def _force_nonpositive_disparity(z, true_disparity, inlier, config, rng):
    """Top up non-positive disparities to the configured share on the farthest inliers (in place)."""
    target = int(round(config.nonpositive_disparity_share * len(z)))
    need = target - int(np.count_nonzero(z[:, 0] - z[:, 2] <= 0))
    candidates = np.flatnonzero(inlier & (z[:, 0] - z[:, 2] > 0))
    if need <= 0 or candidates.size == 0:
        return
    pool = candidates[np.argsort(true_disparity[candidates], kind="stable")[: 5 * need]]
    chosen = rng.choice(pool, size=min(need, len(pool)), replace=False)
    z[chosen, 2] = z[chosen, 0] + rng.uniform(0.0, 1.0, len(chosen))


def _measure(q, ids, num_landmarks, Ks, config, rng):
    """Noisy pixels with outliers and non-positive disparities, shapes (N, 4), (M,)."""
    q_h = np.concatenate([q, np.ones((len(q), 1))], axis=1)
    z_true = projection(q_h) @ Ks.T
    z = z_true + config.pixel_sigma * rng.standard_normal(z_true.shape)
    offsets, outlier = _outlier_offsets(num_landmarks, config, rng)
    z += offsets[ids]
    _force_nonpositive_disparity(z, z_true[:, 0] - z_true[:, 2], ~outlier[ids], config, rng)
    return z, outlier


def _renumber(rows, frames, n_candidates):
    """Ids by first observation frame: ``(source rows in id order, id of each observation)``."""
    first = np.full(n_candidates, np.iinfo(np.int64).max)
    np.minimum.at(first, rows, frames)
    used = np.unique(rows)
    source = used[np.lexsort((used, first[used]))]
    new_id = np.full(n_candidates, -1, dtype=np.int64)
    new_id[source] = np.arange(len(source))
    return source, new_id[rows]


def _sparse_layout(ids, frames, T):
    """Frame-major order (ids increasing within a frame) and ``frame_ptr``, shapes (N,), (T+1,)."""
    order = np.lexsort((ids, frames))
    frame_ptr = np.zeros(T + 1, dtype=np.int64)
    np.cumsum(np.bincount(frames, minlength=T), out=frame_ptr[1:])
    return order, frame_ptr


def simulate_tracks(world_T_imu, landmarks, K, b, imu_T_cam, config, rng, appear=None,
                    max_landmarks=None, time_stamps=None):
    """Simulated stereo feature tracks of known landmarks seen from known poses.

    See the module docstring for the track model (appearance, visibility, random loss,
    per-frame cap, ids by first frame, pixel noise, outliers, non-positive disparities).

    Parameters
    ----------
    world_T_imu : array_like, shape (T, 4, 4)
        True IMU poses.
    landmarks : array_like, shape (n, 3)
        Candidate landmark positions (world); those never tracked are left out.
    K : array_like, shape (3, 3)
    b : float
    imu_T_cam : array_like, shape (4, 4)
    config : SimulationConfig
    rng : numpy.random.Generator
    appear : array_like of int, shape (n,), optional
        Frame from which each landmark may be detected (default 0: from its first
        visible frame).
    max_landmarks : int, optional
        Keep a random subset of at most this many tracks.
    time_stamps : array_like, shape (T,), optional
        Default: uniform steps of ``config.time_step``.

    Returns
    -------
    SimulatedTracks
        With M <= n tracks and N observations.
    """
    world_T_imu = _check_poses(world_T_imu, "simulate_tracks")
    landmarks = np.asarray(landmarks, dtype=float).reshape(-1, 3)
    n, T = len(landmarks), len(world_T_imu)
    appear = np.zeros(n, dtype=np.int64) if appear is None else np.asarray(appear, dtype=np.int64)
    if appear.shape != (n,):
        raise ValueError(f"simulate_tracks: appear must have shape ({n},), got {appear.shape}")
    camera = StereoCamera(K, b, imu_T_cam)
    cam_T_world = camera.cam_T_imu @ lie.se3_inv(world_T_imu)
    change = _scene_change(world_T_imu, _default_time_stamps(time_stamps, T, config), config)
    clock = np.concatenate([[0.0], np.cumsum(change)])
    budget = rng.exponential(1.0 / config.track_loss_probability, n)
    rows, frames, q = _march(cam_T_world, landmarks, appear, clock, budget, camera.Ks, config)
    keep = _select_tracks(rows, frames, q, n, max_landmarks, config, rng)
    rows, frames, q = rows[keep], frames[keep], q[keep]
    source, ids = _renumber(rows, frames, n)
    order, frame_ptr = _sparse_layout(ids, frames, T)
    z, outlier = _measure(q[order], ids[order], len(source), camera.Ks, config, rng)
    return SimulatedTracks(landmarks[source], source, frame_ptr, ids[order], z, outlier)


# -------------------------------------------------------------------------- drives


def _streams(seed):
    """Independent generators for motion, landmarks, tracks and IMU noise."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]


def _rig(config, default):
    """Calibration from the config where given, else from ``default`` = (K, b, imu_T_cam)."""
    K = default[0] if config.K is None else np.asarray(config.K, dtype=float)
    b = default[1] if config.b is None else float(config.b)
    imu_T_cam = default[2] if config.imu_T_cam is None else np.asarray(config.imu_T_cam, dtype=float)
    StereoCamera(K, b, imu_T_cam)  # validates shapes and the baseline
    return K, b, imu_T_cam


def _build(time_stamps, true_v, true_w, rig, config, rngs, **fields):
    """Poses, landmarks, tracks and IMU noise assembled into a Dataset."""
    _, rng_landmarks, rng_tracks, rng_imu = rngs
    K, b, imu_T_cam = rig
    poses = integrate_poses(time_stamps, true_v, true_w)
    n_candidates = int(math.ceil(config.candidate_factor * config.num_landmarks))
    landmarks, appear = place_landmarks(poses, n_candidates, config, rng_landmarks, time_stamps)
    tracks = simulate_tracks(poses, landmarks, K, b, imu_T_cam, config, rng_tracks, appear=appear,
                             max_landmarks=config.num_landmarks, time_stamps=time_stamps)
    meas_v, meas_w = add_imu_noise(true_v, true_w, config, rng_imu)
    truth = GroundTruth(world_T_imu=poses, landmarks=tracks.landmarks, linear_velocity=true_v,
                        angular_velocity=true_w, outlier=tracks.outlier)
    return Dataset(time_stamps=time_stamps, linear_velocity=meas_v, angular_velocity=meas_w,
                   K=K, b=b, imu_T_cam=imu_T_cam, num_landmarks=len(tracks.landmarks),
                   frame_ptr=tracks.frame_ptr, obs_ids=tracks.obs_ids, obs_z=tracks.obs_z,
                   ground_truth=truth, **fields)


def simulate_drive(preset="course", seed=0, **overrides):
    """A seeded, deterministic simulated drive with ground truth.

    Parameters
    ----------
    preset : {"tiny", "small", "course"}
        Scale, see :data:`PRESETS` (``"course"``: 1010 frames, ~5000 landmarks,
        ~65,000 observations, like course dataset 3).
    seed : int
        Same seed, same arrays. Motion, landmarks, tracks and IMU noise draw from
        separate streams, so e.g. changing ``pixel_sigma`` keeps the drive and the map.
    **overrides
        :class:`SimulationConfig` fields, including ``K``, ``b`` and ``imu_T_cam``.

    Returns
    -------
    Dataset
        Named ``"sim"`` (``"sim-small"``, ``"sim-tiny"``), with ``ground_truth`` and
        ``extra = {"preset", "seed", "config"}``.
    """
    config = make_config(preset, **overrides)
    rngs = _streams(seed)
    time_stamps, true_v, true_w = simulate_motion(config, rngs[0])
    rig = _rig(config, default_rig())
    args = ", ".join([f"preset={preset!r}", f"seed={seed!r}"] + [f"{k}=..." for k in sorted(overrides)])
    return _build(
        time_stamps, true_v, true_w, rig, config, rngs,
        name=_PRESET_NAMES[preset],
        source=f"visla_edu.simulate.simulate_drive({args}); {config.describe()}",
        label=f"simulated drive (preset {preset}, seed {seed}) with ground truth",
        extra={"preset": preset, "seed": seed, "config": config},
    )


# ------------------------------------------------------------------------ stand-in


def _load_npz(path, keys):
    """The named arrays of an ``.npz`` file, with clear errors for a missing file or key."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            present = list(data.files)
            arrays = {k: np.asarray(data[k], dtype=float) for k in keys if k in present}
    except (OSError, EOFError, ValueError, AttributeError) as err:  # not an npz archive
        raise ValueError(f"{path}: cannot read as an .npz archive ({err})") from err
    missing = [k for k in keys if k not in arrays]
    if missing:
        raise ValueError(f"{path}: missing key(s) {missing}; keys present: {sorted(present)}")
    return arrays


def _check_shape(array, shape, path, key):
    if array.shape != shape:
        raise ValueError(f"{path}: key {key!r} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{path}: key {key!r} contains non-finite values")
    return array


def _read_imu_drive(path):
    """``time_stamps`` (T,), ``linear_velocity`` and ``angular_velocity`` (T, 3) from a course file."""
    d = _load_npz(path, ["time_stamps", "linear_velocity", "angular_velocity"])
    stamps = d["time_stamps"]
    if stamps.ndim not in (1, 2) or stamps.size != stamps.shape[-1] or stamps.size < 2:
        raise ValueError(f"{path}: key 'time_stamps' must have shape (1, T) or (T,) with T >= 2, "
                         f"got {stamps.shape}")
    stamps = _check_shape(stamps.ravel(), (stamps.size,), path, "time_stamps")
    if np.any(np.diff(stamps) <= 0):
        raise ValueError(f"{path}: key 'time_stamps' must be strictly increasing")
    T = stamps.size
    v = _check_shape(d["linear_velocity"], (3, T), path, "linear_velocity").T.copy()
    w = _check_shape(d["angular_velocity"], (3, T), path, "angular_velocity").T.copy()
    return stamps, v, w


def _read_calibration(path, need_extrinsic):
    """``K`` (3, 3), ``b`` and (if needed) ``imu_T_cam`` (4, 4) from a 2021+ course file."""
    keys = ["K", "b"] + (["imu_T_cam"] if need_extrinsic else [])
    d = _load_npz(path, keys)
    K = _check_shape(d["K"], (3, 3), path, "K")
    b = _check_shape(d["b"].reshape(-1), (1,), path, "b")[0]
    if b <= 0:
        raise ValueError(f"{path}: key 'b' (baseline) must be positive, got {b}")
    imu_T_cam = _check_shape(d["imu_T_cam"], (4, 4), path, "imu_T_cam") if need_extrinsic else None
    return K, float(b), imu_T_cam


def standin_dataset10(imu_only_path, calibration_path, seed=0, imu_T_cam=None, **overrides):
    """The STAND-IN for course dataset 10: its real IMU drive with simulated stereo tracks.

    The real feature file ``10.npz`` is not available. The measured velocities of
    ``10_imu_only.npz`` define the true drive, landmarks are placed along that path and
    tracked as in :func:`simulate_drive` (about :data:`STANDIN_NUM_LANDMARKS` landmarks), and
    the measured IMU is the real velocities plus the simulation noise.

    The real gyro has biases of about 0.01 rad/s: integrating it as it is would make the
    "true" car climb over a kilometre and roll over. The true angular velocity is therefore
    the real one minus its mean roll and pitch rates (a car ends about as level as it
    started); that mean is kept in the measurement as a constant gyro bias
    (``config.gyro_bias``, also in ``extra["level_gyro_bias"]``), so the measured velocities
    are still the real ones plus noise.

    Parameters
    ----------
    imu_only_path : str or Path
        ``10_imu_only.npz``: ``time_stamps`` (1, T), ``linear_velocity`` (3, T),
        ``angular_velocity`` (3, T).
    calibration_path : str or Path
        A 2021+ course file of the same rig (``03.npz``): ``K`` (3, 3), ``b``, ``imu_T_cam``.
    seed : int
    imu_T_cam : array_like, shape (4, 4), optional
        Use this extrinsic instead of the file's (e.g. a corrected one).
    **overrides
        :class:`SimulationConfig` fields (``K``, ``b`` too); the motion fields and
        ``num_frames`` do not apply (the file decides).

    Returns
    -------
    Dataset
        Named ``"10-standin"``, labelled :data:`STANDIN_LABEL`, time stamps identical to
        the file's, with ``ground_truth``.

    Raises
    ------
    FileNotFoundError
        A file does not exist.
    ValueError
        A key is missing or has the wrong shape.
    """
    time_stamps, true_v, real_w = _read_imu_drive(imu_only_path)
    if "num_frames" in overrides:
        raise ValueError("standin_dataset10: num_frames comes from the IMU file and cannot be overridden")
    overrides.setdefault("num_landmarks", STANDIN_NUM_LANDMARKS)
    level_bias = (float(real_w[:, 0].mean()), float(real_w[:, 1].mean()), 0.0)
    true_w = real_w - np.array(level_bias)
    overrides.setdefault("gyro_bias", level_bias)
    if imu_T_cam is not None:
        overrides["imu_T_cam"] = imu_T_cam
    config = make_config("course", num_frames=len(time_stamps), **overrides)
    rig = _rig(config, _read_calibration(calibration_path, need_extrinsic=imu_T_cam is None))
    extrinsic = "imu_T_cam given by the caller" if imu_T_cam is not None else f"imu_T_cam from {calibration_path}"
    return _build(
        time_stamps, true_v, true_w, rig, config, _streams(seed),
        name="10-standin",
        source=(f"visla_edu.simulate.standin_dataset10: IMU drive from {imu_only_path}, K and b from "
                f"{calibration_path}, {extrinsic}, seed={seed!r}; {config.describe()}"),
        label=STANDIN_LABEL,
        extra={"preset": "standin", "seed": seed, "config": config, "level_gyro_bias": level_bias},
    )
