"""The plotting palette: colour-blind-safe colours, one distinct style per role, used by the views."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.colors as mcolors  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from visla_edu import plotting  # noqa: E402

#: The Okabe-Ito colours (Okabe and Ito 2008), written out here independently of the module.
OKABE_ITO = {"#000000", "#e69f00", "#56b4e9", "#009e73", "#f0e442", "#0072b2", "#d55e00", "#cc79a7"}


def _hex(color):
    return mcolors.to_hex(color)


#: Matplotlib's long names of the named line styles (Line2D.get_linestyle reports every dash
#: pattern as "--", so the style's own value is compared, with the names normalised).
_NAMED = {"solid": "-", "dashed": "--", "dashdot": "-.", "dotted": ":", "none": "None", " ": "None", "": "None"}


def _linestyle(style):
    ls = style.get("linestyle", "-")
    return _NAMED.get(ls, ls) if isinstance(ls, str) else str(ls)


def _look(style):
    """What tells a role apart on the page: colour, line style (dash pattern, normalised) and marker."""
    line = matplotlib.lines.Line2D([], [], **style)
    return _hex(line.get_color()), _linestyle(style), str(line.get_marker())


def _roles():
    """Role names, one per distinct style object (``"ekf"`` is the estimate's style under its name)."""
    seen, roles = set(), []
    for name, style in plotting.STYLES.items():
        if id(style) not in seen:
            seen.add(id(style))
            roles.append(name)
    return roles


def test_palette_is_okabe_ito_and_grey():
    colors = {_hex(c) for name, c in plotting.PALETTE.items() if name != "grey"}
    assert colors == OKABE_ITO
    r, g, b = mcolors.to_rgb(plotting.PALETTE["grey"])
    assert r == g == b, "the neutral colour is a grey"


def test_every_role_has_its_own_colour_and_line_style_or_marker():
    roles = _roles()
    assert {"estimate", "dead_reckoning", "ground_truth", "landmarks", "smoother", "window"} <= set(roles)
    looks = {name: _look(plotting.STYLES[name]) for name in roles}
    assert len(set(looks.values())) == len(looks), looks
    lines = [name for name in roles if looks[name][1] != "None"]
    # trajectories differ in colour AND in line style: they stay apart in greyscale too
    assert len({looks[n][0] for n in lines}) == len(lines), looks
    assert len({looks[n][1] for n in lines}) == len(lines), looks
    assert plotting.STYLES["ekf"] is plotting.STYLES["estimate"]
    assert plotting.GROUND_TRUTH_STYLE is plotting.STYLES["ground_truth"]


def test_ground_truth_unlike_landmarks_and_colours_from_the_palette():
    palette = {_hex(c) for c in plotting.PALETTE.values()}
    for name, style in plotting.STYLES.items():
        assert _hex(style["color"]) in palette, name
    truth, landmarks = _look(plotting.STYLES["ground_truth"]), _look(plotting.STYLES["landmarks"])
    assert truth[0] != landmarks[0] and truth[1] != landmarks[1]


def test_series_styles_are_distinct_and_course_style_sets_the_cycle():
    looks = [(_hex(s["color"]), str(s["linestyle"])) for s in map(plotting.series_style, range(8))]
    assert len(set(c for c, _ in looks)) == 8 and len(set(ls for _, ls in looks)) == 8
    assert plotting.series_style(8) == plotting.series_style(0)
    saved = matplotlib.rcParams["axes.prop_cycle"]
    try:
        plotting.course_style()
        fig, ax = plt.subplots()
        first, second = ax.plot([0, 1], [0, 1])[0], ax.plot([0, 1], [1, 0])[0]
        assert _hex(first.get_color()) == _hex(plotting.SERIES_COLORS[0])
        assert (_hex(second.get_color()), second.get_linestyle()) != (_hex(first.get_color()), first.get_linestyle())
        assert _hex("C1") == _hex(plotting.SERIES_COLORS[1])
        plt.close(fig)
    finally:
        matplotlib.rcParams["axes.prop_cycle"] = saved


@pytest.mark.parametrize("with_reference", [False, True])
def test_trajectory_map_draws_each_role_in_its_style(with_reference):
    t = np.linspace(0, 1, 30)
    poses = np.tile(np.eye(4), (30, 1, 1))
    poses[:, 0, 3], poses[:, 1, 3] = 100 * t, 10 * np.sin(3 * t)
    landmarks = np.c_[np.linspace(0, 100, 12), np.full(12, 20.0), np.zeros(12)]
    fig, ax = plt.subplots()
    plotting.plot_trajectory_map(poses, landmarks, ax=ax, reference=poses + 1.0 if with_reference else None,
                                 ground_truth=poses - 1.0)
    lines = {line.get_label(): line for line in ax.get_lines() if not line.get_label().startswith("_")}
    expected = {"estimate": "estimate", "ground truth": "ground_truth"}
    if with_reference:
        expected["dead reckoning"] = "dead_reckoning"
    assert set(lines) == set(expected)
    for label, role in expected.items():
        style = plotting.STYLES[role]
        assert _hex(lines[label].get_color()) == _hex(style["color"]), label
        assert lines[label].get_linestyle() == matplotlib.lines.Line2D([], [], **style).get_linestyle(), label
    landmark_colors = {_hex(c) for c in ax.collections[0].get_facecolors()}
    assert landmark_colors == {_hex(plotting.STYLES["landmarks"]["color"])}
    plt.close(fig)


def test_library_views_use_no_default_cycle_colours():
    """The views pick colours from the palette, so they look the same whatever the rcParams say."""
    import inspect
    import re

    from visla_edu.stepper import figure

    for module in (plotting, figure):
        used = re.findall(r"""[=(,]\s*["']C\d""", inspect.getsource(module))
        assert not used, f"{module.__name__} draws with the default cycle colours: {used}"
