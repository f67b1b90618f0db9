"""The parameters of a simulated drive: :class:`SimulationConfig`, its presets, the default rig."""

import dataclasses
from dataclasses import dataclass

import numpy as np

from visla_edu import lie

__all__ = ["SimulationConfig", "PRESETS", "PRESET_NAMES", "OUTLIER_KINDS", "make_config", "default_rig"]

#: How an outlier track is made, see :attr:`SimulationConfig.outlier_kind`.
OUTLIER_KINDS = ("offset", "uniform")


@dataclass
class SimulationConfig:
    """Every parameter of a simulated drive (defaults: the ``"course"`` preset).

    Lengths in metres, times in seconds, angles in radians; a pair ``(lo, hi)`` is a range sampled uniformly; a
    ``*_timescale`` is the correlation time of its smooth noise.

    Attributes
    ----------
    num_frames, time_step, time_step_jitter, start_time
        T (ignored by the stand-in: the file decides); the mean step between time stamps, the standard deviation of
        its jitter, the first stamp.
    speed_range, speed_timescale, yaw_rate_sigma, yaw_timescale, roll_pitch_amplitude, roll_pitch_timescale
        Forward speed ``mid + half_width * tanh(smooth noise)`` in the band; gentle curves: smooth yaw-rate noise of
        this standard deviation; roll and pitch angles: smooth noise of this amplitude (their rates are tiny).
    turn_interval, turn_angle_range, turn_duration_range
        One turn per ``turn_interval`` of drive time (a 100 s drive has 4 at 25 s); its heading change (either
        direction) and duration.
    side_velocity_sigma, linear_velocity_sigma, angular_velocity_sigma, gyro_bias, imu_lag
        Smooth lateral and vertical body velocity (a car barely slips); the measured IMU velocities are
        ``true[k - imu_lag]`` (edge samples repeated) + white noise of these sigmas (+ the bias (3,) on the angular
        one), so sample ``t + imu_lag`` moves frame ``t`` to ``t + 1``. ``imu_lag`` is 1 on the KITTI raw drives; 0 is
        the course's convention.
    K, b, imu_T_cam, K_right, reported_imu_T_cam : ndarray (3, 3), float, ndarray (4, 4), (3, 3), (4, 4), or None
        Calibration; None means :func:`default_rig` (stand-in: the calibration file). ``K_right``: the right camera's
        own intrinsics (a rig with two: :class:`visla_edu.camera.StereoCamera`), None: the same as ``K``.
        ``reported_imu_T_cam``: the extrinsic the dataset *reports*, when it differs from the simulated
        ``imu_T_cam`` (e.g. flipped axes like dataset 3's; the true one is kept in ``extra["simulated_imu_T_cam"]``),
        None: the true one.
    image_size, pixel_sigma
        Width and height; the standard deviation of the noise on each of ``[uL, vL, uR, vR]``.
    num_landmarks, candidate_factor : int, float
        Target number of tracks M (the per-frame cap may remove a few); landmarks placed per wanted track (some are
        never seen, or only once).
    imu_height, ahead_range, lateral_range, height_range, far_share, far_range, far_height_range, far_bearing
        A roadside landmark sits this far along the road ahead of its anchor pose, to the left or right of the path,
        and above the road (``imu_height`` below the IMU); a share ``far_share`` are far (buildings, trees, hills:
        tiny disparity), ``far_range`` from the anchor pose, ``far_height_range`` above the road, at most
        ``far_bearing`` left or right of straight ahead.
    scene_speed_floor, depth_range, track_loss_probability, min_track_length, max_start_delay
    max_observations_per_frame
        The track model's (:mod:`visla_edu.simulate`, steps 1-3); the lifetimes are exponential in scene-change units,
        mean ``1 / track_loss_probability`` frames, plus ``min_track_length`` guaranteed frames.
    outlier_share, outlier_kind, outlier_offset_range
        Share of landmark tracks that are gross outliers, and how they are made. ``"offset"``: the true track shifted
        by a constant offset of a size in ``outlier_offset_range``, in both images (wrong feature) or the right image's
        u only (wrong stereo match), half of the outliers each. ``"uniform"``: random pixels at every observation,
        ``uL > uR`` uniform in the width, ``vL`` in the height, ``vR = vL`` + noise (a match that passes the
        rectified-stereo check).
    nonpositive_disparity_share : float
        Share of observations with ``uL - uR <= 0``: noise on far points, topped up by forcing the farthest inlier
        observations to disparities in ``(-1, 0]``.
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
    imu_lag: int = 0
    K: object = None
    b: object = None
    imu_T_cam: object = None
    reported_imu_T_cam: object = None
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
    outlier_kind: str = "offset"
    outlier_offset_range: tuple = (20.0, 60.0)
    nonpositive_disparity_share: float = 0.01
    K_right: object = None

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
        _require(0 < self.track_loss_probability <= 1, "track_loss_probability", self.track_loss_probability,
                 "in (0, 1]")
        for name in ("min_track_length", "max_observations_per_frame", "candidate_factor"):
            _require(getattr(self, name) >= 1, name, getattr(self, name), ">= 1")
        _require(isinstance(self.imu_lag, (int, np.integer)) and abs(self.imu_lag) < self.num_frames,
                 "imu_lag", self.imu_lag, "an integer smaller in size than num_frames")
        _require(self.outlier_kind in OUTLIER_KINDS, "outlier_kind", self.outlier_kind, f"one of {OUTLIER_KINDS}")
        _require(self.reported_imu_T_cam is None or np.shape(self.reported_imu_T_cam) == (4, 4),
                 "reported_imu_T_cam", None if self.reported_imu_T_cam is None else np.shape(self.reported_imu_T_cam),
                 "None or a (4, 4) pose (shape shown)")
        _require(0 < self.depth_range[0] < self.depth_range[1], "depth_range", self.depth_range, "0 < near < far")
        for name in ("speed_range", "turn_angle_range", "turn_duration_range", "ahead_range", "lateral_range",
                     "height_range", "far_range", "far_height_range", "outlier_offset_range"):
            lo, hi = getattr(self, name)
            _require(lo <= hi, name, getattr(self, name), "(lo, hi) with lo <= hi")
        return self

    def describe(self):
        """One line ``name=value, ...``; arrays are shown by shape."""
        def shown(value):
            return f"array{value.shape}" if isinstance(value, np.ndarray) else value

        parts = [f"{f.name}={shown(getattr(self, f.name))}" for f in dataclasses.fields(self)]
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
PRESET_NAMES = {"tiny": "sim-tiny", "small": "sim-small", "course": "sim"}


def make_config(preset="course", **overrides):
    """:class:`SimulationConfig` of a preset (a key of :data:`PRESETS`) with some fields replaced, validated.

    ``"tiny"`` is for unit tests, ``"course"`` at dataset-3 scale; an unknown preset or field is a ValueError.
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
    """A KITTI-like stereo rig ``(K (3, 3), b, imu_T_cam (4, 4))``, made up for visla-edu (not from any course file).

    Left camera: ``fsu = fsv = 550`` px, principal point ``(680, 240)``, 1400x500 images, baseline 0.6 m, 1.5 m ahead
    of and 0.6 m above the IMU, looking forward (camera x = -IMU y, camera y = -IMU z, camera z = IMU x) with a
    ~1 degree misalignment.
    """
    K = np.array([[550.0, 0.0, 680.0], [0.0, 550.0, 240.0], [0.0, 0.0, 1.0]])
    imu_R_cam_nominal = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    imu_T_cam = np.eye(4)
    imu_T_cam[:3, :3] = imu_R_cam_nominal @ lie.so3_exp(np.array([0.01, -0.012, 0.006]))
    imu_T_cam[:3, 3] = [1.5, 0.0, 0.6]
    return K, 0.6, imu_T_cam
