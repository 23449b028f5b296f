"""Figures of reconstructions: images against the truth, the λ rule's criterion, spectra, the paper's panels."""

from __future__ import annotations

import numpy as np

from .axes import finish_log_axes, log_limits, log_plot, no_log_margins
from .common import new_figure, suptitle

__all__ = ["reconstructions_figure", "reconstruction_figure", "criterion_figure", "conditioning_figure",
           "panels_figure"]


def _image_panel(figure, axis, image, title, *, vmin=0.0, vmax=1.0, cmap="gray"):
    shown = axis.imshow(image, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    axis.set_title(title, fontsize=8)
    axis.set_xticks([])
    axis.set_yticks([])
    return shown


def reconstructions_figure(name: str, truth: np.ndarray, panels: list):
    """The true image beside reconstructions, on one reflectance scale with its colour bar.

    Parameters
    ----------
    panels : list of (str, numpy.ndarray, str)
        (title, image, a note such as its PSNR) per reconstruction.

    Returns
    -------
    matplotlib.figure.Figure
    """
    figure = new_figure(2.6 * (len(panels) + 1) + 0.6, 3.3, dpi=100)
    axes = figure.subplots(1, len(panels) + 1)
    shown = _image_panel(figure, axes[0], truth, "true image")
    for axis, (title, image, note) in zip(axes[1:], panels):
        _image_panel(figure, axis, image, f"{title}\n{note}")
    figure.colorbar(shown, ax=list(axes), label="reflectance", shrink=0.8)
    suptitle(figure, name, fontsize=9)
    return figure


def reconstruction_figure(truth: np.ndarray, image: np.ndarray, *, title: str = ""):
    """Truth, reconstruction and their difference, each with a colour bar.

    Returns
    -------
    matplotlib.figure.Figure
    """
    figure = new_figure(11.0, 3.6, dpi=100)
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
        suptitle(figure, title, fontsize=9)
    return figure


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
            log_plot(left, lambdas, criterion, ".-")
        else:
            no_log_margins(left, "x")
            left.semilogx(lambdas[finite], criterion[finite], ".-")
            log_limits(left, "x")
            if r.rule == "discrepancy":
                left.axhline(0.0, color="0.5", lw=0.8)
        left.set_ylabel(_CRITERION_LABELS.get(r.rule, "criterion"), fontsize=8)
    else:
        left.set_xscale("log")
        no_log_margins(left, "x")
        left.text(0.5, 0.5, f"λ given: {r.lam:.3g}", ha="center", transform=left.transAxes)
    left.axvline(r.lam, color="C3", ls="--", label=f"chosen λ = {r.lam:.3g}")
    left.set_xlabel("λ (weight of ||D f||², unit pixel spacing)", fontsize=8)
    left.legend(fontsize=8)
    left.set_title(f"rule: {r.rule}", fontsize=9)
    tiny = np.finfo(float).tiny
    log_plot(right, r.residual_norms, np.maximum(r.seminorms, tiny), ".-", ms=3)
    if np.isfinite(r.residual_norm) and r.residual_norm > 0:
        right.loglog([r.residual_norm], [max(r.seminorm, tiny)], "o", color="C3", label="chosen λ")
        right.legend(fontsize=8)
    right.set_xlabel("||A f − y|| (units of y)", fontsize=8)
    right.set_ylabel("||D f|| (reflectance per pixel²)", fontsize=8)
    right.set_title("L-curve", fontsize=9)
    for axis in (left, right):
        finish_log_axes(axis)
    if title:
        suptitle(figure, title, fontsize=9)
    return figure


def conditioning_figure(table: list[dict], *, title: str = ""):
    """Singular-value spectra (one curve per (W, T)) and effective rank against W.

    Parameters
    ----------
    table : list of dict
        Rows with ``extent``, ``period``, ``sigma``, ``singular_values`` and
        ``effective_rank`` (:func:`analytic.operator.conditioning.conditioning_table`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    figure = new_figure(11.0, 4.2)
    left, right = figure.subplots(1, 2)
    periods = sorted({row["period"] for row in table})
    for i, period in enumerate(periods):
        rows = sorted((r for r in table if r["period"] == period), key=lambda r: r["extent"])
        for j, row in enumerate(rows):
            values = np.asarray(row["singular_values"], float)
            log_plot(left, np.arange(values.size), values, logx=False, color=f"C{i}",
                      alpha=0.4 + 0.6 * j / max(len(rows) - 1, 1), lw=1,
                      label=f"T = {period:g} m, W = {row['extent']:g} m")
        right.plot([r["extent"] for r in rows], [r["effective_rank"] for r in rows], "o-",
                   color=f"C{i}", label=f"T = {period:g} m")
    if table and table[0]["sigma"] > 0:      # σ = 0 has no place on a log axis
        left.axhline(table[0]["sigma"], color="k", ls="--", lw=0.8, label=f"σ = {table[0]['sigma']:g}")
    left.set_xlabel("index i", fontsize=8)
    left.set_ylabel("singular value s_i of A (W m⁻¹ per unit reflectance)", fontsize=8)
    finish_log_axes(left)
    left.legend(fontsize=6, ncol=2)
    right.set_xlabel("array extent W (m)", fontsize=8)
    right.set_ylabel("effective rank: #{s_i > σ}", fontsize=8)
    right.legend(fontsize=8)
    if title:
        suptitle(figure, title, fontsize=9)
    return figure


def panels_figure(rows: list[dict], *, attenuation: str, intensity: float,
                  illuminations: tuple = ("impulsive", "low-pass"), truth=None):
    """Figs. 7-8 style panel: impulsive (left block) and low-pass (right), rows T, columns W.

    Each image is on a fixed [0, 1] grey scale (colour bar at the right) with
    its PSNR (dB, data range 1) beneath it.

    Returns
    -------
    matplotlib.figure.Figure
    """
    group = [r for r in rows if r["attenuation"] == attenuation and r["intensity"] == intensity]
    periods = sorted({r["period"] for r in group})
    extents = sorted({r["extent"] for r in group})
    columns = len(illuminations) * len(extents) + (1 if truth is not None else 0)
    figure = new_figure(1.9 * columns + 1.0, 2.3 * len(periods) + 0.6, dpi=100)
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
    return figure
