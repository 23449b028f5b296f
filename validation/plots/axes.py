"""Axes that stay readable: log axes that leave out what they cannot show, and cropped path-length axes.

Log axes leave out values they cannot show (0, say, or NaN), keep finite
limits for data near float64's ends, and label a span under a decade with a
few plain numbers that do not run together. Time axes are cropped to the
light (the window's edges drawn when in view) and labelled in metres of
path length from a round origin, with nanoseconds along the top.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .common import NANOSECONDS_PER_METRE, Y_LABEL

__all__ = ["log_plot", "log_limits", "no_log_margins", "finish_log_axes", "TimeAxis", "time_axis", "relay_wall_label",
           "nanosecond_axis", "round_origin", "power_of_ten", "window_edges", "window_edges_in_view"]


def log_plot(axis, x, y, *args, logx: bool = True, **kwargs) -> bool:
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
    no_log_margins(axis, *(("x", "y") if logx else ("y",)))
    if not keep.any():
        axis.text(0.5, 0.5, "nothing above 0 to draw on a log axis", ha="center", va="center",
                  transform=axis.transAxes, fontsize=8, color="0.4")
        return False
    axis.plot(x[keep], y[keep], *args, **kwargs)
    # limits now, from the data: matplotlib's own margins would overflow for data near 1e±308
    for name in ("x", "y") if logx else ("y",):
        log_limits(axis, name)
    return True


#: Powers of ten a log axis's limits stay within: its margins beyond data near float64's ends
#: (λ from 1e-300 to 1e300, a seminorm of 1e-308) would overflow to inf or 0.
_LOG_LIMIT = 300.0
#: Share of a log axis's span (in decades) added either side of its data, as matplotlib's default.
_LOG_MARGIN = 0.05


def log_limits(axis, name: str) -> None:
    """Limits of a log axis from its data, the usual margin added in decades but never past 10^±300.

    The axis's own margin must be 0 while it is drawn (:func:`no_log_margins`):
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


def no_log_margins(axis, *names: str) -> None:
    """No automatic margin on these (log) axes: :func:`log_limits` adds one that stays finite."""
    for name in names:
        (axis.set_xmargin if name == "x" else axis.set_ymargin)(0.0)


def finish_log_axes(axis) -> None:
    """Finite limits (:func:`log_limits`) and tick labels that do not run together on log axes.

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
        log_limits(axis, name)
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


def nanosecond_axis(axis) -> None:
    """Ticks in nanoseconds along the top: 1 m of path is 3.3356 ns."""
    secondary = axis.secondary_xaxis("top", functions=(lambda m: m * NANOSECONDS_PER_METRE,
                                                       lambda ns: ns / NANOSECONDS_PER_METRE))
    secondary.tick_params(labelsize=7, pad=1)
    secondary.set_xlabel("ns", fontsize=7, labelpad=1, loc="right")


def round_origin(edges: np.ndarray) -> float:
    """A round origin for a path-length axis far from 0 (a span under 1 % of its start, such as 1.5 mm
    at 800 m), else 0: matplotlib's offset text would otherwise collide with the nanosecond axis."""
    span, start = float(edges[-1] - edges[0]), float(edges[0])
    if not (span > 0 and abs(start) > 100 * span):
        return 0.0
    step = 10.0 ** math.floor(math.log10(span))
    return math.floor(start / step) * step


#: Smallest power of ten named: the figures draw values times 10^-power (and a faint trace times a further
#: factor), which must stay finite; light below 1e-300 (subnormal values included) is drawn as small numbers
#: times 1e-300.
MIN_POWER = -300


def power_of_ten(values: np.ndarray) -> int:
    """The power of ten to name in the y label when values leave [1e-3, 1e4] (else 0), instead of
    matplotlib's multiplier text; at least :data:`MIN_POWER`, whose 10^-power is finite."""
    peak = float(np.nanmax(np.abs(values))) if values.size and np.isfinite(values).any() else 0.0
    return max(int(math.floor(math.log10(peak))), MIN_POWER) if peak > 0 and not 1e-3 <= peak < 1e4 else 0


class TimeAxis(NamedTuple):
    """The cropped, readable path-length axis of a transient figure (see :func:`time_axis`)."""

    first: int              # first bin drawn
    last: int               # one past the last
    origin: float           # metres subtracted from path lengths (0, or a round number far from 0)
    scale: float            # y is drawn times this (10^-power)
    edges: np.ndarray       # drawn bin edges, metres from origin
    centres: np.ndarray
    window: tuple           # the window's edges, metres from origin
    x_label: str
    y_label: str


def time_axis(sampling, arrays) -> TimeAxis:
    """Crop to the light of the first (reference) array, from a round origin, y in a named power of ten."""
    first, last = _lit_bins(arrays, sampling)
    reference = np.atleast_2d(arrays[0])
    origin, power = round_origin(sampling.edges[first:last + 1]), power_of_ten(reference[:, first:last])
    edges = sampling.edges[first:last + 1] - origin
    return TimeAxis(first, last, origin, 10.0 ** -power, edges, 0.5 * (edges[:-1] + edges[1:]),
                     (sampling.edges[0] - origin, sampling.edges[-1] - origin),
                     "path length (m)" if origin == 0 else f"path length − {origin:g} m (m)",
                     Y_LABEL if power == 0 else Y_LABEL.replace("(W", f"(1e{power} W"))


def relay_wall_label(y_label: str) -> str:
    """A time axis's y label (y_k[n], maybe with a power of ten) as a relay-wall capture's H[n], whose units are
    mitransient's (docs/design.md section 7: radiance times path length, W sr⁻¹ m⁻¹)."""
    return y_label.replace("y_k[n] (", "H[n] (").replace("W m⁻¹", "W sr⁻¹ m⁻¹")


def window_edges_in_view(time: TimeAxis) -> list:
    """The window's edges that fall inside the drawn bins (metres from the axis's origin)."""
    return [edge for edge in time.window if time.edges[0] <= edge <= time.edges[-1]]


def window_edges(axis, time: TimeAxis) -> bool:
    """Dotted lines at the window's edges that are in view; whether any was."""
    shown = window_edges_in_view(time)
    for edge in shown:
        axis.axvline(edge, color="0.4", ls=":", lw=0.8)
    return bool(shown)
