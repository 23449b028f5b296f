"""A capture through a relay wall (docs/design.md section 7): a transient per pair as an image, the light over the
scan, and a few pairs' traces."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .axes import power_of_ten, relay_wall_label, time_axis
from .captures import TRACES_LEGEND, _traced, trace_labels
from .common import new_figure, plain_text
from .transients import finish_time_figure

__all__ = ["WallScan", "relay_wall_figure", "scene_transient_figure", "RELAY_WALL_LABEL"]

#: H's units (docs/design.md section 7: mitransient's nlos_capture_meter, for I in W/sr).
RELAY_WALL_LABEL = "H[n] (W sr⁻¹ m⁻¹)"


@dataclass(frozen=True)
class WallScan:
    """Where a capture's pairs lie on the relay wall: what its figure needs of the scene (or of meta.json).

    Attributes
    ----------
    type : {"single", "confocal", "exhaustive"}
    grid : (int, int)
        W x H read points.
    wall_size : (float, float)
        The wall's sides along x and y, metres.
    laser_point : (float, float, float) or None
        ``single``: the lit point l, metres.
    laser_grid : (int, int) or None
        ``exhaustive``: the lit points' grid.
    """

    type: str
    grid: tuple
    wall_size: tuple
    laser_point: tuple | None = None
    laser_grid: tuple | None = None

    @classmethod
    def for_scene(cls, scene) -> "WallScan | None":
        """The scan of a scene whose kind records one (a relay-wall capture: its ``meta_fields`` hold ``scan``
        and ``relay_wall``), else None."""
        fields = scene.meta_fields()
        if fields.get("scan") is None:
            return None
        return cls.of_meta({**fields, "sensors": scene.sensor_count})

    @classmethod
    def of_meta(cls, meta: dict) -> "WallScan":
        """The scan our ``meta.json`` records (:meth:`analytic.scenes.relay_wall.RelayWallScene.meta_fields`).

        Raises
        ------
        ValueError
            When the record is not a relay-wall scan whose pairs are ``meta["sensors"]``.
        """
        try:
            scan, wall = meta["scan"], meta["relay_wall"]
            made = cls(type=str(scan["type"]), grid=tuple(int(g) for g in scan["grid"]),
                       wall_size=tuple(float(s) for s in wall["size"]),
                       laser_point=None if scan.get("laser_point") is None
                       else tuple(float(v) for v in scan["laser_point"]),
                       laser_grid=None if scan.get("laser_grid") is None
                       else tuple(int(g) for g in scan["laser_grid"]))
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f"its scan and relay_wall records are incomplete ({error})") from None
        if made.type not in ("single", "confocal", "exhaustive") or len(made.grid) != 2 \
                or len(made.wall_size) != 2 or (made.type == "exhaustive" and made.laser_grid is None):
            raise ValueError(f"scan {scan!r} is not a relay-wall scan")
        if made.pairs != int(meta.get("sensors", -1)):
            raise ValueError(f"its scan has {made.pairs} pairs, its sensors say {meta.get('sensors')}")
        return made

    @property
    def reads(self) -> int:
        """W H, the read points."""
        return self.grid[0] * self.grid[1]

    @property
    def lasers(self) -> int:
        """The lit points: 1 (single), W H (confocal: each read point), the laser grid's (exhaustive)."""
        if self.type == "exhaustive":
            return self.laser_grid[0] * self.laser_grid[1]
        return 1 if self.type == "single" else self.reads

    @property
    def pairs(self) -> int:
        """P, the rows of the transient."""
        return self.reads * (self.lasers if self.type == "exhaustive" else 1)

    def cell_edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Edges of the read grid's cells along x and y, metres (the wall centred at the origin)."""
        return tuple(np.linspace(-0.5 * size, 0.5 * size, count + 1)
                     for size, count in zip(self.wall_size, self.grid))


def _norm(values: np.ndarray):
    """A square-root colour scale for light that is nowhere negative (a few pairs near the laser outshine the
    rest by orders of magnitude), else a linear one (a Butterworth pulse undershoots)."""
    from matplotlib.colors import Normalize, PowerNorm

    finite = values[np.isfinite(values)]
    if finite.size and finite.min() >= 0.0 and finite.max() > 0.0:
        return PowerNorm(0.5, vmin=0.0, vmax=float(finite.max())), ", square-root colours"
    return Normalize(), ""


def _pairs_panel(figure, axis, y, time, scan: WallScan) -> None:
    """Every pair's transient as one row of an image: time horizontal, pairs down."""
    from matplotlib.ticker import MaxNLocator

    pairs = y.shape[0]
    shown = y[:, time.first:time.last] * time.scale
    norm, note = _norm(shown)
    image = axis.imshow(shown, aspect="auto", interpolation="nearest", norm=norm,
                        extent=(time.edges[0], time.edges[-1], pairs - 0.5, -0.5), cmap="viridis")
    bar = figure.colorbar(image, ax=axis, pad=0.02)
    bar.set_label(relay_wall_label(time.y_label), fontsize=7)
    bar.ax.tick_params(labelsize=7)
    if scan.type == "exhaustive":
        for laser in range(1, scan.lasers):          # one block of W H read points per lit point
            axis.axhline(laser * scan.reads - 0.5, color="w", lw=0.4, alpha=0.6)
        rows = f"pair p = laser · {scan.reads} + read point"
    else:
        rows = f"pair p = j · {scan.grid[0]} + i"
    axis.set_ylabel(rows, fontsize=8)
    axis.yaxis.set_major_locator(MaxNLocator(nbins=8, integer=True))
    axis.set_xlabel(time.x_label, fontsize=8)
    axis.set_title(f"every pair's transient (P = {pairs}{note})", fontsize=8, loc="left")


def _wall_panel(figure, axis, totals, scan: WallScan, chosen) -> None:
    """The light summed over the window: over the read grid on the wall (single, confocal), or per
    (lit point, read point) (exhaustive); the traced pairs numbered."""
    power = power_of_ten(totals)
    totals = totals * 10.0**-power
    unit = "W sr⁻¹ m⁻¹ · m" if power == 0 else f"1e{power} W sr⁻¹ m⁻¹ · m"
    norm, note = _norm(totals)
    if scan.type == "exhaustive":
        matrix = totals.reshape(scan.lasers, scan.reads)
        shown = axis.imshow(matrix, aspect="auto", interpolation="nearest", cmap="inferno", norm=norm,
                            extent=(-0.5, scan.reads - 0.5, scan.lasers - 0.5, -0.5))
        axis.set_xlabel("read point (row-major over the grid)", fontsize=8)
        axis.set_ylabel("lit point (row-major over the laser grid)", fontsize=8)
        places = [(p % scan.reads, p // scan.reads) for p in chosen]
        axis.set_title(f"light per (lit, read) pair, summed over time ({unit})", fontsize=8, loc="left")
    else:
        column_edges, row_edges = scan.cell_edges()
        shown = axis.pcolormesh(column_edges, row_edges, totals.reshape(scan.grid[1], scan.grid[0]),
                                cmap="inferno", norm=norm)
        axis.set_aspect("equal", adjustable="box")
        axis.set_xlabel("x on the wall (m)", fontsize=8)
        axis.set_ylabel("y on the wall (m)", fontsize=8)
        centres = [0.5 * (edges[:-1] + edges[1:]) for edges in (column_edges, row_edges)]
        places = [(centres[0][p % scan.grid[0]], centres[1][p // scan.grid[0]]) for p in chosen]
        if scan.type == "single":
            axis.plot(scan.laser_point[0], scan.laser_point[1], marker="*", ms=11, color="C2", mec="k", mew=0.6,
                      label="the lit point l")
            axis.legend(fontsize=7, loc="lower right", framealpha=0.8)
            what = "light per read point s (one lit point l)"
        else:
            what = "light per point (lit and read there: l = s)"
        axis.set_title(f"{what}, summed over time ({unit})", fontsize=8, loc="left")
    for number, place in enumerate(places, start=1):
        colour = f"C{number - 1}"
        axis.annotate(str(number), place, color=colour, fontsize=7, fontweight="bold", ha="center", va="center",
                      bbox={"boxstyle": "circle,pad=0.12", "fc": "white", "ec": colour, "lw": 0.8})
    bar = figure.colorbar(shown, ax=axis, pad=0.02)
    bar.set_label(f"H summed over the window{note}", fontsize=7)
    bar.ax.tick_params(labelsize=7)


def relay_wall_figure(sampling, y: np.ndarray, scan: WallScan, *, stderr: np.ndarray | None = None,
                      noisy: np.ndarray | None = None, label: str = "model", title: str = "", traces: int = 4):
    """A relay-wall capture's transient: every pair as an image, the light over the scan, a few traces.

    Left, H(l, s)[n] over pairs x path length (time horizontal, one row per
    pair in the pair order of docs/design.md section 7; an exhaustive scan's
    lit points as blocks); middle, the light summed over the window, on the
    wall's read grid for a single or confocal scan (the lit point starred
    for a single scan), per (lit point, read point) for an exhaustive one;
    right, the traces of the brightest pair and of pairs at evenly spaced
    ranks of brightness (each labelled with its rank), numbered on the
    middle panel, each fainter one drawn times the power of ten that brings
    its peak near the brightest's (in its label;
    :func:`validation.plots.captures.trace_labels`), with ±1 standard error
    as a band and noisy samples as points when given.

    Parameters
    ----------
    sampling : analytic.Sampling
        The bins (path length in metres).
    y : ndarray
        ``(P, N)`` H in W sr⁻¹ m⁻¹ for I in W/sr.
    scan : WallScan
        Where the pairs lie (:meth:`WallScan.for_scene`, :meth:`WallScan.of_meta`).
    stderr : ndarray, optional
        ``(P, N)`` standard error of ``y`` (a render's).
    noisy : ndarray, optional
        ``(P, N)`` noisy samples of the model, drawn as points.
    label : str
        What ``y`` is ("model", "render", "data").
    title : str
        Figure title.
    traces : int
        Pairs traced.

    Returns
    -------
    matplotlib.figure.Figure
    """
    y = np.atleast_2d(y)
    if y.shape[0] != scan.pairs:
        raise ValueError(f"y: {y.shape[0]} rows, the scan has {scan.pairs} pairs")
    time = time_axis(sampling, [y])
    totals = y.sum(axis=1)
    chosen = _traced(totals, traces)
    width, height = 15.5, 4.4
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.6 / width, right=1 - 0.2 / width, top=1 - 0.85 / height, bottom=0.6 / height,
                           wspace=0.42)
    pairs_axis, wall_axis, trace_axis = figure.subplots(1, 3, gridspec_kw={"width_ratios": [1.15, 1.0, 1.05]})
    _pairs_panel(figure, pairs_axis, y, time, scan)
    _wall_panel(figure, wall_axis, totals, scan, chosen)
    labels, factors = trace_labels(totals, chosen, np.abs(y[chosen, time.first:time.last]).max(axis=1, initial=0.0),
                                   [f"pair {p}" for p in chosen])
    low = high = 0.0                   # the lines' (and bands') extent: the points' may be far wider
    points = []
    for number, (p, name, factor) in enumerate(zip(chosen, labels, factors), start=1):
        colour = f"C{number - 1}"
        drawn = time.scale * factor           # a faint pair times a power of ten, said in its label
        values = y[p, time.first:time.last] * drawn
        trace_axis.stairs(values, time.edges, color=colour, lw=1.2, label=name)
        error = 0.0
        if stderr is not None:
            error = np.atleast_2d(stderr)[p, time.first:time.last] * drawn
            trace_axis.fill_between(time.edges, np.append(values - error, values[-1] - error[-1]),
                                    np.append(values + error, values[-1] + error[-1]), step="post", color=colour,
                                    alpha=0.3, lw=0)
        low, high = min(low, float(np.min(values - error))), max(high, float(np.max(values + error)))
        if noisy is not None:
            points.append(np.atleast_2d(noisy)[p, time.first:time.last] * drawn)
            trace_axis.plot(time.centres, points[-1], "o", ms=2.5, color=colour)
    band = (", ±1 standard error (band)" if stderr is not None else "") \
        + (" and model + noise (points)" if noisy is not None else "")
    trace_axis.set_title(plain_text(f"{label}{band}"), fontsize=8, loc="left", parse_math=False)
    legend_title = TRACES_LEGEND
    if points and high > low:
        # the noise of a faint pair, times its factor, would stretch the axis until every line lies flat
        margin = 0.08 * (high - low)
        trace_axis.set_ylim(low - margin, high + margin)
        beyond = int(sum(np.count_nonzero((row < low - margin) | (row > high + margin)) for row in points))
        if beyond:
            legend_title += f"\n{beyond} noisy points beyond the axis not shown"
    trace_axis.set_ylabel(relay_wall_label(time.y_label), fontsize=8)
    trace_axis.set_xlabel(time.x_label, fontsize=8)
    trace_axis.legend(fontsize=7, loc="upper right", title=legend_title, title_fontsize=7)
    for axis in (pairs_axis, wall_axis, trace_axis):
        axis.tick_params(labelsize=8)
    finish_time_figure(figure, trace_axis, time, title)
    return figure


def scene_transient_figure(scene, y: np.ndarray, *, stderr: np.ndarray | None = None,
                           noisy: np.ndarray | None = None, label: str = "model", title: str = ""):
    """A scene's transient as ``forward`` and ``render`` draw it: :func:`relay_wall_figure` for a relay-wall
    capture, :func:`validation.plots.transients.transient_figure` for a plane."""
    from .transients import transient_figure

    scan = WallScan.for_scene(scene)
    if scan is not None:
        return relay_wall_figure(scene.sampling, y, scan, stderr=stderr, noisy=noisy, label=label, title=title)
    return transient_figure(scene.sampling, y, stderr=stderr, noisy=noisy, label=label, title=title)
