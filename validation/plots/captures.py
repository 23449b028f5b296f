"""A capture over a grid of wall points (tal's HDF5, an NLOS scan): the light each point receives, and a few
of its traces."""

from __future__ import annotations

import numpy as np

from .axes import time_axis
from .common import new_figure
from .transients import finish_time_figure

__all__ = ["capture_figure", "trace_labels", "TRACES_LEGEND"]

#: The legend title of traces drawn with :func:`trace_labels`.
TRACES_LEGEND = "ranked by light summed over time;\neach drawn × the factor in its label"


def _plane_axes(positions: np.ndarray) -> tuple[int, int]:
    """The two coordinates along which the points spread most (x and y for tal's wall in z = 0)."""
    spread = np.ptp(positions, axis=0)
    first, second = np.argsort(spread)[::-1][:2]
    return int(min(first, second)), int(max(first, second))


def _traced(totals: np.ndarray, count: int) -> list[int]:
    """The brightest point, then the points at evenly spaced ranks of brightness (quartiles for 4)."""
    order = np.argsort(-totals, kind="stable")
    ranks = np.unique((np.arange(min(count, totals.size)) * totals.size) // max(count, 1))
    return [int(order[rank]) for rank in ranks]


def _ordinal(number: int) -> str:
    suffix = "th" if number % 100 in (11, 12, 13) else {1: "st", 2: "nd", 3: "rd"}.get(number % 10, "th")
    return f"{number}{suffix}"


def _nice_factor(ratio: float) -> float:
    """The largest of 1, 2, 5, 10, 20, 50, ... not above ``ratio`` (1 below 1)."""
    if not ratio >= 1:
        return 1.0
    power = 10.0 ** np.floor(np.log10(ratio))
    return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= ratio * (1 + 1e-12))


def trace_labels(totals: np.ndarray, chosen: list[int], peaks: np.ndarray,
                 names: list[str]) -> tuple[list[str], np.ndarray]:
    """Each traced row's label (its number, row, rank of brightness) and the power of ten it is drawn times.

    A few pairs near the laser outshine the rest by orders of magnitude, so a
    fainter trace drawn as it is lies flat at zero beside the brightest: each
    is multiplied by the largest of 1, 2, 5, 10, 20, ... not above the
    brightest's peak over its own (its label says by how much), so that every
    trace peaks between 0.4 and 1 times the first's height while the labels
    give the true scale.

    Parameters
    ----------
    totals : ndarray
        ``(P,)`` every row's light summed over the window (what ranks them).
    chosen : list of int
        The traced rows, the brightest first (:func:`_traced`).
    peaks : ndarray
        ``(len(chosen),)`` the largest |value| of each traced row as drawn.
    names : list of str
        What each traced row is ("pair 34", "point 34 (0.1, 0.2)").

    Returns
    -------
    (labels, factors)
        ``factors`` of the traces, each 1, 2 or 5 times a power of ten (1 for the first).
    """
    rank_of = np.empty(totals.size, dtype=np.int64)
    rank_of[np.argsort(-totals, kind="stable")] = np.arange(1, totals.size + 1)
    top = float(peaks[0]) if peaks.size else 0.0
    factors = np.ones(len(chosen))
    labels = []
    for number, (row, peak, name) in enumerate(zip(chosen, peaks, names), start=1):
        if number > 1 and top > 0 and peak > 0:
            factors[number - 1] = _nice_factor(top / peak)
        rank = int(rank_of[row])
        place = "the brightest" if rank == 1 else f"the {_ordinal(rank)} brightest of {totals.size}"
        scaled = "" if factors[number - 1] == 1 else f", × {factors[number - 1]:g}"
        labels.append(f"{number}: {name}, {place}{scaled}")
    return labels, factors


def _grid_cells(first: np.ndarray, second: np.ndarray):
    """(column edges, row edges, rows, columns) when the points fill a regular grid of distinct cells, else None."""
    def levels(values):
        span = float(np.ptp(values)) or 1.0
        keys = np.round((values - values.min()) / span * 1e6).astype(np.int64)
        unique, index = np.unique(keys, return_inverse=True)
        centres = np.array([values[index == i].mean() for i in range(unique.size)])
        return centres, index

    columns, column_of = levels(first)
    rows, row_of = levels(second)
    if columns.size * rows.size != first.size or np.unique(row_of * columns.size + column_of).size != first.size:
        return None

    def cell_edges(centres):
        if centres.size == 1:
            return np.array([centres[0] - 0.5, centres[0] + 0.5])
        middle = 0.5 * (centres[1:] + centres[:-1])
        return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])

    return cell_edges(columns), cell_edges(rows), row_of, column_of


def _units(scale: float) -> str:
    """The y label's note for values drawn times ``scale`` (a capture's H is in the file's own units)."""
    power = -int(round(np.log10(scale)))
    return " (the file's units)" if power == 0 else f" (units of 1e{power} of the file's)"


def capture_figure(sampling, transient: np.ndarray, positions: np.ndarray, *, title: str = "", traces: int = 4):
    """Left: each point's light summed over the window, at its place on the wall; right: a few traces.

    Parameters
    ----------
    sampling : analytic.Sampling
        The bins (path length in metres: tal's ``t_start`` and ``delta_t``).
    transient : ndarray
        ``(K, N)`` light per point and bin (H, points in the file's order).
    positions : ndarray
        ``(K, 3)`` the points (tal's ``sensor_grid_xyz``), metres.
    title : str
        Figure title.
    traces : int
        Points drawn as traces (numbered on the map): the brightest, then
        those at evenly spaced ranks of brightness (the quartiles for 4).

    Returns
    -------
    matplotlib.figure.Figure
    """
    transient = np.atleast_2d(transient)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    totals = transient.sum(axis=1)
    time = time_axis(sampling, [transient])
    first, last, scale, edges = time.first, time.last, time.scale, time.edges
    width, height = 10.5, 4.2
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.65 / width, right=1 - 0.25 / width, top=1 - 0.85 / height,
                           bottom=0.6 / height, wspace=0.35)
    map_axis, trace_axis = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.2]})
    across, along = _plane_axes(positions)
    names = "xyz"
    cells = _grid_cells(positions[:, across], positions[:, along])
    if cells is not None:            # a scan grid: each point's cell filled
        column_edges, row_edges, row_of, column_of = cells
        image = np.full((row_edges.size - 1, column_edges.size - 1), np.nan)
        image[row_of, column_of] = totals * scale
        shown = map_axis.pcolormesh(column_edges, row_edges, image, cmap="inferno")
    else:
        shown = map_axis.scatter(positions[:, across], positions[:, along], c=totals * scale, cmap="inferno",
                                 marker="s", s=max(9.0, 4000.0 / max(len(totals), 1)), linewidths=0)
    bar = figure.colorbar(shown, ax=map_axis, pad=0.02)
    bar.set_label(f"H summed over the window{_units(scale)}", fontsize=7)
    bar.ax.tick_params(labelsize=7)
    map_axis.set_aspect("equal", adjustable="datalim")
    map_axis.set_xlabel(f"{names[across]} (m)", fontsize=8)
    map_axis.set_ylabel(f"{names[along]} (m)", fontsize=8)
    map_axis.set_title(f"light per point, summed over time ({len(totals)} points)", fontsize=8, loc="left")
    chosen = _traced(totals, traces)
    labels, factors = trace_labels(totals, chosen, np.abs(transient[chosen, first:last]).max(axis=1, initial=0.0),
                                   [f"point {k} ({positions[k, across]:.3g}, {positions[k, along]:.3g})"
                                    for k in chosen])
    for number, (k, label, factor) in enumerate(zip(chosen, labels, factors), start=1):
        colour = f"C{number - 1}"
        map_axis.annotate(str(number), (positions[k, across], positions[k, along]), color=colour, fontsize=8,
                          fontweight="bold", ha="center", va="center",
                          bbox={"boxstyle": "circle,pad=0.15", "fc": "white", "ec": colour, "lw": 0.8})
        trace_axis.stairs(transient[k, first:last] * scale * factor, edges, color=colour, lw=1.2, label=label)
    trace_axis.set_title("traces of the numbered points", fontsize=8, loc="left")
    trace_axis.set_ylabel(f"H{_units(scale)}", fontsize=8)
    trace_axis.set_xlabel(time.x_label, fontsize=8)
    trace_axis.legend(fontsize=7, loc="upper right", title=TRACES_LEGEND, title_fontsize=7)
    for axis in (map_axis, trace_axis):
        axis.tick_params(labelsize=8)
    finish_time_figure(figure, trace_axis, time, title)
    return figure
