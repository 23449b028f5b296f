"""Figures: axes that need no offset text, whatever the window's position and the data's scale; figures that
say what they show, draw a user's text as it is, and keep log axes and tick labels readable."""

import math
import types

import numpy as np
import pytest

from analytic.scenes.common import Sampling
from validation import plots
from validation.plots import save_figure, transients_figure, z_map_figure
from validation.plots.axes import power_of_ten, round_origin


@pytest.mark.parametrize("start, span, origin", [(1.9, 1.2, 0.0), (0.0, 4.0, 0.0), (800.0001, 0.0014, 800.0),
                                                 (-50.25, 0.01, None)])
def test_a_window_far_from_zero_is_drawn_from_a_round_origin(start, span, origin):
    found = round_origin(np.array([start, start + span]))
    if origin is not None:
        assert found == pytest.approx(origin, abs=1e-12)
    if origin != 0:
        assert 0 <= start - found < 10 * span     # the ticks then read like the span itself


@pytest.mark.parametrize("peak, power", [(409.0, 0), (0.04, 0), (1.2e-14, -14), (3e7, 7), (0.0, 0),
                                         (3e-299, -299), (2e-305, -300), (1.2e-322, -300), (5e-324, -300)])
def test_y_outside_the_readable_range_gets_a_named_power_of_ten(peak, power):
    """Below 1e-300 (subnormal light included) the power stays -300, so that the figures' 10^-power is finite."""
    assert power_of_ten(np.array([0.0, peak])) == power
    assert math.isfinite(10.0 ** -power * 1e8)         # room for a faint trace's factor too


def test_a_far_tiny_transient_is_drawn(tmp_path):
    sampling = Sampling(bin_width_opl=1e-6, start_opl=800.0001, count=50)
    y = 1e-14 * np.exp(-np.arange(50) / 10.0)[None, :]
    save_figure(transients_figure(sampling, {"model": y, "render": y * 1.01},
                                  errors={"render": np.full_like(y, 1e-16)}), tmp_path / "t.png")
    save_figure(z_map_figure(np.zeros((1, 50)), 4.0, sampling, "z"), tmp_path / "z.png")
    assert (tmp_path / "t.png").stat().st_size > 0 and (tmp_path / "z.png").stat().st_size > 0


# ---------------------------------------------------------------- what the figures say


def drawn(figure):
    """The figure as its PNG would show it: drawn, so that text extents and ticks are final."""
    figure.canvas.draw()
    return figure


def _texts(figure) -> str:
    return " ".join(text.get_text() for text in figure.findobj(lambda artist: hasattr(artist, "get_text")))


def _shown_tick_labels(axis, which: str):
    """(tick label, its extent) of every labelled tick inside the view of one axis."""
    ruler = axis.xaxis if which == "x" else axis.yaxis
    low, high = sorted(ruler.get_view_interval())
    renderer = axis.figure.canvas.get_renderer()
    shown = []
    for tick in ruler.get_major_ticks() + ruler.get_minor_ticks():
        label = tick.label1
        if label.get_visible() and label.get_text() and low <= tick.get_loc() <= high:
            shown.append((label.get_text(), label.get_window_extent(renderer)))
    return shown


def _assert_labels_apart(axis, which: str):
    shown = sorted(_shown_tick_labels(axis, which), key=lambda item: item[1].x0 if which == "x" else item[1].y0)
    for (text, box), (next_text, next_box) in zip(shown, shown[1:]):
        gap = next_box.x0 - box.x1 if which == "x" else next_box.y0 - box.y1
        assert gap > 0, f"tick labels {text!r} and {next_text!r} overlap"


def _transients(sensors: int):
    sampling = Sampling(bin_width_opl=0.1, start_opl=1.9, count=12)
    model = np.outer(np.linspace(1.0, 2.0, sensors), np.r_[0.0, 0.0, 5.0, 4.0, 3.0, 2.0, 1.0, 0.5, 0.0, 0, 0, 0])
    stderr = 0.001 * model
    render = model + 2.0 * stderr
    return sampling, model, render, stderr


def test_transients_say_which_sensors_they_show_and_draw_the_real_z_limit():
    sampling, model, render, stderr = _transients(16)
    figure = drawn(plots.transients_figure(sampling, {"model": model, "render": render}, errors={"render": stderr},
                                           z_limit=4.61, title="scene"))
    text = _texts(figure)
    assert "8 of 16" in text and "4.61" in text
    # the error bars (0.1 % of the peak) hide under the points: the legend says so
    assert "within the points" in text
    strips = [axis for axis in figure.axes if axis.get_ylabel() == "z" or axis.get_ylim()[0] < 0]
    levels = {round(abs(line.get_ydata()[0]), 2) for axis in strips for line in axis.get_lines()
              if len(set(line.get_ydata())) == 1}
    assert 4.61 in levels and 3.0 not in levels
    sizes = {label.get_fontsize() for axis in figure.axes for label in axis.get_yticklabels()}
    assert min(sizes) >= 7


def test_titles_show_a_scene_name_as_it_is():
    sampling, model, render, stderr = _transients(1)
    # "$...$" would be mathtext (and this one an error); CJK is not in DejaVu Sans (a glyph warning)
    figures = [drawn(plots.transients_figure(sampling, {"model": model, "render": render}, title="a$\\frac$b 日本")),
               drawn(plots.z_map_figure(np.zeros((1, 12)), 4.0, sampling, "a$\\frac$b 日本"))]
    assert "a$\\frac$b" in _texts(figures[0]) and "a$\\frac$b" in _texts(figures[1])


def test_log_axes_leave_out_errors_of_exactly_zero():
    rows = [{"samples": 2**k, "relative_l2": 0.0} for k in (12, 14, 16)]
    figure = drawn(plots.convergence_figure("exact", rows, None, [{"tolerance": 1e-2, "over_stderr": 0.0}]))
    assert "nothing above 0" in _texts(figure)


def _reconstruction(lambdas, residual_norms, seminorms, rule="gcv"):
    lambdas = np.asarray(lambdas, float)
    return types.SimpleNamespace(rule=rule, lambdas=lambdas, criterion=np.linspace(1.0, 2.0, lambdas.size),
                                 residual_norms=np.asarray(residual_norms, float),
                                 seminorms=np.asarray(seminorms, float), lam=float(lambdas[2]),
                                 residual_norm=float(residual_norms[2]), seminorm=float(seminorms[2]))


def test_criterion_tick_labels_on_a_short_log_span_do_not_run_together():
    # a λ grid and an L-curve spanning less than a decade: matplotlib would label every minor tick
    figure = drawn(plots.criterion_figure(_reconstruction(np.geomspace(1.0, 2.0, 8), np.linspace(0.105, 0.12, 8),
                                                          np.linspace(2.0, 1.5, 8))))
    for axis in figure.axes:
        for which in ("x", "y"):
            _assert_labels_apart(axis, which)
        assert len(_shown_tick_labels(axis, "x")) >= 2


def test_criterion_over_the_whole_float_range_is_drawn():
    # λ from 1e-300 to 1e300 and a seminorm of 0: margins and ticks must stay finite
    lambdas = np.geomspace(1e-300, 1e300, 12)
    figure = drawn(plots.criterion_figure(_reconstruction(lambdas, np.geomspace(1e-5, 1e26, 12),
                                                          np.r_[np.geomspace(2.0, 1e-200, 11), 0.0])))
    for axis in figure.axes:
        for which in ("x", "y"):
            low, high = (axis.get_xlim() if which == "x" else axis.get_ylim())
            assert math.isfinite(low) and math.isfinite(high)
            assert _shown_tick_labels(axis, which)


@pytest.fixture(scope="module")
def check_result():
    from analytic.scenes.common import Scene
    from analytic.operator.matrix_free import forward
    from validation.check import check_transient

    scene = Scene(pixels=6, source=(0.5, 0.5, 1.0), sensors=[(0.2, 0.7, 1.0), (0.6, 0.3, 0.8), (0.5, 0.5, 0.5)],
                  sampling=Sampling(bin_width_opl=0.1, start_opl=1.0, count=30))
    model = forward(scene)
    stderr = np.where(model > 0, 0.01 * np.abs(model).max(), 0.0)
    noise = np.random.default_rng(5).standard_normal(model.shape)
    return scene, check_transient(scene, model + stderr * noise, stderr=stderr)


def test_check_transients_title_legend_and_time_axes(check_result):
    scene, result = check_result
    figure = drawn(plots.check_transients_figure(result))
    renderer = figure.canvas.get_renderer()
    title = figure._suptitle.get_window_extent(renderer)
    (legend,) = figure.legends
    assert not title.overlaps(legend.get_window_extent(renderer))
    assert any(axis.get_xlabel() == "ns" for axis in figure.findobj(lambda a: hasattr(a, "get_xlabel")))


def test_check_transients_shows_the_model_as_given_beside_the_fitted_one(check_result):
    """The data agree, so the fitted model nearly coincides with the model as given: the one as given is a band
    at least twice as wide as the fitted line, drawn beneath it, so that both show; each draws its own
    numbers, in the legend's order."""
    from matplotlib.patches import StepPatch

    scene, result = check_result
    figure = drawn(plots.check_transients_figure(result))
    (legend,) = figure.legends
    assert [text.get_text() for text in legend.get_texts()][0] == "model as given"
    panels = [axis for axis in figure.axes if axis.get_title(loc="left").startswith("sensor ")]
    assert len(panels) == scene.sensor_count
    for axis in panels:
        k = int(axis.get_title(loc="left").split()[1])
        given, fitted = [artist for artist in axis.patches if isinstance(artist, StepPatch)]
        assert given.get_linewidth() >= 2 * fitted.get_linewidth() and given.get_zorder() < fitted.get_zorder()
        assert given.get_visible() and fitted.get_visible() and fitted.get_linestyle() == "--"
        for patch, row in ((given, result.model[k]), (fitted, result.fitted_model[k])):
            values = patch.get_data().values
            scale = values.max() / row.max()
            assert any(np.allclose(values, scale * row[first:first + values.size], rtol=1e-12, atol=0)
                       for first in range(row.size - values.size + 1)), k


def test_check_z_is_drawn_against_path_length(check_result):
    scene, result = check_result
    figure = drawn(plots.check_z_figure(result))
    edges = scene.sampling.edges
    for axis in figure.axes[:2]:
        low, high = axis.get_xlim()
        assert edges[0] - 0.1 <= low < high <= edges[-1] + 0.1       # metres of path, not a bin index
    assert "limit ±" in _texts(figure)


def test_relay_wall_traces_say_their_rank_and_each_shows_its_shape():
    """Pairs a thousandth as bright as the brightest lay flat at zero beside it on one linear scale, under a
    title that read 'by brightness, 1 the brightest' while 2-4 were quartiles. Each trace now says its rank
    of brightness (counted here from the totals), is drawn times the factor its label states, and peaks at
    0.4 to 1 times the brightest's height."""
    import re

    from matplotlib.patches import StepPatch

    scan = plots.WallScan(type="confocal", grid=(4, 4), wall_size=(2.0, 2.0))
    rng = np.random.default_rng(3)
    bins = np.arange(60)
    y = 10.0 ** rng.uniform(-4, 0, 16)[:, None] * np.exp(-0.5 * ((bins - rng.uniform(15, 45, 16)[:, None]) / 3) ** 2)
    figure = drawn(plots.relay_wall_figure(Sampling(bin_width_opl=0.01, start_opl=2.0, count=60), y, scan))
    (axis,) = [axis for axis in figure.axes if axis.get_legend() is not None]
    labels = [text.get_text() for text in axis.get_legend().get_texts()]
    ranks = np.empty(16, dtype=int)
    ranks[np.argsort(-y.sum(axis=1))] = np.arange(1, 17)
    steps = [artist for artist in axis.patches if isinstance(artist, StepPatch)]
    assert len(labels) == len(steps) == 4
    top = steps[0].get_data().values.max()
    unit = None                         # the axis' unit per unit of H (the brightest is drawn as it is)
    for number, (label, step) in enumerate(zip(labels, steps), start=1):
        found = re.fullmatch(r"(\d): pair (\d+), the (brightest|(\d+)(st|nd|rd|th) brightest of 16)(, × (\S+))?",
                             label)
        assert found and int(found[1]) == number, label
        pair = int(found[2])
        assert ranks[pair] == (1 if found[3] == "brightest" else int(found[4])) == 1 + 4 * (number - 1), label
        factor = float(found[7] or 1)
        values = step.get_data().values
        unit = values.max() / y[pair].max() if unit is None else unit
        first = int(np.argmax(y[pair])) - int(np.argmax(values))
        np.testing.assert_allclose(values, y[pair, first:first + values.size] * unit * factor, rtol=1e-12,
                                   atol=1e-12 * top, err_msg=label)
        assert 0.4 * top <= values.max() <= top * (1 + 1e-12), label
