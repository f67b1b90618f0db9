"""Tests of visla_edu.stepper: the filter stepper model (history, frontier, resets)."""

import subprocess
import sys

import numpy as np
import pytest

from visla_edu import data, filters, lie, run
from visla_edu.filters import FilterConfig, FilterDivergedError
from visla_edu.metrics import nis_band
from visla_edu.stepper import NOISE_FIELDS, Stepper, dataset_choices, world_position_covariance


@pytest.fixture(scope="module")
def tiny():
    return data.load("sim-tiny")


def count_steps(stepper):
    """Wrap ``stepper.filter.step`` so the test can count filter steps; returns the counter list."""
    calls = []
    original = stepper.filter.step

    def step():
        calls.append(stepper.filter.t + 1)
        return original()

    stepper.filter.step = step
    return calls


# ------------------------------------------------------------------ history and frontier


def test_starts_at_frame_zero(tiny):
    s = Stepper(tiny)
    assert (s.t, s.frontier, s.steps_computed) == (0, 0, 1)
    assert s.record.t == 0
    assert s.trajectory.shape == (1, 4, 4)
    np.testing.assert_array_equal(s.trajectory[0], np.eye(4))


def test_forward_then_back_returns_the_same_records(tiny):
    s = Stepper(tiny, mode="slam")
    forward = [s.goto(t) for t in range(15)]
    arrays = [(r.world_T_imu.copy(), r.pose_cov.copy(), r.active_means.copy()) for r in forward]
    trajectory = s.trajectory.copy()
    for t in reversed(range(15)):
        rec = s.goto(t)
        assert rec is forward[t]  # the same object from the history, not a recomputation
        assert rec.world_T_imu is forward[t].world_T_imu
        assert s.record is rec and s.t == t
        np.testing.assert_array_equal(rec.world_T_imu, arrays[t][0])
        np.testing.assert_array_equal(rec.pose_cov, arrays[t][1])
        np.testing.assert_array_equal(rec.active_means, arrays[t][2])
        np.testing.assert_array_equal(s.trajectory, trajectory[: t + 1])
    # and forward again: still the same objects
    assert all(s.goto(t) is forward[t] for t in range(15))
    assert s.steps_computed == 15


def test_goto_beyond_frontier_computes_only_missing_frames(tiny):
    s = Stepper(tiny)
    calls = count_steps(s)
    s.goto(5)
    assert calls == [1, 2, 3, 4, 5]
    s.goto(3)
    s.goto(0)
    s.goto(5)
    assert calls == [1, 2, 3, 4, 5]  # reading the history costs no filter steps
    s.goto(12)
    assert calls == list(range(1, 13))
    s.step()
    assert calls[-1] == 13 and len(calls) == 13
    s.back(4)
    assert s.t == 9 and len(calls) == 13
    s.step(2)
    assert s.t == 11 and len(calls) == 13
    assert s.frontier == 13


def test_step_clips_at_the_ends(tiny):
    s = Stepper(tiny)
    assert s.back().t == 0
    s.goto(s.num_frames - 1)
    assert s.step(5).t == s.num_frames - 1
    assert s.filter.done


def test_goto_rejects_bad_frames(tiny):
    s = Stepper(tiny)
    with pytest.raises(IndexError, match="out of range"):
        s.goto(s.num_frames)
    with pytest.raises(IndexError):
        s.goto(-1)
    with pytest.raises(TypeError):
        s.goto(1.5)
    assert s.t == 0


def test_views_are_read_only(tiny):
    s = Stepper(tiny)
    s.goto(4)
    for arr in (s.trajectory, s.nis, s.nis_dof, s.status_counts):
        assert len(arr) == 5
        with pytest.raises(ValueError):
            arr[0] = 0


# ------------------------------------------------------------------ re-configuration


def test_config_change_resets(tiny):
    s = Stepper(tiny)
    s.goto(10)
    old_filter = s.filter
    assert s.configure(sigma_pixel=4.0)
    assert s.config.sigma_pixel == 4.0
    assert s.filter is not old_filter and s.filter.config.sigma_pixel == 4.0
    assert (s.t, s.frontier, s.steps_computed, s.generation) == (0, 0, 1, 1)
    assert not s.configure(sigma_pixel=4.0)  # no change, no reset
    assert s.generation == 1
    s.goto(3)
    assert not s.configure(config=FilterConfig(sigma_pixel=4.0))
    assert s.frontier == 3


def test_mode_and_dataset_change_reset():
    s = Stepper("sim-tiny", mode="slam")
    s.goto(8)
    assert s.configure(mode="vio")
    assert s.mode == "vio" and isinstance(s.filter, filters.VisualInertialOdometry)
    assert s.frontier == 0
    s.goto(8)
    assert s.configure(dataset="sim-small")
    assert s.dataset.num_frames == data.load("sim-small").num_frames
    assert (s.t, s.frontier, s.mode) == (0, 0, "vio")
    assert s.configure(dataset="sim-tiny")  # loaded datasets are kept, switching back is cheap
    assert s.dataset is s._cache["sim-tiny"]


def test_configure_rejects_unknown_settings(tiny):
    s = Stepper(tiny)
    with pytest.raises(ValueError, match="unknown FilterConfig field"):
        s.configure(sigma_pixle=3.0)
    with pytest.raises(ValueError, match="mode must be one of"):
        s.configure(mode="ukf")
    with pytest.raises(ValueError, match="sigma_pixel"):
        s.configure(sigma_pixel=-1.0)
    assert s.mode == "slam" and s.config == FilterConfig()


def test_noise_fields_are_filter_config_fields():
    defaults = FilterConfig()
    for name in ("sigma_pixel", "sigma_linear_velocity", "sigma_angular_velocity", "landmark_prior_sigma",
                 "gate_probability"):
        assert name in NOISE_FIELDS
    for name in NOISE_FIELDS:
        assert hasattr(defaults, name)


# ------------------------------------------------------------------ same numbers as the batch driver


@pytest.mark.parametrize("mode", run.MODES)
def test_trajectory_matches_run_filter(tiny, mode):
    config = FilterConfig(sigma_pixel=1.5)
    s = Stepper(tiny, mode=mode, config=config)
    s.goto(tiny.num_frames - 1)
    result = run.run_filter(tiny, mode=mode, config=config, progress=False)
    np.testing.assert_allclose(s.trajectory, result.world_T_imu, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.nis, result.nis, rtol=1e-12, equal_nan=True)
    np.testing.assert_array_equal(s.nis_dof, result.nis_dof)
    np.testing.assert_array_equal(s.status_counts, result.status_counts)


def test_trajectory_matches_run_filter_after_going_back_and_forth():
    ds = data.load("sim-small")
    s = Stepper(ds, mode="slam")
    for t in (40, 10, 120, 60, ds.num_frames - 1, 5, ds.num_frames - 1):
        s.goto(t)
    result = run.run_filter(ds, mode="slam", progress=False)
    np.testing.assert_allclose(s.trajectory, result.world_T_imu, rtol=0, atol=1e-12)
    assert s.steps_computed == ds.num_frames


# ------------------------------------------------------------------ what the views read


def test_world_position_covariance_is_first_order_push_forward():
    rng = np.random.default_rng(3)
    mu = lie.se3_exp(rng.normal(size=6))
    A = rng.normal(size=(6, 6))
    Sigma = A @ A.T
    eps = 1e-6
    J = np.zeros((3, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = eps
        J[:, i] = ((mu @ lie.se3_exp(d))[:3, 3] - (mu @ lie.se3_exp(-d))[:3, 3]) / (2 * eps)
    np.testing.assert_allclose(world_position_covariance(mu, Sigma), J @ Sigma @ J.T, rtol=1e-6, atol=1e-8)


def test_position_covariance_uses_current_record(tiny):
    s = Stepper(tiny, mode="deadreckon", config=FilterConfig(sigma_linear_velocity=1.0))
    s.goto(20)
    rec = s.record
    R = rec.world_T_imu[:3, :3]
    np.testing.assert_allclose(s.position_covariance(), R @ rec.pose_cov[:3, :3] @ R.T)
    assert np.all(np.linalg.eigvalsh(s.position_covariance()) > 0)


def test_nis_band():
    from scipy.stats import chi2

    lo, hi = nis_band([4, 0, 40])
    assert lo[0] == pytest.approx(chi2.ppf(0.025, 4) / 4) and hi[0] == pytest.approx(chi2.ppf(0.975, 4) / 4)
    assert np.isnan(lo[1]) and np.isnan(hi[1])
    assert lo[0] < lo[2] < 1 < hi[2] < hi[0]  # the band narrows with more dof


def test_nis_band_series_follows_time(tiny):
    s = Stepper(tiny)
    s.goto(10)
    lo, hi = s.nis_band_series()
    assert lo.shape == hi.shape == (11,)
    expected = nis_band(s.nis_dof)
    np.testing.assert_array_equal(lo, expected[0])
    np.testing.assert_array_equal(hi, expected[1])
    s.goto(4)
    assert len(s.nis_band_series()[0]) == 5


def test_retired_landmarks_keep_their_last_active_estimate(tiny):
    s = Stepper(tiny, mode="slam")
    t_end = tiny.num_frames - 1
    s.goto(t_end)
    for t in (t_end, 30, 12):
        s.goto(t)
        ids, means = s.retired_landmarks()
        assert not np.isin(ids, s.record.active_ids).any()
        for i, m in zip(ids, means):
            last = max(k for k in range(t) if i in s.records[k].active_ids)
            rec = s.records[last]
            np.testing.assert_array_equal(m, rec.active_means[np.nonzero(rec.active_ids == i)[0][0]])
    early = s.retired_landmarks()[0]
    s.goto(t_end)
    assert np.isin(early, s.retired_landmarks()[0]).all()  # the map so far only grows


def test_ground_truth_and_dead_reckoning(tiny):
    s = Stepper(tiny)
    s.goto(7)
    np.testing.assert_array_equal(s.ground_truth_pose(), tiny.ground_truth.world_T_imu[7])
    assert s.dead_reckoning.shape == (tiny.num_frames, 4, 4)
    assert "t = 7 / " in s.summary()


def test_ground_truth_of_fewer_frames_than_the_drive(tiny):
    import dataclasses

    from visla_edu.dataset import GroundTruth

    real_like = dataclasses.replace(tiny, ground_truth=GroundTruth(world_T_imu=tiny.ground_truth.world_T_imu[:40]))
    s = Stepper(real_like)
    s.goto(39)
    np.testing.assert_array_equal(s.ground_truth_pose(), tiny.ground_truth.world_T_imu[39])
    s.goto(40)
    assert s.ground_truth_pose() is None  # past the frames the ground truth covers


def test_divergence_stops_at_last_good_frame(tiny):
    s = Stepper(tiny)
    original = s.filter.step

    def step():
        if s.filter.t + 1 == 6:
            raise FilterDivergedError("test: diverged at frame 6")
        return original()

    s.filter.step = step
    with pytest.raises(FilterDivergedError, match="frame 6"):
        s.goto(20)
    assert (s.t, s.frontier) == (5, 5)
    assert s.goto(2).t == 2


def test_blas_threads_argument(tiny):
    assert Stepper(tiny, blas_threads=None).goto(5).t == 5
    with pytest.raises(ValueError, match="blas_threads"):
        Stepper(tiny, blas_threads=0)


def test_model_imports_no_gui():
    code = ("import sys, visla_edu.stepper; "
            "gui = [m for m in ('ipywidgets', 'matplotlib') if m in sys.modules]; assert not gui, gui")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_dataset_choices_list_available_and_small_simulations(data_dir):
    names = [name for _, name in dataset_choices(data_dir)]
    for name in data.available(data_dir):
        assert name in names
    assert "sim-tiny" in names and "sim-small" in names
    labels = dict((name, label) for label, name in dataset_choices(data_dir))
    if "10" in names and not (data_dir / "10.npz").is_file():
        assert "STAND-IN" in labels["10"]



_SIGTERM_CHILD = """
import os, signal, subprocess, time
from visla_edu.stepper import app

class FakeVoila:
    def __init__(self, cmd, **options):
        self.cmd, self.terminated, self.waits = cmd, False, 0
    def wait(self, timeout=None):
        self.waits += 1
        if self.waits == 1:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler interrupts this
        return 0
    def terminate(self):
        self.terminated = True

subprocess.Popen = FakeVoila
proc = app.serve(port=18999, wait=True)
print(proc.terminated, proc.waits, signal.getsignal(signal.SIGTERM) is signal.SIG_DFL)
"""


def test_serve_stops_voila_on_sigterm_as_on_ctrl_c():
    """``visla-edu stepper`` killed with SIGTERM (``kill``) stops its Voila child instead of
    leaving it serving, and puts the default SIGTERM handling back (run in a child process:
    without the handler, SIGTERM ends it)."""
    child = subprocess.run([sys.executable, "-c", _SIGTERM_CHILD], capture_output=True, text=True, timeout=60)
    assert child.returncode == 0, f"the serving process died (status {child.returncode}): {child.stderr[-500:]}"
    assert child.stdout.split() == ["True", "2", "True"]
