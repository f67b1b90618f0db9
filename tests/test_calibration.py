"""Tests of visla_edu.diagnostics.calibrate: the decision from track-reprojection and
visual-odometry evidence, the noise model, the bootstrap, the report and the cache.

Simulated drives have the quirks of the course files (5% tracks of uniformly random pixels,
flipped axes in the reported extrinsic, velocities one sample late or early), so the truth is
known. The course files are data-gated (VISLA_EDU_DATA).
"""

import dataclasses
import json

import numpy as np
import pytest

from visla_edu import data, diagnostics, simulate
from visla_edu.diagnostics import CORRECTIONS, Calibration, calibrate
from visla_edu.diagnostics import _bootstrap, _calibration, _tracks

K_RIG, B_RIG, RIG = simulate.default_rig()
#: A drive with clean velocities (like the 2019 course release) and quick yaw changes (city
#: driving): the velocity sample that moves each frame stands out. On smooth drives with noisy
#: velocities the lag is "not enough evidence" (and lag 0 is kept), which is not wrong.
LIVELY = dict(linear_velocity_sigma=0.02, angular_velocity_sigma=0.002, yaw_rate_sigma=0.1, yaw_timescale=1.0)
#: The quirks: 5% gross outlier tracks of random pixels, the file's extrinsic has flipped axes.
QUIRKS = dict(outlier_share=0.05, outlier_kind="uniform", imu_T_cam=CORRECTIONS["flip_yz"] @ RIG,
              reported_imu_T_cam=RIG)


def _fresh(ds, **fields):
    return dataclasses.replace(ds, extra={}, **fields)


def _json(calibration):
    """The calibration through strict JSON and back."""
    return Calibration.from_dict(json.loads(json.dumps(calibration.to_dict(), allow_nan=False)))


# ----------------------------------------------------------------------------- decisions on simulated drives


@pytest.mark.parametrize("lag", [-1, 1])
def test_quirky_drive_is_calibrated(lag):
    ds = simulate.simulate_drive("small", 0, imu_lag=lag, **LIVELY, **QUIRKS)
    cal = calibrate(ds)
    assert cal.extrinsic_correction == "flip_yz", cal.report()
    assert cal.imu_lag == lag, cal.report()
    np.testing.assert_allclose(cal.imu_T_cam, CORRECTIONS["flip_yz"] @ RIG)
    assert cal.tracks.correction.verdict == "chosen" and cal.tracks.lag.verdict == "chosen"
    assert cal.vo.extrinsic_verdict["flip_yz"] == "agrees" and cal.vo.extrinsic_verdict["none"] == "disagrees"
    assert cal.vo.lag_best == lag
    # the white noise is the simulated one; the filter's sigma adds the hold part
    np.testing.assert_allclose(cal.white_noise, np.repeat([0.02, 0.002], 3), rtol=0.25)
    assert np.all(cal.sigma_linear_velocity >= cal.white_noise[:3])
    assert "the filter will use: extrinsic_correction 'flip_yz', imu_lag " + f"{lag:+d}" in cal.report()


def test_clean_drive_keeps_the_defaults():
    ds = simulate.simulate_drive("small", 1)
    cal = calibrate(ds)
    assert cal.extrinsic_correction == "none" and cal.imu_lag == 0, cal.report()
    np.testing.assert_array_equal(cal.imu_T_cam, ds.imu_T_cam)
    assert cal.tracks.correction.chosen == "none"
    assert cal.vo.gyro_bias["verdict"] == "consistent with zero"


@pytest.mark.parametrize("seed", [0, 1])
def test_sparse_drive_says_not_enough_evidence(seed):
    """About 100 landmarks over 6 s: every verdict is 'not enough evidence', nothing is NaN."""
    ds = simulate.simulate_drive("tiny", seed, num_landmarks=100, **QUIRKS)
    assert 90 <= ds.num_landmarks <= 100
    cal = calibrate(ds)
    assert cal.extrinsic_correction == "none" and cal.imu_lag == 0
    assert cal.tracks.correction.verdict.startswith("not enough evidence")
    assert cal.tracks.lag.verdict.startswith("not enough evidence")
    text = cal.report()
    assert "nan" not in text.lower() and "not enough evidence" in text
    assert _json(cal).report() == text


def test_drive_without_tracks_is_calibrated_without_nan():
    """A camera looking backwards sees nothing: no pairs at all, defaults, noise from the IMU."""
    ds = simulate.simulate_drive("tiny", 0, imu_T_cam=CORRECTIONS["flip_xy"] @ RIG)
    cal = calibrate(ds)
    assert cal.tracks.pairs == 0 and cal.vo.pairs == 0
    assert cal.extrinsic_correction == "none" and cal.imu_lag == 0
    assert all(score is None for scores in cal.tracks.scores.values() for score in scores)
    assert "nan" not in cal.report().lower()
    assert np.all(np.isfinite(cal.sigma_linear_velocity)) and np.all(cal.sigma_angular_velocity > 0)


def test_odometry_must_not_contradict_the_track_choice():
    choice = _tracks.TrackChoice("flip_yz", "flip_yz", "chosen", {})
    check = dataclasses.make_dataclass("Check", ["verdict"])
    name, why = _calibration._decide_correction(choice, check({"flip_yz": "disagrees"}))
    assert name == "none" and "disagrees" in why
    assert _calibration._decide_correction(choice, check({"flip_yz": "not enough evidence"}))[0] == "flip_yz"
    undecided = _tracks.TrackChoice(None, "flip_yz", "not enough evidence: none not worse", {})
    assert _calibration._decide_correction(undecided, check({"flip_yz": "agrees"}))[0] == "none"


def test_velocity_scale_and_gyro_bias_are_measured():
    ds = simulate.simulate_drive("small", 0, gyro_bias=(0.02, -0.01, 0.0))
    scaled = _fresh(ds, linear_velocity=ds.linear_velocity / 1.1)
    scale = diagnostics.velocity_scale(scaled, scaled.imu_T_cam)
    assert scale["scale"] == pytest.approx(1.1, abs=0.02) and scale["verdict"].startswith("differs from 1 by +")
    bias = diagnostics.gyro_bias(ds, ds.imu_T_cam)
    assert bias["verdict"] == "nonzero"
    assert np.all(np.abs(np.array(bias["bias"]) - [0.02, -0.01, 0.0]) < 4 * np.array(bias["stderr"]) + 2e-3), bias


def test_bad_input_names_the_problem():
    ds = simulate.simulate_drive("tiny", 0)
    v = ds.linear_velocity.copy()
    v[7, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite time stamp or velocity at frame 7"):
        calibrate(_fresh(ds, linear_velocity=v))
    z = ds.obs_z.copy()
    z[ds.frame_ptr[3], 0] = np.inf
    with pytest.raises(ValueError, match="non-finite pixels at frame 3"):
        calibrate(_fresh(ds, obs_z=z))
    with pytest.raises(ValueError, match=r"angular_velocity must have shape \(60, 3\)"):
        calibrate(_fresh(ds, angular_velocity=ds.angular_velocity[:, :2]))
    stamps = ds.time_stamps.copy()
    stamps[5] = stamps[4]
    with pytest.raises(ValueError, match="frame 5"):
        calibrate(_fresh(ds, time_stamps=stamps))
    with pytest.raises(TypeError, match="Dataset"):
        calibrate("03")


# ----------------------------------------------------------------------------- noise model


def test_white_and_hold_noise_of_known_signals():
    rng = np.random.default_rng(0)
    T, tau, white = 5000, 0.1, 0.05
    t = tau * np.arange(T)
    twists = np.zeros((T, 6))
    smooth = 10 + 2 * np.sin(0.5 * t)
    twists[:, 0] = smooth + white * rng.standard_normal(T)  # smooth + white
    twists[:, 3] = 0.3 * np.sin(0.5 * t)  # no white noise: only the hold part
    noise = diagnostics.imu_noise(twists)
    assert noise["white"][0] == pytest.approx(white, rel=0.05)
    # hold: half the rms change per step of the smooth part, seen through the white noise
    assert noise["hold"][0] == pytest.approx(np.sqrt(np.mean(np.diff(smooth) ** 2)) / 2, rel=0.15)
    assert noise["white"][3] < 1e-3
    assert noise["hold"][3] == pytest.approx(np.sqrt(np.mean(np.diff(twists[:, 3]) ** 2)) / 2, rel=0.02)
    # floors for the axes that never move
    np.testing.assert_array_equal(noise["sigma"][[1, 2]], diagnostics.MIN_SIGMA_LINEAR)
    np.testing.assert_array_equal(noise["sigma"][[4, 5]], diagnostics.MIN_SIGMA_ANGULAR)
    np.testing.assert_allclose(noise["sigma"][0], np.hypot(noise["white"][0], noise["hold"][0]))
    with pytest.raises(ValueError, match=r"\(T, 6\)"):
        diagnostics.imu_noise(np.zeros((10, 3)))


def test_one_glitched_sample_does_not_set_the_noise():
    """A single absurd velocity (past the loader's checks) leaves the measured noise as it was."""
    rng = np.random.default_rng(1)
    t = 0.1 * np.arange(2000)
    twists = np.zeros((2000, 6))
    twists[:, 0] = 10 + 2 * np.sin(0.5 * t) + 0.05 * rng.standard_normal(2000)
    clean = diagnostics.imu_noise(twists)["sigma"]
    twists[700, 0] = 1e200
    np.testing.assert_allclose(diagnostics.imu_noise(twists)["sigma"], clean, rtol=0.02)


# ----------------------------------------------------------------------------- bootstrap and track pairs


def test_resampled_medians_match_weighted_medians():
    rng = np.random.default_rng(1)
    values = rng.gamma(2.0, 2.0, 3000)
    cluster = rng.integers(0, 400, 3000)
    weights = _bootstrap.cluster_resamples(400, 50, seed=3)
    assert weights.shape == (400, 50) and np.all(weights.sum(axis=0) == 400)
    np.testing.assert_array_equal(weights, _bootstrap.cluster_resamples(400, 50, seed=3))
    medians = _bootstrap.resampled_medians(values, cluster, weights)
    order = np.argsort(values)
    for b in range(50):
        w = weights[cluster[order], b]
        exact = values[order][np.searchsorted(np.cumsum(w), 0.5 * w.sum())]
        assert medians[b] == pytest.approx(exact, abs=0.02)  # within a bin of about 0.5% of the pairs


def test_track_pairs_skip_stale_copies_and_far_anchors():
    ds = simulate.simulate_drive("tiny", 0, outlier_share=0.0)
    anchor, later, gap = diagnostics.track_pairs(ds)
    frames = ds.observation_frames()
    assert np.all(ds.obs_ids[anchor] == ds.obs_ids[later])
    np.testing.assert_array_equal(frames[later] - frames[anchor], gap)
    assert gap.min() >= 1 and gap.max() <= _tracks.MAX_GAP
    assert np.all(ds.obs_z[anchor, 0] - ds.obs_z[anchor, 2] > _tracks.MIN_DISPARITY)
    # a stale copy: the second observation of a landmark repeats the first bit for bit
    z = ds.obs_z.copy()
    landmark = ds.obs_ids[anchor[0]]
    mine = np.flatnonzero(ds.obs_ids == landmark)
    z[mine[1]] = z[mine[0]]
    _, later_stale, _ = diagnostics.track_pairs(_fresh(ds, obs_z=z))
    assert mine[1] in later and mine[1] not in later_stale


# ----------------------------------------------------------------------------- serialisation and cache


@pytest.fixture(scope="module")
def small_drive():
    return simulate.simulate_drive("small", 2, outlier_share=0.05, outlier_kind="uniform")


def test_to_dict_round_trip(small_drive):
    cal = calibrate(_fresh(small_drive), cache=False)
    back = _json(cal)
    assert back.report() == cal.report()
    np.testing.assert_array_equal(back.imu_T_cam, cal.imu_T_cam)
    assert back.tracks == cal.tracks and back.vo == cal.vo
    assert back.track_correlation == cal.track_correlation and "residual correlation along tracks" in cal.report()
    with pytest.raises(ValueError, match="sigma_linear_velocity"):
        Calibration.from_dict({**cal.to_dict(), "sigma_linear_velocity": [1.0, 2.0]})
    with pytest.raises(ValueError, match="malformed"):
        Calibration.from_dict({"extrinsic_correction": "none"})


def test_second_run_reuses_the_cache(small_drive):
    first = calibrate(_fresh(small_drive))
    path = diagnostics.cache_path(small_drive)
    assert first.source == "computed" and path.is_file()
    second = calibrate(_fresh(small_drive))
    assert second.source == f"cache {path}"
    assert second.to_dict() == first.to_dict()
    assert "reused from the cache" in second.report()
    assert calibrate(_fresh(small_drive), cache=False).source == "computed"


def test_cache_is_invalidated_by_a_new_version_or_changed_data(small_drive, monkeypatch):
    calibrate(_fresh(small_drive))
    old_path = diagnostics.cache_path(small_drive)
    version = _calibration.CALIBRATION_VERSION
    monkeypatch.setattr(_calibration, "CALIBRATION_VERSION", version + 1)
    assert diagnostics.cache_path(small_drive) != old_path
    assert calibrate(_fresh(small_drive)).source == "computed"
    monkeypatch.setattr(_calibration, "CALIBRATION_VERSION", version)
    z = small_drive.obs_z.copy()
    z[0, 0] += 0.5
    changed = _fresh(small_drive, obs_z=z)
    assert diagnostics.cache_path(changed) != old_path
    assert calibrate(changed).source == "computed"
    # an old-version file under the current name is recomputed, not trusted
    stored = json.loads(old_path.read_text())
    old_path.write_text(json.dumps({**stored, "version": stored["version"] - 1}))
    assert calibrate(_fresh(small_drive)).source == "computed"


@pytest.mark.parametrize("content", ["{not json", "[1, 2]", '{"version": 1, "calibration": {"imu_lag": 0}}', ""])
def test_corrupt_cache_file_is_recomputed(small_drive, content):
    path = diagnostics.cache_path(small_drive)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(content)
    cal = calibrate(_fresh(small_drive))
    assert cal.source == "computed"
    assert calibrate(_fresh(small_drive)).source == f"cache {path}"  # rewritten, readable again


def _edit(key, value, inner=None):
    def change(stored):
        (stored[inner] if inner else stored)[key] = value
    return change


@pytest.mark.parametrize("change", [
    _edit("imu_lag", 10**6), _edit("imu_lag", "x"), _edit("imu_lag", True), _edit("imu_lag", 1.5),
    _edit("sigma_linear_velocity", [0.0, 0.0, 0.0]), _edit("sigma_angular_velocity", [-1.0, 0.1, 0.1]),
    _edit("white_noise", [-1.0] * 6), _edit("reasons", None), _edit("reasons", {"imu_lag": 3}),
    _edit("outliers", "x"), _edit("outliers", {"epipolar": 2.0}), _edit("repeated_frames", [1e9]),
    _edit("repeated_frames", None), _edit("seconds", "x"), _edit("rotation_slope", None, inner="vo"),
    _edit("lag_residual", None, inner="vo"), _edit("track_correlation", 2.0), _edit("track_correlation", None),
    _edit("correlated_tracks", -1),
], ids=["lag-huge", "lag-text", "lag-bool", "lag-float", "sigma-zero", "sigma-negative", "white-negative",
        "reasons-none", "reason-number", "outliers-text", "outliers-partial", "repeated-float", "repeated-none",
        "seconds-text", "vo-slope-none", "vo-residual-none", "rho-above-one", "rho-none", "tracks-negative"])
def test_a_cache_file_with_edited_values_is_recomputed(small_drive, change):
    """Valid JSON with values calibrate never writes: recomputed, never used by the filter or the report."""
    computed = calibrate(_fresh(small_drive), cache=False)
    path = diagnostics.cache_path(small_drive)
    path.parent.mkdir(parents=True, exist_ok=True)
    stored = computed.to_dict()
    change(stored)
    path.write_text(json.dumps({"version": _calibration.CALIBRATION_VERSION, "calibration": stored}))
    cal = calibrate(_fresh(small_drive))
    assert cal.source == "computed" and cal.imu_lag == computed.imu_lag
    np.testing.assert_array_equal(cal.sigma_linear_velocity, computed.sigma_linear_velocity)
    assert "the filter will use" in cal.report()
    assert calibrate(_fresh(small_drive)).source == f"cache {path}"  # rewritten, readable again


def test_unwritable_cache_folder_never_fails(small_drive, tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("VISLA_EDU_CACHE", str(blocker / "cache"))
    cal = calibrate(_fresh(small_drive))
    assert cal.source == "computed" and not (blocker / "cache").exists()


# ----------------------------------------------------------------------------- course data


def _load(require_data, name):
    return data.load(require_data(name))


@pytest.mark.data
def test_dataset_0020_lag_plus_one_no_correction(require_data):
    cal = calibrate(_load(require_data, "0020"))
    assert cal.extrinsic_correction == "none" and cal.imu_lag == 1, cal.report()
    assert cal.tracks.lag.verdict == "chosen"
    # nearly noise-free velocities: the filter's noise is small, well below the old 0.5 m/s
    assert np.all(cal.sigma_linear_velocity < 0.1) and np.all(cal.sigma_angular_velocity < 0.02)


@pytest.mark.data
def test_dataset_03_flip_yz_and_its_lag(require_data):
    cal = calibrate(_load(require_data, "03"))
    assert cal.extrinsic_correction == "flip_yz" and cal.imu_lag == 1, cal.report()
    assert cal.vo.extrinsic_verdict["flip_yz"] == "agrees"
    assert cal.repeated_frames == [1008]


@pytest.mark.data
def test_dataset_0022_no_correction(require_data):
    cal = calibrate(_load(require_data, "0022"))
    assert cal.extrinsic_correction == "none", cal.report()
    assert cal.tracks.correction.verdict == "chosen"
    # the 2020 release's velocity noise, 0.5 m/s and 0.05 rad/s
    np.testing.assert_allclose(cal.white_noise, np.repeat([0.5, 0.05], 3), rtol=0.1)


@pytest.mark.data
def test_standin_flip_yz(require_data):
    require_data("10_imu_only")
    require_data("03")
    ds = data.load("10", require_data("03").parent)
    cal = calibrate(ds)
    assert cal.extrinsic_correction == "flip_yz" and cal.imu_lag == 0, cal.report()
    np.testing.assert_allclose(cal.imu_T_cam, ds.extra["simulated_imu_T_cam"], atol=1e-12)


def test_lag_rule_takes_the_best_lag_when_it_clearly_beats_lag_zero():
    """Undecided between +1 and +2, both confidently better than 0: +1 (the best) is used;
    undecided against 0 itself: 0 is kept."""
    beats_zero = _tracks.TrackChoice(None, 1, f"{_tracks.NOT_ENOUGH}: +2 not worse with 95% confidence",
                                     {"+0": [0.9, 0.4], "+2": [0.1, -0.2], "-1": [1.5, 1.0]})
    lag, why = _calibration._decide_lag(beats_zero)
    assert lag == 1 and "beats lag 0" in why
    undecided = _tracks.TrackChoice(None, 1, f"{_tracks.NOT_ENOUGH}: +0 not worse with 95% confidence",
                                    {"+0": [0.4, -0.7], "+2": [0.1, -0.7]})
    assert _calibration._decide_lag(undecided)[0] == 0
    assert _calibration._decide_lag(_tracks.TrackChoice(2, 2, "chosen", {"+0": [1.0, 0.5]}))[0] == 2


def test_a_drive_too_short_to_measure_its_noise_gets_the_courses_values_and_says_so():
    rng = np.random.default_rng(2)
    short = diagnostics.imu_noise(rng.normal(size=(diagnostics.MIN_NOISE_SAMPLES - 1, 6)))
    assert not short["measured"]
    np.testing.assert_array_equal(short["sigma"], [0.5] * 3 + [0.05] * 3)
    assert diagnostics.imu_noise(rng.normal(size=(diagnostics.MIN_NOISE_SAMPLES, 6)))["measured"]
    piece = simulate.simulate_drive("tiny", 0).segment(0, 4)
    calibration = diagnostics.calibrate(piece)
    np.testing.assert_array_equal(calibration.sigma_linear_velocity, [0.5] * 3)
    np.testing.assert_array_equal(calibration.sigma_angular_velocity, [0.05] * 3)
    report = calibration.report(piece.name)
    assert "IMU noise per axis from the velocities: not measured: 4 velocity samples, fewer than 10" in report
    assert "white (second differences)" not in report
