"""The filter modes' settings: noise, initialisation, gating, and the teaching comparisons."""

from dataclasses import asdict, dataclass

import numpy as np

from visla_edu.filters._settings import check_settings, setting

__all__ = ["FilterConfig"]


@dataclass
class FilterConfig:
    """Noise, initialisation and gating parameters of the filter modes.

    Each setting names the modes that read it (``deadreckon``, ``mapping``, ``vio``,
    ``slam``; see :data:`visla_edu.codes.MODES`). How the driver runs (BLAS threads, progress
    bar) is not a setting: those are arguments of :func:`visla_edu.run.run_filter`.

    The defaults work without per-dataset tuning on the simulated drives, datasets 03 and
    0022 and the dataset-10 stand-in. They were chosen from evidence, not guessed (notebook 07
    recomputes each figure):

    * ``visla-edu info`` measures the IMU noise from second differences of the velocities:
      up to 0.5 m/s and 0.05 rad/s (dataset 0022, the noisiest file), so those are the
      velocity noise settings. With 0.02 rad/s instead, 03 and 0022 gate about twice as many
      observations (15.7% and 14.9%, against 8.0% and 4.5%), and the 03 trajectory ends 36 m
      below its start height after 1.3 km (4 m with 0.05 rad/s).
    * The gated share grows with a track's age (tracker drift: roughly 10% after ten frames
      on 03), and the distances are heavy-tailed (about 1% of them above 100 for a
      chi-square(4) variable), so gating stays on.
    * ``sigma_pixel`` 1.5 gives accepted observations a NIS per degree of freedom of 0.9 on
      03 (1.5 at 1 px): slightly conservative, as it should be with drifting tracks.
    * ``min_init_disparity`` 3 px (depth up to ``fsu b / 3``, 110 m on dataset 03's rig): a
      far landmark triangulated from a 2 px disparity is a poor Gaussian in x, y, z that makes
      joint SLAM overconfident and less accurate, while fixed far landmarks help VIO hold its
      orientation. Against 2 px, SLAM's error on the dataset-10 stand-in drops from 24 m to
      15 m and the NEES on 300-frame drives falls by a third; 5 px helps SLAM a little more
      but makes VIO worse than dead reckoning on some simulated drives. 03 and 0022 gate
      8.0% and 4.5% of their observations (7.5% and 4.4% at 2 px).
    * The extrinsic check finds dataset 03's ``imu_T_cam`` axes flipped (rotation slope -0.78,
      +0.83 after the ``flip_yz`` correction), hence ``extrinsic_correction="auto"``.
    * The time-alignment check prefers ``imu_lag=+1`` by only 0.2% (03) and 1% (0022) of
      the rotation residual: too weak to leave the course's convention ``u[t]`` for ``t->t+1``.

    Each field declares what it accepts next to its default (:func:`visla_edu.filters._settings.setting`:
    kind, plausible range and why, words such as ``"auto"``, None or not); the same
    declaration checks values given in Python and parses ``visla-edu run --set NAME=VALUE``
    strictly (:func:`visla_edu.filters._settings.parse_setting`). An out-of-range value is
    refused with its range, never clipped.

    The three switches ``landmark_cross_covariance``, ``mapping_motion_noise`` and
    ``vio_refine_landmarks`` are the teaching comparisons of the modes that read them: the
    default is the consistent filter, the other value the tempting shortcut the notebooks
    measure against it (04 mapping, 05 VIO, 06 SLAM).

    Attributes
    ----------
    sigma_pixel : float
        Modes: mapping, vio, slam. Standard deviation of each stereo pixel coordinate (px);
        ``R = sigma_pixel^2 I4``.
    sigma_linear_velocity : float
        Modes: all. White noise on each linear-velocity sample (m/s); ``W`` scales it by the
        time step.
    sigma_angular_velocity : float
        Modes: all. White noise on each angular-velocity sample (rad/s).
    landmark_prior_inflation : float
        Modes: mapping, vio, slam. A landmark enters the state at its first observation (which
        it consumes) with its mean at the stereo triangulation and the covariance
        ``inflation^2 C_tri + sigma^2 I`` from the pixels, plus, in VIO and SLAM, the pose's
        uncertainty (in SLAM also its correlation) carried through the triangulation (see
        :func:`visla_edu.ekf.initialize_landmarks`). ``C_tri`` is long along the viewing ray
        and grows with depth squared; the inflation allows for the linearisation error of far
        points.
    landmark_prior_sigma : float
        Modes: mapping, vio, slam. Isotropic part of a new landmark's covariance (m).
    initial_pose_sigma : float
        Modes: all. Standard deviation of the first pose; 0 because ``world`` is the first IMU
        frame.
    gate_probability : float
        Modes: mapping, vio, slam. Observations whose Mahalanobis distance exceeds the
        chi-square quantile with 4 degrees of freedom at this probability are rejected as
        outliers (1.0 disables gating).
    min_init_disparity : float
        Modes: mapping, vio, slam. Minimum disparity ``uL - uR`` (px) to triangulate a new
        landmark; smaller disparities give depths beyond ``fsu b / min_init_disparity``.
        Observations with non-positive disparity are never used.
    imu_lag : int
        Modes: all (and the driver's dead-reckoning reference). Which velocity sample drives
        the step ``t -> t+1``: ``u[t + imu_lag]``, -2 to 2.
    extrinsic_correction : str
        Modes: all (the driver resolves the camera with it, :func:`visla_edu.run.make_filter`).
        ``"auto"`` applies the correction that :func:`visla_edu.diagnostics.check_extrinsics`
        finds with strong evidence; ``"none"`` uses the file's ``imu_T_cam`` as is; or the name
        of a correction (``"flip_yz"``, ...), see :data:`visla_edu.diagnostics.CORRECTIONS`.
    landmark_cross_covariance : bool
        Mode: slam (teaching comparison, notebook 06). True: a new landmark enters correlated
        with the state (``G_pose Sigma_pose,x``). False is the textbook shortcut (pixel
        covariance only, no correlation), which makes the filter overconfident.
    mapping_motion_noise : bool
        Mode: mapping (teaching comparison, notebook 04). True: widen each observation's noise
        by the dead-reckoning motion noise since the landmark's first sighting. False takes
        the dead-reckoned poses as exact.
    vio_refine_landmarks : bool
        Mode: vio (teaching comparison, notebook 05). True: also update the landmarks with the
        observations that just corrected the pose, which counts each observation twice; off
        by default.
    skip_repeated_frames : bool
        Modes: mapping, vio, slam. Make no update at frames whose observations exactly repeat
        the previous frame's (a duplicated camera frame while the IMU moved on; dataset 03
        has one at 1008).
    landmark_stride : int
        Modes: mapping, vio, slam. Use only landmarks whose index is a multiple of this (the
        textbook workaround for the dense filter's memory; 1 = every landmark).
    """

    sigma_pixel: float = setting(1.5, float, 1e-3, 100.0, unit="px",
                                 why="no tracker locates a feature to a thousandth of a pixel; 100 px is no location")
    sigma_linear_velocity: float = setting(0.5, float, 0.0, 50.0, unit="m/s",
                                           why="0 trusts the velocities; 50 m/s (180 km/h) of noise is no measurement")
    sigma_angular_velocity: float = setting(0.05, float, 0.0, 5.0, unit="rad/s",
                                            why="5 rad/s of noise is almost a turn per second")
    landmark_prior_inflation: float = setting(1.0, float, 0.0, 1000.0,
                                              why="a factor on the triangulation's standard deviation")
    landmark_prior_sigma: float = setting(0.1, float, 0.0, 1e4, low_open=True, unit="m",
                                          why="a prior wider than 10 km says nothing")
    initial_pose_sigma: float = setting(0.0, float, 0.0, 1e3, unit="m",
                                        why="world is the first IMU frame, so 0 is exact")
    gate_probability: float = setting(0.999, float, 0.0, 1.0, low_open=True,
                                      why="a probability; 1 disables gating")
    min_init_disparity: float = setting(3.0, float, 0.0, 1000.0, unit="px",
                                        why="no image is wider than the range")
    imu_lag: int = setting(0, int, -2, 2,
                           why="which velocity sample near the step drives it; a larger shift is a broken file")
    extrinsic_correction: str = setting("auto", str,
                                        why="'auto', 'none' or a correction of visla_edu.diagnostics.CORRECTIONS")
    landmark_cross_covariance: bool = setting(True, bool)
    mapping_motion_noise: bool = setting(True, bool)
    vio_refine_landmarks: bool = setting(False, bool)
    skip_repeated_frames: bool = setting(True, bool)
    landmark_stride: int = setting(1, int, 1, 1_000_000, why="1 uses every landmark")

    def __post_init__(self):
        check_settings(self)

    @property
    def pixel_variance(self):
        """``sigma_pixel^2``."""
        return self.sigma_pixel**2

    @property
    def gate_threshold(self):
        """Chi-square (4 dof) quantile at ``gate_probability``; ``inf`` when gating is off."""
        if self.gate_probability >= 1:
            return np.inf
        from scipy.stats import chi2

        return float(chi2.ppf(self.gate_probability, 4))

    def to_dict(self):
        """Plain dict of the settings (for saving with results)."""
        return asdict(self)
