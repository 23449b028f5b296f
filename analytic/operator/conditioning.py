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
import numpy as np

from ..scenes.common import Illumination, Scene, sensor_grid
from .system import system_matrix
from .window import covering_sampling

__all__ = ["singular_values", "conditioning_summary", "scene_for", "conditioning_table"]


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
        :func:`analytic.operator.window.covering_sampling`).
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
