"""The stepper's figure (no ipywidgets): a persistent matplotlib figure rendering a :class:`Stepper` to PNG bytes."""

import contextlib
import io

import numpy as np

from visla_edu.codes import (DEADRECKON, OBS_DELAYED, OBS_FAR, OBS_GATED, OBS_IGNORED, OBS_NEW, OBS_NO_DEPTH, OBS_USED,
                              STATUS_NAMES)
from visla_edu.plotting import GROUND_TRUTH_STYLE, PALETTE, STYLES
from visla_edu.stepper.model import MODE_LABELS, world_position_covariance

__all__ = ["StepperFigure"]

_STATUS_STYLE = {  # status -> (marker, colour, label)
    OBS_USED: ("o", PALETTE["blue"], "used"),
    OBS_NEW: ("s", PALETTE["bluish_green"], "new landmark"),
    OBS_GATED: ("x", PALETTE["vermillion"], "gated (outlier)"),
    OBS_NO_DEPTH: ("v", PALETTE["reddish_purple"], "no depth"),
    OBS_FAR: (".", PALETTE["grey"], "too far / unused"),
    OBS_DELAYED: ("d", PALETTE["sky_blue"], "held for its track's update"),
}


class StepperFigure:
    """One persistent matplotlib figure of a :class:`Stepper`, redrawn by updating its artists.

    Panels: the top-down map, the stereo frame (left and right: observed and predicted pixels, innovations) and
    NIS/dof over time with the 95% band of ``chi2(dof)/dof``. What does not change is drawn once into cached backgrounds
    (the map's redrawn only when its view moves, :meth:`draw`); each frame blits the time-dependent artists on top.
    Text is slow, so besides the title the per-frame numbers are only in :attr:`captions` unless ``annotate``.

    Parameters
    ----------
    figsize, dpi : (float, float), float
        Inches; the PNG's resolution.
    n_sigma : float
        Size of the covariance ellipses.
    follow : bool
        Map view around the current pose (at least ``follow_radius`` metres each way, moving in jumps when the
        pose nears its edge) instead of the whole drive.

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
        handles = [self._image[self.ax_left][k] for k in (OBS_USED, "pred", OBS_NEW, OBS_GATED, OBS_NO_DEPTH, OBS_FAR)]
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
        self.gt_line, = ax.plot([], [], label="ground truth", zorder=2, **GROUND_TRUTH_STYLE)
        self.gt_points = ax.scatter(np.zeros(0), np.zeros(0), s=2, c="0.8", zorder=1, label="true landmarks")
        self.gt_pose, = ax.plot([], [], "o", color=GROUND_TRUTH_STYLE["color"], ms=7, mfc="none", mew=1.5, zorder=7)
        self.dr_line, = ax.plot([], [], label="dead reckoning", zorder=3, **{**STYLES["dead_reckoning"], "linewidth": 1.2})
        self.map_points = ax.scatter(np.zeros(0), np.zeros(0), s=3, c="0.45", zorder=2, label="map so far")
        self.active_ellipses = LineCollection([], colors=PALETTE["orange"], linewidths=0.7, alpha=0.7, zorder=4)
        ax.add_collection(self.active_ellipses)
        self.active_points = ax.scatter(np.zeros(0), np.zeros(0), s=10, c=PALETTE["orange"], zorder=5,
                                        label=f"active landmarks ({self.n_sigma:g}σ)")
        self.est_line, = ax.plot([], [], label="estimate", zorder=6, **{**STYLES["estimate"], "linewidth": 2})
        self.pose_ellipse, = ax.plot([], [], "-", color=STYLES["estimate"]["color"], lw=1.5, zorder=8,
                                     label=f"pose {self.n_sigma:g}σ (x-y)")
        self.heading, = ax.plot([], [], "-", color=STYLES["estimate"]["color"], lw=2.5, zorder=8)
        self.pose_marker, = ax.plot([], [], "o", color=STYLES["estimate"]["color"], ms=6, zorder=9)
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

        arts = {"innov": self._dyn(LineCollection([], colors=PALETTE["orange"], linewidths=1.0, zorder=2))}
        ax.add_collection(arts["innov"])
        for code, (marker, color, label) in _STATUS_STYLE.items():
            style = dict(c=color) if marker in ("x", ".") else dict(facecolors="none", edgecolors=color)
            arts[code] = self._dyn(ax.scatter(np.zeros(0), np.zeros(0), s=18 if marker != "." else 8,
                                              marker=marker, linewidths=1.0, label=label, zorder=3, **style))
        arts["pred"] = self._dyn(ax.scatter(np.zeros(0), np.zeros(0), s=5, c=PALETTE["orange"], label="predicted", zorder=4))
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
        self.nis_band = self._dyn(Polygon(np.zeros((0, 2)), closed=True, fc=PALETTE["bluish_green"], alpha=0.3, ec="none",
                                          label="95% band of χ²(dof)/dof"))
        ax.add_patch(self.nis_band)
        self.nis_line = self._dyn(ax.plot([], [], ".-", color=PALETTE["blue"], ms=2.5, lw=0.7, label="NIS / dof")[0])
        self.nis_now = self._dyn(ax.axvline(0, color="k", lw=0.8, alpha=0.6))
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
            known = gt.landmarks if gt.landmarks is not None else np.zeros((0, 3))  # a real drive: poses only
            self.gt_points.set_offsets(known[np.isfinite(known[:, 0]), :2])
        else:
            self.gt_line.set_data([], [])
            self.gt_points.set_offsets(np.zeros((0, 2)))
        self.gt_pose.set_data([], [])
        self._dr = stepper.dead_reckoning[:, :3, 3] if stepper.mode != DEADRECKON else None
        self._static_paths = [stepper.dead_reckoning[:, :2, 3]] + ([gt.world_T_imu[:, :2, 3]] if gt is not None else [])
        handles = [self.est_line, self.pose_ellipse]
        if stepper.mode != DEADRECKON:
            handles += [self.dr_line, self.active_points, self.map_points]
        if gt is not None:
            handles += [self.gt_line] + ([self.gt_points] if gt.landmarks is not None else [])
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
        counts = np.bincount(rec.status, minlength=len(STATUS_NAMES))
        self.captions["frame"] = (f"frame {t}: {len(rec.ids)} observations, {counts[OBS_USED]} used, "
                                  f"{counts[OBS_NEW]} new, {counts[OBS_GATED]} gated")
        self._update_nis(stepper, rec, t)
        self.title.set_text(f"{stepper.dataset.name}: {MODE_LABELS[stepper.mode]}\nt = {t} / {stepper.num_frames - 1}"
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
        else:  # no ground truth, or past the frames it covers
            self.gt_pose.set_data([], [])
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
            if code == OBS_FAR:
                sel |= rec.status == OBS_IGNORED
            arts[code].set_offsets(z[sel][:, [cu, cv]] if np.any(sel) else np.zeros((0, 2)))
        ok = np.isfinite(rec.z_pred[:, 0])
        pred = rec.z_pred[ok][:, [cu, cv]]
        arts["pred"].set_offsets(pred if len(pred) else np.zeros((0, 2)))
        arts["innov"].set_segments(np.stack([pred, z[ok][:, [cu, cv]]], axis=1) if len(pred) else [])

    def _update_nis(self, stepper, rec, t):
        nis, dof = stepper.nis, stepper.nis_dof
        frames = np.arange(t + 1)
        ok = dof > 0
        ratio = np.divide(nis, dof, out=np.full(t + 1, np.nan), where=ok)
        self.nis_line.set_data(frames, ratio)
        lo, hi = stepper.nis_band_series()
        f, lo, hi = frames[ok], lo[ok], hi[ok]
        self.nis_band.set_xy(np.concatenate([np.stack([f, lo], 1), np.stack([f[::-1], hi[::-1]], 1)])
                             if len(f) else np.zeros((0, 2)))
        self.nis_now.set_xdata([t, t])
        inside = f"; {100 * np.mean((ratio[ok] >= lo) & (ratio[ok] <= hi)):.0f}% of updates so far in the band" \
            if len(f) else ""
        if rec.nis_dof:
            self.captions["nis"] = f"NIS/dof = {rec.nis / rec.nis_dof:.2f} (dof {rec.nis_dof}){inside}"
        elif stepper.mode == DEADRECKON:
            self.captions["nis"] = "dead reckoning: no updates, no NIS"
        else:
            self.captions["nis"] = f"no update at frame {t}{inside}"

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
        """Render onto the Agg canvas: cached background (rebuilt when stale), then the time-dependent artists."""
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
            self.fig.draw_artist(a)

    def render_png(self):
        """The figure as PNG bytes (fast zlib setting: the image is shown once)."""
        from PIL import Image

        self.draw()
        rgba = np.asarray(self.fig.canvas.buffer_rgba())
        buf = io.BytesIO()
        Image.fromarray(rgba[..., :3]).save(buf, format="png", compress_level=1)
        return buf.getvalue()
