"""``check``'s figures: data against the model as given and after the fit, and z by path length."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .axes import nanosecond_axis, round_origin, time_axis
from .common import columns_for_legend, new_figure, suptitle

__all__ = ["check_transients_figure", "check_z_figure"]

#: Line widths (points) of the model as given (a band beneath) and of the fitted model (a line on top).
AS_GIVEN_WIDTH, FITTED_WIDTH = 4.0, 1.2


class _Bins(NamedTuple):
    """The bins of a transient that is not a scene's own (``check``'s data): edges and count."""

    edges: np.ndarray
    count: int


def check_transients_figure(result, *, max_panels: int = 9):
    """Data (with one-standard-error bars) against the model as given and after the fit.

    Parameters
    ----------
    result : CheckResult
        What :func:`check_transient` returned.
    max_panels : int
        At most this many sensors, those with the largest |z| as given first.

    Returns
    -------
    matplotlib.figure.Figure
    """
    sensors = result.data.shape[0]
    if result.as_given is not None:
        worst = np.nan_to_num(np.abs(result.as_given.z), nan=-1.0).max(axis=1)
        order = np.argsort(-worst, kind="stable")[:max_panels]
    else:
        order = np.arange(min(sensors, max_panels))
    order = np.sort(order)
    edges = np.asarray(result.edges, dtype=float)
    time = time_axis(_Bins(edges, edges.size - 1), [result.model, result.data])
    first, last, scale = time.first, time.last, time.scale
    columns = int(np.ceil(np.sqrt(len(order))))
    rows = int(np.ceil(len(order) / columns))
    fit = result.fit
    names = ["model as given", f"fitted: {fit.scale:.6g} × model, its start_opl {fit.offset_opl:+.2g} m",
             "data ±1 se" if result.stderr is not None else "data (no errors)"]
    width = max(3.6 * columns, 6.0)
    legend_columns = columns_for_legend(names, width)
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
        # the model as given, a broad pale band beneath; the fitted one, thin and dashed on top: where they
        # coincide (scale 1, offset 0: the usual case) both stay visible
        drawn = [axis.stairs(result.model[k, first:last] * scale, time.edges, color="C0", lw=AS_GIVEN_WIDTH,
                             alpha=0.45, zorder=2),
                 axis.stairs(result.fitted_model[k, first:last] * scale, time.edges, color="C1", ls="--",
                             lw=FITTED_WIDTH, zorder=3)]
        data = result.data[k, first:last] * scale
        if result.stderr is not None:
            drawn.append(axis.errorbar(time.centres, data, yerr=result.stderr[k, first:last] * scale, fmt="o",
                                       ms=2.5, color="k", elinewidth=1.0, capsize=1.5, zorder=4))
        else:
            drawn.append(axis.plot(time.centres, data, "o", ms=2.5, color="k", zorder=4)[0])
        if panel == 0:
            handles = drawn
        axis.set_title(f"sensor {k}", fontsize=9, loc="left")
        axis.tick_params(labelsize=8)
        if panel % columns == 0:
            axis.set_ylabel(time.y_label, fontsize=8)
        if panel >= len(order) - columns:
            axis.set_xlabel(time.x_label, fontsize=8)
        if panel < columns and time.origin == 0:
            nanosecond_axis(axis)
    shown = (f"every sensor (K = {sensors})" if len(order) == sensors
             else f"{len(order)} of {sensors} sensors: those with the largest |z| as given")
    suptitle(figure, "data against the model", fontsize=10, y=1 - 0.1 / height, va="top")
    figure.text(0.5, 1 - 0.42 / height, shown, ha="center", va="top", fontsize=8, color="0.25")
    figure.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, 1 - 0.64 / height),
                  ncol=legend_columns, fontsize=8, frameon=False)
    return figure


def check_z_figure(result, *, named: int = 3):
    """z of every judged bin against its path length, as given and after the fit, with the limits.

    Every sensor's bins are drawn in one panel per verdict (the limit, not
    the sensor, decides agreement), sensor 0 to K - 1 from left to right
    within each bin's width; the ``named`` bins of largest |z| are labelled
    with their sensor.

    Parameters
    ----------
    result : CheckResult
        A result judged with errors (not by shape only).
    named : int
        Bins labelled with their sensor in each panel.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if result.as_given is None:
        raise ValueError("result: judged by shape only, it has no z to plot")
    edges = np.asarray(result.edges, dtype=float)
    judged = np.isfinite(result.as_given.z) | np.isfinite(result.after_fit.z)
    columns = np.nonzero(judged.any(axis=0))[0]
    first, last = (int(columns[0]), int(columns[-1]) + 1) if columns.size else (0, edges.size - 1)
    origin = round_origin(edges[first:last + 1])
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
        nanosecond_axis(axes[0])
    x_label = "path length (m)" if origin == 0 else f"path length − {origin:g} m (m)"
    if sensors > 1:
        x_label += f": each bin's sensors side by side, 0 to {sensors - 1} from the left"
    axes[1].set_xlabel(x_label, fontsize=9)
    return figure
