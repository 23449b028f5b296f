"""Every figure the project draws, as PNG (matplotlib imported inside each function).

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas,
never through pyplot's global state, and written atomically. Time axes are
cropped to the light (the window's edges drawn when in view) and labelled in
metres of path length (the transients' also in nanoseconds); every image
has a colour bar.

Figures draw without warnings, whatever the data and the scene's name: a
user's text (a scene's name in a title) is drawn as it is, never as
mathtext, with characters the font lacks as U+FFFD; log axes leave out
values they cannot show (0, say, or NaN), keep finite limits for data
near float64's ends, and label a span under a decade with a few plain
numbers that do not run together.
"""

from __future__ import annotations

import functools
import math
import textwrap
from pathlib import Path
from typing import NamedTuple

import numpy as np

from analytic.io import atomic_write

__all__ = ["save_figure", "new_figure", "plot_transients", "model_figure",
           "plot_z_map", "plot_convergence", "plot_reconstructions", "plot_reconstruction", "plot_criterion",
           "criterion_figure", "plot_conditioning", "plot_panels", "plot_check_transients", "plot_check_z",
           "plot_speed_against_error", "NANOSECONDS_PER_METRE", "Y_LABEL"]

#: Light travels 1 m of path in 3.3356 ns.
NANOSECONDS_PER_METRE = 1e9 / 299_792_458.0
#: y's units for a source intensity in W/sr (DESIGN.md section 1; the README explains them).
Y_LABEL = "y_k[n] (W m⁻¹)"


def new_figure(width: float, height: float, layout: str | None = "constrained"):
    """A Figure on an Agg canvas (no pyplot state), constrained layout unless ``layout=None``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), layout=layout)
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure, path: str | Path, dpi: int = 110) -> Path:
    """Write a figure as PNG, atomically."""
    return atomic_write(path, lambda temporary: figure.savefig(temporary, format="png", dpi=dpi))


@functools.lru_cache(maxsize=1)
def _font_characters() -> frozenset:
    """Code points the default font can draw."""
    from matplotlib import font_manager

    font = font_manager.get_font(font_manager.findfont(font_manager.FontProperties()))
    return frozenset(font.get_charmap())


def _plain_text(text: str) -> str:
    """Text from a user (a scene's name) with every character the default font lacks as U+FFFD.

    Such a character would draw as an empty box and make matplotlib warn.
    Draw the result with ``parse_math=False`` (:func:`_suptitle`): a ``$``
    would otherwise start mathtext, where ``a$\\frac$b`` is an error, not a
    title.
    """
    drawable = _font_characters()
    return "".join(c if c == "\n" or ord(c) in drawable else "\ufffd" for c in text)


def _suptitle(figure, text: str, **options) -> None:
    """A figure title that may hold a user's text, drawn as it is (:func:`_plain_text`)."""
    figure.suptitle(_plain_text(text), parse_math=False, **options)


def _log_plot(axis, x, y, *args, logx: bool = True, **kwargs) -> bool:
    """``loglog`` (or ``semilogy`` without ``logx``) of the points that log axes can show.

    Points at or below 0 (an error that is exactly 0, say) or not finite
    cannot be drawn on a log axis, and matplotlib warns about them; they are
    left out, and when none is left the axis says so in words. Returns
    whether anything was drawn.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    keep = np.isfinite(x) & np.isfinite(y) & (y > 0) & ((x > 0) if logx else True)
    axis.set_yscale("log")
    if logx:
        axis.set_xscale("log")
    _no_log_margins(axis, *(("x", "y") if logx else ("y",)))
    if not keep.any():
        axis.text(0.5, 0.5, "nothing above 0 to draw on a log axis", ha="center", va="center",
                  transform=axis.transAxes, fontsize=8, color="0.4")
        return False
    axis.plot(x[keep], y[keep], *args, **kwargs)
    # limits now, from the data: matplotlib's own margins would overflow for data near 1e±308
    for name in ("x", "y") if logx else ("y",):
        _log_limits(axis, name)
    return True


#: Powers of ten a log axis's limits stay within: its margins beyond data near float64's ends
#: (λ from 1e-300 to 1e300, a seminorm of 1e-308) would overflow to inf or 0.
_LOG_LIMIT = 300.0
#: Share of a log axis's span (in decades) added either side of its data, as matplotlib's default.
_LOG_MARGIN = 0.05


def _log_limits(axis, name: str) -> None:
    """Limits of a log axis from its data, the usual margin added in decades but never past 10^±300.

    The axis's own margin must be 0 while it is drawn (:func:`_no_log_margins`):
    matplotlib adds it on the first look at the limits, beyond 10^308 for
    data near 1e300, before these limits can replace it.
    """
    ruler = axis.xaxis if name == "x" else axis.yaxis
    if ruler.get_scale() != "log":
        return
    low, high = axis.dataLim.intervalx if name == "x" else axis.dataLim.intervaly
    if not (np.isfinite(low) and np.isfinite(high) and 0 < low <= high):
        return                                   # nothing drawn: matplotlib's defaults stand
    first, last = math.log10(low), math.log10(high)
    margin = _LOG_MARGIN * max(last - first, 1e-12)
    if last - first < 1e-12:                     # one value: a decade around it
        margin = 0.5
    first, last = max(first - margin, -_LOG_LIMIT), min(last + margin, _LOG_LIMIT)
    # set before any autoscaling (which would itself overflow); an inversion, if wanted, comes after
    (axis.set_xlim if name == "x" else axis.set_ylim)(10.0 ** first, 10.0 ** last)


def _no_log_margins(axis, *names: str) -> None:
    """No automatic margin on these (log) axes: :func:`_log_limits` adds one that stays finite."""
    for name in names:
        (axis.set_xmargin if name == "x" else axis.set_ymargin)(0.0)


def _finish_log_axes(axis) -> None:
    """Finite limits (:func:`_log_limits`) and tick labels that do not run together on log axes.

    Over a span under a decade matplotlib labels its minor ticks in
    scientific notation (1.05×10⁻¹ 1.1×10⁻¹ ...), which collide; there a few
    plain labels (0.105, 0.11, ...) at round values take their place. Call
    it once the data are drawn.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullFormatter, NullLocator

    for name in ("x", "y"):
        ruler = axis.xaxis if name == "x" else axis.yaxis
        if ruler.get_scale() != "log":
            continue
        _log_limits(axis, name)
        low, high = sorted(axis.get_xlim() if name == "x" else axis.get_ylim())
        if not low > 0:
            continue
        first, last = math.log10(low), math.log10(high)
        if max(-first, last) > _LOG_LIMIT - 50:
            # matplotlib's LogLocator reaches a stride of decades past the limits: inf near 1e308
            stride = max(int(math.ceil((last - first) / 6)), 1)
            ruler.set_major_locator(FixedLocator(10.0 ** np.arange(math.ceil(first), math.floor(last) + 1,
                                                                   stride)))
            ruler.set_minor_locator(NullLocator())
            continue
        if last - first >= 1.0:
            continue
        ticks = MaxNLocator(nbins=4).tick_values(low, high)
        ticks = ticks[(ticks >= low) & (ticks <= high) & (ticks > 0)]
        if ticks.size < 2:
            ticks = np.array([low, high])
        labels = _distinct_labels(ticks)
        ruler.set_major_locator(FixedLocator(ticks))
        ruler.set_major_formatter(FuncFormatter(lambda value, position: labels.get(value, f"{value:.3g}")))
        ruler.set_minor_formatter(NullFormatter())


def _distinct_labels(ticks: np.ndarray) -> dict:
    """Tick value -> the shortest ``%g`` label (from 2 significant digits) that tells every tick apart."""
    for digits in range(2, 17):
        labels = [f"{value:.{digits}g}" for value in ticks]
        if len(set(labels)) == len(labels):
            break
    return dict(zip(ticks.tolist(), labels))


def _lit_bins(arrays, sampling, margin: int = 2) -> tuple[int, int]:
    """[first, last) bins where the first (reference) array holds light, with ``margin`` bins either side."""
    stacked = np.abs(np.atleast_2d(arrays[0]))   # the reference: noisy curves would light every bin
    peak = float(stacked.max()) if stacked.size else 0.0
    lit = np.nonzero(stacked.max(axis=0) > 1e-6 * peak)[0] if peak > 0 else np.arange(sampling.count)
    if lit.size == 0:
        return 0, sampling.count
    return max(int(lit[0]) - margin, 0), min(int(lit[-1]) + 1 + margin, sampling.count)


def _nanosecond_axis(axis) -> None:
    """Ticks in nanoseconds along the top: 1 m of path is 3.3356 ns."""
    secondary = axis.secondary_xaxis("top", functions=(lambda m: m * NANOSECONDS_PER_METRE,
                                                       lambda ns: ns / NANOSECONDS_PER_METRE))
    secondary.tick_params(labelsize=7, pad=1)
    secondary.set_xlabel("ns", fontsize=7, labelpad=1, loc="right")


def _round_origin(edges: np.ndarray) -> float:
    """A round origin for a path-length axis far from 0 (a span under 1 % of its start, such as 1.5 mm
    at 800 m), else 0: matplotlib's offset text would otherwise collide with the nanosecond axis."""
    span, start = float(edges[-1] - edges[0]), float(edges[0])
    if not (span > 0 and abs(start) > 100 * span):
        return 0.0
    step = 10.0 ** math.floor(math.log10(span))
    return math.floor(start / step) * step


def _power_of_ten(values: np.ndarray) -> int:
    """The power of ten to name in the y label when values leave [1e-3, 1e4] (else 0), instead of
    matplotlib's multiplier text."""
    peak = float(np.nanmax(np.abs(values))) if values.size and np.isfinite(values).any() else 0.0
    return int(math.floor(math.log10(peak))) if peak > 0 and not 1e-3 <= peak < 1e4 else 0


class _TimeAxis(NamedTuple):
    """The cropped, readable path-length axis of a transient figure (see :func:`_time_axis`)."""

    first: int              # first bin drawn
    last: int               # one past the last
    origin: float           # metres subtracted from path lengths (0, or a round number far from 0)
    scale: float            # y is drawn times this (10^-power)
    edges: np.ndarray       # drawn bin edges, metres from origin
    centres: np.ndarray
    window: tuple           # the window's edges, metres from origin
    x_label: str
    y_label: str


def _time_axis(sampling, arrays) -> _TimeAxis:
    """Crop to the light of the first (reference) array, from a round origin, y in a named power of ten."""
    first, last = _lit_bins(arrays, sampling)
    reference = np.atleast_2d(arrays[0])
    origin, power = _round_origin(sampling.edges[first:last + 1]), _power_of_ten(reference[:, first:last])
    edges = sampling.edges[first:last + 1] - origin
    return _TimeAxis(first, last, origin, 10.0 ** -power, edges, 0.5 * (edges[:-1] + edges[1:]),
                     (sampling.edges[0] - origin, sampling.edges[-1] - origin),
                     "path length (m)" if origin == 0 else f"path length − {origin:g} m (m)",
                     Y_LABEL if power == 0 else Y_LABEL.replace("(W", f"(1e{power} W"))


def _window_edges_in_view(time: _TimeAxis) -> list:
    """The window's edges that fall inside the drawn bins (metres from the axis's origin)."""
    return [edge for edge in time.window if time.edges[0] <= edge <= time.edges[-1]]


def _window_edges(axis, time: _TimeAxis) -> bool:
    """Dotted lines at the window's edges that are in view; whether any was."""
    shown = _window_edges_in_view(time)
    for edge in shown:
        axis.axvline(edge, color="0.4", ls=":", lw=0.8)
    return bool(shown)


def _sensor_list(chosen: np.ndarray, sensors: int) -> str:
    """"sensors 0, 2, 4, ..., 15 (8 of 16, evenly spaced)", or "every sensor" when all are drawn."""
    if len(chosen) == sensors:
        return f"every sensor (K = {sensors})"
    return f"sensors {', '.join(str(k) for k in chosen)} ({len(chosen)} of {sensors}, evenly spaced)"


def _error_bars_visible(transients: dict, errors: dict, chosen, first: int, last: int) -> bool:
    """Whether any ±1 se bar is at least 1 % of its panel's height (else it hides under its point)."""
    reference = np.atleast_2d(next(iter(transients.values())))[chosen, first:last]
    height = np.abs(reference).max(axis=1, initial=0.0)
    for label, error in errors.items():
        widest = np.atleast_2d(error)[chosen, first:last].max(axis=1, initial=0.0)
        if np.any(2 * widest >= 0.01 * np.where(height > 0, height, np.inf)):
            return True
    return False


#: Above this many drawn bins a transient's points carry no error bars (a thousand bars hide the model).
_MOST_ERROR_BARS = 100


def _legend_columns(names: list[str], width: float) -> int:
    """Most legend columns whose widest row of 8-point entries fits ``width`` inches."""
    entries = [0.06 * len(name) + 0.75 for name in names]     # 8-point text and its handle, inches
    for columns in range(len(names), 1, -1):
        if sum(sorted(entries, reverse=True)[:columns]) <= 0.95 * width:
            return columns
    return 1


def plot_transients(path: str | Path, sampling, transients: dict[str, np.ndarray], *,
                    errors: dict[str, np.ndarray] | None = None, z_limit: float | None = None,
                    title: str = "", max_panels: int = 8) -> Path:
    """Transients against path length, one panel per sensor, with z residuals when errors are given.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    sampling : analytic.Sampling
        The bins (path length in metres).
    transients : dict
        Label -> ``(K, N)`` samples. The first is the reference, drawn as a
        step line; the others as points, with ±1 standard-error bars from
        ``errors`` (none over more than 100 drawn bins).
    errors : dict, optional
        Label -> ``(K, N)`` standard errors. With them each panel gets a strip
        below it showing z = (value − reference) / error per bin, where the
        error bars are too small (or too many) to see; the legend says when.
    z_limit : float, optional
        The largest |z| a bin may have for the data to agree (the Šidák
        limit of :func:`validation.compare.compare_transients`): drawn in
        each z strip and named in the legend.
    title : str
        Figure title; the sensors drawn are named beneath it.
    max_panels : int
        At most this many sensors, evenly chosen, are drawn.
    """
    errors = errors or {}
    labels = list(transients)
    reference = np.atleast_2d(transients[labels[0]])
    sensors = reference.shape[0]
    chosen = np.unique(np.linspace(0, sensors - 1, min(sensors, max_panels)).round().astype(int))
    time = _time_axis(sampling, list(transients.values()))
    first, last, origin, scale, edges, centres = (time.first, time.last, time.origin, time.scale, time.edges,
                                                   time.centres)
    x_label, y_label = time.x_label, time.y_label
    dense = last - first > _MOST_ERROR_BARS
    if dense:
        note = f"±1 se not drawn over {last - first} bins: see z"
    elif _error_bars_visible(transients, errors, chosen, first, last):
        note = "±1 se"
    else:
        note = "±1 se, bars within the points: see z"
    names = [labels[0]] + [f"{label} ({note})" if label in errors else label for label in labels[1:]]
    residual = bool(errors)
    if residual and z_limit is not None:
        names.append(f"z limit ±{z_limit:.2f} (data that agree stay inside)")
    columns = min(len(chosen), 4)
    rows = int(np.ceil(len(chosen) / columns))
    # a fixed layout (constrained layout would double the drawing time): title, note and legend on top
    panel = 3.5 if residual else 2.7
    width = max(3.4 * columns, 5.2)
    legend_columns = _legend_columns(names, width)
    notes = [_sensor_list(chosen, sensors)]
    if residual:
        notes.append("z = (value − model) / se below each panel")
    if _window_edges_in_view(time):
        notes.append("dotted: the window's edges")
    note = textwrap.fill("; ".join(notes), width=int(0.95 * width / 0.06))     # 8-point characters
    note_lines = note.count("\n") + 1
    header = 1.45 + 0.2 * (int(np.ceil(len(names) / legend_columns)) - 1) + 0.16 * (note_lines - 1)
    height = panel * rows + header + 0.2
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.8 / width, right=1 - 0.2 / width, top=1 - header / height,
                           bottom=0.55 / height, wspace=0.25)
    grid = figure.add_gridspec(rows, columns, hspace=0.36 if residual else 0.5)
    handles = []
    for slot, k in enumerate(chosen):
        row, column = divmod(slot, columns)
        cell = grid[row, column].subgridspec(2, 1, height_ratios=[3, 1], hspace=0.08) if residual else None
        axis = figure.add_subplot(cell[0] if residual else grid[row, column])
        drawn = []
        for i, label in enumerate(labels):
            data = np.atleast_2d(transients[label])[k, first:last] * scale
            if i == 0:
                drawn.append(axis.stairs(data, edges, color="C0", lw=1.2, zorder=3))
            elif label in errors and not dense:
                drawn.append(axis.errorbar(centres, data, yerr=np.atleast_2d(errors[label])[k, first:last] * scale,
                                           fmt="o", ms=3, color=f"C{i}", elinewidth=1.2, capsize=2.0,
                                           ecolor="k" if i == 1 else f"C{i}"))
            else:
                drawn.append(axis.plot(centres, data, "o", ms=1.5 if dense else 3, color=f"C{i}")[0])
        _window_edges(axis, time)
        axis.set_title(f"sensor {k}", fontsize=9, loc="left")
        axis.tick_params(labelsize=8)
        if column == 0:
            axis.set_ylabel(y_label, fontsize=8)
        if row == 0 and origin == 0:
            _nanosecond_axis(axis)
        if slot == 0:
            handles = drawn
        if residual:
            axis.tick_params(labelbottom=False)
            strip = figure.add_subplot(cell[1], sharex=axis)
            largest = 0.0
            for i, label in enumerate(labels[1:], start=1):
                if label not in errors:
                    continue
                se = np.atleast_2d(errors[label])[k, first:last]
                value = np.atleast_2d(transients[label])[k, first:last]
                with np.errstate(divide="ignore", invalid="ignore"):
                    z = np.where(se > 0, (value - reference[k, first:last]) / se, np.nan)
                strip.plot(centres, z, "o", ms=1.5 if dense else 2.5, color=f"C{i}")
                if np.isfinite(z).any():
                    largest = max(largest, float(np.nanmax(np.abs(z))))
            strip.axhline(0, color="0.3", lw=0.6)
            span = max(largest, z_limit or 0.0, 1.0) * 1.2
            if z_limit is not None:
                for level in (-z_limit, z_limit):
                    limit_line = strip.axhline(level, color="C3", lw=0.8, ls="--")
                if slot == 0:
                    handles.append(limit_line)
            strip.set_ylim(-span, span)
            if column == 0:
                strip.set_ylabel("z", fontsize=8)
            strip.tick_params(labelsize=8)
            strip.set_xlabel(x_label, fontsize=8)
        else:
            axis.set_xlabel(x_label, fontsize=8)
    if title:
        _suptitle(figure, title, fontsize=10, y=1 - 0.1 / height, va="top")
    figure.text(0.5, 1 - 0.42 / height, note, ha="center", va="top", fontsize=8, color="0.25")
    figure.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, 1 - (0.64 + 0.16 * (note_lines - 1))
                                                                      / height),
                  ncol=legend_columns, fontsize=8, frameon=False)
    return save_figure(figure, path)


def model_figure(sampling, y: np.ndarray, noisy: np.ndarray | None = None, *, title: str = "",
                 max_curves: int = 4):
    """``forward``'s figure: every sensor's transient as an image, and a few of them as curves.

    Two panels whatever K is (:func:`plot_transients`' eight took ``forward``
    longer to draw than to compute A): left, y_k[n] over sensors x path
    length; right, the step curves of up to ``max_curves`` sensors with
    distinct transients (evenly chosen; a symmetric array repeats curves),
    with the noisy samples as points when there are any, and the
    nanosecond axis and the window's edges (dotted, when in view).

    Parameters
    ----------
    sampling : analytic.Sampling
        The bins (path length in metres).
    y : ndarray
        ``(K, N)`` noiseless transient, W m⁻¹ for I in W/sr.
    noisy : ndarray, optional
        ``(K, N)`` noisy transient.
    title : str
        Figure title.
    max_curves : int
        Sensors drawn as curves.

    Returns
    -------
    matplotlib.figure.Figure
    """
    y = np.atleast_2d(y)
    sensors = y.shape[0]
    time = _time_axis(sampling, [y])
    first, last, scale, edges = time.first, time.last, time.scale, time.edges
    width, height = 10.0, 3.9
    # a fixed layout: constrained layout would double the drawing time
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.6 / width, right=1 - 0.2 / width, top=1 - 0.85 / height,
                           bottom=0.55 / height, wspace=0.32)
    image_axis, curve_axis = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.0]})
    image = image_axis.imshow(y[:, first:last] * scale, aspect="auto", interpolation="nearest",
                              extent=(edges[0], edges[-1], sensors - 0.5, -0.5), cmap="viridis")
    bar = figure.colorbar(image, ax=image_axis, pad=0.02)
    bar.set_label(time.y_label, fontsize=8)
    bar.ax.tick_params(labelsize=7)
    image_axis.set_ylabel("sensor k", fontsize=8)
    image_axis.set_title(f"every sensor (K = {sensors})", fontsize=8, loc="left")
    from matplotlib.ticker import MaxNLocator

    if sensors <= 8:
        image_axis.set_yticks(range(sensors))
    else:
        image_axis.yaxis.set_major_locator(MaxNLocator(nbins=6, integer=True))
    peak = float(np.abs(y).max()) or 1.0
    distinct = np.sort(np.unique(np.round(y / (1e-9 * peak)), axis=0, return_index=True)[1])
    chosen = distinct[np.unique(np.linspace(0, distinct.size - 1, min(distinct.size, max_curves)).round()
                                .astype(int))]
    for i, k in enumerate(chosen):
        curve_axis.stairs(y[k, first:last] * scale, edges, color=f"C{i}", lw=1.2, label=f"sensor {k}")
        if noisy is not None:
            curve_axis.plot(time.centres, np.atleast_2d(noisy)[k, first:last] * scale, "o", ms=2.5,
                            color=f"C{i}")
    curve_axis.set_ylabel(time.y_label, fontsize=8)
    curve_axis.set_title("model (lines)" + (" and model + noise (points)" if noisy is not None else ""),
                         fontsize=8, loc="left")
    curve_axis.legend(fontsize=7, loc="upper right")
    edges_shown = _window_edges(curve_axis, time)
    for axis in (image_axis, curve_axis):
        axis.set_xlabel(time.x_label, fontsize=8)
        axis.tick_params(labelsize=8)
    if time.origin == 0:
        _nanosecond_axis(curve_axis)
    if title:
        _suptitle(figure, title + ("  (dotted: the window's edges)" if edges_shown else ""), fontsize=9)
    return figure


def plot_z_map(path: str | Path, z: np.ndarray, threshold: float, sampling, title: str) -> Path:
    """z-scores over sensors x bins (cropped to the judged bins); grey where a bin was not judged."""
    from matplotlib.patches import Patch

    judged = np.isfinite(z)
    columns = np.nonzero(judged.any(axis=0))[0]
    first, last = (int(columns[0]), int(columns[-1]) + 1) if columns.size else (0, z.shape[1])
    shown = z[:, first:last]
    limit = max(threshold, float(np.nanmax(np.abs(shown))) if np.isfinite(shown).any() else threshold)
    figure = new_figure(7.5, max(0.3 * z.shape[0] + 2.0, 3.2))
    axis = figure.add_subplot()
    from matplotlib import colormaps
    from matplotlib.ticker import MaxNLocator

    cmap = colormaps["RdBu_r"].with_extremes(bad="0.85")
    origin = _round_origin(sampling.edges[first:last + 1])
    edges = sampling.edges[first:last + 1] - origin
    image = axis.pcolormesh(edges, np.arange(z.shape[0] + 1) - 0.5, np.ma.masked_invalid(shown),
                            cmap=cmap, vmin=-limit, vmax=limit)
    if limit > threshold:
        where = "dashed"
    else:
        where = "the scale's ends"
    bar = figure.colorbar(image, ax=axis, label=f"z = (render − model) / se\n(limit ±{threshold:.2f}: {where})")
    for level in (-threshold, threshold):
        bar.ax.axhline(level, color="k", lw=1.0, ls="--")
    axis.set_xlabel("path length (m)" if origin == 0 else f"path length − {origin:g} m (m)")
    axis.set_ylabel("sensor k")
    if z.shape[0] <= 16:
        axis.set_yticks(range(z.shape[0]))
    else:
        axis.yaxis.set_major_locator(MaxNLocator(integer=True))
    axis.invert_yaxis()
    if origin == 0:
        _nanosecond_axis(axis)
    figure.legend(handles=[Patch(color="0.85", label="not judged: too few samples (se ≥ 0.1 y) or none")],
                  fontsize=7, loc="outside lower center", frameon=False)
    axis.set_title(_plain_text(title), fontsize=9, parse_math=False)
    return save_figure(figure, path, dpi=100)


def plot_convergence(path: str | Path, name: str, render_rows: list, slope: float | None,
                     model_rows: list) -> Path:
    """Render error against samples (with N^-1/2) and the model's error against tolerance.

    An error of exactly 0 cannot be drawn on the log axes and is left out
    (:func:`_log_plot`).
    """
    figure = new_figure(8.5, 3.4)
    left, right = figure.subplots(1, 2)
    samples = np.array([r["samples"] for r in render_rows], float)
    errors = np.array([r["relative_l2"] for r in render_rows], float)
    label = "render" + ("" if slope is None else f" (slope {slope:.3f})")
    if _log_plot(left, samples, errors, "o-", label=label):
        anchor = int(np.argmax(np.isfinite(errors) & (errors > 0)))
        _log_plot(left, samples, errors[anchor] * (samples / samples[anchor]) ** -0.5, ":", color="grey",
                  label="N^-1/2")
        left.legend(fontsize=7)
    left.set_xlabel("samples N")
    left.set_ylabel("relative L2 error against the model")
    _finish_log_axes(left)
    if model_rows:
        tolerance = [r["tolerance"] for r in model_rows]
        over = [max(r["over_stderr"], 1e-18) for r in model_rows]
        _log_plot(right, tolerance, over, "s-", label="model error / se (worst judged bin)")
        right.axhline(1.0, color="red", lw=0.8, label="the render's noise")
        right.set_xlabel("model tolerance (requested)")
        right.set_ylabel("max |y(tol) − y(1e-7)| / se")
        _finish_log_axes(right)
        right.invert_xaxis()
        right.legend(fontsize=7)
    else:
        right.set_axis_off()
    _suptitle(figure, f"{name}: convergence", fontsize=9)
    return save_figure(figure, path, dpi=100)


def _image_panel(figure, axis, image, title, *, vmin=0.0, vmax=1.0, cmap="gray"):
    shown = axis.imshow(image, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    axis.set_title(title, fontsize=8)
    axis.set_xticks([])
    axis.set_yticks([])
    return shown


def plot_reconstructions(path: str | Path, name: str, truth: np.ndarray, panels: list) -> Path:
    """The true image beside reconstructions, on one reflectance scale with its colour bar.

    Parameters
    ----------
    panels : list of (str, numpy.ndarray, str)
        (title, image, a note such as its PSNR) per reconstruction.
    """
    figure = new_figure(2.6 * (len(panels) + 1) + 0.6, 3.3)
    axes = figure.subplots(1, len(panels) + 1)
    shown = _image_panel(figure, axes[0], truth, "true image")
    for axis, (title, image, note) in zip(axes[1:], panels):
        _image_panel(figure, axis, image, f"{title}\n{note}")
    figure.colorbar(shown, ax=list(axes), label="reflectance", shrink=0.8)
    _suptitle(figure, name, fontsize=9)
    return save_figure(figure, path, dpi=100)


def plot_reconstruction(path: str | Path, truth: np.ndarray, image: np.ndarray, *, title: str = "") -> Path:
    """Truth, reconstruction and their difference, each with a colour bar."""
    figure = new_figure(11.0, 3.6)
    axes = figure.subplots(1, 3)
    shown = _image_panel(figure, axes[0], truth, "scene reflectance (truth)")
    _image_panel(figure, axes[1], image, "reconstruction (clipped to [0, 1] for display)")
    figure.colorbar(shown, ax=list(axes[:2]), label="reflectance", shrink=0.85)
    difference = image - truth
    limit = float(np.max(np.abs(difference))) or 1.0
    error = _image_panel(figure, axes[2], difference, "reconstruction − truth", vmin=-limit, vmax=limit,
                         cmap="RdBu_r")
    figure.colorbar(error, ax=axes[2], label="difference", shrink=0.85)
    if title:
        _suptitle(figure, title, fontsize=9)
    return save_figure(figure, path, dpi=100)


_CRITERION_LABELS = {
    "oracle": "||f_λ − f||² (squared image error)",
    "gcv": "GCV(λ) = ||r||² / trace(I − H)²",
    "lcurve": "L-curve curvature",
    "discrepancy": "||r||² − m σ²",
}


def criterion_figure(reconstruction, *, title: str = ""):
    """The λ rule's criterion against λ with the chosen λ marked, beside the L-curve.

    Parameters
    ----------
    reconstruction : analytic.Reconstruction
        Its ``lambdas``, ``criterion``, ``residual_norms``, ``seminorms`` and ``lam``.
    title : str
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    r = reconstruction
    figure = new_figure(10.0, 3.9)
    left, right = figure.subplots(1, 2)
    lambdas, criterion = np.asarray(r.lambdas, float), np.asarray(r.criterion, float)
    finite = np.isfinite(criterion)
    if np.any(finite):
        if r.rule in ("oracle", "gcv") and np.all(criterion[finite] > 0):
            _log_plot(left, lambdas, criterion, ".-")
        else:
            _no_log_margins(left, "x")
            left.semilogx(lambdas[finite], criterion[finite], ".-")
            _log_limits(left, "x")
            if r.rule == "discrepancy":
                left.axhline(0.0, color="0.5", lw=0.8)
        left.set_ylabel(_CRITERION_LABELS.get(r.rule, "criterion"), fontsize=8)
    else:
        left.set_xscale("log")
        _no_log_margins(left, "x")
        left.text(0.5, 0.5, f"λ given: {r.lam:.3g}", ha="center", transform=left.transAxes)
    left.axvline(r.lam, color="C3", ls="--", label=f"chosen λ = {r.lam:.3g}")
    left.set_xlabel("λ (weight of ||D f||², unit pixel spacing)", fontsize=8)
    left.legend(fontsize=8)
    left.set_title(f"rule: {r.rule}", fontsize=9)
    tiny = np.finfo(float).tiny
    _log_plot(right, r.residual_norms, np.maximum(r.seminorms, tiny), ".-", ms=3)
    if np.isfinite(r.residual_norm) and r.residual_norm > 0:
        right.loglog([r.residual_norm], [max(r.seminorm, tiny)], "o", color="C3", label="chosen λ")
        right.legend(fontsize=8)
    right.set_xlabel("||A f − y|| (units of y)", fontsize=8)
    right.set_ylabel("||D f|| (reflectance per pixel²)", fontsize=8)
    right.set_title("L-curve", fontsize=9)
    for axis in (left, right):
        _finish_log_axes(axis)
    if title:
        _suptitle(figure, title, fontsize=9)
    return figure


def plot_criterion(path: str | Path, reconstruction, *, title: str = "") -> Path:
    """Write :func:`criterion_figure` as PNG (atomically)."""
    return save_figure(criterion_figure(reconstruction, title=title), path, dpi=110)


def plot_conditioning(path: str | Path, table: list[dict], *, title: str = "") -> Path:
    """Singular-value spectra (one curve per (W, T)) and effective rank against W.

    Parameters
    ----------
    table : list of dict
        Rows with ``extent``, ``period``, ``sigma``, ``singular_values`` and
        ``effective_rank`` (:func:`analytic.conditioning.conditioning_table`).
    """
    figure = new_figure(11.0, 4.2)
    left, right = figure.subplots(1, 2)
    periods = sorted({row["period"] for row in table})
    for i, period in enumerate(periods):
        rows = sorted((r for r in table if r["period"] == period), key=lambda r: r["extent"])
        for j, row in enumerate(rows):
            values = np.asarray(row["singular_values"], float)
            _log_plot(left, np.arange(values.size), values, logx=False, color=f"C{i}",
                      alpha=0.4 + 0.6 * j / max(len(rows) - 1, 1), lw=1,
                      label=f"T = {period:g} m, W = {row['extent']:g} m")
        right.plot([r["extent"] for r in rows], [r["effective_rank"] for r in rows], "o-",
                   color=f"C{i}", label=f"T = {period:g} m")
    if table and table[0]["sigma"] > 0:      # σ = 0 has no place on a log axis
        left.axhline(table[0]["sigma"], color="k", ls="--", lw=0.8, label=f"σ = {table[0]['sigma']:g}")
    left.set_xlabel("index i", fontsize=8)
    left.set_ylabel("singular value s_i of A (W m⁻¹ per unit reflectance)", fontsize=8)
    _finish_log_axes(left)
    left.legend(fontsize=6, ncol=2)
    right.set_xlabel("array extent W (m)", fontsize=8)
    right.set_ylabel("effective rank: #{s_i > σ}", fontsize=8)
    right.legend(fontsize=8)
    if title:
        _suptitle(figure, title, fontsize=9)
    return save_figure(figure, path, dpi=110)


def plot_panels(path: str | Path, rows: list[dict], *, attenuation: str, intensity: float,
                illuminations: tuple = ("impulsive", "low-pass"), truth=None) -> Path:
    """Figs. 7-8 style panel: impulsive (left block) and low-pass (right), rows T, columns W.

    Each image is on a fixed [0, 1] grey scale (colour bar at the right) with
    its PSNR (dB, data range 1) beneath it.
    """
    group = [r for r in rows if r["attenuation"] == attenuation and r["intensity"] == intensity]
    periods = sorted({r["period"] for r in group})
    extents = sorted({r["extent"] for r in group})
    columns = len(illuminations) * len(extents) + (1 if truth is not None else 0)
    figure = new_figure(1.9 * columns + 1.0, 2.3 * len(periods) + 0.6)
    axes = np.atleast_2d(figure.subplots(len(periods), columns, squeeze=False))
    table = {(r["illumination"], r["period"], r["extent"]): r for r in group}
    shown = None
    for i, period in enumerate(periods):
        for block, name in enumerate(illuminations):
            for j, extent in enumerate(extents):
                axis = axes[i, block * len(extents) + j]
                row = table[(name, period, extent)]
                shown = _image_panel(figure, axis, np.clip(row["image"], 0, 1),
                                     f"{name}\nT = {period:g}, W = {extent:g}")
                axis.set_xlabel(f"{row['psnr']:.1f} dB", fontsize=7)
        if truth is not None:
            _image_panel(figure, axes[i, -1], truth, "true image")
    if shown is not None:
        figure.colorbar(shown, ax=axes.ravel().tolist(), label="reflectance", shrink=0.6)
    figure.suptitle(f"oracle-λ reconstructions, {attenuation} attenuation, σ = {group[0]['sigma']:g}, "
                    f"source {intensity:g} W/sr (PSNR beneath, data range 1)", fontsize=9)
    return save_figure(figure, path, dpi=100)


class _Bins(NamedTuple):
    """The bins of a transient that is not a scene's own (``check``'s data): edges and count."""

    edges: np.ndarray
    count: int


def plot_check_transients(path: str | Path, result, *, max_panels: int = 9) -> Path:
    """Data (with one-standard-error bars) against the model as given and after the fit.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    result : CheckResult
        What :func:`check_transient` returned.
    max_panels : int
        At most this many sensors, those with the largest |z| as given first.
    """
    sensors = result.data.shape[0]
    if result.as_given is not None:
        worst = np.nan_to_num(np.abs(result.as_given.z), nan=-1.0).max(axis=1)
        order = np.argsort(-worst, kind="stable")[:max_panels]
    else:
        order = np.arange(min(sensors, max_panels))
    order = np.sort(order)
    edges = np.asarray(result.edges, dtype=float)
    time = _time_axis(_Bins(edges, edges.size - 1), [result.model, result.data])
    first, last, scale = time.first, time.last, time.scale
    columns = int(np.ceil(np.sqrt(len(order))))
    rows = int(np.ceil(len(order) / columns))
    fit = result.fit
    names = ["model as given", f"fitted: {fit.scale:.6g} × model, its start_opl {fit.offset_opl:+.2g} m",
             "data ±1 se" if result.stderr is not None else "data (no errors)"]
    width = max(3.6 * columns, 6.0)
    legend_columns = _legend_columns(names, width)
    header = 1.45 + 0.2 * (int(np.ceil(len(names) / legend_columns)) - 1)
    height = 2.9 * rows + header + 0.35
    # a fixed layout: the title, its note and the legend each get a line above the panels
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.85 / width, right=1 - 0.2 / width, top=1 - header / height,
                           bottom=0.6 / height, wspace=0.25, hspace=0.45)
    axes = np.atleast_2d(figure.subplots(rows, columns, squeeze=False))
    for panel, axis in enumerate(axes.flat):
        if panel >= len(order):
            axis.axis("off")
            continue
        k = int(order[panel])
        drawn = [axis.stairs(result.model[k, first:last] * scale, time.edges, color="C0"),
                 axis.stairs(result.fitted_model[k, first:last] * scale, time.edges, color="C1", ls="--")]
        data = result.data[k, first:last] * scale
        if result.stderr is not None:
            drawn.append(axis.errorbar(time.centres, data, yerr=result.stderr[k, first:last] * scale, fmt="o",
                                       ms=2.5, color="k", elinewidth=1.0, capsize=1.5))
        else:
            drawn.append(axis.plot(time.centres, data, "o", ms=2.5, color="k")[0])
        if panel == 0:
            handles = drawn
        axis.set_title(f"sensor {k}", fontsize=9, loc="left")
        axis.tick_params(labelsize=8)
        if panel % columns == 0:
            axis.set_ylabel(time.y_label, fontsize=8)
        if panel >= len(order) - columns:
            axis.set_xlabel(time.x_label, fontsize=8)
        if panel < columns and time.origin == 0:
            _nanosecond_axis(axis)
    shown = (f"every sensor (K = {sensors})" if len(order) == sensors
             else f"{len(order)} of {sensors} sensors: those with the largest |z| as given")
    _suptitle(figure, "data against the model", fontsize=10, y=1 - 0.1 / height, va="top")
    figure.text(0.5, 1 - 0.42 / height, shown, ha="center", va="top", fontsize=8, color="0.25")
    figure.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, 1 - 0.64 / height),
                  ncol=legend_columns, fontsize=8, frameon=False)
    return save_figure(figure, path)


def plot_check_z(path: str | Path, result, *, named: int = 3) -> Path:
    """z of every judged bin against its path length, as given and after the fit, with the limits.

    Every sensor's bins are drawn in one panel per verdict (the limit, not
    the sensor, decides agreement), sensor 0 to K - 1 from left to right
    within each bin's width; the ``named`` bins of largest |z| are labelled
    with their sensor.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    result : CheckResult
        A result judged with errors (not by shape only).
    named : int
        Bins labelled with their sensor in each panel.
    """
    if result.as_given is None:
        raise ValueError("result: judged by shape only, it has no z to plot")
    edges = np.asarray(result.edges, dtype=float)
    judged = np.isfinite(result.as_given.z) | np.isfinite(result.after_fit.z)
    columns = np.nonzero(judged.any(axis=0))[0]
    first, last = (int(columns[0]), int(columns[-1]) + 1) if columns.size else (0, edges.size - 1)
    origin = _round_origin(edges[first:last + 1])
    centres = 0.5 * (edges[first:last] + edges[first + 1:last + 1]) - origin
    sensors = result.data.shape[0]
    # sensors side by side within each bin's width, in order, so that one bin's points do not overlap
    width = float(np.min(np.diff(edges[first:last + 1]))) if last > first else 0.0
    spread = (np.arange(sensors) / max(sensors - 1, 1) - 0.5) * 0.6 * width if sensors > 1 else np.zeros(1)
    figure = new_figure(8.0, 5.6)
    axes = figure.subplots(2, 1, sharex=True)
    for axis, agreement, label in ((axes[0], result.as_given, "as given"),
                                   (axes[1], result.after_fit, "after the fit")):
        z = agreement.z[:, first:last]
        path_lengths = centres[None, :] + spread[:, None]
        finite = np.isfinite(z)
        axis.plot(path_lengths[finite], z[finite], "o", ms=3, alpha=0.7,
                  color="C0" if agreement.agrees else "C3", label="a judged bin")
        for sign in (-1, 1):
            axis.axhline(sign * agreement.z_threshold, color="0.3", ls="--", lw=0.8,
                         label=f"limit ±{agreement.z_threshold:.2f}" if sign > 0 else None)
        axis.axhline(0, color="0.6", lw=0.6)
        largest = np.argsort(-np.nan_to_num(np.abs(z), nan=-1.0), axis=None)[:named if sensors > 1 else 0]
        for rank, flat in enumerate(largest):
            k, n = divmod(int(flat), z.shape[1])
            if np.isfinite(z[k, n]):
                axis.annotate(f"sensor {k}", (path_lengths[k, n], z[k, n]), xytext=(5, 9 * (1 - rank)),
                              textcoords="offset points", fontsize=7, va="center",
                              arrowprops={"arrowstyle": "-", "color": "0.5", "lw": 0.5})
        limit = max(agreement.z_threshold * 1.3, float(np.max(np.abs(z[finite]))) * 1.1 if finite.any() else 1)
        axis.set_ylim(-limit, limit)
        verdict = "agrees" if agreement.agrees else "disagrees"
        axis.set_title(f"{label}: {verdict}, χ²/dof = {agreement.chi2_per_dof:.3g}, "
                       f"max |z| = {agreement.max_abs_z:.3g} (limit {agreement.z_threshold:.2f})", fontsize=9)
        axis.set_ylabel("z (normal equivalent of t)" if result.dof is not None else "z", fontsize=9)
        axis.tick_params(labelsize=8)
        axis.legend(fontsize=7, loc="lower right")
    if origin == 0:
        _nanosecond_axis(axes[0])
    x_label = "path length (m)" if origin == 0 else f"path length − {origin:g} m (m)"
    if sensors > 1:
        x_label += f": each bin's sensors side by side, 0 to {sensors - 1} from the left"
    axes[1].set_xlabel(x_label, fontsize=9)
    return save_figure(figure, path)


def plot_speed_against_error(path: str | Path, report: dict) -> Path:
    """RMS error against wall time, ours and mitransient's, one panel per bench scene.

    Parameters
    ----------
    report : dict
        :func:`validation.bench.speed_against_error`'s report: ``scenes`` ->
        {``ours``, ``mitransient``: rows with ``seconds`` and ``rms_error``},
        and ``device``.
    """
    scenes = report["scenes"]
    figure = new_figure(5.0 * len(scenes), 3.9)
    axes = np.atleast_1d(figure.subplots(1, len(scenes), squeeze=False)[0])
    for axis, (name, entry) in zip(axes, scenes.items()):
        for label, rows in (("ours", entry["ours"]), ("mitransient", entry.get("mitransient", []))):
            if rows:
                _log_plot(axis, [r["seconds"] for r in rows], [r["rms_error"] for r in rows], "o-", label=label)
        axis.set_xlabel("wall time (s)")
        axis.set_ylabel("RMS relative L2 error against the model")
        axis.set_title(_plain_text(name), fontsize=9, parse_math=False)
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=8)
        _finish_log_axes(axis)
    _suptitle(figure, f"speed against error ({report['device']})", fontsize=9)
    return save_figure(figure, path)
