"""How close a reconstruction is to the true image: PSNR and SSIM."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["image_metrics", "structural_similarity", "flat_image_psnr"]


def structural_similarity(estimate, truth, *, data_range: float = 1.0, window: int = 7) -> float:
    """Mean SSIM (Wang et al. 2004) with a uniform ``window`` x ``window`` window.

    Constants K1 = 0.01, K2 = 0.03 on ``data_range``; sample (N - 1)
    covariances; averaged over windows lying wholly inside the image. These
    are scikit-image's ``structural_similarity`` defaults.
    """
    from scipy.ndimage import uniform_filter

    x = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if min(x.shape) < window:
        raise ValueError(f"window: {window} exceeds the image side {min(x.shape)}")
    count = window * window
    correction = count / (count - 1.0)
    mean_x = uniform_filter(x, window)
    mean_t = uniform_filter(t, window)
    var_x = correction * (uniform_filter(x * x, window) - mean_x**2)
    var_t = correction * (uniform_filter(t * t, window) - mean_t**2)
    cov = correction * (uniform_filter(x * t, window) - mean_x * mean_t)
    c1 = (0.01 * data_range) ** 2
    c2 = (0.03 * data_range) ** 2
    ssim = ((2 * mean_x * mean_t + c1) * (2 * cov + c2)) / (
        (mean_x**2 + mean_t**2 + c1) * (var_x + var_t + c2))
    pad = (window - 1) // 2
    return float(ssim[pad:-pad, pad:-pad].mean()) if pad else float(ssim.mean())


def image_metrics(estimate, truth, *, data_range: float = 1.0) -> dict:
    """Error of a reconstructed image against the true one.

    Parameters
    ----------
    estimate, truth : array_like
        ``(M, M)`` images, units of reflectance.
    data_range : float
        Range of valid values used by PSNR and SSIM; 1.0 for reflectance in
        [0, 1] (the estimate is not clipped).

    Returns
    -------
    dict
        ``mse`` (mean squared error), ``psnr`` (10 log10(range² / mse), dB;
        inf when mse = 0), ``ssim`` (see :func:`structural_similarity`),
        ``data_range``.
    """
    x = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if x.shape != t.shape:
        raise ValueError(f"estimate: shape {x.shape} differs from truth's {t.shape}")
    if not data_range > 0:
        raise ValueError(f"data_range: must be > 0, got {data_range!r}")
    mse = float(np.mean((x - t) ** 2))
    psnr = math.inf if mse == 0 else 10.0 * math.log10(data_range**2 / mse)
    ssim = structural_similarity(x, t, data_range=data_range) if min(x.shape) >= 7 else math.nan
    return {"mse": mse, "psnr": psnr, "ssim": ssim, "data_range": float(data_range)}


def flat_image_psnr(truth, *, data_range: float = 1.0) -> float:
    """PSNR of the best constant image (the true mean): the floor a reconstruction must beat, dB."""
    truth = np.asarray(truth, dtype=np.float64)
    return image_metrics(np.full_like(truth, truth.mean()), truth, data_range=data_range)["psnr"]
