"""The filter stepper as an interactive view (ipywidgets + matplotlib): ``StepperWidget("sim")``.

Every control re-configures the :class:`~visla_edu.stepper.Stepper` (dataset, mode, noise: the filter restarts
from frame 0) or sets its time; the figure is then rendered to a PNG in an ``ipywidgets.Output``: no ipympl, the
same image in JupyterLab, classic notebooks and Voila (a page of its own: :mod:`visla_edu.stepper.app`).
"""

import base64
import contextlib
import time

import ipywidgets as w
import numpy as np

from visla_edu.codes import SLAM
from visla_edu.filters import FilterConfig, FilterDivergedError
from visla_edu.stepper.figure import StepperFigure
from visla_edu.stepper.model import MODE_LABELS, NOISE_FIELDS, Stepper, dataset_choices

__all__ = ["StepperWidget", "NOISE_RANGES"]

#: Slider ranges ``(min, max)`` of the noise and initialisation settings; log scale for sigmas.
NOISE_RANGES = {
    "sigma_pixel": (0.1, 50.0),
    "sigma_linear_velocity": (0.01, 10.0),
    "sigma_angular_velocity": (1e-4, 1.0),
    "landmark_prior_sigma": (0.01, 100.0),
    "landmark_prior_inflation": (0.1, 10.0),
    "gate_probability": (0.9, 1.0),
}
_NOISE_DESCRIPTIONS = {
    "sigma_pixel": ("pixel σ (px)", "observation noise: R = σ² I per stereo pixel"),
    "sigma_linear_velocity": ("v σ (m/s)", "IMU linear-velocity noise (motion noise W)"),
    "sigma_angular_velocity": ("ω σ (rad/s)", "IMU angular-velocity noise (motion noise W)"),
    "landmark_prior_sigma": ("landmark σ (m)", "isotropic prior of a new landmark"),
    "landmark_prior_inflation": ("prior inflation", "scale of the triangulation covariance of a new landmark"),
    "gate_probability": ("gate prob.", "chi-square gate (4 dof) probability; 1 = no gating"),
}


class _Busy:
    """Re-entrancy guard: changes made by the view itself do not trigger more work."""

    def __init__(self):
        self.depth = 0

    @contextlib.contextmanager
    def __call__(self):
        self.depth += 1
        try:
            yield
        finally:
            self.depth -= 1

    def __bool__(self):
        return self.depth > 0


class StepperWidget(w.VBox):
    """The filter stepper: controls and figure (displays itself as a cell's last expression).

    Parameters
    ----------
    dataset : str or Dataset
        Initial dataset, a name of :func:`visla_edu.stepper.dataset_choices` or a loaded one.
    mode, config, data_dir, filter_factory
        As :class:`visla_edu.stepper.Stepper`. With a ``filter_factory`` the mode menu is disabled, and any error
        its ``step()`` raises is shown under the figure.
    **figure_options
        Passed to :class:`~visla_edu.stepper.figure.StepperFigure` (``figsize``, ``dpi``, ``follow``...).

    Attributes
    ----------
    stepper : visla_edu.stepper.Stepper
        The model; the view only calls ``goto``/``configure`` on it.
    figure : visla_edu.stepper.figure.StepperFigure
    noise_sliders : dict of str -> slider
        One per :data:`visla_edu.stepper.NOISE_FIELDS`; a change re-runs the filter.
    status, output : ipywidgets.HTML, ipywidgets.Output
        ``t = ...``, what the current frame did and errors; the rendered figure.
    """

    def __init__(self, dataset="sim", mode=SLAM, config=None, data_dir=None, filter_factory=None, **figure_options):
        self.data_dir = data_dir
        self._busy = _Busy()
        self.render_count = 0
        self.last_redraw_seconds = 0.0
        self.last_update_seconds = 0.0
        self.stepper = Stepper(dataset, mode=mode, config=config, data_dir=data_dir, filter_factory=filter_factory)
        self.figure = StepperFigure(**figure_options)
        self.last_update_seconds = self.stepper.last_update_seconds
        self._header = self._build_header(dataset)
        self._time_row = self._build_time_row()
        self._noise_box = self._build_noise_box()
        self.status = w.HTML(layout=w.Layout(min_height="2.6em"))
        self.output = w.Output(layout=w.Layout(min_height="300px"))
        super().__init__([self._header, self._time_row, self._noise_box, self.status, self.output],
                         layout=w.Layout(width="100%"))
        self.add_class("visla-stepper")
        self.redraw()

    # ------------------------------------------------------------ controls
    def _build_header(self, dataset):
        """Dataset and mode menus, map-view toggle."""
        choices = dataset_choices(self.data_dir)
        if not isinstance(dataset, str):
            choices.append((f"{dataset.name} (given)", dataset))
        elif dataset not in [v for _, v in choices]:
            choices.append((dataset, dataset))
        self.dataset_dropdown = w.Dropdown(options=choices, value=dataset, description="dataset",
                                           layout=w.Layout(width="auto", min_width="22em"))
        self.mode_dropdown = w.Dropdown(options=[(label, m) for m, label in MODE_LABELS.items()],
                                        value=self.stepper.mode, description="mode", layout=w.Layout(width="auto"),
                                        disabled=self.stepper.filter_factory is not None)
        self.view_toggle = w.ToggleButtons(options=[("follow", True), ("whole drive", False)],
                                           value=self.figure.follow, description="map view",
                                           style={"button_width": "8em", "description_width": "5em"})
        self.dataset_dropdown.observe(self._on_dataset, names="value")
        self.mode_dropdown.observe(self._on_mode, names="value")
        self.view_toggle.observe(self._on_view, names="value")
        return w.HBox([self.dataset_dropdown, self.mode_dropdown, self.view_toggle],
                      layout=w.Layout(flex_flow="row wrap"))

    def _build_time_row(self):
        """Play button and time slider (linked), step buttons."""
        T = self.stepper.num_frames
        self.play = w.Play(value=0, min=0, max=T - 1, step=1, interval=250, description="play",
                           show_repeat=False)
        self.time_slider = w.IntSlider(value=0, min=0, max=T - 1, description="frame t",
                                       continuous_update=False, layout=w.Layout(width="40em"))
        self._play_link = w.link((self.play, "value"), (self.time_slider, "value"))
        self.time_slider.observe(self._on_time, names="value")
        self.first_button = _button("first", "frame 0", lambda _: self._set_time(0))
        self.back_button = _button("◀ back", "one frame back", lambda _: self._set_time(self.stepper.t - 1))
        self.step_button = _button("step ▶", "one frame forward", lambda _: self._set_time(self.stepper.t + 1))
        self.jump_button = _button("+10 ▶▶", "ten frames forward", lambda _: self._set_time(self.stepper.t + 10))
        self.end_button = _button("end", "last frame (runs the filter to the end)",
                                  lambda _: self._set_time(self.stepper.num_frames - 1))
        return w.HBox([self.play, self.time_slider, self.first_button, self.back_button,
                       self.step_button, self.jump_button, self.end_button],
                      layout=w.Layout(flex_flow="row wrap", align_items="center"))

    def _build_noise_box(self):
        """One slider per noise setting and a defaults button, in a closed accordion."""
        in_use = self.stepper.config_in_use  # resolved: "auto" settings carry the measured values
        self.noise_sliders = {name: _noise_slider(name, _slider_value(getattr(in_use, name))) for name in NOISE_FIELDS}
        for slider in self.noise_sliders.values():
            slider.observe(self._on_noise, names="value")
        self.defaults_button = w.Button(description="defaults", tooltip="restore the default noise settings",
                                        layout=w.Layout(width="7em"))
        self.defaults_button.on_click(self._on_defaults)
        grid = w.GridBox(list(self.noise_sliders.values()) + [self.defaults_button],
                         layout=w.Layout(grid_template_columns="repeat(3, 25em)"))
        box = w.Accordion(children=[grid], selected_index=None)
        box.set_title(0, "noise and initialisation (a change re-runs the filter from frame 0)")
        return box

    # ------------------------------------------------------------ handlers
    def _set_time(self, t):
        self.time_slider.value = int(np.clip(t, 0, self.stepper.num_frames - 1))

    def _on_time(self, change):
        if self._busy:
            return
        self.goto(change["new"])

    def goto(self, t):
        """Set the stepper's time to ``t`` and redraw (what the slider and buttons do)."""
        error = None
        if int(t) - self.stepper.frontier > 50:
            self._show_status(f"<i>running the filter from frame {self.stepper.frontier} to {int(t)}...</i>")
        # A student's filter may fail in any way: show it instead of losing it in a callback.
        caught = FilterDivergedError if self.stepper.filter_factory is None else Exception
        try:
            self.stepper.goto(int(t))
        except caught as err:
            error = err
        self.last_update_seconds = self.stepper.last_update_seconds
        if self.time_slider.value != self.stepper.t:
            with self._busy():
                self.time_slider.value = self.stepper.t
                self.play.playing = False
        self.redraw(error=error)

    def _on_dataset(self, change):
        if not self._busy:
            self._reconfigure({"dataset": change["new"]}, keep_time=False, change=change)

    def _on_mode(self, change):
        if not self._busy:
            self._reconfigure({"mode": change["new"]}, keep_time=True, change=change)

    def _on_noise(self, change):
        if not self._busy:
            name = next(k for k, v in self.noise_sliders.items() if v is change["owner"])
            self._reconfigure({name: float(change["new"])}, keep_time=True, change=change)

    def _on_defaults(self, _):
        defaults = FilterConfig()
        self._reconfigure({name: getattr(defaults, name) for name in self.noise_sliders}, keep_time=True)
        in_use = self.stepper.config_in_use
        with self._busy():
            for name, slider in self.noise_sliders.items():
                slider.value = _slider_value(getattr(in_use, name))

    def _on_view(self, change):
        self.figure.follow = bool(change["new"])
        self.redraw()

    def _reconfigure(self, settings, keep_time, change=None):
        """Re-configure the stepper (it restarts at frame 0), then go back to the same frame; a refused ``change``
        (the control's) is reverted."""
        t = self.stepper.t
        self.play.playing = False
        self._show_status("<i>re-running the filter...</i>")
        try:
            self.stepper.configure(**settings)
        except (ValueError, FileNotFoundError, TypeError) as err:
            if change is not None:
                with self._busy():
                    change["owner"].value = change["old"]
            self.redraw(error=err)
            return
        T = self.stepper.num_frames
        t = min(t, T - 1) if keep_time else 0
        with self._busy():
            self.time_slider.max = T - 1
            self.play.max = T - 1
            self.time_slider.value = t
        self.goto(t)

    # ------------------------------------------------------------ drawing
    def _show_status(self, extra=""):
        s = self.stepper
        c = self.figure.captions
        frame = c["frame"].split(": ", 1)[-1]
        self.status.value = (
            f"<b>t = {s.t}</b> / {s.num_frames - 1} ({s.time_stamps[s.t]:.2f} s) &middot; {_html(frame)}"
            f" &middot; {_html(c['nis'])}<br>{_html(c['map']).replace(chr(10), ' &middot; ')}"
            f"<br><small>{_html(s.dataset.label or s.dataset.name)} &middot; frontier {s.frontier} &middot; "
            f"state update {1e3 * self.last_update_seconds:.1f} ms &middot; "
            f"redraw {1e3 * self.last_redraw_seconds:.0f} ms &middot; renders {self.render_count}</small>"
            + (f"<br>{extra}" if extra else ""))

    def redraw(self, error=None):
        """Update the figure to the stepper's frame and replace the image in ``output``."""
        start = time.perf_counter()
        self.figure.update(self.stepper)
        png = self.figure.render_png()
        self.output.outputs = ({
            "output_type": "display_data",
            "data": {"image/png": base64.b64encode(png).decode("ascii"),
                     "text/plain": f"<stepper figure, t = {self.stepper.t}>"},
            "metadata": {},
        },)
        self.render_count += 1
        self.last_redraw_seconds = time.perf_counter() - start
        extra = ""
        if error is not None:
            extra = (f"<span style='color:#b00'><b>{type(error).__name__}:</b> {_html(str(error))}</span>"
                     + (" (stopped at the last good frame; change the noise settings to re-run)"
                        if isinstance(error, FilterDivergedError) else ""))
        self._show_status(extra)


def _button(text, tooltip, handler):
    b = w.Button(description=text, tooltip=tooltip, layout=w.Layout(width="auto"))
    b.on_click(handler)
    return b


def _slider_value(value):
    """One number for a slider: a per-axis setting shows its largest axis."""
    return float(np.max(value))


def _noise_slider(name, value):
    """Slider over :data:`NOISE_RANGES`, widened to hold ``value``: the gate's linear, sigmas' log."""
    lo, hi = NOISE_RANGES[name]
    label, tip = _NOISE_DESCRIPTIONS[name]
    common = dict(description=label, tooltip=tip, continuous_update=False,
                  style={"description_width": "8em"}, layout=w.Layout(width="24em"))
    if name == "gate_probability":
        return w.FloatSlider(value=value, min=min(lo, value), max=hi, step=0.0005, readout_format=".4f", **common)
    lo, hi = min(lo, value), max(hi, value)
    return w.FloatLogSlider(value=value, base=10, min=np.log10(lo), max=np.log10(hi), step=0.05,
                            readout_format=".3g", **common)


def _html(text):
    import html

    return html.escape(str(text))
