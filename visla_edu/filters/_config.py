"""The filter modes' settings: noise, initialisation, gating, and the teaching comparisons."""

from dataclasses import asdict, dataclass, replace

import numpy as np

from visla_edu.diagnostics import CORRECTIONS
from visla_edu.metrics import chi2_quantile
from visla_edu.settings import check_settings, setting

__all__ = ["FilterConfig", "AUTO", "MAX_IMU_LAG", "AUTO_FIELDS", "DRIVE_FIELDS", "INFLATION_POWER", "GYRO_REGIME_RATIO",
           "MSCKF_WINDOW", "gyro_ratio", "pixel_noise_inflation", "msckf_window"]

#: The value of a setting the driver measures from the data (:func:`visla_edu.diagnostics.calibrate`).
AUTO = "auto"
#: ``imu_lag`` is searched and accepted in ``-MAX_IMU_LAG .. MAX_IMU_LAG`` frames.
MAX_IMU_LAG = 2
#: Settings that may be ``"auto"`` and their attribute on the calibration that resolves them.
AUTO_FIELDS = ("sigma_linear_velocity", "sigma_angular_velocity", "imu_lag")
#: Settings that may be ``"auto"`` and are resolved from the drive's gyro ratio (:func:`gyro_ratio`).
DRIVE_FIELDS = ("pixel_noise_inflation", "msckf_window")
#: Largest ``pixel_noise_inflation`` (the camera is then ignored in all but name).
MAX_INFLATION = 1e4
#: Exponent of :func:`pixel_noise_inflation`, chosen on the cross-drive benchmark
#: (``benchmarks/bench_accuracy.py`` prints the candidates).
INFLATION_POWER = 2
#: The gyro regime: :func:`gyro_ratio` at least this. Chosen on the cross-drive benchmark, where
#: the simulated drives and dataset 10's motion (ratio 1.1-1.3) gain from the clones and the
#: GPS-aided drives 0020 and 0042 and their pieces (2.6-4.2) lose by them.
GYRO_REGIME_RATIO = 2.0
#: ``msckf_window`` outside the gyro regime: on the cross-drive benchmark where the camera carries the
#: estimate, 20 clones beat the filter without them, and 10 and 30 were worse.
MSCKF_WINDOW = 20


def gyro_ratio(sigma_pixel, focal_length, sigma_angular, time_step):
    """``r = (sigma_pixel / focal_length) / (sigma_w tau)``: an observation's angle over the gyro's in a step.

    ``sigma_pixel`` (px), ``focal_length`` the camera's ``fsu`` (px), ``sigma_angular`` (rad/s;
    per-axis values (3,) are averaged), ``time_step`` a typical ``tau`` (s). A float, ``inf`` for a
    noise-free gyro.
    """
    gyro_angle = float(np.mean(sigma_angular)) * float(time_step)
    return float(sigma_pixel / focal_length / gyro_angle) if gyro_angle > 0 else np.inf


def pixel_noise_inflation(sigma_pixel, focal_length, sigma_angular, time_step, power=INFLATION_POWER,
                          track_correlation=0.0):
    """How much less than ``sigma_pixel`` promises the camera is to be trusted on a drive (a float).

    ``max(1, r)^power`` with ``r`` of :func:`gyro_ratio` (the first four arguments are its), and in
    the gyro regime (``r >=`` :data:`GYRO_REGIME_RATIO`) at least ``(1 + rho) / (1 - rho)``: with
    track errors correlated from frame to frame, a track of ``L`` observations is worth about
    ``L (1 - rho) / (1 + rho)``, and where the gyro resolves angles better than one observation
    (``r > 1``) a camera treated as independent pixels would pull a good dead reckoning off by the
    sum of its correlated errors. ``rho`` (``track_correlation``, in ``[-1, 1)``) is
    :func:`visla_edu.diagnostics.track_correlation` along the dead-reckoned poses. The factor lies
    in ``[1, MAX_INFLATION]``.
    """
    ratio = gyro_ratio(sigma_pixel, focal_length, sigma_angular, time_step)
    if not np.isfinite(ratio):
        return MAX_INFLATION  # a noise-free gyro: the camera can add nothing
    inflation = max(1.0, ratio) ** power
    if ratio >= GYRO_REGIME_RATIO:
        rho = min(float(track_correlation), 1 - 1 / MAX_INFLATION)
        inflation = max(inflation, (1 + rho) / (1 - rho))
    return float(min(MAX_INFLATION, inflation))


def msckf_window(sigma_pixel, focal_length, sigma_angular, time_step):
    """Clones kept on a drive (an int): 0 (the joint EKF without clones) in the gyro regime, else :data:`MSCKF_WINDOW`.

    The arguments are :func:`gyro_ratio`'s. In the gyro regime (:data:`GYRO_REGIME_RATIO`) the clones'
    multi-frame updates of the short tracks add the tracks' correlated errors more than information.
    """
    return 0 if gyro_ratio(sigma_pixel, focal_length, sigma_angular, time_step) >= GYRO_REGIME_RATIO else MSCKF_WINDOW


@dataclass
class FilterConfig:
    """Noise, initialisation and gating parameters of the filter modes.

    Each field's declaration below is the one statement of its default, kind, unit, plausible range
    and why, and of the words it accepts such as ``"auto"`` (:mod:`visla_edu.settings`;
    ``visla-edu run --help`` lists them); the attributes say what each setting means and which modes
    read it (how the driver runs is :func:`visla_edu.run.run_filter`'s arguments). ``"auto"`` is
    measured from each drive's data (:meth:`resolve`); the comments at the declarations give the
    evidence for the rest (notebooks 04, 10, 11 and ``benchmarks/bench_accuracy.py`` recompute it).
    The switches ``landmark_cross_covariance``, ``mapping_motion_noise`` and
    ``vio_refine_landmarks`` are teaching comparisons: the default is the consistent filter, the
    other value the shortcut its notebook measures.

    Attributes
    ----------
    sigma_pixel : float
        Modes: mapping, vio, slam. Standard deviation of each stereo pixel coordinate;
        ``R = (pixel_noise_inflation sigma_pixel)^2 I4``.
    pixel_noise_inflation : float or "auto"
        Modes: mapping, vio, slam. A factor on ``sigma_pixel`` (:func:`pixel_noise_inflation`).
    sigma_linear_velocity, sigma_angular_velocity : float, (float, float, float) or "auto"
        Modes: all. Noise on each linear (angular) velocity sample, for all or per body axis
        (:func:`visla_edu.motion.motion_noise`).
    landmark_prior_inflation, landmark_prior_sigma : float
        Modes: mapping, vio, slam. A new landmark's covariance is ``inflation^2 C_tri + sigma^2 I``
        (:func:`visla_edu.ekf.initialize_landmarks`); the inflation allows for far points'
        linearisation error.
    initial_pose_sigma : float
        Modes: all. Standard deviation of the first pose.
    gate_probability : float
        Modes: mapping, vio, slam. Observations beyond this chi-square (4 dof) quantile are gated.
    min_init_disparity : float
        Modes: mapping, vio, slam. Least disparity ``uL - uR`` to triangulate a new landmark (a
        depth up to ``fsu b / min_init_disparity``); a non-positive disparity is never used.
    imu_lag : int or "auto"
        Modes: all (and the driver's dead reckoning). The step ``t -> t+1`` uses ``u[t + imu_lag]``.
    extrinsic_correction : str
        Modes: all, through the camera (:func:`visla_edu.run.make_filter`). ``"none"``: the file's
        ``imu_T_cam``; ``"auto"``: what :func:`visla_edu.diagnostics.check_extrinsics` finds with
        strong evidence; or one of :data:`visla_edu.diagnostics.CORRECTIONS`.
    landmark_cross_covariance : bool
        Mode: slam (notebook 08). A new landmark enters correlated, ``G_pose Sigma_pose,x``.
    mapping_motion_noise : bool
        Mode: mapping (notebook 05). Widen each observation's noise by the dead-reckoning motion
        noise since the landmark's first sighting; False takes the dead-reckoned poses as exact.
    vio_refine_landmarks : bool
        Mode: vio (notebook 07). Also update the landmarks, which counts each observation twice.
    skip_repeated_frames : bool
        Modes: mapping, vio, slam. No update at frames repeating the previous one's observations
        exactly (a duplicated camera frame while the IMU moved on).
    skip_stale_copies : bool
        Modes: mapping, vio, slam. Leave out the observations that repeat their landmark's pixels of
        the frame before bit for bit (:func:`visla_edu.dataset.stale_copies`: they claim the scene did
        not move); in the clone window such a gap does not end the track.
    landmark_stride : int
        Modes: mapping, vio, slam. Use only the landmarks whose index is a multiple of this (the
        textbook workaround for the dense filter's memory).
    slam_error : {"invariant", "right"}
        Mode: slam. What the joint state's error means (:mod:`visla_edu.filters._forms`).
    reinit_gated_landmarks : bool
        Mode: slam (``msckf_window=0``). A landmark no update has used yet is placed again from its
        next observation when that one is gated (the first was the outlier); False keeps the first
        placement, so a landmark born from a bad observation gates its whole track.
    msckf_window : int or "auto"
        Mode: slam (not dense). Past poses kept as clones (``"auto"``: :func:`msckf_window`): a
        track seen longer enters the state, a shorter one is used in one null-space (MSCKF) update
        when it ends (:mod:`visla_edu.filters._clones`). 0: the joint EKF of notebook 08.
    track_gate_probability : float
        Mode: slam with clones. A track whose null-space residual exceeds this chi-square quantile
        (``4 n - 3`` dof) is refused whole.
    max_slam_landmarks : int
        Mode: slam with clones. Most landmarks in the state; longer tracks beyond them are used in
        window-long pieces.
    """

    # 1.5 px: a slightly conservative NIS on the course drives, as it should be with drifting tracks.
    sigma_pixel: float = setting(1.5, float, 1e-3, 100.0, unit="px",
                                 why="no tracker locates a feature to a thousandth of a pixel; 100 px is no location")
    # "auto": a fixed noise fits no drive (the KITTI drives' velocities are nearly clean, the 2020
    # release's carry about 0.5 m/s and 0.05 rad/s), and a filter told the wrong level trusts far
    # landmarks over an accurate IMU, or an IMU over the camera.
    sigma_linear_velocity: object = setting(AUTO, float, 0.0, 50.0, words=(AUTO,), per_axis=True, unit="m/s",
                                            why="0 trusts the velocities; 50 m/s (180 km/h) of noise is no measurement")
    sigma_angular_velocity: object = setting(AUTO, float, 0.0, 5.0, words=(AUTO,), per_axis=True, unit="rad/s",
                                             why="5 rad/s of noise is almost a turn per second")
    landmark_prior_inflation: float = setting(1.0, float, 0.0, 1000.0,
                                              why="a factor on the triangulation's standard deviation")
    landmark_prior_sigma: float = setting(0.1, float, 0.0, 1e4, low_open=True, unit="m",
                                          why="a prior wider than 10 km says nothing")
    initial_pose_sigma: float = setting(0.0, float, 0.0, 1e3, unit="m",
                                        why="world is the first IMU frame, so 0 is exact")
    # Gating stays on (and reinit_gated_landmarks): track reprojection errors are heavy-tailed, and
    # the gated share grows with a track's age (tracker drift).
    gate_probability: float = setting(0.999, float, 0.0, 1.0, low_open=True,
                                      why="a probability; 1 disables gating")
    # 3 px (110 m deep on dataset 03's rig): a landmark triangulated from a smaller disparity is a
    # poor Gaussian in x, y, z that makes joint SLAM overconfident.
    min_init_disparity: float = setting(3.0, float, 0.0, 1000.0, unit="px",
                                        why="no image is wider than the range")
    # "auto": a lag other than 0 only when it beats lag 0 with 95% confidence (a block bootstrap).
    imu_lag: object = setting(AUTO, int, -MAX_IMU_LAG, MAX_IMU_LAG, words=(AUTO,),
                              why="which velocity sample near the step drives it; a larger shift is a broken file")
    extrinsic_correction: str = setting("auto", str, words=(AUTO, *CORRECTIONS),
                                        why="'auto' applies what the data show; see visla_edu.diagnostics.CORRECTIONS")
    landmark_cross_covariance: bool = setting(True, bool)
    mapping_motion_noise: bool = setting(True, bool)
    vio_refine_landmarks: bool = setting(False, bool)
    skip_repeated_frames: bool = setting(True, bool)
    skip_stale_copies: bool = setting(True, bool)
    landmark_stride: int = setting(1, int, 1, 1_000_000, why="1 uses every landmark")
    # "invariant": consistent where the right perturbation becomes overconfident (notebook 10).
    slam_error: str = setting("invariant", str, words=("invariant", "right"),
                              why="the invariant EKF, or the right perturbation notebooks 06-08 derive")
    reinit_gated_landmarks: bool = setting(True, bool)
    pixel_noise_inflation: object = setting(AUTO, float, 1.0, MAX_INFLATION, words=(AUTO,),
                                            why="a factor of at least 1 on sigma_pixel")
    msckf_window: object = setting(AUTO, int, 0, 200, words=(AUTO,),
                                   why="0 is the classic joint EKF; a clone is a 6x6 block per frame")
    track_gate_probability: float = setting(0.95, float, 0.0, 1.0, low_open=True,
                                            why="a probability; 1 disables the whole-track gate")
    max_slam_landmarks: int = setting(40, int, 0, 100_000, why="0 keeps every track in the window")

    def __post_init__(self):
        check_settings(self)

    @property
    def pixel_variance(self):
        """``(pixel_noise_inflation sigma_pixel)^2``, the filters' pixel noise variance (resolved configs only)."""
        inflation = 1.0 if self.pixel_noise_inflation == AUTO else self.pixel_noise_inflation
        return (inflation * self.sigma_pixel) ** 2

    @property
    def gate_threshold(self):
        """Chi-square (4 dof) quantile at ``gate_probability``; ``inf`` when gating is off."""
        if self.gate_probability >= 1:
            return np.inf
        return float(chi2_quantile(self.gate_probability, 4))

    @property
    def resolved(self):
        """True when no setting of :data:`AUTO_FIELDS` nor of :data:`DRIVE_FIELDS` is ``"auto"``."""
        return not any(isinstance(getattr(self, name), str) for name in AUTO_FIELDS + DRIVE_FIELDS)

    def resolve(self, calibration, focal_length=None, time_step=None):
        """A copy with every ``"auto"`` of :data:`AUTO_FIELDS` and :data:`DRIVE_FIELDS` replaced by the drive's value.

        ``calibration`` (or None when no ``"auto"`` needs it) has the attributes of
        :data:`AUTO_FIELDS` (per-axis sigmas (3,), an int lag) and ``track_correlation``, e.g. a
        :class:`visla_edu.diagnostics.Calibration`; only those an ``"auto"`` needs are read.
        ``focal_length`` (``fsu``, px) and ``time_step`` (a typical step, s) serve
        :data:`DRIVE_FIELDS`. Returns a new config with :attr:`resolved` True (``self`` unchanged;
        ``extrinsic_correction`` as it was).

        Raises ``ValueError`` for a calibration value outside the setting's declared range,
        ``AttributeError`` if ``calibration`` lacks a needed attribute, ``TypeError`` if a
        :data:`DRIVE_FIELDS` setting is ``"auto"`` and ``focal_length`` or ``time_step`` is missing.
        """
        values = {name: getattr(calibration, name) for name in AUTO_FIELDS if getattr(self, name) == AUTO}
        config = replace(self, **values)
        auto = [name for name in DRIVE_FIELDS if getattr(config, name) == AUTO]
        if not auto:
            return config
        if focal_length is None or time_step is None:
            raise TypeError(f"FilterConfig.resolve: {auto[0]}='auto' needs the drive's focal_length "
                            "and time_step (visla_edu.run.resolve_config passes them)")
        drive = (config.sigma_pixel, focal_length, config.sigma_angular_velocity, time_step)
        if config.msckf_window == AUTO:
            config = replace(config, msckf_window=msckf_window(*drive))
        if config.pixel_noise_inflation == AUTO:
            rho = calibration.track_correlation if gyro_ratio(*drive) >= GYRO_REGIME_RATIO else 0.0
            config = replace(config, pixel_noise_inflation=pixel_noise_inflation(*drive, track_correlation=rho))
        return config

    def to_dict(self):
        """Plain dict of the settings (for saving with results)."""
        return asdict(self)

