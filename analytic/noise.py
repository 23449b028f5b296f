"""Measurement noise: additive Gaussian (the paper's σ = 0.1) and photon counting."""

from __future__ import annotations

import numpy as np

from .scene import Noise

__all__ = ["add_noise"]


def add_noise(y: np.ndarray, noise: Noise, rng: np.random.Generator | None = None) -> np.ndarray:
    """Noisy copy of the samples y.

    Parameters
    ----------
    y : numpy.ndarray
        Noiseless samples, any shape, units of y.
    noise : Noise
        ``gaussian``: y + σ ε with ε ~ N(0, 1) i.i.d.;
        ``poisson``: Poisson(photons · y) / photons (photon counting at low
        flux; y must be >= 0).
    rng : numpy.random.Generator, optional
        Generator; default ``numpy.random.default_rng(noise.seed)``.

    Returns
    -------
    numpy.ndarray
        float64, same shape as y.
    """
    rng = np.random.default_rng(noise.seed) if rng is None else rng
    y = np.asarray(y, dtype=np.float64)
    if noise.kind == "gaussian":
        return y + noise.sigma * rng.standard_normal(y.shape)
    if np.any(y < 0):
        raise ValueError("Poisson noise needs non-negative samples")
    return rng.poisson(noise.photons * y).astype(np.float64) / noise.photons
