"""Strict settings (visla_edu.settings): one declaration per config field checks and parses."""

import dataclasses

import numpy as np
import pytest

from visla_edu import settings
from visla_edu.filters import FilterConfig
from visla_edu.settings import check_settings, parse_setting, parse_settings, setting, specs


@dataclasses.dataclass
class _Example:
    """A config with the declarations FilterConfig does not use yet: a word and an optional value."""

    lag: int = setting("auto", int, -2, 2, words=("auto",))
    threads: int = setting(None, int, 1, 64, optional=True)
    mode: str = setting("fast", str, words=("fast", "exact"))

    def __post_init__(self):
        check_settings(self)


@pytest.mark.parametrize("text, value", [("true", True), ("TRUE", True), ("Yes", True), ("1", True),
                                         ("false", False), ("no", False), ("0", False)])
def test_booleans_take_only_the_documented_words(text, value):
    assert parse_setting(FilterConfig, f"skip_repeated_frames={text}") == ("skip_repeated_frames", value)


@pytest.mark.parametrize("text", ["Treu", "", "2", "on", "y"])
def test_a_boolean_typo_is_an_error(text):
    with pytest.raises(ValueError, match=r"skip_repeated_frames needs a bool \(true or false"):
        parse_setting(FilterConfig, f"skip_repeated_frames={text}")


@pytest.mark.parametrize("pair, value", [("imu_lag=+2", 2), ("imu_lag=-2", -2), ("landmark_stride= 20 ", 20),
                                         ("sigma_pixel=1e-3", 1e-3), ("gate_probability=1", 1.0)])
def test_values_in_range_parse(pair, value):
    name, parsed = parse_setting(FilterConfig, pair)
    assert parsed == value and type(parsed) is type(value)
    FilterConfig(**{name: parsed})


@pytest.mark.parametrize("pair, message", [
    ("imu_lag=5000", r"imu_lag must be an integer in \[-2, 2\] or 'auto' \(which velocity sample.*got 5000"),
    ("imu_lag=2.0", r"imu_lag needs an int"),
    ("landmark_stride=1_0", r"landmark_stride needs an int"),
    ("sigma_pixel=inf", r"sigma_pixel needs a float"),
    ("sigma_pixel=1e400", r"sigma_pixel needs a float"),
    ("sigma_linear_velocity=51", r"sigma_linear_velocity must be a number in \[0, 50\] m/s"),
    ("landmark_prior_sigma=0", r"landmark_prior_sigma must be a number in \(0, 10000\] m"),
])
def test_values_out_of_range_name_the_range(pair, message):
    with pytest.raises(ValueError, match=message):
        parse_setting(FilterConfig, pair)


def test_the_library_checks_with_the_same_declaration():
    with pytest.raises(ValueError, match=r"FilterConfig.imu_lag must be an integer in \[-2, 2\]"):
        FilterConfig(imu_lag=5000)
    with pytest.raises(ValueError, match=r"FilterConfig.sigma_angular_velocity must be a number in \[0, 5\] rad/s"):
        FilterConfig(sigma_angular_velocity=1e300)
    with pytest.raises(ValueError, match=r"FilterConfig.landmark_cross_covariance must be true or false"):
        FilterConfig(landmark_cross_covariance=1)
    with pytest.raises(ValueError, match=r"FilterConfig.landmark_stride must be an integer"):
        FilterConfig(landmark_stride=True)
    config = FilterConfig(landmark_stride=np.int64(4), imu_lag=1.0, mapping_motion_noise=np.bool_(False))
    assert (type(config.landmark_stride), type(config.imu_lag), type(config.mapping_motion_noise)) == (int, int, bool)


def test_words_and_none_when_declared():
    assert _Example().lag == "auto" and _Example(lag=-1).lag == -1
    assert parse_settings(_Example, ["lag=AUTO", "threads=none", "mode=exact"]) == {
        "lag": "auto", "threads": None, "mode": "exact"}
    assert parse_setting(_Example, "threads=8") == ("threads", 8)
    with pytest.raises(ValueError, match=r"lag must be an integer in \[-2, 2\] or 'auto', got 3"):
        parse_setting(_Example, "lag=3")
    with pytest.raises(ValueError, match=r"mode must be one of 'fast', 'exact'"):
        _Example(mode="slow")
    with pytest.raises(ValueError, match=r"sigma_pixel needs a float"):
        parse_setting(FilterConfig, "sigma_pixel=none")  # not optional
    assert specs(_Example)["threads"].describe() == "an integer in [1, 64] or none"


def test_names_and_repetition():
    with pytest.raises(ValueError, match=r"unknown setting 'sigma'; settings are sigma_pixel, sigma_linear_velocity"):
        parse_setting(FilterConfig, "sigma=1")
    with pytest.raises(ValueError, match=r"expected NAME=VALUE"):
        parse_setting(FilterConfig, "sigma_pixel")
    with pytest.raises(ValueError, match=r"sigma_pixel is set twice"):
        parse_settings(FilterConfig, ["sigma_pixel=1", "sigma_pixel=2"])


def test_every_field_declares_what_it_accepts():
    for field in dataclasses.fields(FilterConfig):
        spec = field.metadata[settings.SPEC]
        assert spec.kind in (bool, int, float, str), field.name
        spec.check(field.name, field.default)  # the defaults are valid
        if spec.kind in (int, float):
            assert spec.low is not None and spec.high is not None and spec.why, field.name


def test_the_smoothers_settings_are_declared_the_same_way():
    """SmootherConfig: every field has a spec with a valid default; its own settings and the ones
    it takes from the filter (FROM_FILTER) are all its fields, each once."""
    from visla_edu import smoother

    declared = specs(smoother.SmootherConfig)
    assert list(declared) == [field.name for field in dataclasses.fields(smoother.SmootherConfig)]
    for name, spec in declared.items():
        assert spec.kind in (bool, int, float, str) and spec.default == getattr(smoother.SmootherConfig(), name), name
        spec.check(name, spec.default)
    assert sorted([*smoother.OWN_SETTINGS, *smoother.FROM_FILTER]) == sorted(declared)
    assert set(smoother.FROM_FILTER.values()) <= set(specs(FilterConfig))
    with pytest.raises(ValueError, match=r"SmootherConfig.pose_covariance must be true or false"):
        smoother.SmootherConfig(pose_covariance=1)  # was taken as is


def test_messages_name_the_config_class():
    with pytest.raises(ValueError, match=r"^_Example.mode must be one of 'fast', 'exact'"):
        _Example(mode="slow")
    with pytest.raises(ValueError, match=r"^FilterConfig.extrinsic_correction must be one of 'auto', 'none', 'flip_yz'"):
        FilterConfig(extrinsic_correction="flip")  # refused when made, not when the camera is resolved
    assert parse_setting(FilterConfig, "extrinsic_correction=FLIP_YZ") == ("extrinsic_correction", "flip_yz")


@pytest.mark.parametrize("value, text", [(True, "true"), (None, "none"), (1_000_000, "1000000"), (1e-6, "1e-06"),
                                         (0.999, "0.999"), ("auto", "auto"), ((0.1, 0.02, 0.02), "0.1,0.02,0.02")])
def test_format_value_is_what_name_value_would_set(value, text):
    assert settings.format_value(value) == text
    if not isinstance(value, str) and value is not None:
        spec = settings.SettingSpec(type(value[0] if isinstance(value, tuple) else value), per_axis=True)
        assert spec.parse("x", text) == value
