"""Reconstruction from photon counts: the Laplacian-Tikhonov rule on counts under the detector's model.

Counts c (``(K, N)``) of a detector (:class:`analytic.measurement.detector.Detector`:
photons per cycle per unit of y, background per bin per cycle, cycles C,
dead time) carry y through the rates λ = photons · y + background. Two
solvers:

- :func:`reconstruct_counts` (the rule used; an approximation): each bin's
  rate is estimated from its counts, λ̂_n = c_n / C without dead time and
  Coates' λ̂_n = -log1p(-c_n / R_n) with it (R_n the cycles still armed,
  :func:`analytic.measurement.detector.coates_estimate`), giving
  ŷ = (λ̂ - background) / photons with a variance v from the detector's
  model; then the weighted problem

      f = argmin Σ (A f - ŷ)² / v + λ ||D f||²

  is solved by :func:`analytic.inversion.reconstruct` on the whitened rows
  (σ = 1), λ by its rule (the discrepancy principle by default: the
  whitened residual's squared norm equal to the number of rows). The
  variances are first the estimate's own (a bin with no count floored at one
  count), then, in a second pass, the model's at the first pass's
  prediction (iteratively reweighted least squares). This is the
  second-order (Gaussian) approximation of the Poisson (or multinomial)
  log-likelihood about its maximum.
- :func:`poisson_map` (the exact reference): the maximum a posteriori
  image under the exact likelihood, f = argmin 2 NLL(f) + λ ||D f||² over
  f >= 0 (2 NLL is the deviance up to a constant, so at the same λ it
  weighs the prior as the first does), by L-BFGS-B with the exact
  gradient. Poisson: NLL = Σ μ - c log μ, μ = C λ(f). Dead time: the
  multinomial of the first photons, NLL = -Σ_n c_n log p_n - c_∅ log p_∅
  with p from λ(f) (Coates), ∂NLL/∂λ_m = R_{m+1} - c_m / (e^{λ_m} - 1).

:func:`compare_to_map` measures the approximation's error against the
exact MAP at the same λ (``benchmarks/bench_counts.py`` prints it beside the
PSNR table).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from ..measurement.detector import Detector, coates_estimate, detection_probabilities, rates, sums_before
from ..errors import DataError
from .laplacian import neumann_laplacian
from .result import Reconstruction
from .tikhonov import reconstruct

__all__ = ["rate_estimate", "reconstruct_counts", "poisson_map", "compare_to_map", "negative_log_likelihood"]


def _counts(counts, detector: Detector, rows: int) -> np.ndarray:
    counts = np.asarray(counts, dtype=np.float64)
    if counts.size != rows:
        raise DataError(f"counts: {counts.size} bins, the matrix has {rows} rows")
    if not np.all(np.isfinite(counts)) or np.any(counts < 0) or np.any(counts != np.round(counts)):
        raise DataError("counts: every count must be a finite whole number >= 0")
    return counts.reshape(-1, counts.shape[-1]) if counts.ndim > 1 else counts.reshape(1, -1)


def rate_estimate(counts, detector: Detector) -> tuple[np.ndarray, np.ndarray]:
    """ŷ = (λ̂ - background) / photons per bin and its variance (units of y and y²), ``counts.shape``.

    Without dead time λ̂ = c / C, variance max(c, 1) / C²; with it Coates'
    estimate and its delta-method variance (c floored at one count; a bin
    where every armed cycle fired is read as c = R - 1/2, where the
    logarithm stays finite).
    """
    counts = np.asarray(counts, dtype=np.float64)
    if detector.dead_time == "none":
        lam = counts / detector.cycles
        variance = np.maximum(counts, 1.0) / detector.cycles**2
    else:
        armed = detector.cycles - sums_before(counts)
        counts = np.minimum(counts, np.maximum(armed - 0.5, 0.0))
        lam, _ = coates_estimate(counts, detector.cycles)
        floored = np.maximum(counts, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            variance = floored / (armed * np.maximum(armed - floored, 0.5))
        # a bin no cycle was armed for carries nothing
        lam = np.where(armed > 0, lam, 0.0)
        variance = np.where(armed > 0, variance, np.inf)
    photons = detector.photons
    return (lam - detector.background) / photons, variance / photons**2


def _model_variance(y, detector: Detector) -> np.ndarray:
    """Variance of ŷ predicted by the detector's model at y (the IRLS weights' second pass)."""
    lam = np.maximum(rates(y, detector), 1e-300)
    if detector.dead_time == "none":
        return lam / detector.cycles / detector.photons**2
    p, _ = detection_probabilities(lam)
    armed = detector.cycles * (np.cumsum(np.concatenate([np.zeros(lam.shape[:-1] + (1,)), -p], axis=-1),
                                         axis=-1)[..., :-1] + 1.0)
    # Var λ̂ ≈ q / (R (1 - q)), q = 1 - e^{-λ} the per-armed-cycle probability, R the expected armed cycles
    q = -np.expm1(-lam)
    with np.errstate(divide="ignore"):
        variance = q / (np.maximum(armed, 1e-300) * np.maximum(1.0 - q, 1e-300))
    return variance / detector.photons**2


def reconstruct_counts(matrix, counts, detector: Detector, pixels: int, *, rule="discrepancy", truth=None,
                       lambdas=None, passes: int = 2) -> Reconstruction:
    """The Laplacian-Tikhonov image from counts: weighted least squares on the rate estimates (module docstring).

    Parameters
    ----------
    matrix : scipy.sparse array or numpy.ndarray
        A, ``(K N, M²)``.
    counts : array_like
        ``(K, N)`` counts.
    detector : Detector
    pixels : int
        M.
    rule : str or float
        As for :func:`analytic.inversion.reconstruct` (the whitened
        problem has σ = 1).
    truth : array_like, optional
        For ``"oracle"``.
    lambdas : array_like, optional
        λ grid.
    passes : int
        1: weights from the counts alone; 2 (default): reweighted at the
        first pass's prediction.

    Returns
    -------
    Reconstruction
        Of the whitened problem (its λ weighs ||D f||² against
        Σ (A f - ŷ)² / v).
    """
    rows = matrix.shape[0]
    flat = _counts(counts, detector, rows)
    estimate, variance = rate_estimate(flat, detector)
    estimate, variance = estimate.ravel(), variance.ravel()
    matrix = scipy.sparse.csr_array(matrix)
    result = None
    for _ in range(max(int(passes), 1)):
        # bins no cycle was armed for carry no information: left out, so the discrepancy counts the others
        informative = np.isfinite(variance) & (variance > 0)
        weights = 1.0 / np.sqrt(variance[informative])
        whitened = scipy.sparse.diags(weights) @ matrix[informative]
        result = reconstruct(whitened, weights * estimate[informative], pixels, rule=rule, truth=truth, sigma=1.0,
                             lambdas=lambdas)
        prediction = (matrix @ result.image.ravel()).reshape(flat.shape)
        variance = _model_variance(prediction, detector).ravel()
    return result


def negative_log_likelihood(matrix, counts, detector: Detector, image) -> tuple[float, np.ndarray]:
    """(NLL(f), ∂NLL/∂f) of the counts under the detector's exact model (module docstring), up to a constant."""
    matrix = scipy.sparse.csr_array(matrix)
    flat = _counts(counts, detector, matrix.shape[0])
    y = (matrix @ np.ravel(image)).reshape(flat.shape)
    lam = np.maximum(detector.photons * y + detector.background, 1e-300)
    if detector.dead_time == "none":
        mu = detector.cycles * lam
        value = float(np.sum(mu - flat * np.log(mu)))
        gradient_lam = detector.cycles * (1.0 - flat / mu)
    else:
        total = np.sum(lam, axis=-1, keepdims=True)
        before = sums_before(lam)
        missed = detector.cycles - flat.sum(axis=-1, keepdims=True)
        value = float(np.sum(flat * before) - np.sum(flat * np.log(-np.expm1(-lam))) + np.sum(missed * total))
        after = detector.cycles - np.cumsum(flat, axis=-1)          # R_{m+1}
        # 1 / (e^λ - 1) as e^{-λ} / (1 - e^{-λ}): no overflow for a bin of λ beyond 709
        gradient_lam = after - flat * np.exp(-lam) / -np.expm1(-lam)
    return value, detector.photons * (matrix.T @ gradient_lam.ravel())


def poisson_map(matrix, counts, detector: Detector, pixels: int, lam: float, *, start=None,
                iterations: int = 5000) -> np.ndarray:
    """The exact MAP image: argmin over f >= 0 of 2 NLL(f) + λ ||D f||² (L-BFGS-B), ``(M, M)``.

    Parameters
    ----------
    matrix, counts, detector, pixels
        As for :func:`reconstruct_counts`.
    lam : float
        λ, in the units of the whitened problem (2 NLL ≈ its weighted residual).
    start : array_like, optional
        Starting image (default: a flat 0.5).
    iterations : int
        Most L-BFGS-B iterations.
    """
    from scipy import optimize

    laplacian = neumann_laplacian(pixels)
    x0 = np.full(pixels * pixels, 0.5) if start is None else np.clip(np.ravel(start), 0.0, None)

    def objective(f):
        value, gradient = negative_log_likelihood(matrix, counts, detector, f)
        smooth = laplacian @ f
        return 2.0 * value + lam * float(smooth @ smooth), 2.0 * gradient + 2.0 * lam * (laplacian.T @ smooth)

    found = optimize.minimize(objective, x0, jac=True, method="L-BFGS-B", bounds=[(0.0, None)] * x0.size,
                              options={"maxiter": iterations, "ftol": 1e-15, "gtol": 1e-12})
    return found.x.reshape(pixels, pixels)


def compare_to_map(matrix, counts, detector: Detector, pixels: int, approximation: Reconstruction) -> dict:
    """The approximation's image against the exact MAP at its own λ: relative difference and both images.

    Returns
    -------
    dict
        ``relative_difference`` ||f - f_MAP|| / ||f_MAP||, ``map_image``,
        ``lam``.
    """
    exact = poisson_map(matrix, counts, detector, pixels, approximation.lam, start=approximation.image)
    difference = float(np.linalg.norm(approximation.image - exact) / np.linalg.norm(exact))
    return {"relative_difference": difference, "map_image": exact, "lam": float(approximation.lam)}
