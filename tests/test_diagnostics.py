"""Tests of visla_edu.diagnostics' single checks on simulated drives (known truth) and on the
course files: the visual-odometry extrinsic check, time alignment, IMU noise and gyro bias,
outlier indicators, the report. The calibration decision and its cache are tested in
tests/test_calibration.py.

Real-data tests need VISLA_EDU_DATA (they are skipped with the reason otherwise).
"""

import dataclasses

import numpy as np
import pytest

from visla_edu import data, diagnostics, run, simulate
from visla_edu.diagnostics import CORRECTIONS
from visla_edu.filters import FilterConfig

K_RIG, B_RIG, RIG = simulate.default_rig()

#: A drive whose yaw rate changes quickly and whose pixels are precise: the one velocity
#: sample that explains each frame step stands out. On the default drives the yaw rate is
#: smooth (4 s time scale), so neighbouring samples differ by less than the visual
#: odometry's noise and the time-alignment residuals of different lags differ by ~1%.
WIGGLY = dict(yaw_rate_sigma=0.3, yaw_timescale=0.5, pixel_sigma=0.3)


def _fresh(ds, **fields):
    """A copy with some fields replaced and no cached diagnostics."""
    return dataclasses.replace(ds, extra={}, **fields)


def _shift_velocities(ds, by=1):
    """Velocities delayed by ``by`` samples: the step t -> t+1 is then explained by u[t + by]."""
    v = np.concatenate([np.repeat(ds.linear_velocity[:1], by, axis=0), ds.linear_velocity[:-by]])
    w = np.concatenate([np.repeat(ds.angular_velocity[:1], by, axis=0), ds.angular_velocity[:-by]])
    return _fresh(ds, linear_velocity=v, angular_velocity=w)


@pytest.fixture(scope="module")
def small():
    return simulate.simulate_drive("small", 0)


@pytest.fixture(scope="module")
def small_flipped():
    """The rig is really mounted as flip_yz @ RIG, but the file says RIG."""
    ds = simulate.simulate_drive("small", 0, imu_T_cam=CORRECTIONS["flip_yz"] @ RIG)
    return _fresh(ds, imu_T_cam=RIG.copy())


# ----------------------------------------------------------------------------- extrinsics


@pytest.mark.parametrize("seed", [0, 1])
def test_check_extrinsics_accepts_a_correct_calibration(seed):
    ds = simulate.simulate_drive("small", seed)
    check = diagnostics.check_extrinsics(ds)
    assert check.recommended == "none"
    assert check.pairs > 200
    assert check.rotation_slope["none"] > 0.5 and check.translation_slope["none"] > 0.5
    # the flipped candidates disagree
    assert check.rotation_slope["flip_yz"] < -0.5 and check.translation_slope["flip_xy"] < -0.5
    assert check.verdict == {"none": "agrees", "flip_yz": "disagrees", "flip_xy": "disagrees", "flip_xz": "disagrees"}
    assert "none" in check.report() and "agrees" in check.report()


def test_check_extrinsics_finds_the_flip(small_flipped):
    check = diagnostics.check_extrinsics(small_flipped)
    assert check.recommended == "flip_yz"
    assert check.rotation_slope["none"] < -0.5
    assert check.rotation_slope["flip_yz"] > 0.5 and check.translation_slope["flip_yz"] > 0.5
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(small_flipped, "auto")
    np.testing.assert_allclose(imu_T_cam, CORRECTIONS["flip_yz"] @ RIG)
    assert "flip_yz" in evidence
    # the filter uses the corrected calibration
    flt = run.make_filter(small_flipped, "slam", FilterConfig())
    np.testing.assert_allclose(flt.camera.imu_T_cam, CORRECTIONS["flip_yz"] @ RIG)


@pytest.mark.parametrize("seed", range(6))
def test_no_flip_on_weak_evidence(seed):
    """A 6 s drive barely turns: never a flip for a correct rig, never a wrong flip for a flipped one."""
    ds = simulate.simulate_drive("tiny", seed)
    check = diagnostics.check_extrinsics(ds)
    assert check.recommended == "none"
    flipped = _fresh(simulate.simulate_drive("tiny", seed, imu_T_cam=CORRECTIONS["flip_yz"] @ RIG),
                     imu_T_cam=RIG.copy())
    assert diagnostics.check_extrinsics(flipped).recommended in ("none", "flip_yz")


def test_check_extrinsics_without_visual_odometry_recommends_nothing():
    """A camera that looks backwards sees nothing: no pairs, no evidence, no correction."""
    ds = simulate.simulate_drive("tiny", 0, imu_T_cam=CORRECTIONS["flip_xy"] @ RIG)
    check = diagnostics.check_extrinsics(ds)
    assert check.pairs == 0 and check.recommended == "none"


def test_resolve_extrinsics(small):
    ds = _fresh(small)
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(ds, "none")
    np.testing.assert_array_equal(imu_T_cam, ds.imu_T_cam)
    assert evidence == ""
    for name in ("flip_yz", "flip_xy", "flip_xz"):
        imu_T_cam, evidence = diagnostics.resolve_extrinsics(ds, name)
        np.testing.assert_allclose(imu_T_cam, CORRECTIONS[name] @ ds.imu_T_cam)
        assert name in evidence
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(ds, "auto")
    np.testing.assert_array_equal(imu_T_cam, ds.imu_T_cam)
    assert evidence == ""
    assert ds.extra["calibration"].extrinsic_correction == "none"  # cached
    with pytest.raises(ValueError, match="flip_yz"):
        diagnostics.resolve_extrinsics(ds, "flip_zz")


def test_corrections_are_rotations():
    for C in CORRECTIONS.values():
        np.testing.assert_allclose(C[:3, :3] @ C[:3, :3].T, np.eye(3))
        assert np.linalg.det(C[:3, :3]) == pytest.approx(1.0)


# ----------------------------------------------------------------------------- time alignment


@pytest.mark.parametrize("seed", [0, 2])
def test_time_alignment_finds_the_lag(seed):
    ds = simulate.simulate_drive("small", seed, **WIGGLY)
    result = diagnostics.check_time_alignment(ds, ds.imu_T_cam)
    assert result["best"] == 0, result
    assert set(result["residual"]) == {-2, -1, 0, 1, 2}
    shifted = diagnostics.check_time_alignment(_shift_velocities(ds, 1), ds.imu_T_cam)
    assert shifted["best"] == 1, shifted
    # the residual of lag L on the shifted data is that of lag L - 1 on the original
    assert shifted["residual"][1] == pytest.approx(result["residual"][0], rel=1e-6)


def test_time_alignment_uses_the_corrected_calibration_by_default(small_flipped):
    ds = _fresh(small_flipped)
    auto = diagnostics.check_time_alignment(ds)
    explicit = diagnostics.check_time_alignment(ds, CORRECTIONS["flip_yz"] @ RIG)
    assert auto == explicit


# ----------------------------------------------------------------------------- IMU noise and bias


def test_imu_noise_and_gyro_bias_are_recovered():
    bias = np.array([0.03, -0.02, 0.01])
    ds = simulate.simulate_drive("small", 0, gyro_bias=tuple(bias), linear_velocity_sigma=0.2,
                                 angular_velocity_sigma=0.02)
    out = diagnostics.imu_noise_and_bias(ds, ds.imu_T_cam)
    np.testing.assert_allclose(out["linear_noise"], 0.2, rtol=0.2)
    np.testing.assert_allclose(out["angular_noise"], 0.02, rtol=0.2)
    assert np.all(out["gyro_bias_stderr"] < 0.03)
    assert np.all(np.abs(out["gyro_bias"] - bias) < 4 * out["gyro_bias_stderr"] + 1e-3), out
    # the well-determined axis (roll, about the direction of travel) is found accurately
    assert out["gyro_bias"][0] == pytest.approx(0.03, abs=0.01)


def test_no_gyro_bias_is_found_where_there_is_none(small):
    out = diagnostics.imu_noise_and_bias(small, small.imu_T_cam)
    assert np.all(np.abs(out["gyro_bias"]) < 4 * out["gyro_bias_stderr"] + 1e-3), out
    # and a noise-free IMU reads as (nearly) noise-free
    quiet = simulate.simulate_drive("small", 0, linear_velocity_sigma=0.0, angular_velocity_sigma=0.0)
    out = diagnostics.imu_noise_and_bias(quiet, quiet.imu_T_cam)
    assert np.all(out["linear_noise"] < 0.02) and np.all(out["angular_noise"] < 0.002)


# ----------------------------------------------------------------------------- outliers, report


def test_outlier_indicators_count_non_positive_disparity(small):
    out = diagnostics.outlier_indicators(small)
    z = small.obs_z
    assert out["non_positive_disparity"] == pytest.approx(np.mean(z[:, 0] - z[:, 2] <= 0))
    assert out["non_positive_disparity"] == pytest.approx(small.extra["config"].nonpositive_disparity_share, abs=2e-3)
    assert out["epipolar"] == pytest.approx(np.mean(np.abs(z[:, 1] - z[:, 3]) > 3.0))
    assert 0 <= out["vo_rejected"] < 0.5
    # a constructed share: exactly every 10th observation broken
    z2 = z.copy()
    z2[:, 2] = z2[:, 0] - 5.0  # all positive
    z2[::10, 2] = z2[::10, 0]  # zero disparity
    out2 = diagnostics.outlier_indicators(_fresh(small, obs_z=z2))
    assert out2["non_positive_disparity"] == pytest.approx(len(z2[::10]) / len(z2))


def test_diagnose_reports_every_section(small):
    text = diagnostics.diagnose(_fresh(small))
    for phrase in ("extrinsic check", "time alignment", "best lag", "IMU noise", "gyro bias",
                   "repeating the previous frame", "non-positive disparity", "epipolar", "visual odometry"):
        assert phrase in text, phrase
    assert "the filter will use: extrinsic_correction 'none'" in text


def test_diagnose_explains_a_correction(small_flipped):
    text = diagnostics.diagnose(_fresh(small_flipped))
    assert "flip_yz" in text and "disagrees" in text
    assert "the filter will use: extrinsic_correction 'flip_yz'" in text


# ----------------------------------------------------------------------------- course data


@pytest.mark.data
def test_dataset_03_needs_flip_yz(require_data):
    ds = data.load(require_data("03"))
    check = diagnostics.check_extrinsics(ds)
    assert check.recommended == "flip_yz", check.report()
    assert data.repeated_frames(ds) == [1008]
    text = diagnostics.diagnose(ds)
    assert "flip_yz" in text and "1008" in text


@pytest.mark.data
def test_dataset_0022_needs_no_correction(require_data):
    ds = data.load(require_data("0022"))
    check = diagnostics.check_extrinsics(ds)
    assert check.recommended == "none", check.report()
    assert check.rotation_slope["none"] > 0.5 and check.translation_slope["none"] > 0.5


def test_an_inverted_extrinsic_is_named_in_a_warning():
    """The odometry contradicts every axis correction of cam_T_imu stored as imu_T_cam: the run says so."""
    ds = simulate.simulate_drive("small", seed=0)
    assert diagnostics.resolve_extrinsics(ds, "auto")[1] == ""
    # a 60-frame drive attenuates every odometry slope (to about 0.25): no false alarm
    assert diagnostics.resolve_extrinsics(simulate.simulate_drive("tiny", seed=0), "auto")[1] == ""
    inverted = dataclasses.replace(ds, imu_T_cam=np.linalg.inv(ds.imu_T_cam), extra={})
    imu_T_cam, evidence = diagnostics.resolve_extrinsics(inverted, "auto")
    assert evidence.startswith("warning: the visual odometry contradicts the file's imu_T_cam")
    assert "stored inverted (cam_T_imu)" in evidence
    np.testing.assert_array_equal(imu_T_cam, inverted.imu_T_cam)


def test_a_divergence_with_angular_velocity_in_degrees_says_so():
    from visla_edu.run import workload

    ds = simulate.simulate_drive("tiny", seed=0)
    assert "deg/s" not in workload.divergence_hint(ds, FilterConfig(), frame=5)
    degrees = dataclasses.replace(ds, angular_velocity=np.degrees(ds.angular_velocity), extra={})
    hint = workload.divergence_hint(degrees, FilterConfig(), frame=5)
    assert "beyond what a car does (below 2 rad/s): is it in deg/s? Convert with np.radians(angular_velocity)" in hint
