"""Headless tests of the stepper widget: set widget values and press buttons as a user does,
then read the stepper's state and check that the view re-rendered."""

import base64
import os

import ipywidgets
import numpy as np
import pytest

from visla_edu import filters
from visla_edu.filters import FilterConfig, FilterDivergedError
from visla_edu.stepper.app import app_notebook_path
from visla_edu.stepper.figure import StepperFigure
from visla_edu.stepper.widget import StepperWidget


@pytest.fixture
def widget():
    return StepperWidget("sim-tiny")


def shown_png(w):
    """The PNG bytes the Output widget currently shows."""
    (out,) = w.output.outputs
    assert out["output_type"] == "display_data"
    png = base64.b64decode(out["data"]["image/png"])
    assert png.startswith(b"\x89PNG")
    return png


def test_constructs_and_shows_frame_zero(widget):
    assert isinstance(widget, ipywidgets.VBox)  # displays itself as a cell's last expression
    assert widget.stepper.t == 0 and widget.stepper.mode == "slam"
    assert widget.render_count == 1
    assert "t = 0</b> / 59" in widget.status.value
    assert "t = 0 / 59" in widget.figure.title.get_text()
    shown_png(widget)
    assert widget.time_slider.max == widget.stepper.num_frames - 1 == widget.play.max


def test_slider_sets_time_and_redraws(widget):
    before = shown_png(widget)
    widget.time_slider.value = 12
    assert widget.stepper.t == 12 and widget.stepper.frontier == 12
    assert widget.render_count == 2
    assert "<b>t = 12</b>" in widget.status.value
    assert "t = 12 / 59" in widget.figure.title.get_text()
    assert shown_png(widget) != before
    widget.time_slider.value = 3  # back: read from the history
    assert widget.stepper.t == 3 and widget.stepper.frontier == 12
    assert widget.stepper.steps_computed == 13
    assert "<b>t = 3</b>" in widget.status.value and widget.render_count == 3


def test_step_buttons(widget):
    widget.time_slider.value = 12
    widget.step_button.click()
    assert widget.stepper.t == 13 == widget.time_slider.value
    widget.back_button.click()
    widget.back_button.click()
    assert widget.stepper.t == 11
    widget.jump_button.click()
    assert widget.stepper.t == 21
    widget.first_button.click()
    assert widget.stepper.t == 0
    widget.back_button.click()  # clipped at 0: nothing changes
    assert widget.stepper.t == 0
    widget.end_button.click()
    last = widget.stepper.num_frames - 1
    assert widget.stepper.t == last == widget.stepper.frontier
    widget.step_button.click()
    assert widget.stepper.t == last
    assert f"<b>t = {last}</b>" in widget.status.value


def test_play_is_linked_to_the_slider(widget):
    widget.play.value = 5
    assert widget.time_slider.value == 5 and widget.stepper.t == 5
    widget.time_slider.value = 7
    assert widget.play.value == 7


def test_mode_dropdown_reconfigures_and_keeps_the_time(widget):
    widget.time_slider.value = 9
    renders = widget.render_count
    widget.mode_dropdown.value = "vio"
    s = widget.stepper
    assert s.mode == "vio" and isinstance(s.filter, filters.VisualInertialOdometry)
    assert s.t == 9 and s.frontier == 9 and s.steps_computed == 10  # re-run from frame 0
    assert widget.render_count > renders
    assert "visual-inertial odometry" in widget.figure.title.get_text()
    widget.mode_dropdown.value = "deadreckon"
    assert isinstance(widget.stepper.filter, filters.DeadReckoning) and widget.stepper.t == 9


def test_noise_slider_reruns_the_filter(widget):
    widget.time_slider.value = 15
    first_run = widget.stepper.record
    widget.noise_sliders["sigma_pixel"].value = 4.0
    s = widget.stepper
    assert s.config.sigma_pixel == pytest.approx(4.0)
    assert s.t == 15 and s.steps_computed == 16 and s.record is not first_run
    assert not np.array_equal(s.record.pose_cov, first_run.pose_cov)
    widget.noise_sliders["gate_probability"].value = 0.99
    assert s.config.gate_probability == pytest.approx(0.99)
    widget.noise_sliders["landmark_prior_sigma"].value = 0.5
    assert s.config.landmark_prior_sigma == pytest.approx(0.5)
    widget.defaults_button.click()
    assert s.config == FilterConfig()
    assert widget.noise_sliders["sigma_pixel"].value == pytest.approx(FilterConfig().sigma_pixel)
    assert s.t == 15


def test_dataset_dropdown_switches_dataset(widget):
    widget.time_slider.value = 20
    assert "sim-small" in [value for _, value in widget.dataset_dropdown.options]
    widget.dataset_dropdown.value = "sim-small"
    s = widget.stepper
    assert s.dataset.name.startswith("sim-small") or s.dataset.num_frames == 300
    assert s.t == 0 and widget.time_slider.value == 0
    assert widget.time_slider.max == s.num_frames - 1 == widget.play.max
    assert f"t = 0</b> / {s.num_frames - 1}" in widget.status.value
    widget.time_slider.value = 150
    assert s.t == 150


def test_dataset_load_error_is_shown_and_reverted(widget, monkeypatch):
    from visla_edu import data

    def load(name, data_dir=None):
        raise FileNotFoundError(f"course file {name}.npz not found (test)")

    monkeypatch.setattr(data, "load", load)
    widget.time_slider.value = 4
    widget.dataset_dropdown.value = "sim-small"
    assert "FileNotFoundError" in widget.status.value and "not found (test)" in widget.status.value
    assert widget.dataset_dropdown.value == "sim-tiny"
    assert widget.stepper.dataset.num_frames == 60 and widget.stepper.t == 4


def test_divergence_is_reported_not_raised(widget):
    s = widget.stepper
    original = s.filter.step

    def step():
        if s.filter.t + 1 == 8:
            raise FilterDivergedError("test: diverged at frame 8")
        return original()

    s.filter.step = step
    widget.time_slider.value = 30
    assert s.t == 7 and widget.time_slider.value == 7
    assert "FilterDivergedError" in widget.status.value and "frame 8" in widget.status.value


def test_view_toggle_redraws(widget):
    widget.time_slider.value = 10
    renders = widget.render_count
    widget.view_toggle.value = False
    assert widget.figure.follow is False and widget.render_count == renders + 1
    x0, x1 = widget.figure.ax_map.get_xlim()
    gt = widget.stepper.ground_truth.world_T_imu[:, 0, 3]
    assert x0 <= gt.min() and gt.max() <= x1  # whole drive in view


def test_figure_shows_the_current_frame():
    w = StepperWidget("sim-tiny")
    w.time_slider.value = 25
    fig, rec = w.figure, w.stepper.record
    x, y = fig.est_line.get_data()
    assert len(x) == 26
    assert np.allclose(fig.pose_marker.get_data()[0], rec.world_T_imu[0, 3])
    assert len(fig.active_points.get_offsets()) == len(rec.active_ids)
    assert len(fig.active_ellipses.get_segments()) == len(rec.active_ids)
    shown = sum(len(fig._image[fig.ax_left][code].get_offsets()) for code in
                (filters.OBS_USED, filters.OBS_NEW, filters.OBS_GATED, filters.OBS_NO_DEPTH, filters.OBS_FAR,
                 filters.OBS_DELAYED))
    assert shown == len(rec.ids)
    assert fig.captions["frame"].startswith("frame 25: ")
    assert "frame 25: " not in w.status.value and "25</b>" in w.status.value


def test_figure_draws_a_poses_only_ground_truth_in_its_own_style():
    import dataclasses

    import matplotlib.colors

    from visla_edu import data
    from visla_edu.dataset import GroundTruth
    from visla_edu.plotting import GROUND_TRUTH_STYLE
    from visla_edu.stepper import Stepper

    tiny = data.load("sim-tiny")
    truth = GroundTruth(world_T_imu=tiny.ground_truth.world_T_imu[:40])  # a real drive's: poses only, 40 frames
    s = Stepper(dataclasses.replace(tiny, ground_truth=truth), mode="slam")
    fig = StepperFigure(dpi=40, annotate=True)
    s.goto(45)
    fig.update(s)
    assert fig.render_png().startswith(b"\x89PNG")
    assert len(fig.gt_line.get_xdata()) == 40 and len(fig.gt_points.get_offsets()) == 0
    assert len(fig.gt_pose.get_xdata()) == 0 and "position error" not in fig.captions["map"]  # frame 45 > 39
    labels = [t.get_text() for t in fig.ax_map.get_legend().get_texts()]
    assert "ground truth" in labels and "true landmarks" not in labels
    color = matplotlib.colors.to_hex(fig.gt_line.get_color())
    assert color == matplotlib.colors.to_hex(GROUND_TRUTH_STYLE["color"]) and fig.gt_line.get_linestyle() == "-."
    others = [fig.est_line, fig.dr_line]
    assert all((matplotlib.colors.to_hex(a.get_color()), a.get_linestyle()) != (color, "-.") for a in others)
    s.goto(20)
    fig.update(s)
    assert "position error" in fig.captions["map"]


def test_redraw_is_fast_enough_headless():
    w = StepperWidget("sim-tiny")
    times = []
    for t in range(1, 15):
        w.time_slider.value = t
        times.append(w.last_redraw_seconds)
    # generous bound for a loaded CI machine; the benchmark reports the real figures
    assert np.median(times) < 1.0


def test_standalone_page_is_package_data():
    path = app_notebook_path()
    assert path.is_file() and path.parent.name == "visla_edu"
    assert "StepperWidget" in path.read_text()


def test_standalone_notebook_executes(monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    nbformat = pytest.importorskip("nbformat")
    monkeypatch.setenv("VISLA_EDU_STEPPER_DATASET", "sim-tiny")
    nb = nbformat.read(app_notebook_path(), as_version=4)
    nbclient.NotebookClient(nb, timeout=120, kernel_name="python3",
                            resources={"metadata": {"path": str(app_notebook_path().parent)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert any("application/vnd.jupyter.widget-view+json" in o.get("data", {}) for o in outputs), outputs
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert os.environ["VISLA_EDU_STEPPER_DATASET"] == "sim-tiny"


def test_stepper_figure_alone_renders_png():
    from visla_edu.stepper import Stepper

    s = Stepper("sim-tiny", mode="mapping")
    fig = StepperFigure(dpi=50, annotate=True)
    s.goto(10)
    fig.update(s)
    a = fig.render_png()
    s.goto(11)
    fig.update(s)
    b = fig.render_png()
    assert a.startswith(b"\x89PNG") and a != b
    assert fig.image_text.get_text() == fig.captions["frame"] and "frame 11" in fig.captions["frame"]
    fig.follow = False  # the whole drive: the map background is rebuilt once
    fig.update(s)
    assert fig.render_png() != b


def test_plotting_helpers_added_for_the_stepper():
    from matplotlib.figure import Figure

    from visla_edu.plotting import covariance_ellipse, covariance_ellipses, plot_nis

    rng = np.random.default_rng(0)
    means = rng.normal(size=(4, 2))
    A = rng.normal(size=(4, 2, 2))
    covs = A @ np.swapaxes(A, 1, 2)
    batch = covariance_ellipses(means, covs, n_sigma=3.0, n_points=25)
    assert batch.shape == (4, 25, 2)
    for m, c, e in zip(means, covs, batch):
        np.testing.assert_allclose(e, covariance_ellipse(m, c, n_sigma=3.0, n_points=25), atol=1e-12)
    assert covariance_ellipses(np.zeros((0, 2)), np.zeros((0, 2, 2))).shape == (0, 40, 2)

    ax = Figure().add_subplot()
    dof = np.array([0, 40, 40, 40])
    nis = np.array([np.nan, 40.0, 41.0, 400.0])
    assert plot_nis(nis, dof, ax=ax) is ax
    assert "67% of updates inside the band" in ax.get_title()
