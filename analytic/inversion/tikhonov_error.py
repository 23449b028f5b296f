"""What Laplacian-Tikhonov regularisation trades: the estimate's exact bias and variance per pixel.

For a fixed λ the estimate is linear in the data,

    f_λ = H y,   H = (AᵀA + λ DᵀD)⁻¹ Aᵀ,

so with y = A f + noise of covariance diag(v) (v = σ² for Gaussian noise,
max(y, 0) / p for Poisson counts of p photons per unit of y):

    bias = (R − I) f,   R = H A,
    cov  = H diag(v) Hᵀ   (σ² G⁻¹ AᵀA G⁻¹ for Gaussian noise, G = AᵀA + λ DᵀD),

exactly, D the Neumann 5-point Laplacian of :mod:`.laplacian` (unit
spacing, as the reconstruction penalises). Beside the Cramér-Rao bound
(:mod:`.bounds`, which holds for unbiased estimates only) it shows what the
penalty buys: a standard deviation below the bound, paid for in bias.
(A λ chosen from the same data, as the rules do, makes f_λ slightly
non-linear in y; the formulas are those of the λ reached.)

G is factored by Cholesky on a copy of A scaled by a power of two (exact),
or, should rounding make it indefinite (λ tiny against an ill-conditioned
A), through the QR factors of the stacked [A; √λ D], which never square A's
condition number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse

from .information import DEFAULT_MEMORY_LIMIT
from .laplacian import neumann_laplacian

__all__ = ["TikhonovError", "tikhonov_error", "data_variance", "scene_tikhonov_error", "tikhonov_error_skipped",
           "MOST_PIXELS"]


@dataclass(frozen=True)
class TikhonovError:
    """Bias and standard deviation per pixel of the Tikhonov estimate at one λ (:func:`tikhonov_error`).

    Attributes
    ----------
    bias : numpy.ndarray
        ``(M, M)`` E f_λ − f, reflectance.
    stddev : numpy.ndarray
        ``(M, M)`` standard deviation of f_λ over noise draws, reflectance.
    lam : float
        λ.
    """

    bias: np.ndarray
    stddev: np.ndarray
    lam: float

    def summary(self, bound=None) -> dict:
        """The numbers a report shows: rms bias, median standard deviation, the expected rms error, and
        the Cramér-Rao bound's median over the pixels it fixes (``bound``: its ``(M, M)`` image)."""
        record = {"lambda": self.lam, "bias_rms": float(np.sqrt(np.mean(self.bias**2))),
                  "bias_max_abs": float(np.max(np.abs(self.bias))),
                  "stddev_median": float(np.median(self.stddev)),
                  "rmse_expected": float(np.sqrt(np.mean(self.bias**2 + self.stddev**2)))}
        if bound is not None:
            finite = bound[np.isfinite(bound)]
            record["crb_median"] = float(np.median(finite)) if finite.size else math.inf
            record["crb_unbounded_pixels"] = int(bound.size - finite.size)
        return record


def data_variance(y, noise) -> np.ndarray:
    """Each sample's variance under the scene's ``[noise]`` (units of y squared), ``y.shape``."""
    y = np.asarray(y, dtype=np.float64)
    if noise.kind == "gaussian":
        return np.full(y.shape, noise.sigma**2)
    return np.maximum(y, 0.0) / noise.photons


def _gain(dense: np.ndarray, lam: float, pixels: int) -> np.ndarray:
    """H = (AᵀA + λ DᵀD)⁻¹ Aᵀ, ``(M², rows)``."""
    scale = 2.0 ** -math.frexp(float(np.max(np.abs(dense))) or 1.0)[1]     # exact: a power of two
    scaled = dense * scale
    penalty = neumann_laplacian(pixels)
    lam_scaled = lam * scale**2
    normal = scaled.T @ scaled + lam_scaled * (penalty.T @ penalty).toarray()
    try:
        factor = scipy.linalg.cho_factor(normal, check_finite=False)
        return scipy.linalg.cho_solve(factor, scaled.T, check_finite=False) * scale
    except np.linalg.LinAlgError:
        q, r = np.linalg.qr(np.vstack([scaled, math.sqrt(lam_scaled) * penalty.toarray()]))
        return scipy.linalg.solve_triangular(r, q[:scaled.shape[0]].T) * scale


def tikhonov_error(matrix, truth, lam: float, *, variance=0.0) -> TikhonovError:
    """Exact bias and standard deviation per pixel of argmin ‖A f − y‖² + λ ‖D f‖² at the true image.

    Parameters
    ----------
    matrix : scipy.sparse array or numpy.ndarray
        A, ``(rows, M²)``.
    truth : array_like
        ``(M, M)`` true image f.
    lam : float
        λ > 0, in the units :func:`analytic.inversion.reconstruct` reports.
    variance : float or array_like
        The data's variance per sample (units of y squared): σ², or ``(rows,)``
        (:func:`data_variance`). 0: noiseless (the bias alone).

    Returns
    -------
    TikhonovError
    """
    truth = np.asarray(truth, dtype=np.float64)
    pixels = truth.shape[0]
    dense = matrix.toarray() if scipy.sparse.issparse(matrix) else np.asarray(matrix, dtype=np.float64)
    if not (math.isfinite(lam) and lam > 0):
        raise ValueError(f"lam: must be finite and > 0, got {lam!r}")
    gain = _gain(dense, float(lam), pixels)
    mean = gain @ (dense @ truth.ravel())
    variance = np.broadcast_to(np.asarray(variance, dtype=np.float64).ravel(), (dense.shape[0],))
    spread = np.sqrt(np.maximum((gain**2) @ variance, 0.0))
    return TikhonovError(bias=(mean - truth.ravel()).reshape(truth.shape), stddev=spread.reshape(truth.shape),
                         lam=float(lam))


#: Most pixels whose dense (M², M²) normal matrix the scene-level report factors (M = 64: 134 MB, seconds).
MOST_PIXELS = 64**2


def tikhonov_error_skipped(scene, matrix, memory_limit: int | None = None) -> str | None:
    """Why :func:`scene_tikhonov_error` computes nothing for ``scene`` and its ``matrix``, in words, or None.

    The exact error holds A dense with its gain H (2 rows M² doubles) and the (M², M²) normal matrix twice;
    the Cramér-Rao bound beside it a dense SVD of A (3 rows M² doubles). Beyond ``memory_limit`` bytes, beyond
    :data:`MOST_PIXELS`, neither is computed (an A applied matrix-free, an operator, is made dense below it).
    ``memory_limit`` defaults to the inversion's ``DEFAULT_MEMORY_LIMIT`` (2 GiB).
    """
    memory_limit = DEFAULT_MEMORY_LIMIT if memory_limit is None else int(memory_limit)
    rows, unknowns = scene.sensor_count * scene.sampling.count, scene.pixels**2
    if unknowns > MOST_PIXELS:
        return (f"not computed: M² = {unknowns:,} pixels, over the {MOST_PIXELS:,} whose dense (M², M²) normal "
                f"matrix the exact error factors")
    need = 8 * (2 * rows * unknowns + 2 * unknowns**2)
    if scene.noise is not None:
        need = max(need, 3 * rows * unknowns * 8)
    if need > memory_limit:
        return (f"not computed: the exact error and the Cramér-Rao bound need A dense ({rows:,} x {unknowns:,}), "
                f"{need / 2**30:.3g} GiB, over the {memory_limit / 2**30:.3g} GiB limit")
    return None


def scene_tikhonov_error(scene, matrix, lam: float):
    """The Tikhonov estimate's error at λ for a scene's image and ``[noise]``, beside its Cramér-Rao bound.

    Returns
    -------
    (TikhonovError, numpy.ndarray or None, dict) or None
        The error, the bound's ``(M, M)`` image (None without ``[noise]``: the bias alone, no variance), and
        :meth:`TikhonovError.summary` with a ``note``; None when :func:`tikhonov_error_skipped` gives a
        reason (M² over :data:`MOST_PIXELS`, or dense copies of A over the memory limit).
    """
    from ..operator.matrix_free import forward
    from .bounds import crb

    if tikhonov_error_skipped(scene, matrix) is not None:
        return None
    if not (scipy.sparse.issparse(matrix) or isinstance(matrix, np.ndarray)):
        matrix = matrix.toarray()       # an operator (analytic.operator.offset_operator): its dense copy fits
    noise = scene.noise
    variance = 0.0 if noise is None else data_variance(forward(scene, matrix).ravel(), noise)
    error = tikhonov_error(matrix, scene.reflectance, lam, variance=variance)
    bound = None if noise is None else crb(scene, matrix=matrix, measurement="noise").image
    summary = error.summary(bound)
    summary["note"] = ("exact for this λ at the scene's reflectance: bias (R - I) f, standard deviation from "
                       "H diag(v) Hᵀ, H = (AᵀA + λ DᵀD)⁻¹ Aᵀ" + ("" if noise is not None else
                                                                 "; no [noise]: the bias alone")
                       + "; crb_median is the Cramér-Rao bound on unbiased estimates (inf where the data "
                         "cannot fix a pixel)")
    return error, bound, summary
