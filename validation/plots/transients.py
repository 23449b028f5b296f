"""Figures of transients: model against render per sensor with z strips, one transient (the model, a render, any
file ``plot`` reads), and the z map."""

from __future__ import annotations

import textwrap

import numpy as np

from .axes import nanosecond_axis, relay_wall_label, round_origin, time_axis, window_edges, window_edges_in_view
from .common import columns_for_legend, new_figure, plain_text, suptitle

__all__ = ["transients_figure", "transient_figure", "model_figure", "z_map_figure", "finish_time_figure"]


#: What a transient's rows are -> their symbol: a plane's sensors k, a relay-wall capture's pairs p.
ROW_SYMBOLS = {"sensor": ("k", "K"), "pair": ("p", "P")}


def _sensor_list(chosen: np.ndarray, sensors: int, row_kind: str = "sensor") -> str:
    """"sensors 0, 2, 4, ..., 15 (8 of 16, evenly spaced)", or "every sensor" when all are drawn."""
    if len(chosen) == sensors:
        return f"every {row_kind} ({ROW_SYMBOLS[row_kind][1]} = {sensors})"
    return f"{row_kind}s {', '.join(str(k) for k in chosen)} ({len(chosen)} of {sensors}, evenly spaced)"


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


def transients_figure(sampling, transients: dict[str, np.ndarray], *,
                      errors: dict[str, np.ndarray] | None = None, z_limit: float | None = None,
                      title: str = "", max_panels: int = 8, row_kind: str = "sensor"):
    """Transients against path length, one panel per sensor, with z residuals when errors are given.

    Parameters
    ----------
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
        limit of :func:`validation.judging.compare.compare_transients`): drawn in
        each z strip and named in the legend.
    title : str
        Figure title; the sensors drawn are named beneath it.
    max_panels : int
        At most this many sensors, evenly chosen, are drawn.
    row_kind : {"sensor", "pair"}
        What the rows are: a plane's sensors, a relay-wall capture's pairs.

    Returns
    -------
    matplotlib.figure.Figure
    """
    errors = errors or {}
    labels = list(transients)
    reference = np.atleast_2d(transients[labels[0]])
    sensors = reference.shape[0]
    chosen = np.unique(np.linspace(0, sensors - 1, min(sensors, max_panels)).round().astype(int))
    time = time_axis(sampling, list(transients.values()))
    first, last, origin, scale, edges, centres = (time.first, time.last, time.origin, time.scale, time.edges,
                                                   time.centres)
    x_label, y_label = time.x_label, time.y_label if row_kind == "sensor" else relay_wall_label(time.y_label)
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
    legend_columns = columns_for_legend(names, width)
    notes = [_sensor_list(chosen, sensors, row_kind)]
    if residual:
        notes.append("z = (value − model) / se below each panel")
    if window_edges_in_view(time):
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
        window_edges(axis, time)
        axis.set_title(f"{row_kind} {k}", fontsize=9, loc="left")
        axis.tick_params(labelsize=8)
        if column == 0:
            axis.set_ylabel(y_label, fontsize=8)
        if row == 0 and origin == 0:
            nanosecond_axis(axis)
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
        suptitle(figure, title, fontsize=10, y=1 - 0.1 / height, va="top")
    figure.text(0.5, 1 - 0.42 / height, note, ha="center", va="top", fontsize=8, color="0.25")
    figure.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, 1 - (0.64 + 0.16 * (note_lines - 1))
                                                                      / height),
                  ncol=legend_columns, fontsize=8, frameon=False)
    return figure


def model_figure(sampling, y: np.ndarray, noisy: np.ndarray | None = None, *, title: str = "", max_curves: int = 4):
    """``forward``'s figure: :func:`transient_figure` of the model, with its noisy samples when there are any."""
    return transient_figure(sampling, y, noisy=noisy, label="model", title=title, max_curves=max_curves)


def _sensor_groups(y: np.ndarray) -> list[list[int]]:
    """Sensors whose transients are equal (to 1e-9 of the peak) grouped, in order of their first sensor:
    a symmetric array repeats curves, and one line serves each group."""
    peak = float(np.abs(y).max()) or 1.0
    groups: dict[bytes, list[int]] = {}
    for k, row in enumerate(np.round(y / (1e-9 * peak))):
        groups.setdefault(row.tobytes(), []).append(k)
    return list(groups.values())


def _group_label(sensors: list[int]) -> str:
    if len(sensors) == 1:
        return f"sensor {sensors[0]}"
    shown = ", ".join(str(k) for k in sensors[:6]) + (", ..." if len(sensors) > 6 else "")
    return f"sensors {shown} (equal)"


def _curves_title(label: str, drawn: int, groups: int, sensors: int, *, band: bool, noisy: bool) -> str:
    """What the curve panel shows: which data, how drawn, and which of the sensors."""
    what = f"{label} (lines)" + (", ±1 standard error (band)" if band else "") \
        + (" and model + noise (points)" if noisy else "")
    if drawn == groups:
        return what if groups == sensors else f"{what}; equal curves drawn once"
    if groups == sensors:
        return f"{what}; {drawn} of {sensors} sensors, evenly chosen"
    return f"{what}; {drawn} of {groups} distinct curves ({sensors} sensors), evenly chosen"


def transient_figure(sampling, y: np.ndarray, *, stderr: np.ndarray | None = None, noisy: np.ndarray | None = None,
                     label: str = "model", title: str = "", max_curves: int = 16):
    """A transient on its time axis: every sensor as an image, and one line per sensor.

    Two panels whatever K is (:func:`transients_figure`' eight took ``forward``
    longer to draw than to compute A): left, y_k[n] over sensors x path
    length; right, one step line per sensor (sensors with equal transients,
    as a symmetric array has, share one line named after all of them; beyond
    ``max_curves`` lines an evenly chosen ``max_curves``, and the panel says
    so), with ±1 standard error as a band and noisy samples as points when
    given; the nanosecond axis along the top and the window's edges (dotted,
    when in view).

    Parameters
    ----------
    sampling : analytic.Sampling
        The bins (path length in metres).
    y : ndarray
        ``(K, N)`` transient, W m⁻¹ for I in W/sr.
    stderr : ndarray, optional
        ``(K, N)`` standard error of ``y`` (a render's), drawn as a band.
    noisy : ndarray, optional
        ``(K, N)`` noisy samples of the model, drawn as points.
    label : str
        What ``y`` is ("model", "render", "data").
    title : str
        Figure title.
    max_curves : int
        Most lines drawn.

    Returns
    -------
    matplotlib.figure.Figure
    """
    y = np.atleast_2d(y)
    sensors = y.shape[0]
    time = time_axis(sampling, [y])
    first, last, scale, edges = time.first, time.last, time.scale, time.edges
    groups = _sensor_groups(y)
    chosen = [groups[i] for i in np.unique(np.linspace(0, len(groups) - 1, min(len(groups), max_curves))
                                           .round().astype(int))]
    outside = len(chosen) > 4           # a legend of many lines goes beside the panel, not over the curves
    width, height = (11.5 if outside else 10.0), 3.9
    # a fixed layout: constrained layout would double the drawing time
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.6 / width, right=1 - (1.75 if outside else 0.2) / width, top=1 - 0.85 / height,
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
    colours = _line_colours(len(chosen))
    for colour, group in zip(colours, chosen):
        k = group[0]
        curve_axis.stairs(y[k, first:last] * scale, edges, color=colour, lw=1.2, label=_group_label(group))
        if stderr is not None:
            error = np.atleast_2d(stderr)[k, first:last] * scale
            low, high = y[k, first:last] * scale - error, y[k, first:last] * scale + error
            curve_axis.fill_between(edges, np.append(low, low[-1]), np.append(high, high[-1]), step="post",
                                    color=colour, alpha=0.3, lw=0)
        if noisy is not None:
            curve_axis.plot(time.centres, np.atleast_2d(noisy)[k, first:last] * scale, "o", ms=2.5,
                            color=colour)
    curve_axis.set_ylabel(time.y_label, fontsize=8)
    curve_axis.set_title(plain_text(_curves_title(label, len(chosen), len(groups), sensors,
                                                  band=stderr is not None, noisy=noisy is not None)),
                         fontsize=8, loc="left", parse_math=False)
    if outside:
        curve_axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    else:
        curve_axis.legend(fontsize=7, loc="upper right")
    for axis in (image_axis, curve_axis):
        axis.set_xlabel(time.x_label, fontsize=8)
        axis.tick_params(labelsize=8)
    finish_time_figure(figure, curve_axis, time, title)
    return figure


def finish_time_figure(figure, axis, time, title: str) -> None:
    """The time panel's window edges (dotted, when in view) and nanosecond axis (along its top, when the
    path lengths start at 0), and the figure's title, which names the dotted edges when they are drawn."""
    edges_shown = window_edges(axis, time)
    if time.origin == 0:
        nanosecond_axis(axis)
    if title:
        suptitle(figure, title + ("  (dotted: the window's edges)" if edges_shown else ""), fontsize=9)


def _line_colours(count: int) -> list:
    """matplotlib's ten cycle colours, or evenly spaced viridis colours for more lines."""
    if count <= 10:
        return [f"C{i}" for i in range(count)]
    from matplotlib import colormaps

    return [colormaps["viridis"](value) for value in np.linspace(0.0, 0.9, count)]


def z_map_figure(z: np.ndarray, threshold: float, sampling, title: str, *, row_kind: str = "sensor"):
    """z-scores over sensors x bins (cropped to the judged bins); grey where a bin was not judged.

    ``row_kind`` names the rows: ``"sensor"`` (a plane's) or ``"pair"`` (a relay-wall capture's).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.patches import Patch

    judged = np.isfinite(z)
    columns = np.nonzero(judged.any(axis=0))[0]
    first, last = (int(columns[0]), int(columns[-1]) + 1) if columns.size else (0, z.shape[1])
    shown = z[:, first:last]
    limit = max(threshold, float(np.nanmax(np.abs(shown))) if np.isfinite(shown).any() else threshold)
    # 0.3 inch a row up to 20 rows, then no taller (a relay-wall capture has hundreds of pairs)
    figure = new_figure(7.5, min(max(0.3 * z.shape[0] + 2.0, 3.2), 8.0), dpi=100)
    axis = figure.add_subplot()
    from matplotlib import colormaps
    from matplotlib.ticker import MaxNLocator

    cmap = colormaps["RdBu_r"].with_extremes(bad="0.85")
    origin = round_origin(sampling.edges[first:last + 1])
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
    axis.set_ylabel(f"{row_kind} {ROW_SYMBOLS[row_kind][0]}")
    if z.shape[0] <= 16:
        axis.set_yticks(range(z.shape[0]))
    else:
        axis.yaxis.set_major_locator(MaxNLocator(integer=True))
    axis.invert_yaxis()
    if origin == 0:
        nanosecond_axis(axis)
    figure.legend(handles=[Patch(color="0.85", label="not judged: too few samples (under about 100) or none")],
                  fontsize=7, loc="outside lower center", frameon=False)
    axis.set_title(plain_text(title), fontsize=9, parse_math=False)
    return figure
