"""PNG plots of transients (matplotlib is imported inside each function so the CLI starts fast)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analytic.io import save_figure

__all__ = ["plot_transients", "save_figure"]


def plot_transients(path: str | Path, edges: np.ndarray, transients: dict[str, np.ndarray], *,
                    errors: dict[str, np.ndarray] | None = None, title: str = "",
                    max_panels: int = 16) -> Path:
    """One panel per sensor: each named transient against path length.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    edges : numpy.ndarray
        ``(N + 1,)`` bin edges, metres of path length.
    transients : dict
        Label -> ``(K, N)`` samples. The first is drawn as a step line, the
        others as points (with error bars from ``errors`` when given).
    errors : dict, optional
        Label -> ``(K, N)`` one-standard-error bars.
    title : str
        Figure title.
    max_panels : int
        At most this many sensors are drawn.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    errors = errors or {}
    first = next(iter(transients.values()))
    sensors = min(first.shape[0], max_panels)
    columns = int(np.ceil(np.sqrt(sensors)))
    rows = int(np.ceil(sensors / columns))
    figure, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.4 * rows), squeeze=False,
                                sharex=True)
    centres = 0.5 * (edges[:-1] + edges[1:])
    for k in range(rows * columns):
        axis = axes.flat[k]
        if k >= sensors:
            axis.axis("off")
            continue
        for i, (label, data) in enumerate(transients.items()):
            if i == 0:
                axis.stairs(data[k], edges, label=label, color="C0")
            elif label in errors:
                axis.errorbar(centres, data[k], yerr=errors[label][k], fmt=".", ms=3, color=f"C{i}",
                              label=label, elinewidth=0.8)
            else:
                axis.plot(centres, data[k], ".", ms=3, color=f"C{i}", label=label)
        axis.set_title(f"sensor {k}", fontsize=8)
        axis.tick_params(labelsize=7)
    axes.flat[0].legend(fontsize=7)
    figure.supxlabel("path length t (m, c = 1)", fontsize=9)
    figure.supylabel("y_k[n]", fontsize=9)
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    return save_figure(figure, path)
