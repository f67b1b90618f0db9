"""Simulated stereo-inertial drives with ground truth.

:func:`simulate_drive` invents a car-like drive (smooth speed, curves and turns); :func:`simulate_along_drive`
takes given true velocities (e.g. a real IMU drive, as :func:`visla_edu.data.standin_dataset10` does). Both return
a :class:`~visla_edu.dataset.Dataset` with a :class:`~visla_edu.dataset.GroundTruth`, through one pipeline that is
usable on its own for any true trajectory::

    world_T_imu = motion.dead_reckon(time_stamps, true_twists)     # (T, 4, 4)
    landmarks, appear = place_landmarks(world_T_imu, n, config, rng, time_stamps)
    tracks = simulate_tracks(world_T_imu, landmarks, K, b, imu_T_cam, config, rng,
                             appear=appear, max_landmarks=config.num_landmarks)

Also :func:`make_config` (:data:`PRESETS`), :func:`default_rig`, :func:`simulate_motion`, :func:`add_imu_noise`,
:func:`lag_samples` and :func:`with_stale_copies` (the course files' stale copies). ``config`` is a
:class:`SimulationConfig`, ``rng`` a :class:`numpy.random.Generator`. ``world`` = the IMU frame at the first time stamp
(x forward, y left, z up); camera optical frame x right, y down, z forward; other conventions: :mod:`visla_edu.lie`.

The track model (vectorised: the one loop runs over track *age*, not frames):

1. Every landmark has an *appearance frame* (its placement's anchor), from which the detector may pick it up.
   Anchors are spread in proportion to the *scene change* per step, distance travelled + ``scene_speed_floor`` *
   elapsed time, with a burst at frame 0 (the detector starts with a full image).
2. A track starts at the first frame, at most ``max_start_delay`` after the appearance frame, in which the landmark
   is visible (depth within ``depth_range``, inside both images), and lasts while it stays visible, up to a random
   lifetime: lost with probability about ``track_loss_probability`` per frame of average scene change (a stopped
   car keeps its tracks; the number tracked stays about constant). One run each.
3. Tracks shorter than ``min_track_length`` are dropped; a random subset keeps ``num_landmarks``; frames with more
   than ``max_observations_per_frame`` observations lose their farthest ones (a track keeps its longest remaining run).
4. Ids by first observation frame. Pixels are ``Ks pi(q)`` + white noise on each of ``[uL, vL, uR, vR]``
   (rectified: ``vR`` = ``vL`` + noise); a share of tracks are gross outliers (``outlier_kind``), a share of
   observations get a non-positive disparity (noise on far points, topped up by forced ones).
"""

from visla_edu.simulate._config import PRESETS, SimulationConfig, default_rig, make_config
from visla_edu.simulate._drive import simulate_along_drive, simulate_drive
from visla_edu.simulate._landmarks import place_landmarks
from visla_edu.simulate._motion import add_imu_noise, lag_samples, simulate_motion
from visla_edu.simulate._stale import with_stale_copies
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
    "with_stale_copies",
]
