"""Simulated stereo-inertial drives with ground truth.

Two entry points build a :class:`~visla_edu.dataset.Dataset` with a
:class:`~visla_edu.dataset.GroundTruth`:

* :func:`simulate_drive` invents a car-like drive (smooth speed, curves and turns),
  places landmarks along the road and simulates stereo feature tracks and IMU noise.
* :func:`simulate_along_drive` takes given true velocities (e.g. a real IMU drive: the
  dataset-10 stand-in :func:`visla_edu.data.standin_dataset10` is built with it) and
  simulates the landmarks, feature tracks and IMU noise along them.

Both share one pipeline, usable on its own for any true trajectory::

    world_T_imu = motion.dead_reckon(time_stamps, true_twists)     # (T, 4, 4)
    landmarks, appear = place_landmarks(world_T_imu, n, config, rng, time_stamps)
    tracks = simulate_tracks(world_T_imu, landmarks, K, b, imu_T_cam, config, rng,
                             appear=appear, max_landmarks=config.num_landmarks)

Conventions are the library's (:mod:`visla_edu.lie`, :mod:`visla_edu.motion`); ``world`` = IMU
frame at the first time stamp (x forward, y left, z up), camera optical frame x right, y down,
z forward.

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
   rectified); a share of tracks are gross outliers (a constant offset, or uniformly random
   pixels: ``outlier_kind``), and a share of observations get a non-positive disparity (noise
   on far points, topped up by forced ones).

Quirks of real files can be simulated too: velocities recorded one or more samples late
(``imu_lag``, as on the KITTI raw drives), and a reported extrinsic that differs from the rig's
(``reported_imu_T_cam``, e.g. dataset 3's flipped axes).

Modules: ``_config`` (:class:`SimulationConfig`, presets, :func:`default_rig`), ``_motion``
(the car's motion, IMU noise), ``_landmarks``, ``_tracks`` (the track model above),
``_drive`` (whole drives). Everything public is re-exported here.
"""

from visla_edu.simulate._config import PRESETS, SimulationConfig, default_rig, make_config
from visla_edu.simulate._drive import simulate_along_drive, simulate_drive
from visla_edu.simulate._landmarks import place_landmarks
from visla_edu.simulate._motion import add_imu_noise, lag_samples, simulate_motion
from visla_edu.simulate._tracks import SimulatedTracks, simulate_tracks

__all__ = [
    "SimulationConfig",
    "SimulatedTracks",
    "PRESETS",
    "make_config",
    "default_rig",
    "simulate_motion",
    "add_imu_noise",
    "lag_samples",
    "place_landmarks",
    "simulate_tracks",
    "simulate_drive",
    "simulate_along_drive",
]
