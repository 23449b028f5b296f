"""Figures of what a capture can tell: the Cramér-Rao bound as an image, the whitened spectrum, Tikhonov's error."""

from __future__ import annotations

import numpy as np

from .common import new_figure, suptitle

__all__ = ["bound_image_figure", "whitened_spectrum_figure", "tikhonov_error_figure"]


def _panel(figure, axis, image, title, label, *, cmap="viridis", vmin=None, vmax=None):
    shown = axis.imshow(image, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    axis.set_title(title, fontsize=8)
    axis.set_xticks([])
    axis.set_yticks([])
    figure.colorbar(shown, ax=axis, label=label, shrink=0.85)


def _bound_panel(figure, axis, bound, title):
    """The bound on a log colour scale; unbounded pixels (inf) in red."""
    from matplotlib.colors import LogNorm

    finite = np.isfinite(bound) & (bound > 0)
    shown = np.where(finite, bound, np.nan)
    cmap = __import__("matplotlib").colormaps["viridis"].with_extremes(bad="tab:red")
    if finite.any():
        low, high = float(shown[finite].min()), float(shown[finite].max())
        norm = LogNorm(vmin=low, vmax=high if high > low else low * 1.01)
        image = axis.imshow(shown, cmap=cmap, norm=norm, interpolation="nearest")
        figure.colorbar(image, ax=axis, label="std of an unbiased estimate (reflectance)", shrink=0.85)
    else:
        axis.imshow(np.zeros_like(bound), cmap=cmap.with_extremes(under="tab:red"), vmin=1, vmax=2)
    unbounded = int(np.count_nonzero(~np.isfinite(bound)))
    axis.set_title(f"{title}\n(red: unbounded, {unbounded} of {bound.size} pixels)", fontsize=8)
    axis.set_xticks([])
    axis.set_yticks([])


def bound_image_figure(truth: np.ndarray, bound: np.ndarray, *, title: str = ""):
    """The scene's image beside each pixel's Cramér-Rao bound (log scale; inf in red)."""
    figure = new_figure(9.0, 3.8, dpi=100)
    left, right = figure.subplots(1, 2)
    _panel(figure, left, truth, "scene reflectance", "reflectance", cmap="gray", vmin=0.0, vmax=1.0)
    _bound_panel(figure, right, bound, "Cramér-Rao bound per pixel")
    if title:
        suptitle(figure, title, fontsize=9)
    return figure


def whitened_spectrum_figure(values: np.ndarray, *, title: str = ""):
    """Singular values of the whitened A against 1 (components above 1 stand above the noise)."""
    figure = new_figure(6.5, 4.0, dpi=100)
    axis = figure.subplots()
    values = np.asarray(values, dtype=np.float64)
    finite = values[np.isfinite(values) & (values > 0)]
    index = np.arange(1, finite.size + 1)
    above = finite > 1.0
    axis.semilogy(index[above], finite[above], ".", color="C0", ms=4,
                  label=f"above 1: {int(above.sum())} components the data fix")
    axis.semilogy(index[~above], finite[~above], ".", color="C1", ms=4,
                  label=f"below 1: {int((~above).sum())} under the noise")
    axis.axhline(1.0, color="k", ls="--", lw=0.8)
    axis.set_xlabel("index i", fontsize=8)
    axis.set_ylabel("singular value of the whitened A (noise units per unit reflectance)", fontsize=8)
    axis.legend(fontsize=7)
    axis.grid(True, which="major", alpha=0.3)
    if title:
        suptitle(figure, title, fontsize=9)
    return figure


def tikhonov_error_figure(bias: np.ndarray, stddev: np.ndarray, bound: np.ndarray | None, *, title: str = ""):
    """The Tikhonov estimate's bias and standard deviation per pixel beside the Cramér-Rao bound (when known)."""
    figure = new_figure(13.0 if bound is not None else 9.0, 3.8, dpi=100)
    axes = figure.subplots(1, 3 if bound is not None else 2)
    limit = float(np.max(np.abs(bias))) or 1.0
    _panel(figure, axes[0], bias, "bias (R − I) f", "reflectance", cmap="RdBu_r", vmin=-limit, vmax=limit)
    _panel(figure, axes[1], stddev, "standard deviation of the estimate", "reflectance")
    if bound is not None:
        _bound_panel(figure, axes[2], bound, "Cramér-Rao bound (unbiased estimates)")
    if title:
        suptitle(figure, title, fontsize=9)
    return figure
