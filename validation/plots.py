"""Every figure the project draws, as PNG (matplotlib imported inside each function).

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas,
never through pyplot's global state, and written atomically. Time axes are
cropped to the light (the window's edges drawn when in view) and labelled in
metres of path length (the transients' also in nanoseconds); every image
has a colour bar.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from analytic.io import atomic_write

__all__ = ["save_figure", "new_figure", "plot_transients", "model_figure",
           "plot_z_map", "plot_convergence", "plot_reconstructions", "plot_reconstruction", "plot_criterion",
           "plot_conditioning", "plot_panels", "plot_check_transients", "plot_check_z",
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
    secondary.tick_params(labelsize=6, pad=1)
    secondary.set_xlabel("ns", fontsize=6, labelpad=1, loc="right")


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


def _window_edges(axis, time: _TimeAxis) -> bool:
    """Dotted lines at the window's edges that are in view; whether any was."""
    shown = [edge for edge in time.window if time.edges[0] <= edge <= time.edges[-1]]
    for edge in shown:
        axis.axvline(edge, color="0.4", ls=":", lw=0.8)
    return bool(shown)


def plot_transients(path: str | Path, sampling, transients: dict[str, np.ndarray], *,
                    errors: dict[str, np.ndarray] | None = None, title: str = "",
                    max_panels: int = 8) -> Path:
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
        ``errors``.
    errors : dict, optional
        Label -> ``(K, N)`` standard errors. With them each panel gets a strip
        below it showing z = (value − reference) / error per bin, where the
        error bars are too small to see.
    title : str
        Figure title.
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
    edges_shown = False
    columns = min(len(chosen), 4)
    rows = int(np.ceil(len(chosen) / columns))
    residual = bool(errors)
    # a fixed layout: constrained layout would double the drawing time
    panel = 3.4 if residual else 2.6
    width, height = max(3.3 * columns, 5.0), panel * rows + 0.9
    figure = new_figure(width, height, layout=None)
    figure.subplots_adjust(left=0.75 / width, right=1 - 0.15 / width, top=1 - 0.75 / height,
                           bottom=0.5 / height, wspace=0.22)
    grid = figure.add_gridspec(rows, columns, hspace=0.32 if residual else 0.45)
    for slot, k in enumerate(chosen):
        row, column = divmod(slot, columns)
        cell = grid[row, column].subgridspec(2, 1, height_ratios=[3, 1], hspace=0.08) if residual else None
        axis = figure.add_subplot(cell[0] if residual else grid[row, column])
        for i, label in enumerate(labels):
            data = np.atleast_2d(transients[label])[k, first:last] * scale
            if i == 0:
                axis.stairs(data, edges, label=label, color="C0", lw=1.2)
            elif label in errors:
                axis.errorbar(centres, data, yerr=np.atleast_2d(errors[label])[k, first:last] * scale, fmt="o",
                              ms=2.5, color=f"C{i}", label=f"{label} ±1 se", elinewidth=1.0, capsize=1.5)
            else:
                axis.plot(centres, data, "o", ms=2.5, color=f"C{i}", label=label)
        edges_shown = _window_edges(axis, time)
        axis.set_title(f"sensor {k}", fontsize=8, loc="left")
        axis.tick_params(labelsize=6)
        if column == 0:
            axis.set_ylabel(y_label, fontsize=7)
        if row == 0 and origin == 0:
            _nanosecond_axis(axis)
        if slot == 0:
            axis.legend(fontsize=6, loc="upper right")
        if residual:
            axis.tick_params(labelbottom=False)
            strip = figure.add_subplot(cell[1], sharex=axis)
            for i, label in enumerate(labels[1:], start=1):
                if label not in errors:
                    continue
                se = np.atleast_2d(errors[label])[k, first:last]
                value = np.atleast_2d(transients[label])[k, first:last]
                with np.errstate(divide="ignore", invalid="ignore"):
                    z = np.where(se > 0, (value - reference[k, first:last]) / se, np.nan)
                strip.plot(centres, z, "o", ms=2, color=f"C{i}")
            strip.axhline(0, color="0.3", lw=0.6)
            for level in (-3, 3):
                strip.axhline(level, color="0.6", lw=0.6, ls="--")
            if column == 0:
                strip.set_ylabel("z", fontsize=7)
            strip.tick_params(labelsize=6)
            strip.set_xlabel(x_label, fontsize=7)
        else:
            axis.set_xlabel(x_label, fontsize=7)
    if title:
        figure.suptitle(title + ("  (dotted: the window's edges)" if edges_shown else ""), fontsize=9)
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
    bar.set_label(time.y_label, fontsize=7)
    bar.ax.tick_params(labelsize=6)
    image_axis.set_ylabel("sensor k", fontsize=7)
    image_axis.set_title(f"every sensor (K = {sensors})", fontsize=8, loc="left")
    from matplotlib.ticker import MaxNLocator

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
    curve_axis.set_ylabel(time.y_label, fontsize=7)
    curve_axis.set_title("model (lines)" + (" and model + noise (points)" if noisy is not None else ""),
                         fontsize=8, loc="left")
    curve_axis.legend(fontsize=6, loc="upper right")
    edges_shown = _window_edges(curve_axis, time)
    for axis in (image_axis, curve_axis):
        axis.set_xlabel(time.x_label, fontsize=7)
        axis.tick_params(labelsize=6)
    if time.origin == 0:
        _nanosecond_axis(curve_axis)
    if title:
        figure.suptitle(title + ("  (dotted: the window's edges)" if edges_shown else ""), fontsize=9)
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
    figure.colorbar(image, ax=axis, label=f"z = (render − model) / se\n(limit ±{threshold:.2f})")
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
    axis.set_title(title, fontsize=9)
    return save_figure(figure, path, dpi=100)


def plot_convergence(path: str | Path, name: str, render_rows: list, slope: float | None,
                     model_rows: list) -> Path:
    """Render error against samples (with N^-1/2) and the model's error against tolerance."""
    figure = new_figure(8.5, 3.4)
    left, right = figure.subplots(1, 2)
    samples = np.array([r["samples"] for r in render_rows], float)
    errors = np.array([r["relative_l2"] for r in render_rows])
    label = "render" + ("" if slope is None else f" (slope {slope:.3f})")
    left.loglog(samples, errors, "o-", label=label)
    left.loglog(samples, errors[0] * (samples / samples[0]) ** -0.5, ":", color="grey", label="N^-1/2")
    left.set_xlabel("samples N")
    left.set_ylabel("relative L2 error against the model")
    left.legend(fontsize=7)
    if model_rows:
        tolerance = [r["tolerance"] for r in model_rows]
        over = [max(r["over_stderr"], 1e-18) for r in model_rows]
        right.loglog(tolerance, over, "s-", label="model error / se (worst judged bin)")
        right.axhline(1.0, color="red", lw=0.8, label="the render's noise")
        right.set_xlabel("model tolerance (requested)")
        right.set_ylabel("max |y(tol) − y(1e-7)| / se")
        right.invert_xaxis()
        right.legend(fontsize=7)
    else:
        right.set_axis_off()
    figure.suptitle(f"{name}: convergence", fontsize=9)
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
    figure.suptitle(name, fontsize=9)
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
        figure.suptitle(title, fontsize=9)
    return save_figure(figure, path, dpi=100)


_CRITERION_LABELS = {
    "oracle": "||f_λ − f||² (squared image error)",
    "gcv": "GCV(λ) = ||r||² / trace(I − H)²",
    "lcurve": "L-curve curvature",
    "discrepancy": "||r||² − m σ²",
}


def plot_criterion(path: str | Path, reconstruction, *, title: str = "") -> Path:
    """The λ rule's criterion against λ with the chosen λ marked, beside the L-curve.

    Parameters
    ----------
    reconstruction : analytic.Reconstruction
        Its ``lambdas``, ``criterion``, ``residual_norms``, ``seminorms`` and ``lam``.
    """
    r = reconstruction
    figure = new_figure(10.0, 3.9)
    left, right = figure.subplots(1, 2)
    finite = np.isfinite(r.criterion)
    if np.any(finite):
        if r.rule in ("oracle", "gcv") and np.all(r.criterion[finite] > 0):
            left.loglog(r.lambdas, r.criterion, ".-")
        else:
            left.semilogx(r.lambdas, r.criterion, ".-")
            if r.rule == "discrepancy":
                left.axhline(0.0, color="0.5", lw=0.8)
        left.set_ylabel(_CRITERION_LABELS.get(r.rule, "criterion"), fontsize=8)
    else:
        left.text(0.5, 0.5, f"λ given: {r.lam:.3g}", ha="center", transform=left.transAxes)
    left.axvline(r.lam, color="C3", ls="--", label=f"chosen λ = {r.lam:.3g}")
    left.set_xlabel("λ (weight of ||D f||², unit pixel spacing)", fontsize=8)
    left.legend(fontsize=8)
    left.set_title(f"rule: {r.rule}", fontsize=9)
    right.loglog(r.residual_norms, np.maximum(r.seminorms, np.finfo(float).tiny), ".-", ms=3)
    right.loglog([r.residual_norm], [max(r.seminorm, np.finfo(float).tiny)], "o", color="C3",
                 label="chosen λ")
    right.set_xlabel("||A f − y|| (units of y)", fontsize=8)
    right.set_ylabel("||D f|| (reflectance per pixel²)", fontsize=8)
    right.set_title("L-curve", fontsize=9)
    right.legend(fontsize=8)
    if title:
        figure.suptitle(title, fontsize=9)
    return save_figure(figure, path, dpi=110)


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
            left.semilogy(row["singular_values"], color=f"C{i}",
                          alpha=0.4 + 0.6 * j / max(len(rows) - 1, 1), lw=1,
                          label=f"T = {period:g} m, W = {row['extent']:g} m")
        right.plot([r["extent"] for r in rows], [r["effective_rank"] for r in rows], "o-",
                   color=f"C{i}", label=f"T = {period:g} m")
    if table:
        left.axhline(table[0]["sigma"], color="k", ls="--", lw=0.8, label=f"σ = {table[0]['sigma']:g}")
    left.set_xlabel("index i", fontsize=8)
    left.set_ylabel("singular value s_i of A (W m⁻¹ per unit reflectance)", fontsize=8)
    left.legend(fontsize=6, ncol=2)
    right.set_xlabel("array extent W (m)", fontsize=8)
    right.set_ylabel("effective rank: #{s_i > σ}", fontsize=8)
    right.legend(fontsize=8)
    if title:
        figure.suptitle(title, fontsize=9)
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
    columns = int(np.ceil(np.sqrt(len(order))))
    rows = int(np.ceil(len(order) / columns))
    figure = new_figure(max(3.6 * columns, 6.0), max(2.8 * rows, 3.8) + 0.5)
    axes = np.atleast_2d(figure.subplots(rows, columns, squeeze=False))
    centres = 0.5 * (result.edges[:-1] + result.edges[1:])
    fit = result.fit
    for panel, axis in enumerate(axes.flat):
        if panel >= len(order):
            axis.axis("off")
            continue
        k = int(order[panel])
        axis.stairs(result.model[k], result.edges, color="C0", label="model as given")
        axis.stairs(result.fitted_model[k], result.edges, color="C1", ls="--",
                    label=f"{fit.scale:.4g} × model(t0 {fit.offset_opl:+.3g} m)")
        if result.stderr is not None:
            axis.errorbar(centres, result.data[k], yerr=result.stderr[k], fmt=".", ms=3, color="k",
                          elinewidth=0.8, label="data ± se")
        else:
            axis.plot(centres, result.data[k], ".", ms=3, color="k", label="data (no errors)")
        axis.set_title(f"sensor {k}", fontsize=8)
        axis.tick_params(labelsize=7)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside upper center", ncol=3, fontsize=7, frameon=False)
    figure.supxlabel("path length (m)", fontsize=9)
    figure.supylabel(Y_LABEL, fontsize=9)
    shown = "" if len(order) == sensors else f" ({len(order)} of {sensors} sensors, worst first)"
    figure.suptitle(f"data against the model{shown}", fontsize=10)
    return save_figure(figure, path)


def plot_check_z(path: str | Path, result) -> Path:
    """z by bin (sensor-major), as given and after the fit, with the max-|z| limits.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    result : CheckResult
        A result judged with errors (not by shape only).
    """
    if result.as_given is None:
        raise ValueError("result: judged by shape only, it has no z to plot")
    figure = new_figure(8.0, 4.8)
    axes = figure.subplots(2, 1, sharex=True)
    bins = result.data.shape[1]
    for axis, agreement, label in ((axes[0], result.as_given, "as given"),
                                   (axes[1], result.after_fit, "after the fit")):
        z = agreement.z.ravel()
        index = np.arange(z.size)
        finite = np.isfinite(z)
        axis.plot(index[finite], z[finite], ".", ms=3, color="C0" if agreement.agrees else "C3")
        for sign in (-1, 1):
            axis.axhline(sign * agreement.z_threshold, color="0.4", ls=":", lw=0.8)
        for k in range(1, result.data.shape[0]):
            axis.axvline(k * bins - 0.5, color="0.85", lw=0.6)
        limit = max(agreement.z_threshold * 1.3, float(np.max(np.abs(z[finite]))) * 1.05 if finite.any() else 1)
        axis.set_ylim(-limit, limit)
        verdict = "agrees" if agreement.agrees else "disagrees"
        axis.set_title(f"{label}: {verdict}, χ²/dof = {agreement.chi2_per_dof:.3g}, "
                       f"max |z| = {agreement.max_abs_z:.3g} (limit {agreement.z_threshold:.2f})", fontsize=9)
        axis.set_ylabel("z (normal equivalent of t)" if result.dof is not None else "z", fontsize=9)
        axis.tick_params(labelsize=7)
    axes[1].set_xlabel(f"bin k·N + n (sensor-major, N = {bins})", fontsize=9)
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
                axis.loglog([r["seconds"] for r in rows], [r["rms_error"] for r in rows], "o-", label=label)
        axis.set_xlabel("wall time (s)")
        axis.set_ylabel("RMS relative L2 error against the model")
        axis.set_title(name, fontsize=9)
        axis.legend(fontsize=8)
    figure.suptitle(f"speed against error ({report['device']})", fontsize=9)
    return save_figure(figure, path)
