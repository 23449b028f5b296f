"""Conditioning of the system matrix A against the array extent W and the period T.

For each (W, T) the scene's K sensors are laid out as a square grid of extent
W centred above the source (as in the paper's Figs. 7-8), the bins are laid to
cover every path length from the plane, A is assembled and its singular values
s_1 ≥ s_2 ≥ … are computed (dense SVD; A is (K N) x M²).

Reported per case:

- ``condition``: s_1 / s_{M²}, infinite when A has fewer than M² singular
  values above the numerical-rank threshold (rank-deficient);
- ``numerical_rank``: singular values above s_1 max(K N, M²) ε;
- ``effective_rank``: singular values above the noise level σ. A unit-norm
  image component along the right singular vector v_i reaches the data with
  amplitude s_i; it stands above white noise of standard deviation σ in one
  projection only when s_i > σ. This is the number of image directions the
  data resolve at SNR > 1, so it counts how much of the image survives the
  noise — the measure the paper's "conditioning" statements are judged by.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .isochrone import LAMBERTIAN, make_frame, rectangle_range
from .scene import Illumination, Sampling, Scene, sensor_grid
from .waveforms import make_waveform
from .system import system_matrix

__all__ = ["singular_values", "conditioning_summary", "covering_sampling", "scene_for",
           "conditioning_table", "plot_conditioning"]


def singular_values(matrix, *, memory_limit: int = 2 * 2**30) -> np.ndarray:
    """All singular values of A, descending (dense SVD).

    Parameters
    ----------
    matrix : scipy.sparse array or numpy.ndarray
        A, ``(K N, M²)``.
    memory_limit : int
        Bytes the dense copy may use; ValueError beyond it.
    """
    rows, columns = matrix.shape
    if 2 * rows * columns * 8 > memory_limit:
        raise ValueError(f"memory_limit: a dense {rows} x {columns} SVD needs "
                         f"{2 * rows * columns * 8 / 2**30:.1f} GiB, over {memory_limit / 2**30:.1f} GiB")
    dense = matrix.toarray() if hasattr(matrix, "toarray") else np.asarray(matrix, dtype=np.float64)
    dense = dense[np.any(dense != 0, axis=1)]  # zero rows add no singular values
    return np.linalg.svd(dense, compute_uv=False)


def conditioning_summary(values: np.ndarray, unknowns: int, rows: int, *, sigma: float) -> dict:
    """Condition number and ranks from singular values.

    Parameters
    ----------
    values : numpy.ndarray
        Singular values of A, descending, units of y per unit of f.
    unknowns : int
        M².
    rows : int
        K N.
    sigma : float
        Noise standard deviation per sample, units of y.
    """
    if not sigma > 0:
        raise ValueError(f"sigma: must be > 0, got {sigma!r}")
    largest = float(values[0]) if values.size else 0.0
    threshold = largest * max(rows, unknowns) * np.finfo(float).eps
    rank = int(np.sum(values > threshold))
    full = rank >= unknowns
    return {
        "largest": largest,
        "smallest": float(values[unknowns - 1]) if values.size >= unknowns else 0.0,
        "condition": largest / float(values[unknowns - 1]) if full else math.inf,
        "numerical_rank": rank,
        "effective_rank": int(np.sum(values > sigma)),
        "unknowns": unknowns,
        "sigma": float(sigma),
    }


def covering_sampling(scene: Scene, period: float) -> Sampling:
    """Bins of width ``period`` holding every path length and the pulse's tail.

    From the earliest first arrival over the plane to the latest last one
    (exact, :func:`analytic.isochrone.rectangle_range`) plus the waveform's
    duration, so no light leaves the window.
    """
    low, high = np.inf, -np.inf
    for sensor in scene.sensors:
        frame = make_frame(np.asarray(scene.source, float), np.asarray(sensor, float), LAMBERTIAN)
        first, last = rectangle_range(frame, 0.0, scene.size, 0.0, scene.size)
        low, high = min(low, first), max(high, last)
    longest = high + make_waveform(scene.illumination, period).duration
    start = math.floor(low / period) * period
    count = int(math.floor((longest - start) / period)) + 1
    return Sampling(bin_width_opl=period, start_opl=start, count=count)


def scene_for(base: Scene, *, extent: float, period: float, illumination: Illumination | None = None,
              attenuation: str | None = None, grid=(4, 4)) -> Scene:
    """The base scene with a ``grid`` array of extent W centred above the source at its height.

    Parameters
    ----------
    base : Scene
        Plane, source, reflectance, noise.
    extent : float
        Array extent W, metres.
    period : float
        Bin width T, metres of path length (bins cover every path, see
        :func:`covering_sampling`).
    illumination : Illumination, optional
        Default: the base scene's.
    attenuation : {"lambertian", "paper"}, optional
        Default: the base scene's.
    """
    sensors = sensor_grid(grid, extent, base.source)
    scene = base.replace(sensors=sensors, illumination=illumination or base.illumination,
                         attenuation=attenuation or base.attenuation)
    return scene.replace(sampling=covering_sampling(scene, period))


def conditioning_table(base: Scene, *, extents=(0.5, 1.0, 2.0, 4.0), periods=(0.05, 0.1, 0.2),
                       sigma: float | None = None, progress: bool = False) -> list[dict]:
    """Singular-value statistics of A over a grid of (W, T).

    Parameters
    ----------
    base : Scene
        Plane, source, illumination, attenuation; its sensors are replaced.
    extents : sequence of float
        Array extents W, metres.
    periods : sequence of float
        Bin widths T, metres of path length.
    sigma : float, optional
        Noise level for the effective rank; default the base scene's
        Gaussian σ (0.1 if it has none).
    progress : bool
        Show a tqdm bar.

    Returns
    -------
    list of dict
        One row per (W, T): ``extent``, ``period``, ``rows``, the fields of
        :func:`conditioning_summary`, and ``singular_values``.
    """
    if sigma is None:
        sigma = base.noise.sigma if base.noise is not None and base.noise.kind == "gaussian" else 0.1
    cases = [(w, t) for t in periods for w in extents]
    if progress:
        from tqdm import tqdm
        cases = tqdm(cases, desc="conditioning", unit="case")
    table = []
    for extent, period in cases:
        scene = scene_for(base, extent=extent, period=period)
        matrix = system_matrix(scene)
        values = singular_values(matrix)
        row = {"extent": extent, "period": period, "rows": matrix.shape[0]}
        row.update(conditioning_summary(values, scene.pixels**2, matrix.shape[0], sigma=sigma))
        row["singular_values"] = values
        table.append(row)
    return table


def plot_conditioning(path, table: list[dict], *, title: str = "") -> Path:
    """Singular-value spectra (one curve per (W, T)) and effective rank against W.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    table : list of dict
        From :func:`conditioning_table`.
    title : str
        Figure title.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import save_figure

    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    periods = sorted({row["period"] for row in table})
    for i, period in enumerate(periods):
        rows = sorted((r for r in table if r["period"] == period), key=lambda r: r["extent"])
        for j, row in enumerate(rows):
            left.semilogy(row["singular_values"], color=f"C{i}", alpha=0.4 + 0.6 * j / max(len(rows) - 1, 1),
                          lw=1, label=f"T = {period:g}, W = {row['extent']:g}")
        right.plot([r["extent"] for r in rows], [r["effective_rank"] for r in rows], "o-",
                   color=f"C{i}", label=f"T = {period:g} m")
    if table:
        left.axhline(table[0]["sigma"], color="k", ls="--", lw=0.8, label=f"σ = {table[0]['sigma']:g}")
    left.set_xlabel("index i", fontsize=8)
    left.set_ylabel("singular value s_i of A", fontsize=8)
    left.legend(fontsize=6, ncol=2)
    right.set_xlabel("array extent W (m)", fontsize=8)
    right.set_ylabel("effective rank: #{s_i > σ}", fontsize=8)
    right.legend(fontsize=8)
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()

    return save_figure(figure, path, dpi=110)
