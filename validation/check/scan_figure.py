"""``check``'s figure for a relay-wall (NLOS) capture: z over pairs x bins, and over the scan grid.

A relay-wall capture has many pairs (a 16 x 16 scan has 256), too many for
one panel per pair: the figure shows z = (data - model) / se of every
judged bin as an image (pairs down, path length across), as given and after
the fit, and beside them each read point's time-summed transient laid out
on the wall's scan grid (its z, and its relative difference), where a
convention error or a bug in one region of the wall stands out. The time
sums are compared as given: a time sum is far more precise than one bin,
so a global fit's scale, set by the bins, would show there as a
disagreement of its own. matplotlib is imported inside the function.
"""

from __future__ import annotations

import numpy as np

from validation.plots.axes import round_origin
from validation.plots.common import new_figure, suptitle

__all__ = ["scan_z_figure", "summed_z"]


def summed_z(result, model: np.ndarray) -> np.ndarray:
    """z of each pair's time-summed transient against ``model``'s: ``(P,)``.

    Σ_n (y_data - y_model) over the bins judged, divided by its standard
    error: from the replicas' sums when the data are replicas (whatever the
    correlation between bins), else sqrt(Σ_n se²) (bins taken as independent).
    """
    judged = np.isfinite(result.as_given.z)
    difference = np.where(judged, result.data - model, 0.0).sum(axis=1)
    if result.replica_data is not None:
        sums = np.where(judged[None], result.replica_data, 0.0).sum(axis=2)          # (R, P)
        error = sums.std(axis=0, ddof=1) / np.sqrt(sums.shape[0])
    else:
        error = np.sqrt((np.where(judged, result.stderr, 0.0) ** 2).sum(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(error > 0, difference / np.where(error > 0, error, 1.0), np.nan)


def _grid_of(values: np.ndarray, scene, pooled: str = "z") -> np.ndarray:
    """Per-pair values on the read grid ``(H, W)``; an exhaustive scan's lit points pooled per read point.

    ``pooled="z"``: Σ z / sqrt(L) (the z of a sum of L independent parts); ``"mean"``: their mean.
    """
    width, height = scene.scan.grid
    values = values.reshape(-1, height, width)
    if values.shape[0] == 1:
        return values[0]
    if pooled == "mean":
        return np.nanmean(values, axis=0)
    return np.nansum(values, axis=0) / np.sqrt(np.sum(np.isfinite(values), axis=0).clip(min=1))


def scan_z_figure(result, scene):
    """z over pairs x bins and the time-summed z on the scan grid, as given and after the fit.

    Parameters
    ----------
    result : CheckResult
        Judged with errors (not by shape only) and with a fit.
    scene : analytic.scenes.relay_wall.RelayWallScene
        The capture's scene (its scan grid and pair order).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib import colormaps

    if result.as_given is None or result.after_fit is None:
        raise ValueError("result: needs z as given and after the fit")
    cmap = colormaps["RdBu_r"].with_extremes(bad="0.85")
    edges = np.asarray(result.edges, dtype=float)
    judged = np.isfinite(result.as_given.z) | np.isfinite(result.after_fit.z)
    columns = np.nonzero(judged.any(axis=0))[0]
    first, last = (int(columns[0]), int(columns[-1]) + 1) if columns.size else (0, edges.size - 1)
    origin = round_origin(edges[first:last + 1])
    pairs = result.data.shape[0]
    width, height = scene.scan.grid
    figure = new_figure(11.0, 7.2)
    grid = figure.add_gridspec(2, 2, width_ratios=[2.2, 1.0])
    for row, (agreement, model, label) in enumerate(((result.as_given, result.model, "as given"),
                                                     (result.after_fit, result.fitted_model, "after the fit"))):
        z = agreement.z[:, first:last]
        limit = max(agreement.z_threshold, float(np.nanmax(np.abs(z))) if np.isfinite(z).any() else 0.0)
        axis = figure.add_subplot(grid[row, 0])
        image = axis.pcolormesh(edges[first:last + 1] - origin, np.arange(pairs + 1) - 0.5,
                                np.ma.masked_invalid(z), cmap=cmap, vmin=-limit, vmax=limit)
        bar = figure.colorbar(image, ax=axis, label="z per bin")
        for level in (-agreement.z_threshold, agreement.z_threshold):
            bar.ax.axhline(level, color="k", lw=1.0, ls="--")
        axis.invert_yaxis()
        axis.set_ylabel("pair p")
        axis.set_title(f"{label}: {'agrees' if agreement.agrees else 'disagrees'}, χ²/dof = "
                       f"{agreement.chi2_per_dof:.3g}, max |z| = {agreement.max_abs_z:.3g} "
                       f"(limit {agreement.z_threshold:.2f})", fontsize=9, loc="left")
        if row == 1:
            axis.set_xlabel("path length (m)" if origin == 0 else f"path length − {origin:g} m (m)")
        if row == 0:
            values, label_text, title = (_grid_of(summed_z(result, model), scene), "z of the time-summed transient",
                                         "time sums as given, per read point")
        else:
            judged = np.isfinite(result.as_given.z)
            ratio = (np.where(judged, result.data, 0.0).sum(axis=1)
                     / np.where(judged, result.model, 0.0).sum(axis=1) - 1.0)
            values, label_text, title = (_grid_of(ratio, scene, pooled="mean"), "Σ data / Σ model − 1",
                                         "time sums as given, relative")
        top = float(np.nanmax(np.abs(values))) if np.isfinite(values).any() else 1.0
        top = max(top, 3.0) if row == 0 else (top if top > 0 else 1.0)
        wall = figure.add_subplot(grid[row, 1])
        half_x, half_y = 0.5 * scene.wall_size[0], 0.5 * scene.wall_size[1]
        shown = wall.pcolormesh(np.linspace(-half_x, half_x, width + 1), np.linspace(-half_y, half_y, height + 1),
                                np.ma.masked_invalid(values), cmap=cmap, vmin=-top, vmax=top)
        figure.colorbar(shown, ax=wall, label=label_text)
        wall.set_aspect("equal")
        wall.set_xlabel("wall x (m)")
        wall.set_ylabel("wall y (m)")
        wall.set_title(title + (", lit points pooled" if scene.scan.type == "exhaustive" else ""),
                       fontsize=9, loc="left")
    error = "replicas' sums" if result.replica_data is not None else "bins taken as independent"
    suptitle(figure, f"z = (data − model) / se over {pairs} pairs ({scene.scan.type} scan, {width} x {height} "
                     f"read points); grey: not judged; time sums' error from the {error}", fontsize=10)
    return figure
