"""Matplotlib views: top-down trajectory and map, covariance ellipses, image-plane view, NIS.

Every function draws into a given ``Axes`` (or a new figure) and returns it; nothing is shown or saved unless
asked, so notebooks, the CLI and the widgets share them. Every role has one style (:data:`STYLES`) from one
colour-blind-safe palette (:data:`PALETTE`), trajectories differing in colour *and* line style (apart in
greyscale too); :func:`course_style` does the same for matplotlib's colour cycle.
"""


import numpy as np

from visla_edu._files import atomic_write, expand_user
from visla_edu.codes import DEADRECKON, OBS_GATED

__all__ = ["PALETTE", "STYLES", "SERIES_COLORS", "SERIES_LINESTYLES", "series_style", "course_style",
           "GROUND_TRUTH_STYLE", "covariance_ellipse", "plot_trajectory_map", "plot_result", "plot_image_plane",
           "covariance_ellipses", "plot_nis", "figure_suffixes", "save_figure"]


def figure_suffixes():
    """Suffixes (tuple of str) matplotlib can save a figure as: ``".png"``, ``".pdf"``, ``".svg"``, then the others.

    Lower case with the dot; the rest alphabetical, without ``.pgf`` (it needs LaTeX).
    """
    from matplotlib.backend_bases import FigureCanvasBase

    first = ("png", "pdf", "svg")
    others = sorted(set(FigureCanvasBase.get_supported_filetypes()) - set(first) - {"pgf"})
    return tuple(f".{ext}" for ext in (*first, *others))


def save_figure(fig, path, dpi=120):
    """Save ``fig`` (a matplotlib Figure) to ``path`` atomically; return the absolute path (pathlib.Path).

    Parameters
    ----------
    path : str or os.PathLike
        ``~`` is expanded. Its suffix (any case) is the format, one of :func:`figure_suffixes`; no suffix saves a
        PNG under that name.
    dpi : float
        Resolution of raster formats.

    Raises
    ------
    ValueError
        ``path`` is a folder, or matplotlib does not know the suffix's format.
    """
    path = expand_user(path)
    with atomic_write(path, "wb") as f:
        fig.savefig(f, dpi=dpi, format=path.suffix.lstrip(".").lower() or "png")
    return path.resolve()

#: The colour-blind-safe palette: the eight colours of Okabe and Ito (2008), "Color universal
#: design", and a neutral grey (for landmarks and reference lines).
PALETTE = {
    "black": "#000000",
    "orange": "#e69f00",
    "sky_blue": "#56b4e9",
    "bluish_green": "#009e73",
    "yellow": "#f0e442",
    "blue": "#0072b2",
    "vermillion": "#d55e00",
    "reddish_purple": "#cc79a7",
    "grey": "#8c8c8c",
}

_ESTIMATE = {"color": PALETTE["blue"], "linestyle": "-", "linewidth": 1.6}

#: One style per role (keyword arguments of ``Axes.plot``): each trajectory has its own colour
#: and its own line style; landmarks are grey dots, unlike the ground truth (bluish green,
#: dash-dot). ``"ekf"`` is the estimate's style under the name used beside a smoother.
STYLES = {
    "estimate": _ESTIMATE,
    "ekf": _ESTIMATE,
    "dead_reckoning": {"color": PALETTE["vermillion"], "linestyle": "--", "linewidth": 1.5},
    "ground_truth": {"color": PALETTE["bluish_green"], "linestyle": "-.", "linewidth": 2.2, "alpha": 0.9},
    "smoother": {"color": PALETTE["reddish_purple"], "linestyle": ":", "linewidth": 2.2},
    "window": {"color": PALETTE["orange"], "linestyle": (0, (6, 2, 1, 2, 1, 2)), "linewidth": 1.6},
    "landmarks": {"color": PALETTE["grey"], "linestyle": "None", "marker": ".", "markersize": 2},
    "start": {"color": PALETTE["black"], "linestyle": "None", "marker": "o", "markersize": 5},
}

#: How the true trajectory is drawn in every view (these plots and the stepper's map).
GROUND_TRUTH_STYLE = STYLES["ground_truth"]

#: Colours of the notebooks' series, in order (all eight Okabe-Ito colours, yellow last: it is
#: the hardest to see on white).
SERIES_COLORS = tuple(PALETTE[name] for name in ("blue", "vermillion", "bluish_green", "reddish_purple", "orange",
                                                 "sky_blue", "black", "yellow"))
#: Line styles of the series, one per colour, so that series differ without colour too.
SERIES_LINESTYLES = ("-", "--", "-.", ":", (0, (8, 3)), (0, (3, 1, 1, 1, 1, 1)), (0, (1, 3)), (0, (8, 3, 2, 3)))


def series_style(index):
    """``{"color", "linestyle"}`` (``Axes.plot`` keywords) of the ``index``-th series, cycling after eight."""
    k = int(index) % len(SERIES_COLORS)
    return {"color": SERIES_COLORS[k], "linestyle": SERIES_LINESTYLES[k]}


def course_style():
    """Make matplotlib's colour cycle :data:`SERIES_COLORS` with :data:`SERIES_LINESTYLES` (sets ``rcParams``)."""
    import matplotlib
    from cycler import cycler

    matplotlib.rcParams["axes.prop_cycle"] = cycler(color=list(SERIES_COLORS), linestyle=list(SERIES_LINESTYLES))


def _axes(ax, figsize=(8, 7)):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=figsize)[1]


def covariance_ellipse(mean_xy, cov_xy, n_sigma=2.0, n_points=60):
    """Points (n_points, 2) of the ``n_sigma`` ellipse of the 2-D Gaussian ``mean_xy`` (2,), ``cov_xy`` (2, 2)."""
    vals, vecs = np.linalg.eigh(np.asarray(cov_xy, dtype=float))
    angles = np.linspace(0, 2 * np.pi, n_points)
    circle = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return np.asarray(mean_xy) + n_sigma * (circle * np.sqrt(np.clip(vals, 0, None))) @ vecs.T


def plot_trajectory_map(world_T_imu, landmarks=None, ax=None, label="estimate", color=None,
                        landmark_color=None, reference=None, reference_label="dead reckoning",
                        ground_truth=None):
    """Top-down (x-y) view of a trajectory and a landmark map.

    Parameters
    ----------
    world_T_imu : ndarray, shape (T, 4, 4)
    landmarks : ndarray, shape (M, 3), optional
        NaN rows are skipped.
    color, landmark_color : matplotlib colour, optional
        Default: ``STYLES["estimate"]``, ``STYLES["landmarks"]``.
    reference : ndarray, shape (T, 4, 4), optional
        A second trajectory (e.g. dead reckoning), in ``STYLES["dead_reckoning"]``.
    ground_truth : visla_edu.dataset.GroundTruth or ndarray of shape (n, 4, 4), optional
        In :data:`GROUND_TRUTH_STYLE`; it may cover fewer frames than the estimate. Anything else: ValueError.
    """
    ax = _axes(ax)
    if landmarks is not None:
        ok = np.isfinite(landmarks[:, 0])
        ax.scatter(landmarks[ok, 0], landmarks[ok, 1], s=2, c=landmark_color or STYLES["landmarks"]["color"],
                   label=f"landmarks ({ok.sum()})", zorder=1)
    paths = []
    if ground_truth is not None:
        p = _truth_poses(ground_truth)[:, :3, 3]
        ax.plot(p[:, 0], p[:, 1], label="ground truth", zorder=2, **GROUND_TRUTH_STYLE)
        paths.append(p)
    if reference is not None:
        p = reference[:, :3, 3]
        ax.plot(p[:, 0], p[:, 1], label=reference_label, zorder=3, **STYLES["dead_reckoning"])
        paths.append(p)
    p = world_T_imu[:, :3, 3]
    ax.plot(p[:, 0], p[:, 1], label=label, zorder=4, **{**STYLES["estimate"], **({"color": color} if color else {})})
    ax.plot(p[0, 0], p[0, 1], zorder=5, **STYLES["start"])
    ax.set_xlabel("x (m, world = first IMU frame)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="box")
    _limit_to_path(ax, [p] + paths)
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, alpha=0.3)
    return ax


def _truth_poses(ground_truth):
    """The ``(n, 4, 4)`` true poses of a :class:`~visla_edu.dataset.GroundTruth` or of an array."""
    poses = np.asarray(getattr(ground_truth, "world_T_imu", ground_truth), dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"ground_truth: expected a GroundTruth or poses of shape (n, 4, 4), got shape {poses.shape}")
    return poses


def _limit_to_path(ax, paths, margin=0.15):
    """Zoom on the trajectories so a few far landmarks do not shrink the view."""
    pts = np.concatenate([p[:, :2] for p in paths])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = margin * max(hi - lo) + 20
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)


def plot_result(result, path=None, ground_truth=None, title=None):
    """A matplotlib Figure of a :class:`visla_edu.run.RunResult`: trajectory and map, with dead reckoning.

    Saved to ``path`` when given (:func:`save_figure`); ``ground_truth`` as in :func:`plot_trajectory_map`.
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 7))
    plot_trajectory_map(result.world_T_imu, result.landmarks, ax=ax, label=f"{result.mode} estimate",
                        reference=result.dead_reckoning if result.mode != DEADRECKON else None,
                        ground_truth=ground_truth)
    ax.set_title(title or f"{result.name}: {result.mode}{' (dense)' if result.dense else ''}")
    fig.tight_layout()
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_image_plane(z, z_pred=None, status=None, image_size=(1400, 500), ax=None):
    """Left-image pixels of one frame: observed, predicted, innovations, gated outliers.

    Parameters
    ----------
    z, z_pred : ndarray, shape (k, 4)
        Observed and (optional) predicted ``[uL, vL, uR, vR]``; predictions (NaN rows skipped) are joined to their
        observations by a line.
    status : ndarray of int, shape (k,), optional
        ``OBS_*`` codes (:mod:`visla_edu.codes`); gated observations are drawn as red crosses.
    image_size : (width, height)
    """
    ax = _axes(ax, figsize=(10, 4))
    gated = np.zeros(len(z), dtype=bool) if status is None else status == OBS_GATED
    ax.scatter(z[~gated, 0], z[~gated, 1], s=14, facecolors="none", edgecolors=PALETTE["blue"], label="observed")
    if np.any(gated):
        ax.scatter(z[gated, 0], z[gated, 1], s=30, marker="x", c=PALETTE["vermillion"], label="gated (outlier)")
    if z_pred is not None:
        ok = np.isfinite(z_pred[:, 0])
        ax.scatter(z_pred[ok, 0], z_pred[ok, 1], s=6, c=PALETTE["orange"], label="predicted")
        for (u0, v0), (u1, v1) in zip(z_pred[ok, :2], z[ok, :2]):
            ax.plot([u0, u1], [v0, v1], "-", color=PALETTE["orange"], lw=0.8)
    ax.set_xlim(0, image_size[0])
    ax.set_ylim(image_size[1], 0)
    ax.set_xlabel("u (px, left image)")
    ax.set_ylabel("v (px)")
    ax.legend(loc="upper right", fontsize="small")
    return ax


def covariance_ellipses(means_xy, covs_xy, n_sigma=2.0, n_points=40):
    """:func:`covariance_ellipse` of ``means_xy`` (n, 2), ``covs_xy`` (n, 2, 2) at once: (n, n_points, 2)."""
    means_xy = np.asarray(means_xy, dtype=float).reshape(-1, 2)
    covs_xy = np.asarray(covs_xy, dtype=float).reshape(-1, 2, 2)
    if len(means_xy) != len(covs_xy):
        raise ValueError(f"covariance_ellipses: {len(means_xy)} means but {len(covs_xy)} covariances")
    if len(means_xy) == 0:
        return np.zeros((0, n_points, 2))
    vals, vecs = np.linalg.eigh(0.5 * (covs_xy + np.swapaxes(covs_xy, 1, 2)))
    angles = np.linspace(0, 2 * np.pi, n_points)
    circle = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (p, 2)
    scaled = circle[None] * (n_sigma * np.sqrt(np.clip(vals, 0, None)))[:, None, :]  # (n, p, 2)
    return means_xy[:, None, :] + scaled @ np.swapaxes(vecs, 1, 2)


def plot_nis(nis, dof, time=None, probability=0.95, ax=None):
    """NIS per degree of freedom over time, with the ``probability`` band of ``chi2(dof)/dof``.

    A consistent filter stays inside it (:func:`visla_edu.metrics.nis_band`) about ``probability`` of the time;
    above it, it is over-confident (noise too small), below it too cautious.

    Parameters
    ----------
    nis, dof, time : array_like, shape (T,)
        NIS (NaN where there was no update), its degrees of freedom (int), x values (default: frame index).
    """
    from visla_edu.metrics import nis_band

    ax = _axes(ax, figsize=(8, 3))
    nis = np.asarray(nis, dtype=float)
    dof = np.asarray(dof, dtype=float)
    x = np.arange(len(nis)) if time is None else np.asarray(time)
    ok = dof > 0
    ratio = np.divide(nis, dof, out=np.full(len(nis), np.nan), where=ok)
    lo, hi = nis_band(dof, probability)
    ax.fill_between(x, lo, hi, color=PALETTE["bluish_green"], alpha=0.25, lw=0, label=f"{100 * probability:.0f}% band of chi2(dof)/dof")
    ax.plot(x, ratio, ".-", color=PALETTE["blue"], ms=3, lw=0.8, label="NIS / dof")
    ax.axhline(1.0, color="0.4", lw=0.8, ls=":")
    if np.any(ok):
        inside = np.mean((ratio[ok] >= lo[ok]) & (ratio[ok] <= hi[ok]))
        ax.set_title(f"NIS/dof: {100 * inside:.0f}% of updates inside the band", fontsize="medium")
    ax.set_yscale("log")
    ax.set_xlabel("frame" if time is None else "time (s)")
    ax.set_ylabel("NIS / dof")
    ax.legend(loc="upper right", fontsize="small")
    ax.grid(True, alpha=0.3)
    return ax
