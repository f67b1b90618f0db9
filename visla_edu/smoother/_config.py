"""Settings of the batch and sliding-window smoothers: :class:`SmootherConfig`."""

from dataclasses import asdict, dataclass

import numpy as np

from visla_edu.filters._config import MAX_IMU_LAG

__all__ = ["SmootherConfig", "LOSSES", "WINDOW_MODES", "OWN_SETTINGS", "FILTER_SETTINGS", "BATCH_ONLY", "WINDOW_ONLY",
           "check_mode_settings", "as_smoother_config", "parse_setting",
           "settings_help"]

#: Robust losses on the whitened reprojection error (``"none"``: plain least squares).
LOSSES = ("cauchy", "huber", "none")
#: What the sliding window does with the states that leave it.
WINDOW_MODES = ("fix", "marginalize")
#: The filter settings :meth:`SmootherConfig.from_filter_config` reads (the shared model); the
#: sliding window uses no other filter setting but ``extrinsic_correction``.
FILTER_SETTINGS = ("sigma_pixel", "sigma_linear_velocity", "sigma_angular_velocity", "imu_lag", "min_init_disparity",
                   "skip_repeated_frames")
#: The settings only the smoothers have (``visla-edu run --smoother-set``); the others (noise,
#: lag, far points, repeated frames) come from the filter's settings
#: (:meth:`SmootherConfig.from_filter_config`).
OWN_SETTINGS = ("loss", "loss_scale", "max_iterations", "function_tolerance", "step_tolerance", "initial_damping",
                "rejection_probability", "rejection_rounds", "min_observations", "min_depth",
                "pose_covariance", "landmark_covariance", "window_size", "window_iterations", "window_mode")
#: Own settings only the batch smoother reads, and only the sliding window (the other ignores them).
BATCH_ONLY = ("max_iterations", "rejection_rounds", "landmark_covariance")
WINDOW_ONLY = ("window_size", "window_iterations", "window_mode")


@dataclass
class SmootherConfig:
    """Noise model, robust loss, stopping rules and window settings of the smoothers.

    The noise settings mean what they mean in :class:`visla_edu.filters.FilterConfig`. Its
    velocity noise and lag default to ``"auto"`` (measured from the data); here they are the
    course's fixed 0.5 m/s, 0.05 rad/s and lag 0. :meth:`from_filter_config` takes a filter's
    resolved settings, which is how ``visla-edu run --mode smooth`` gives both the same model.

    Attributes
    ----------
    sigma_pixel : float
        Standard deviation of each stereo pixel coordinate (px): ``V = sigma_pixel^2 I4``.
    sigma_linear_velocity, sigma_angular_velocity : float or (float, float, float)
        Noise on each velocity sample (m/s, rad/s), one value or one per body axis:
        ``W_t = tau_t^2 diag(sigma_v^2, sigma_w^2)`` (:func:`visla_edu.motion.motion_noise`).
        :meth:`from_filter_config` takes the filter's values, measured from the data when the
        filter's are ``"auto"``.
    imu_lag : int
        The step ``t -> t+1`` uses the twist ``u[t + imu_lag]``, in ``-2 .. 2`` as the filter's
        (:data:`visla_edu.filters.MAX_IMU_LAG`).
    loss : {"cauchy", "huber", "none"}
        Robust loss ``rho(s)`` of the squared whitened reprojection error ``s = |r|^2 / sigma^2``:
        Cauchy ``k^2 log(1 + s / k^2)``, Huber ``s`` up to ``k^2`` then ``2 k sqrt(s) - k^2``.
    loss_scale : float
        ``k``, in units of the whitened error norm ``sqrt(s)`` (4 dof: inliers are below 3.1
        with 95% probability).
    max_iterations : int
        Levenberg-Marquardt iterations of the final round (accepted or not); a rough round
        before a rejection gets half. On drives with few landmarks and short tracks (``0020``)
        the objective's own minimum lies away from the truth, from the EKF's start and from
        the ground truth alike, and more iterations move the estimate towards it: the cap keeps
        the result near its start in directions the data hardly constrain. On the simulated
        drives, whose model is exact, the final round converges within it; on 03 and ``0020`` the
        cost keeps falling slowly past it. ``python benchmarks/bench_smoother.py --cases
        objective`` prints the ATE per iteration budget.
    function_tolerance : float
        Stop when an accepted step lowers the cost by less than this fraction.
    step_tolerance : float
        Stop when the step norm is below ``step_tolerance * (1 + |state|)`` (state: the
        pose translations and landmark positions, in metres).
    initial_damping : float
        First Levenberg-Marquardt damping ``lambda`` (``H + lambda diag(H)``).
    rejection_probability : float
        After each round, observations whose squared whitened error exceeds the chi-square
        (4 dof) quantile at this probability are dropped (1.0 disables rejection).
    rejection_rounds : int
        Rounds of "solve roughly, reject" before the final solve (0: solve once, reject
        nothing).
    min_observations : int
        Landmarks with fewer usable observations are dropped from the problem.
    min_depth : float
        Landmarks predicted closer than this (m, camera z) in any observation are dropped.
    min_disparity : float
        Landmarks never seen with at least this disparity ``uL - uR`` (px) are left out, and
        an estimate that drifts beyond twice that range (largest predicted disparity below
        ``min_disparity / 2``) is dropped after a round. Their depth, beyond
        ``fsu b / min_disparity``, is so poorly observed that Gauss-Newton on xyz landmarks
        sends them off along their viewing rays (on dataset 03, landmarks at 300 m ran to
        minus a million metres in six iterations), which stalls Levenberg-Marquardt. The same
        3 px as :attr:`visla_edu.filters.FilterConfig.min_init_disparity`.
    skip_repeated_frames : bool
        Ignore the observations of frames that exactly repeat the previous frame's.
    pose_covariance, landmark_covariance : bool
        Compute the marginal covariances at the solution.
    window_size : int
        Frames N in the sliding window (20: see :mod:`visla_edu.smoother._window` for the
        measurements behind the window defaults).
    window_iterations : int
        Gauss-Newton iterations per new frame in the sliding window.
    window_mode : {"fix", "marginalize"}
        What happens to a pose leaving the window, see :func:`smooth_window`.
    """

    sigma_pixel: float = 1.5
    sigma_linear_velocity: float = 0.5
    sigma_angular_velocity: float = 0.05
    imu_lag: int = 0
    loss: str = "cauchy"
    loss_scale: float = 3.0
    max_iterations: int = 10
    function_tolerance: float = 1e-6
    step_tolerance: float = 1e-9
    initial_damping: float = 1e-4
    rejection_probability: float = 0.999
    rejection_rounds: int = 1
    min_observations: int = 2
    min_depth: float = 0.5
    min_disparity: float = 3.0
    skip_repeated_frames: bool = True
    pose_covariance: bool = True
    landmark_covariance: bool = True
    window_size: int = 20
    window_iterations: int = 1
    window_mode: str = "fix"

    def __post_init__(self):
        for name in ("sigma_pixel", "loss_scale", "function_tolerance", "step_tolerance", "initial_damping"):
            value = getattr(self, name)
            if not _is_number(value) or not np.isfinite(value) or value <= 0:
                raise ValueError(f"SmootherConfig.{name} must be a positive number, got {value!r}")
        for name in ("sigma_linear_velocity", "sigma_angular_velocity"):
            setattr(self, name, _positive_per_axis(name, getattr(self, name)))
        for name, unit in (("min_depth", "m"), ("min_disparity", "px")):
            value = getattr(self, name)
            if not _is_number(value) or not 0 <= value < np.inf:
                raise ValueError(f"SmootherConfig.{name} must be a number >= 0 ({unit}), got {value!r}")
        if not _is_number(self.rejection_probability) or not 0 < self.rejection_probability <= 1:
            raise ValueError(f"SmootherConfig.rejection_probability must be in (0, 1], got "
                             f"{self.rejection_probability!r}")
        _check_int("imu_lag", self.imu_lag, -MAX_IMU_LAG, MAX_IMU_LAG)
        for name, low in (("max_iterations", 1), ("rejection_rounds", 0), ("min_observations", 2),
                          ("window_size", 2), ("window_iterations", 1)):
            _check_int(name, getattr(self, name), low)
        if self.loss not in LOSSES:
            raise ValueError(f"SmootherConfig.loss must be one of {LOSSES}, got {self.loss!r}")
        if self.window_mode not in WINDOW_MODES:
            raise ValueError(f"SmootherConfig.window_mode must be one of {WINDOW_MODES}, got {self.window_mode!r}")

    @property
    def velocity_sigmas(self):
        """``[sigma_v (3); sigma_w (3)]`` per body axis, shape (6,)."""
        return np.concatenate([np.broadcast_to(self.sigma_linear_velocity, (3,)),
                               np.broadcast_to(self.sigma_angular_velocity, (3,))]).astype(float)

    @classmethod
    def from_filter_config(cls, filter_config, **overrides):
        """The smoother's model from a filter's resolved settings (noise, lag, far points).

        Parameters
        ----------
        filter_config : visla_edu.filters.FilterConfig
            Resolved (no ``"auto"`` noise or lag: :func:`visla_edu.run.resolve_config`).
        **overrides
            Further :class:`SmootherConfig` fields.

        Returns
        -------
        SmootherConfig

        Raises
        ------
        ValueError
            ``filter_config`` still has ``"auto"`` settings.
        """
        if not filter_config.resolved:
            raise ValueError("SmootherConfig.from_filter_config needs resolved settings "
                             "(visla_edu.run.resolve_config(dataset, config))")
        model = dict(sigma_pixel=filter_config.sigma_pixel, sigma_linear_velocity=filter_config.sigma_linear_velocity,
                     sigma_angular_velocity=filter_config.sigma_angular_velocity, imu_lag=filter_config.imu_lag,
                     min_disparity=filter_config.min_init_disparity,
                     skip_repeated_frames=filter_config.skip_repeated_frames)
        return cls(**{**model, **overrides})

    def to_dict(self):
        """Plain dict of the settings (for saving with results)."""
        return asdict(self)


def as_smoother_config(config, caller):
    """``config`` itself, :class:`SmootherConfig` defaults for None, or a TypeError.

    Parameters
    ----------
    config : SmootherConfig or None
    caller : str
        Starts the error message (the public function's name).

    Returns
    -------
    SmootherConfig

    Raises
    ------
    TypeError
        Anything else, e.g. the filters' ``FilterConfig`` (the message says how to convert it)
        or a dict of settings.
    """
    if config is None:
        return SmootherConfig()
    if isinstance(config, SmootherConfig):
        return config
    hint = ("smoother.SmootherConfig.from_filter_config(run.resolve_config(dataset, config)) gives the smoother "
            "the filter's model") if type(config).__name__ == "FilterConfig" else "e.g. SmootherConfig(window_size=10)"
    raise TypeError(f"{caller}: config must be a SmootherConfig, got {type(config).__name__}; {hint}")


def check_mode_settings(mode, names):
    """Refuse own settings that smoother ``mode`` would ignore (a window setting with the batch, or back).

    Parameters
    ----------
    mode : {"smooth", "window"}
        The batch smoother or the sliding window (:data:`visla_edu.codes.SMOOTHER_MODES`).
    names : iterable of str
        Names of :data:`OWN_SETTINGS` given for it.

    Raises
    ------
    ValueError
        A name in :data:`WINDOW_ONLY` for ``"smooth"`` or in :data:`BATCH_ONLY` for ``"window"``.
    """
    ignored, other = (WINDOW_ONLY, "window") if mode == "smooth" else (BATCH_ONLY, "smooth")
    for name in names:
        if name in ignored:
            raise ValueError(f"smoother setting {name}: mode {mode} does not use it (it is mode {other}'s)")


def parse_setting(pair):
    """``"NAME=VALUE"`` -> ``(name, value)`` for one of :data:`OWN_SETTINGS`, checked as a SmootherConfig would.

    The value is read by the type of the setting's default: an integer, a number, ``true`` /
    ``false`` (also ``1/0``, ``yes/no``, as ``--set``), or a word (lower case).

    Parameters
    ----------
    pair : str
        ``"NAME=VALUE"``, split at the first ``=``; spaces around either part are ignored.

    Returns
    -------
    name : str
    value : int, float, bool or str

    Raises
    ------
    ValueError
        No ``=``, a name that is not one of :data:`OWN_SETTINGS` (a filter setting gets a
        pointer to ``--set``), or a value that does not parse or that :class:`SmootherConfig`
        refuses.
    """
    name, sep, text = (part.strip() for part in pair.partition("="))
    if not sep or name not in OWN_SETTINGS:
        what = "expected NAME=VALUE" if not sep else f"{name!r} is not a smoother setting"
        if sep and name in SmootherConfig.__dataclass_fields__:
            what += " of its own (it comes from the filter's settings: use --set)"
        raise ValueError(f"{pair!r}: {what}; the smoother's settings are {', '.join(OWN_SETTINGS)}")
    value = _parse_like(name, text, SmootherConfig.__dataclass_fields__[name].default)
    SmootherConfig(**{name: value})  # the range checks, with their messages
    return name, value


def _parse_like(name, text, default):
    """``text`` read as the type of ``default`` (bool, int, float or str), or a ValueError naming ``name``."""
    words = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}  # as --set's
    try:
        if isinstance(default, bool):
            return words[text.lower()]
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
    except (KeyError, ValueError):
        kind = "true or false (also 1/0, yes/no)" if isinstance(default, bool) else "an integer" if isinstance(default, int) else "a number"
        raise ValueError(f"{name}={text!r}: expected {kind}") from None
    return text.lower()


def _is_number(value):
    """True for a real number (a bool is not one: ``True`` would silently mean 1)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _check_int(name, value, low, high=None):
    """Raise ValueError unless ``value`` is an integer (bools are not) in ``low .. high``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"SmootherConfig.{name} must be an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in {low} .. {high}"
        raise ValueError(f"SmootherConfig.{name} must be {bound}, got {value!r}")


def _positive_per_axis(name, value):
    """A velocity noise: a positive number or three (one per body axis), as a float or a tuple."""
    items = np.ravel(np.asarray(value, dtype=object))
    numbers = not isinstance(value, str) and all(_is_number(x) for x in items)  # True is no noise level
    sigma = np.asarray(value, dtype=float) if numbers else np.full(2, np.nan)
    if sigma.shape not in ((), (3,)) or not np.all(np.isfinite(sigma)) or np.any(sigma <= 0):
        raise ValueError(f"SmootherConfig.{name} must be a positive number or three of them (x, y, z), got {value!r}")
    return float(sigma) if sigma.ndim == 0 else tuple(float(x) for x in sigma)


def settings_help():
    """``visla-edu run --help``'s list: every ``--set`` and ``--smoother-set`` name with its default.

    Returns
    -------
    str
        The :class:`~visla_edu.filters.FilterConfig` settings, then the smoother's own
        (:data:`OWN_SETTINGS`), as ``name=default`` (:func:`visla_edu.filters._settings.defaults_text`).
    """
    from visla_edu.filters import FilterConfig, _settings

    return (f"--set NAME=VALUE, the settings and their defaults: {_settings.defaults_text(FilterConfig)}. "
            "--smoother-set NAME=VALUE (smooth, window; noise and lag come from --set), the settings and their "
            f"defaults: {_settings.defaults_text(SmootherConfig, OWN_SETTINGS)} ({', '.join(BATCH_ONLY)}: smooth "
            f"only; {', '.join(WINDOW_ONLY)}: window only). --mode window takes from --set only "
            f"{', '.join(FILTER_SETTINGS)} and extrinsic_correction.")
