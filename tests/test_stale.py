"""Stale copies: observations that repeat their landmark's pixels of the frame before bit for bit.

Found by :func:`visla_edu.dataset.stale_copies`, added to a simulated drive by
:func:`visla_edu.simulate.with_stale_copies`, left out by the filters and smoothers
(``skip_stale_copies``), and, in the joint filter's clone window, not the end of their track.
"""

import dataclasses

import numpy as np
import pytest

from visla_edu import metrics, run, simulate
from visla_edu.codes import OBS_IGNORED, OBS_USED
from visla_edu.dataset import stale_copies
from visla_edu.filters import FilterConfig
from visla_edu.smoother import SmootherConfig
from visla_edu.smoother._problem import observation_status

FIXED = dict(extrinsic_correction="none", sigma_linear_velocity=0.5, sigma_angular_velocity=0.05, imu_lag=0,
             pixel_noise_inflation=1.0)


@pytest.fixture(scope="module")
def tiny():
    return simulate.simulate_drive("tiny", 0)


@pytest.fixture(scope="module")
def stale_tiny(tiny):
    return simulate.with_stale_copies(tiny, 0.2, seed=1)


def _stale_frames(ds):
    return np.unique(ds.observation_frames()[stale_copies(ds)])


def test_a_simulated_drive_has_no_stale_copy(tiny):
    assert not stale_copies(tiny).any()


def test_stale_copies_are_the_repeats_of_continuing_tracks(tiny, stale_tiny):
    stale = stale_copies(stale_tiny)
    frames = stale_tiny.observation_frames()
    t = int(_stale_frames(stale_tiny)[0])
    ptr = stale_tiny.frame_ptr
    before, now = set(stale_tiny.obs_ids[ptr[t - 1]:ptr[t]].tolist()), stale_tiny.obs_ids[ptr[t]:ptr[t + 1]]
    np.testing.assert_array_equal(stale[ptr[t]:ptr[t + 1]], [lm in before for lm in now.tolist()])
    assert not stale[frames == t - 1].any() or (t - 1) in _stale_frames(stale_tiny)  # the original is kept
    changed = np.any(stale_tiny.obs_z != tiny.obs_z, axis=1)
    np.testing.assert_array_equal(changed, stale)  # a simulated pixel never repeats: every copy is found


def test_a_copy_after_a_gap_is_not_stale(tiny):
    ptr = tiny.frame_ptr
    t = 5
    lm = int(np.intersect1d(tiny.obs_ids[ptr[t - 1]:ptr[t]], tiny.obs_ids[ptr[t + 1]:ptr[t + 2]])[0])
    z = tiny.obs_z.copy()
    i_prev = ptr[t - 1] + int(np.flatnonzero(tiny.obs_ids[ptr[t - 1]:ptr[t]] == lm)[0])
    i_next = ptr[t + 1] + int(np.flatnonzero(tiny.obs_ids[ptr[t + 1]:ptr[t + 2]] == lm)[0])
    z[i_next] = z[i_prev]  # two frames later: a different measurement that happens to match
    assert not stale_copies(dataclasses.replace(tiny, obs_z=z))[i_next]


def test_with_stale_copies_refuses_a_share_outside_0_1(tiny):
    with pytest.raises(ValueError, match=r"share must be in \[0, 1\], got 1.5"):
        simulate.with_stale_copies(tiny, 1.5)


@pytest.mark.parametrize("mode", ["mapping", "vio", "slam"])
def test_the_filters_leave_stale_copies_out(stale_tiny, mode):
    stale = stale_copies(stale_tiny)
    frames = stale_tiny.observation_frames()
    on = list(run.iterate_filter(stale_tiny, mode, FilterConfig(**FIXED)))
    off = list(run.iterate_filter(stale_tiny, mode, FilterConfig(**FIXED, skip_stale_copies=False)))
    for t in _stale_frames(stale_tiny):
        copies = stale[frames == t]
        np.testing.assert_array_equal(on[t].status[copies], OBS_IGNORED)
    used_copies = sum(int(np.sum(off[t].status[stale[frames == t]] != OBS_IGNORED)) for t in _stale_frames(stale_tiny))
    assert used_copies > 0  # with the setting off they are measurements like any other


def _track_count(result):
    counts = result.track_counts
    return counts["tracks_used"] + counts["tracks_gated"] + counts["tracks_short"] + counts["tracks_failed"]


def test_a_stale_copy_does_not_end_its_track_in_the_clone_window(tiny, stale_tiny):
    """Left out, a copy leaves a one-frame gap; a track that ended there would come back as a second, shorter
    track. The clone window sees as many tracks as on the drive without copies."""
    config = FilterConfig(**FIXED, msckf_window=20)
    clean = run.run_filter(tiny, "slam", config)
    stale = run.run_filter(stale_tiny, "slam", config)
    assert _track_count(stale) + stale.track_counts["entered"] <= _track_count(clean) + clean.track_counts["entered"]


@pytest.mark.parametrize("mode", ["vio", "slam"])
def test_stale_copies_do_not_cost_the_filters_their_accuracy(mode):
    """A drive with the 2020 release's velocity noise and one stale frame in ten: the copies, used, multiply the
    error (here about 2.6x); left out, the error stays near that of the drive without them."""
    clean = simulate.simulate_drive("small", 0, linear_velocity_sigma=0.5, angular_velocity_sigma=0.05)
    stale = simulate.with_stale_copies(clean, 0.1, seed=0)
    truth = clean.ground_truth.world_T_imu

    def ate(ds, **settings):
        return metrics.ate(run.run_filter(ds, mode, FilterConfig(**FIXED, msckf_window=20, **settings)).world_T_imu,
                           truth, align=False)

    clean_ate, skipped, used = ate(clean), ate(stale), ate(stale, skip_stale_copies=False)
    assert skipped < 1.5 * clean_ate, (clean_ate, skipped)
    assert used > 1.8 * skipped, (skipped, used)


def test_the_smoothers_leave_stale_copies_out(stale_tiny):
    stale = stale_copies(stale_tiny)
    status = observation_status(stale_tiny, SmootherConfig())
    np.testing.assert_array_equal(status[stale], OBS_IGNORED)
    assert np.all(observation_status(stale_tiny, SmootherConfig(skip_stale_copies=False))[stale] != OBS_IGNORED)
    assert np.any(status[~stale] == OBS_USED)


def test_the_smoother_takes_the_setting_from_the_filter():
    resolved = dataclasses.replace(FilterConfig(**FIXED, skip_stale_copies=False), msckf_window=20)
    assert SmootherConfig.from_filter_config(resolved).skip_stale_copies is False
