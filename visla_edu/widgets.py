"""The filter stepper as an interactive view (ipywidgets + matplotlib).

In a notebook, one line shows it::

    from visla_edu.widgets import StepperWidget; StepperWidget("sim")

As a page of its own (Voila)::

    visla-edu stepper --port 8866          # or: python -c "from visla_edu.widgets import serve; serve(wait=True)"

The view is thin: every control either re-configures the :class:`~visla_edu.stepper.Stepper`
(dataset, mode, noise settings: the filter restarts from frame 0) or sets its time (slider,
play, step buttons), and then the figure is redrawn. The figure is one persistent matplotlib
figure (:class:`StepperFigure`) whose artists are updated in place and rendered to a PNG that
replaces the content of an ``ipywidgets.Output``; no ipympl is needed and the same image shows
in JupyterLab, classic notebooks and Voila.
"""

import base64
import contextlib
import importlib.util
import io
import os
import subprocess
import sys
import time
from pathlib import Path

import ipywidgets as w
import numpy as np

from visla_edu import filters
from visla_edu.filters import FilterConfig, FilterDivergedError
from visla_edu.stepper import MODE_LABELS, NOISE_FIELDS, Stepper, dataset_choices, world_position_covariance

__all__ = ["StepperFigure", "StepperWidget", "serve", "app_notebook_path", "NOISE_RANGES"]

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
_STATUS_STYLE = {  # status -> (marker, colour, label)
    filters.OBS_USED: ("o", "C0", "used"),
    filters.OBS_NEW: ("s", "C2", "new landmark"),
    filters.OBS_GATED: ("x", "C3", "gated (outlier)"),
    filters.OBS_NO_DEPTH: ("v", "m", "no depth"),
    filters.OBS_FAR: (".", "0.5", "too far / unused"),
}


def app_notebook_path():
    """Path of the standalone stepper page (``stepper_app.ipynb``, shipped in the package)."""
    return Path(__file__).resolve().parent / "stepper_app.ipynb"


# ====================================================================== the figure


class StepperFigure:
    """One persistent matplotlib figure of a :class:`Stepper`, redrawn by updating its artists.

    Panels: the top-down map (estimated trajectory, dead reckoning and ground truth, the
    pose covariance ellipse, the map built so far, the active landmarks with their ellipses),
    the current stereo frame (left and right image: observed and predicted pixels, the
    innovations, gated outliers) and NIS/dof over time with the 95% band of ``chi2(dof)/dof``.

    Speed: the right-hand panels' axes, ticks and legends are drawn once into a background,
    the map's axes, ticks and ground truth into a second one (redrawn only when the map view
    moves, its legend pasted from cached pixels); each frame restores that background and
    draws only the time-dependent artists on top (blitting on the Agg canvas), then encodes
    the PNG. Text is slow to render, so besides the title the per-frame numbers are only in
    :attr:`captions` unless ``annotate=True`` (the widget shows them as HTML).

    Parameters
    ----------
    figsize : (float, float)
        Inches.
    dpi : float
        Resolution of the rendered PNG.
    n_sigma : float
        Size of the covariance ellipses.
    follow : bool
        Map view around the current pose (at least ``follow_radius`` metres each way) instead
        of the whole drive. The view moves in jumps when the pose nears its edge.
    follow_radius : float
    annotate : bool
        Also draw the per-frame captions (observation counts, NIS, ellipse size) in the figure.

    Attributes
    ----------
    captions : dict of str -> str
        ``"frame"``, ``"map"``, ``"nis"``: what the current frame shows, in words.
    """

    def __init__(self, figsize=(12.0, 7.0), dpi=72, n_sigma=2.0, follow=True, follow_radius=40.0,
                 annotate=False):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.dpi = dpi
        self.n_sigma = n_sigma
        self.follow = follow
        self.follow_radius = follow_radius
        self.annotate = annotate
        self.captions = {"frame": "", "map": "", "nis": ""}
        self.fig = Figure(figsize=figsize, dpi=dpi)
        FigureCanvasAgg(self.fig)
        gs = self.fig.add_gridspec(3, 2, width_ratios=(1.0, 1.15), left=0.06, right=0.985, bottom=0.075,
                                   top=0.86, wspace=0.14, hspace=0.45)
        self.ax_map = self.fig.add_subplot(gs[:, 0])
        self.ax_left = self.fig.add_subplot(gs[0, 1])
        self.ax_right = self.fig.add_subplot(gs[1, 1])
        self.ax_nis = self.fig.add_subplot(gs[2, 1])
        self.title = self.fig.text(0.01, 0.975, "", fontsize="large", ha="left", va="top")
        self._dynamic = [self.title]
        self._setup_key = None
        self._setup_serial = 0
        self._base = self._base_state = None  # right-hand panels, legends (no map, no dynamic artists)
        self._map_bg = self._map_state = None  # base + the map's axes, ticks, ground truth, legend
        self._legend_pixels = None
        self._center = None
        self._whole_serial = None
        self._build_map()
        self._image = {ax: self._build_image(ax, side) for ax, side in
                       ((self.ax_left, "left"), (self.ax_right, "right"))}
        self._build_nis()
        handles = [self._image[self.ax_left][k] for k in
                   (filters.OBS_USED, "pred", filters.OBS_NEW, filters.OBS_GATED, filters.OBS_NO_DEPTH,
                    filters.OBS_FAR)]
        self.fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.99, 0.985), ncol=3,
                        fontsize="small", frameon=False, handletextpad=0.3, columnspacing=1.0,
                        title="stereo frame: observed by status, predicted (lines: innovations)",
                        title_fontsize="small")

    def _dyn(self, artist):
        self._dynamic.append(artist)
        return artist

    def _caption_text(self, ax, x, y, **kw):
        """A per-frame text artist, only when ``annotate`` (else None)."""
        return self._dyn(ax.text(x, y, "", transform=ax.transAxes, fontsize="small", **kw)) if self.annotate else None

    # ---------------------------------------------------------------- artists, once
    def _build_map(self):
        from matplotlib.collections import LineCollection

        ax = self.ax_map
        self.gt_line, = ax.plot([], [], "-", color="k", lw=1.2, alpha=0.6, label="ground truth", zorder=2)
        self.gt_points = ax.scatter(np.zeros(0), np.zeros(0), s=2, c="0.8", zorder=1, label="true landmarks")
        self.gt_pose, = ax.plot([], [], "o", color="k", ms=7, mfc="none", zorder=7)
        self.dr_line, = ax.plot([], [], "--", color="C3", lw=1.2, label="dead reckoning", zorder=3)
        self.map_points = ax.scatter(np.zeros(0), np.zeros(0), s=3, c="0.45", zorder=2, label="map so far")
        self.active_ellipses = LineCollection([], colors="C1", linewidths=0.7, alpha=0.7, zorder=4)
        ax.add_collection(self.active_ellipses)
        self.active_points = ax.scatter(np.zeros(0), np.zeros(0), s=10, c="C1", zorder=5,
                                        label=f"active landmarks ({self.n_sigma:g}σ)")
        self.est_line, = ax.plot([], [], "-", color="C0", lw=2, label="estimate", zorder=6)
        self.pose_ellipse, = ax.plot([], [], "-", color="C0", lw=1.5, zorder=8,
                                     label=f"pose {self.n_sigma:g}σ (x-y)")
        self.heading, = ax.plot([], [], "-", color="C0", lw=2.5, zorder=8)
        self.pose_marker, = ax.plot([], [], "o", color="C0", ms=6, zorder=9)
        for a in (self.gt_pose, self.dr_line, self.map_points, self.active_ellipses, self.active_points,
                  self.est_line, self.pose_ellipse, self.heading, self.pose_marker):
            self._dyn(a)
        self.map_text = self._caption_text(ax, 0.01, 0.01, va="bottom", zorder=10,
                                           bbox=dict(fc="white", ec="none", alpha=0.75))
        ax.set_xlabel("x (m, world = first IMU frame)")
        ax.set_ylabel("y (m)")
        ax.grid(True, alpha=0.3)

    def _build_image(self, ax, side):
        from matplotlib.collections import LineCollection

        arts = {"innov": self._dyn(LineCollection([], colors="C1", linewidths=1.0, zorder=2))}
        ax.add_collection(arts["innov"])
        for code, (marker, color, label) in _STATUS_STYLE.items():
            if marker in ("x", "."):
                style = dict(c=color)
            else:
                style = dict(facecolors="none", edgecolors=color)
            arts[code] = self._dyn(ax.scatter(np.zeros(0), np.zeros(0), s=18 if marker != "." else 8,
                                              marker=marker, linewidths=1.0, label=label, zorder=3, **style))
        arts["pred"] = self._dyn(ax.scatter(np.zeros(0), np.zeros(0), s=5, c="C1", label="predicted", zorder=4))
        ax.set_ylabel(f"v (px, {side})", fontsize="small")
        ax.tick_params(labelsize="small")
        if side == "left":
            ax.tick_params(labelbottom=False)
            self.image_text = self._caption_text(ax, 0.0, 1.03)
        else:
            ax.set_xlabel("u (px)", fontsize="small", labelpad=1)
        return arts

    def _build_nis(self):
        from matplotlib.patches import Polygon

        ax = self.ax_nis
        self.nis_band = self._dyn(Polygon(np.zeros((0, 2)), closed=True, fc="C2", alpha=0.3, ec="none",
                                          label="95% band of χ²(dof)/dof"))
        ax.add_patch(self.nis_band)
        self.nis_line, = ax.plot([], [], ".-", color="C0", ms=2.5, lw=0.7, label="NIS / dof")
        self.nis_now = ax.axvline(0, color="k", lw=0.8, alpha=0.6)
        self._dyn(self.nis_line)
        self._dyn(self.nis_now)
        ax.axhline(1.0, color="0.4", lw=0.8, ls=":")
        ax.set_yscale("log")
        ax.set_ylim(0.02, 50)
        ax.set_xlabel("frame", fontsize="small", labelpad=1)
        ax.set_ylabel("NIS / dof", fontsize="small")
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize="small")
        ax.legend(handles=[self.nis_line, self.nis_band], loc="upper left", fontsize="x-small", ncol=2)
        self.nis_text = self._caption_text(ax, 0.0, 1.04)

    # ---------------------------------------------------------------- per dataset / mode
    def setup(self, stepper):
        """Draw what does not change with time (ground truth, image size, axes ranges)."""
        ds = stepper.dataset
        self._setup_key = self._key_of(stepper)
        self._setup_serial += 1
        self._center = None
        gt = stepper.ground_truth
        if gt is not None:
            p = gt.world_T_imu[:, :3, 3]
            self.gt_line.set_data(p[:, 0], p[:, 1])
            ok = np.isfinite(gt.landmarks[:, 0])
            self.gt_points.set_offsets(gt.landmarks[ok, :2])
        else:
            self.gt_line.set_data([], [])
            self.gt_points.set_offsets(np.zeros((0, 2)))
        self.gt_pose.set_data([], [])
        self._dr = stepper.dead_reckoning[:, :3, 3] if stepper.mode != "deadreckon" else None
        self._static_paths = [stepper.dead_reckoning[:, :2, 3]] + ([gt.world_T_imu[:, :2, 3]] if gt is not None else [])
        handles = [self.est_line, self.pose_ellipse]
        if stepper.mode != "deadreckon":
            handles += [self.dr_line, self.active_points, self.map_points]
        if gt is not None:
            handles += [self.gt_line, self.gt_points]
        self.ax_map.legend(handles=handles, loc="upper right", fontsize="x-small", framealpha=1.0)
        width, height = self._image_size(ds)
        for ax in self._image:
            ax.set_xlim(0, width)
            ax.set_ylim(height, 0)
        self.ax_nis.set_xlim(0, max(ds.num_frames - 1, 1))

    @staticmethod
    def _key_of(stepper):
        return (id(stepper), stepper.generation)

    @staticmethod
    def _image_size(ds):
        K = np.asarray(ds.K)
        width, height = 2 * K[0, 2], 2 * K[1, 2]
        if ds.num_observations:
            width = max(width, float(np.max(ds.obs_z[:, [0, 2]])) + 5)
            height = max(height, float(np.max(ds.obs_z[:, [1, 3]])) + 5)
        return width, height

    # ---------------------------------------------------------------- per time step
    def update(self, stepper):
        """Move every time-dependent artist to the stepper's current frame."""
        if self._key_of(stepper) != self._setup_key:
            self.setup(stepper)
        rec = stepper.record
        t = stepper.t
        self._update_map(stepper, rec, t)
        for ax, (cu, cv) in ((self.ax_left, (0, 1)), (self.ax_right, (2, 3))):
            self._update_image(self._image[ax], rec, cu, cv)
        counts = np.bincount(rec.status, minlength=len(filters.STATUS_NAMES))
        self.captions["frame"] = (f"frame {t}: {len(rec.ids)} observations, {counts[filters.OBS_USED]} used, "
                                  f"{counts[filters.OBS_NEW]} new, {counts[filters.OBS_GATED]} gated")
        self._update_nis(stepper, rec, t)
        ds = stepper.dataset
        self.title.set_text(f"{ds.name}: {MODE_LABELS[stepper.mode]}\nt = {t} / {ds.num_frames - 1}"
                            f"   ({stepper.time_stamps[t]:.2f} s)")
        if self.annotate:
            for artist, key in ((self.image_text, "frame"), (self.map_text, "map"), (self.nis_text, "nis")):
                artist.set_text(self.captions[key])

    def _map_box_ratio(self):
        pos = self.ax_map.get_position()
        w, h = self.fig.get_size_inches()
        return (pos.height * h) / (pos.width * w)

    def _update_map(self, stepper, rec, t):
        from visla_edu.plotting import covariance_ellipses

        traj = stepper.trajectory[:, :3, 3]
        p = rec.world_T_imu[:3, 3]
        self.est_line.set_data(traj[:, 0], traj[:, 1])
        self.pose_marker.set_data([p[0]], [p[1]])
        cov_xy = world_position_covariance(rec.world_T_imu, rec.pose_cov)[:2, :2]
        ell = covariance_ellipses(p[None, :2], cov_xy[None], self.n_sigma, 60)[0]
        self.pose_ellipse.set_data(ell[:, 0], ell[:, 1])
        if self._dr is not None:
            self.dr_line.set_data(self._dr[: t + 1, 0], self._dr[: t + 1, 1])
        else:
            self.dr_line.set_data([], [])
        gt_pose = stepper.ground_truth_pose()
        if gt_pose is not None:
            self.gt_pose.set_data([gt_pose[0, 3]], [gt_pose[1, 3]])
        _, retired = stepper.retired_landmarks()
        self.map_points.set_offsets(retired[:, :2] if len(retired) else np.zeros((0, 2)))
        means = rec.active_means
        self.active_points.set_offsets(means[:, :2] if len(means) else np.zeros((0, 2)))
        self.active_ellipses.set_segments(
            covariance_ellipses(means[:, :2], rec.active_covs[:, :2, :2], self.n_sigma, 32) if len(means) else [])
        sd = np.sqrt(np.clip(np.linalg.eigvalsh(cov_xy), 0, None))
        error = "" if gt_pose is None else f", position error {np.linalg.norm(p - gt_pose[:3, 3]):.2f} m"
        self.captions["map"] = (f"pose {self.n_sigma:g}σ ellipse (world x-y): {self.n_sigma * sd[1]:.2f} m × "
                                f"{self.n_sigma * sd[0]:.2f} m{error}\n{len(means)} active landmarks, "
                                f"{len(retired)} retired")
        half_w, half_h = self._set_map_limits(p, rec.world_T_imu[:2, 0], traj)
        arrow = 0.08 * min(half_w, half_h) * rec.world_T_imu[:2, 0]
        self.heading.set_data([p[0], p[0] + arrow[0]], [p[1], p[1] + arrow[1]])

    def _set_map_limits(self, p, heading, traj):
        """Follow: move the view only when the pose nears its edge; whole: all paths so far."""
        ax = self.ax_map
        ratio = self._map_box_ratio()
        if self.follow:
            self._whole_serial = None
            R = self.follow_radius
            half_w, half_h = (R, R * ratio) if ratio >= 1 else (R / ratio, R)
            c = self._center
            if c is None or abs(p[0] - c[0]) > 0.6 * half_w or abs(p[1] - c[1]) > 0.6 * half_h:
                direction = heading / max(np.linalg.norm(heading), 1e-9)
                c = self._center = p[:2] + 0.4 * min(half_w, half_h) * direction
                ax.set_xlim(c[0] - half_w, c[0] + half_w)
                ax.set_ylim(c[1] - half_h, c[1] + half_h)
            return half_w, half_h
        self._center = None
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        lo, hi = traj[:, :2].min(axis=0), traj[:, :2].max(axis=0)
        if self._whole_serial != self._setup_serial or lo[0] < x0 or lo[1] < y0 or hi[0] > x1 or hi[1] > y1:
            pts = np.concatenate(self._static_paths + [traj[:, :2]])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            c, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * 1.1 + 10
            half_w, half_h = max(half[0], half[1] / ratio), max(half[1], half[0] * ratio)
            ax.set_xlim(c[0] - half_w, c[0] + half_w)
            ax.set_ylim(c[1] - half_h, c[1] + half_h)
            self._whole_serial = self._setup_serial
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        return 0.5 * (x1 - x0), 0.5 * (y1 - y0)

    @staticmethod
    def _update_image(arts, rec, cu, cv):
        z = rec.z
        for code in _STATUS_STYLE:
            sel = rec.status == code
            if code == filters.OBS_FAR:
                sel |= rec.status == filters.OBS_IGNORED
            arts[code].set_offsets(z[sel][:, [cu, cv]] if np.any(sel) else np.zeros((0, 2)))
        ok = np.isfinite(rec.z_pred[:, 0])
        pred = rec.z_pred[ok][:, [cu, cv]]
        arts["pred"].set_offsets(pred if len(pred) else np.zeros((0, 2)))
        arts["innov"].set_segments(np.stack([pred, z[ok][:, [cu, cv]]], axis=1) if len(pred) else [])

    def _update_nis(self, stepper, rec, t):
        nis, dof = stepper.nis, stepper.nis_dof
        frames = np.arange(t + 1)
        ok = dof > 0
        ratio = np.full(t + 1, np.nan)
        ratio[ok] = nis[ok] / dof[ok]
        self.nis_line.set_data(frames, ratio)
        lo, hi = stepper.nis_band_series()
        f, lo, hi = frames[ok], lo[ok], hi[ok]
        self.nis_band.set_xy(np.concatenate([np.stack([f, lo], 1), np.stack([f[::-1], hi[::-1]], 1)])
                             if len(f) else np.zeros((0, 2)))
        self.nis_now.set_xdata([t, t])
        inside = f"; {100 * np.mean((ratio[ok] >= lo) & (ratio[ok] <= hi)):.0f}% of updates so far in the band" \
            if len(f) else ""
        if rec.nis_dof:
            text = f"NIS/dof = {rec.nis / rec.nis_dof:.2f} (dof {rec.nis_dof}){inside}"
        elif stepper.mode == "deadreckon":
            text = "dead reckoning: no updates, no NIS"
        else:
            text = f"no update at frame {t}{inside}"
        self.captions["nis"] = text

    # ---------------------------------------------------------------- output
    @contextlib.contextmanager
    def _hidden(self, artists):
        for a in artists:
            a.set_visible(False)
        try:
            yield
        finally:
            for a in artists:
                a.set_visible(True)

    def draw(self):
        """Render onto the Agg canvas: restore the cached background, draw the time-dependent artists.

        The backgrounds are rebuilt only when stale: the base (everything but the map and the
        dynamic artists) after :meth:`setup`, the map's when its view limits change.
        """
        canvas = self.fig.canvas
        if self._base is None or self._base_state != self._setup_serial:
            with self._hidden(self._dynamic + [self.ax_map]):
                canvas.draw()
            self._base = canvas.copy_from_bbox(self.fig.bbox)
            self._base_state = self._setup_serial
            self._map_state = self._legend_pixels = None
        map_state = (self._setup_serial, self.follow, self.ax_map.get_xlim(), self.ax_map.get_ylim())
        if map_state != self._map_state:
            canvas.restore_region(self._base)
            legend = self.ax_map.get_legend()
            cached = self._legend_pixels is not None and legend is not None
            with self._hidden(self._dynamic + ([legend] if cached else [])):
                self.fig.draw_artist(self.ax_map)
            if cached:
                canvas.restore_region(self._legend_pixels)  # same place: the map legend never moves
            elif legend is not None:
                self._legend_pixels = canvas.copy_from_bbox(legend.get_window_extent(canvas.get_renderer()))
            self._map_bg = canvas.copy_from_bbox(self.fig.bbox)
            self._map_state = map_state
        else:
            canvas.restore_region(self._map_bg)
        for a in self._dynamic:
            if a is self.title:
                self.fig.draw_artist(a)
            else:
                a.axes.draw_artist(a)

    def render_png(self):
        """The figure as PNG bytes (fast zlib setting: the image is shown once)."""
        from PIL import Image

        self.draw()
        rgba = np.asarray(self.fig.canvas.buffer_rgba())
        buf = io.BytesIO()
        Image.fromarray(rgba[..., :3]).save(buf, format="png", compress_level=1)
        return buf.getvalue()


# ====================================================================== the widget


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
        Initial dataset (a name from :func:`visla_edu.stepper.dataset_choices`, e.g. ``"sim"``,
        ``"sim-tiny"``, ``"03"``, ``"10"``, or a loaded dataset).
    mode : {"deadreckon", "mapping", "vio", "slam"}
    config : FilterConfig, optional
    data_dir : str or os.PathLike, optional
        Folder of the course files (default: ``VISLA_EDU_DATA``).
    **figure_options
        Passed to :class:`StepperFigure` (``figsize``, ``dpi``, ``n_sigma``, ``follow``...).

    Attributes
    ----------
    stepper : visla_edu.stepper.Stepper
        The model; the view only calls ``goto``/``configure`` on it.
    figure : StepperFigure
    dataset_dropdown, mode_dropdown, view_toggle : ipywidgets selection widgets
    play : ipywidgets.Play
        Linked to ``time_slider``.
    time_slider : ipywidgets.IntSlider
    first_button, back_button, step_button, jump_button, end_button : ipywidgets.Button
        Frame 0, one back, one forward, ten forward, the last frame.
    noise_sliders : dict of str -> slider
        One per :data:`visla_edu.stepper.NOISE_FIELDS`; a change re-runs the filter.
    defaults_button : ipywidgets.Button
        Restore the default noise settings.
    status : ipywidgets.HTML
        ``t = ...`` and what the current frame did; errors show here.
    output : ipywidgets.Output
        Holds the rendered figure.
    render_count : int
        Figures rendered so far.
    last_redraw_seconds, last_update_seconds : float
    """

    def __init__(self, dataset="sim", mode="slam", config=None, data_dir=None, **figure_options):
        self.data_dir = data_dir
        self._busy = _Busy()
        self.render_count = 0
        self.last_redraw_seconds = 0.0
        self.last_update_seconds = 0.0
        self.stepper = Stepper(dataset, mode=mode, config=config, data_dir=data_dir)
        self.figure = StepperFigure(**figure_options)
        self.last_update_seconds = self.stepper.last_update_seconds
        self._build_controls(dataset)
        super().__init__([self._header, self._time_row, self._noise_box, self.status, self.output],
                         layout=w.Layout(width="100%"))
        self.add_class("visla-stepper")
        self.redraw()

    # ------------------------------------------------------------ controls
    def _build_controls(self, dataset):
        s = self.stepper
        choices = dataset_choices(self.data_dir)
        if isinstance(dataset, str):
            if dataset not in [v for _, v in choices]:
                choices.append((dataset, dataset))
            value = dataset
        else:
            choices.append((f"{dataset.name} (given)", dataset))
            value = dataset
        self.dataset_dropdown = w.Dropdown(options=choices, value=value, description="dataset",
                                           layout=w.Layout(width="auto", min_width="22em"))
        self.mode_dropdown = w.Dropdown(options=[(label, m) for m, label in MODE_LABELS.items()],
                                        value=s.mode, description="mode", layout=w.Layout(width="auto"))
        self.view_toggle = w.ToggleButtons(options=[("follow", True), ("whole drive", False)],
                                           value=self.figure.follow, description="map view",
                                           style={"button_width": "8em", "description_width": "5em"})
        self.dataset_dropdown.observe(self._on_dataset, names="value")
        self.mode_dropdown.observe(self._on_mode, names="value")
        self.view_toggle.observe(self._on_view, names="value")
        self._header = w.HBox([self.dataset_dropdown, self.mode_dropdown, self.view_toggle],
                              layout=w.Layout(flex_flow="row wrap"))

        T = s.num_frames
        self.play = w.Play(value=0, min=0, max=T - 1, step=1, interval=250, description="play",
                           show_repeat=False)
        self.time_slider = w.IntSlider(value=0, min=0, max=T - 1, description="frame t",
                                       continuous_update=False, layout=w.Layout(width="40em"))
        self._play_link = w.link((self.play, "value"), (self.time_slider, "value"))
        self.time_slider.observe(self._on_time, names="value")

        def button(text, tooltip, handler):
            b = w.Button(description=text, tooltip=tooltip, layout=w.Layout(width="auto"))
            b.on_click(handler)
            return b

        self.first_button = button("first", "frame 0", lambda _: self._set_time(0))
        self.back_button = button("◀ back", "one frame back", lambda _: self._set_time(self.stepper.t - 1))
        self.step_button = button("step ▶", "one frame forward", lambda _: self._set_time(self.stepper.t + 1))
        self.jump_button = button("+10 ▶▶", "ten frames forward", lambda _: self._set_time(self.stepper.t + 10))
        self.end_button = button("end", "last frame (runs the filter to the end)",
                                 lambda _: self._set_time(self.stepper.num_frames - 1))
        self._time_row = w.HBox([self.play, self.time_slider, self.first_button, self.back_button,
                                 self.step_button, self.jump_button, self.end_button],
                                layout=w.Layout(flex_flow="row wrap", align_items="center"))

        defaults = FilterConfig()
        self.noise_sliders = {}
        for name in NOISE_FIELDS:
            lo, hi = NOISE_RANGES[name]
            label, tip = _NOISE_DESCRIPTIONS[name]
            value = getattr(s.config, name)
            common = dict(description=label, tooltip=tip, continuous_update=False,
                          style={"description_width": "8em"}, layout=w.Layout(width="24em"))
            if name == "gate_probability":
                slider = w.FloatSlider(value=value, min=min(lo, value), max=hi, step=0.0005,
                                       readout_format=".4f", **common)
            else:
                lo, hi = min(lo, value, getattr(defaults, name)), max(hi, value, getattr(defaults, name))
                slider = w.FloatLogSlider(value=value, base=10, min=np.log10(lo), max=np.log10(hi),
                                          step=0.05, readout_format=".3g", **common)
            slider.observe(self._on_noise, names="value")
            self.noise_sliders[name] = slider
        self.defaults_button = w.Button(description="defaults", tooltip="restore the default noise settings",
                                        layout=w.Layout(width="7em"))
        self.defaults_button.on_click(self._on_defaults)
        grid = w.GridBox(list(self.noise_sliders.values()) + [self.defaults_button],
                         layout=w.Layout(grid_template_columns="repeat(3, 25em)"))
        self._noise_box = w.Accordion(children=[grid], selected_index=None)
        self._noise_box.set_title(0, "noise and initialisation (a change re-runs the filter from frame 0)")
        self.status = w.HTML(layout=w.Layout(min_height="2.6em"))
        self.output = w.Output(layout=w.Layout(min_height="300px"))

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
        try:
            self.stepper.goto(int(t))
        except FilterDivergedError as err:
            error = err
        self.last_update_seconds = self.stepper.last_update_seconds
        if self.time_slider.value != self.stepper.t:
            with self._busy():
                self.time_slider.value = self.stepper.t
                self.play.playing = False
        self.redraw(error=error)

    def _on_dataset(self, change):
        if self._busy:
            return
        self._reconfigure(dict(dataset=change["new"]), keep_time=False,
                          revert=lambda: setattr(self.dataset_dropdown, "value", change["old"]))

    def _on_mode(self, change):
        if self._busy:
            return
        self._reconfigure(dict(mode=change["new"]), keep_time=True,
                          revert=lambda: setattr(self.mode_dropdown, "value", change["old"]))

    def _on_noise(self, change):
        if self._busy:
            return
        name = next(k for k, v in self.noise_sliders.items() if v is change["owner"])
        self._reconfigure({name: float(change["new"])}, keep_time=True,
                          revert=lambda: setattr(change["owner"], "value", change["old"]))

    def _on_defaults(self, _):
        defaults = FilterConfig()
        with self._busy():
            for name, slider in self.noise_sliders.items():
                slider.value = getattr(defaults, name)
        self._reconfigure({name: getattr(defaults, name) for name in self.noise_sliders}, keep_time=True)

    def _on_view(self, change):
        self.figure.follow = bool(change["new"])
        self.redraw()

    def _reconfigure(self, settings, keep_time, revert=None):
        """Re-configure the stepper (it restarts at frame 0), then go back to the same frame."""
        t = self.stepper.t
        self.play.playing = False
        self._show_status("<i>re-running the filter...</i>")
        try:
            self.stepper.configure(**settings)
        except (ValueError, FileNotFoundError, TypeError) as err:
            if revert is not None:
                with self._busy():
                    revert()
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



def _html(text):
    import html

    return html.escape(str(text))


# ====================================================================== Voila page


def serve(port=8866, open_browser=False, data_dir=None, dataset=None, mode=None, wait=False, **popen_options):
    """Serve the stepper as a standalone page with Voila (``voila stepper_app.ipynb --port N``).

    Parameters
    ----------
    port : int
    open_browser : bool
        Let Voila open the page in a browser.
    data_dir : str or os.PathLike, optional
        Folder of the course files, passed to the page as ``VISLA_EDU_DATA``.
    dataset : str, optional
        Dataset the page opens with (default ``"sim"``), via ``VISLA_EDU_STEPPER_DATASET``.
    mode : str, optional
        Filter mode the page opens with (default ``"slam"``), via ``VISLA_EDU_STEPPER_MODE``.
    wait : bool
        Block until the server exits (Ctrl-C stops it); otherwise return at once.
    **popen_options
        Passed to :class:`subprocess.Popen` (e.g. ``stdout=``, ``stderr=`` to capture the log).

    Returns
    -------
    subprocess.Popen
        The Voila process (the page is at ``http://localhost:<port>/``); stop it with
        ``terminate()``.
    """
    notebook = app_notebook_path()
    if not notebook.is_file():
        raise FileNotFoundError(f"the stepper page {notebook} is missing from the installed package")
    cmd = [sys.executable, "-m", "voila", str(notebook), f"--port={int(port)}"]
    if not open_browser:
        cmd.append("--no-browser")
    env = dict(os.environ)
    if data_dir is not None:
        from visla_edu import data

        env[data.ENV_VAR] = str(Path(data_dir).expanduser().resolve())
    if dataset is not None:
        env["VISLA_EDU_STEPPER_DATASET"] = str(dataset)
    if mode is not None:
        env["VISLA_EDU_STEPPER_MODE"] = str(mode)
    if importlib.util.find_spec("voila") is None:
        raise RuntimeError("the stepper page needs Voila: pip install voila")
    proc = subprocess.Popen(cmd, env=env, cwd=str(notebook.parent), **popen_options)
    if wait:
        try:
            proc.wait()
        except KeyboardInterrupt:
            proc.terminate()
            proc.wait(timeout=10)
    return proc
