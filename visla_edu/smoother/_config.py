"""Settings of the smoothers, :class:`SmootherConfig`, declared like the filters' (:mod:`visla_edu.settings`)."""

from dataclasses import asdict, dataclass, fields

import numpy as np

from visla_edu.filters import MAX_IMU_LAG
from visla_edu.settings import check_settings, setting

__all__ = ["SmootherConfig", "LOSSES", "WINDOW_MODES", "STARTS", "FROM_FILTER", "OWN_SETTINGS", "FILTER_SETTINGS", "BATCH_ONLY",
           "WINDOW_ONLY", "check_own_settings", "as_smoother_config"]

#: Robust losses on the whitened reprojection error (``"none"``: plain least squares).
LOSSES = ("cauchy", "huber", "none")
#: What the sliding window does with the states that leave it.
WINDOW_MODES = ("fix", "marginalize")
#: The settings :meth:`SmootherConfig.from_filter_config` takes from the filter's (the shared
#: model): smoother setting -> :class:`~visla_edu.filters.FilterConfig` setting; ``sigma_pixel``
#: is multiplied by the filter's ``pixel_noise_inflation``.
FROM_FILTER = {"sigma_pixel": "sigma_pixel", "sigma_linear_velocity": "sigma_linear_velocity",
               "sigma_angular_velocity": "sigma_angular_velocity", "imu_lag": "imu_lag",
               "min_disparity": "min_init_disparity", "skip_repeated_frames": "skip_repeated_frames",
               "skip_stale_copies": "skip_stale_copies"}
#: The filter settings the smoothers read; the sliding window uses no other filter setting but
#: ``extrinsic_correction``.
FILTER_SETTINGS = tuple(FROM_FILTER.values()) + ("pixel_noise_inflation",)
#: Own settings only the batch smoother reads, and only the sliding window (the other ignores them).
BATCH_ONLY = ("max_iterations", "rejection_rounds", "landmark_covariance", "start")
#: Starts of the batch smoother (``visla-edu run --mode smooth``, :func:`visla_edu.run.run_smoother`).
STARTS = ("slam", "best")
WINDOW_ONLY = ("window_size", "window_iterations", "window_mode")


@dataclass
class SmootherConfig:
    """Noise model, robust loss, stopping rules and window settings of the smoothers.

    The noise settings mean what they mean in :class:`visla_edu.filters.FilterConfig`; :meth:`from_filter_config`
    takes a filter's resolved model (:data:`FROM_FILTER`), as ``visla-edu run --mode smooth`` does. Defaults, units
    and ranges: the field declarations (and ``visla-edu run --help``).

    Attributes
    ----------
    sigma_pixel, sigma_linear_velocity, sigma_angular_velocity, imu_lag, skip_repeated_frames, skip_stale_copies
        As the filters': ``V = sigma_pixel^2 I4``, ``W_t = tau_t^2 diag(sigma_v^2, sigma_w^2)`` (a velocity sigma may
        be per axis), the step ``t -> t+1`` uses ``u[t + imu_lag]``.
    loss, loss_scale
        :func:`robust_loss` of the squared whitened reprojection error, and its ``k`` in whitened error norms (4 dof:
        inliers are below 3.1 with 95% probability).
    max_iterations
        Levenberg-Marquardt iterations of the final round (accepted or not); a rough round before a rejection gets
        half. Where the data hardly constrain the estimate the objective's own minimum lies away from the truth and
        the cap keeps the result near its start (``python benchmarks/bench_smoother.py --cases objective``).
    function_tolerance, step_tolerance, initial_damping
        Stop when an accepted step lowers the cost by less than this fraction, or when the step norm is below
        ``step_tolerance * (1 + |state|)`` (poses' and landmarks' positions, m); the first ``lambda`` of
        ``H + lambda diag(H)``.
    rejection_probability, rejection_rounds
        Rounds of "solve roughly, reject" before the final solve; each drops the observations beyond the
        chi-square (4 dof) quantile of ``rejection_probability`` (1.0: none).
    min_observations, min_depth, min_disparity
        Landmarks with fewer usable observations, or predicted closer than ``min_depth`` (camera z) in any
        observation, are dropped. Landmarks never seen with a disparity ``uL - uR`` of at least ``min_disparity`` are
        left out, and one whose largest predicted disparity falls below ``min_disparity / 2`` is dropped after a round:
        beyond ``fsu b / min_disparity`` Gauss-Newton sends xyz landmarks off along their viewing rays, which stalls
        Levenberg-Marquardt.
    window_size, window_iterations, window_mode
        Frames N in the sliding window, Gauss-Newton iterations per new frame, what happens to a pose leaving the
        window (the modes and the evidence behind the defaults: :mod:`visla_edu.smoother._window`).
    start : {"slam", "best"}
        Where the batch smoother starts (:func:`visla_edu.run.run_smoother`): the joint EKF's estimate, or the lowest
        objective (:func:`start_cost`) of dead reckoning, VIO and the joint EKF; all three costs are reported.
    """

    sigma_pixel: float = setting(1.5, float, 0.0, low_open=True, unit="px",
                                 why="the reprojection factors are weighted by 1 / sigma_pixel^2")
    sigma_linear_velocity: object = setting(0.5, float, 0.0, low_open=True, per_axis=True, unit="m/s",
                                            why="the motion factors are weighted by 1 / sigma^2")
    sigma_angular_velocity: object = setting(0.05, float, 0.0, low_open=True, per_axis=True, unit="rad/s",
                                             why="the motion factors are weighted by 1 / sigma^2")
    imu_lag: int = setting(0, int, -MAX_IMU_LAG, MAX_IMU_LAG, why="the filter's range, visla_edu.filters.MAX_IMU_LAG")
    loss: str = setting("cauchy", str, words=LOSSES)
    loss_scale: float = setting(3.0, float, 0.0, low_open=True, why="in units of the whitened error")
    max_iterations: int = setting(10, int, 1)
    function_tolerance: float = setting(1e-6, float, 0.0, low_open=True, why="a relative decrease of the cost")
    step_tolerance: float = setting(1e-9, float, 0.0, low_open=True, why="relative to the state's size")
    initial_damping: float = setting(1e-4, float, 0.0, low_open=True,
                                     why="the damping is scaled up and down from it, so 0 would stay 0")
    rejection_probability: float = setting(0.999, float, 0.0, 1.0, low_open=True, why="a probability")
    rejection_rounds: int = setting(1, int, 0)
    min_observations: int = setting(2, int, 2)
    min_depth: float = setting(0.5, float, 0.0, unit="m")
    min_disparity: float = setting(3.0, float, 0.0, unit="px")
    skip_repeated_frames: bool = setting(True, bool)
    skip_stale_copies: bool = setting(True, bool)
    pose_covariance: bool = setting(True, bool)
    landmark_covariance: bool = setting(True, bool)
    window_size: int = setting(20, int, 2, why="two frames hold one motion step")
    window_iterations: int = setting(1, int, 1)
    window_mode: str = setting("fix", str, words=WINDOW_MODES)
    start: str = setting("slam", str, words=STARTS)

    def __post_init__(self):
        check_settings(self)

    @property
    def velocity_sigmas(self):
        """``[sigma_v (3); sigma_w (3)]`` per body axis, shape (6,)."""
        return np.concatenate([np.broadcast_to(self.sigma_linear_velocity, (3,)),
                               np.broadcast_to(self.sigma_angular_velocity, (3,))]).astype(float)

    @classmethod
    def from_filter_config(cls, filter_config, **overrides):
        """A filter's resolved model (:data:`FROM_FILTER`) with ``overrides``; unresolved settings are a ValueError."""
        if not filter_config.resolved:
            raise ValueError("SmootherConfig.from_filter_config needs resolved settings "
                             "(visla_edu.run.resolve_config(dataset, config))")
        model = {name: getattr(filter_config, source) for name, source in FROM_FILTER.items()}
        model["sigma_pixel"] *= filter_config.pixel_noise_inflation  # the filters' camera noise (resolved)
        return cls(**{**model, **overrides})

    def to_dict(self):
        """Plain dict of the settings (for saving with results)."""
        return asdict(self)


def as_smoother_config(config, caller):
    """``config``; defaults for None; else a TypeError naming ``caller`` (how to convert a ``FilterConfig``)."""
    if config is None:
        return SmootherConfig()
    if isinstance(config, SmootherConfig):
        return config
    hint = ("smoother.SmootherConfig.from_filter_config(run.resolve_config(dataset, config)) gives the smoother "
            "the filter's model") if type(config).__name__ == "FilterConfig" else "e.g. SmootherConfig(window_size=10)"
    raise TypeError(f"{caller}: config must be a SmootherConfig, got {type(config).__name__}; {hint}")


#: The settings only the smoothers have (``visla-edu run --smoother-set``); the others come from
#: the filter's settings (:data:`FROM_FILTER`).
OWN_SETTINGS = tuple(f.name for f in fields(SmootherConfig) if f.name not in FROM_FILTER)


def check_own_settings(mode, names):
    """Refuse (ValueError) names not in :data:`OWN_SETTINGS` or that ``mode`` ignores (:data:`WINDOW_ONLY` in
    ``"smooth"``, :data:`BATCH_ONLY` in ``"window"``).
    """
    names = list(names)
    unknown = sorted(set(names) - set(OWN_SETTINGS))
    if unknown:
        raise ValueError(f"smoother_settings: {unknown} are not the smoother's own settings; they are "
                         f"{', '.join(OWN_SETTINGS)} (noise and lag come from the filter's config)")
    ignored, other = (WINDOW_ONLY, "window") if mode == "smooth" else (BATCH_ONLY, "smooth")
    for name in names:
        if name in ignored:
            raise ValueError(f"smoother setting {name}: mode {mode} does not use it (it is mode {other}'s)")
