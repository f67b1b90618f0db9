"""The stepper steps a filter it did not build: any object with the step interface (notebook 12)."""

import numpy as np
import pytest

from visla_edu import data, motion
from visla_edu.codes import OBS_IGNORED
from visla_edu.filters import FilterConfig, StepRecord
from visla_edu.stepper import SteppableFilter, Stepper


@pytest.fixture(scope="module")
def tiny():
    return data.load("sim-tiny")


class ConstantVelocityGuess:
    """A tiny custom filter: the IMU mean only, a covariance growing by ``sigma_pixel`` per frame.

    Not a library class and not derived from one: only ``step()`` and ``config``.
    """

    def __init__(self, dataset, config, fail_at=None):
        self.dataset, self.config, self.fail_at = dataset, config, fail_at
        self.t = -1
        self.world_T_imu = np.eye(4)
        self.steps = 0

    def step(self):
        self.t += 1
        self.steps += 1
        if self.t == self.fail_at:
            raise ValueError(f"my filter broke at frame {self.t}")
        if self.t > 0:
            ds = self.dataset
            self.world_T_imu = motion.predict_pose(self.world_T_imu, ds.twists[self.t - 1], ds.time_steps[self.t - 1])
        ids, z = self.dataset.observations(self.t)
        return StepRecord(t=self.t, world_T_imu=self.world_T_imu.copy(),
                          pose_cov=(1 + self.t) * self.config.sigma_pixel**2 * np.eye(6),
                          ids=ids, z=z, z_pred=np.full(z.shape, np.nan), status=np.full(len(ids), OBS_IGNORED),
                          nis=np.nan, nis_dof=0, active_ids=np.zeros(0, dtype=np.int64),
                          active_means=np.zeros((0, 3)), active_covs=np.zeros((0, 3, 3)))


def test_steps_a_custom_filter_and_reads_back_its_history(tiny):
    built = []

    def factory(ds, cfg):
        built.append(cfg)
        return ConstantVelocityGuess(ds, cfg)

    s = Stepper(tiny, mode="deadreckon", config=FilterConfig(sigma_pixel=3.0), filter_factory=factory)
    assert isinstance(s.filter, ConstantVelocityGuess) and isinstance(s.filter, SteppableFilter)
    assert len(built) == 1 and built[0].resolved and built[0].sigma_pixel == 3.0  # "auto" measured first
    rec = s.goto(20)
    assert (rec.t, s.frontier, s.filter.steps) == (20, 20, 21)
    expected = motion.dead_reckon(tiny.time_stamps, tiny.twists)[:21]
    np.testing.assert_allclose(s.trajectory, expected, atol=1e-12)
    assert s.goto(5) is s.records[5] and s.filter.steps == 21  # back: the history, no filter work
    np.testing.assert_allclose(s.record.pose_cov, 6 * 9.0 * np.eye(6))
    assert "no update" in s.summary()


def test_new_settings_rebuild_the_custom_filter(tiny):
    built = []
    s = Stepper(tiny, filter_factory=lambda ds, cfg: built.append(cfg) or ConstantVelocityGuess(ds, cfg))
    s.goto(7)
    assert s.configure(sigma_pixel=5.0)
    assert len(built) == 2 and built[1].sigma_pixel == 5.0 and s.t == 0
    assert s.config_in_use is s.filter.config and s.config_in_use.sigma_pixel == 5.0
    np.testing.assert_allclose(s.goto(3).pose_cov, 4 * 25.0 * np.eye(6))


def test_a_failing_custom_filter_stops_at_the_last_good_frame(tiny):
    s = Stepper(tiny, filter_factory=lambda ds, cfg: ConstantVelocityGuess(ds, cfg, fail_at=9))
    with pytest.raises(ValueError, match="broke at frame 9"):
        s.goto(15)
    assert s.t == s.frontier == 8


def test_a_factory_product_without_the_interface_is_named(tiny):
    with pytest.raises(TypeError, match="filter_factory must be a callable"):
        Stepper(tiny, filter_factory="mine")
    with pytest.raises(TypeError, match=r"object lacks \['step', 'config'\].*SteppableFilter"):
        Stepper(tiny, filter_factory=lambda ds, cfg: object())

    class NoRecord(ConstantVelocityGuess):
        def step(self):
            return super().step().world_T_imu

    with pytest.raises(TypeError, match="must return a visla_edu.filters.StepRecord, got ndarray"):
        Stepper(tiny, filter_factory=lambda ds, cfg: NoRecord(ds, cfg))


def test_the_widget_passes_the_factory_through(tiny):
    pytest.importorskip("ipywidgets")
    from visla_edu.stepper.widget import StepperWidget

    w = StepperWidget(tiny, mode="vio", filter_factory=lambda ds, cfg: ConstantVelocityGuess(ds, cfg, fail_at=6))
    assert isinstance(w.stepper.filter, ConstantVelocityGuess)
    assert w.mode_dropdown.disabled  # the factory decides what the filter does
    w.time_slider.value = 4
    assert w.stepper.t == 4
    w.time_slider.value = 10  # the custom filter's own error is shown, not raised
    assert w.stepper.t == 5 and "ValueError" in w.status.value and "broke at frame 6" in w.status.value
    w.noise_sliders["sigma_pixel"].value = 4.0  # rebuilt through the factory with the new setting
    assert isinstance(w.stepper.filter, ConstantVelocityGuess) and w.stepper.filter.config.sigma_pixel == 4.0
