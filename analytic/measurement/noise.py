"""Measurement noise: additive Gaussian (the paper's σ = 0.1) and photon counting."""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..scenes.common import Noise
from ..values import exact

__all__ = ["add_noise", "MAX_EXPECTED_PHOTONS"]

#: Largest expected count per sample that Poisson sampling handles exactly
#: (NumPy's limit is about 9.2e18; beyond 1e15 the counts' spacing exceeds 1).
MAX_EXPECTED_PHOTONS = 1e15


def add_noise(y: np.ndarray, noise: Noise, rng: np.random.Generator | None = None) -> np.ndarray:
    """Noisy copy of the samples y.

    Parameters
    ----------
    y : numpy.ndarray
        Noiseless samples, any shape, units of y.
    noise : Noise
        ``gaussian``: y + σ ε with ε ~ N(0, 1) i.i.d.;
        ``poisson``: Poisson(photons · max(y, 0)) / photons (photon counting
        at low flux; a negative y, from a pulse's undershoot, is light no
        modulator emits and expects no photons).
    rng : numpy.random.Generator, optional
        Generator; default ``numpy.random.default_rng(noise.seed)``.

    Returns
    -------
    numpy.ndarray
        float64, same shape as y.

    Raises
    ------
    SceneError
        ``noise.photons`` so large that a sample expects more than
        :data:`MAX_EXPECTED_PHOTONS` photons.
    """
    rng = np.random.default_rng(noise.seed) if rng is None else rng
    y = np.asarray(y, dtype=np.float64)
    if noise.kind == "gaussian":
        return y + noise.sigma * rng.standard_normal(y.shape)
    expected = noise.photons * np.clip(y, 0.0, None)
    largest = float(np.max(expected)) if expected.size else 0.0
    if not largest <= MAX_EXPECTED_PHOTONS:
        raise SceneError("noise.photons", f"{exact(noise.photons)} photons per unit of y make a sample "
                                          f"expect {exact(largest)} photons, over the "
                                          f"{MAX_EXPECTED_PHOTONS:g} Poisson sampling handles; "
                                          f"use fewer photons (or Gaussian noise)")
    return rng.poisson(expected).astype(np.float64) / noise.photons
