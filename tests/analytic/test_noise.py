"""Noise: the stated σ, photon counts, seeded, and its limits."""

import math

import numpy as np
import pytest

from analytic.errors import SceneError
from analytic.measurement.noise import MAX_EXPECTED_PHOTONS, add_noise
from analytic.scenes.common import Noise


def test_gaussian_noise_has_the_stated_sigma_and_is_seeded():
    y = np.zeros(200_000)
    noisy = add_noise(y, Noise(sigma=0.1, seed=4))
    assert abs(noisy.std() - 0.1) < 4 * 0.1 / math.sqrt(2 * y.size)
    assert np.array_equal(noisy, add_noise(y, Noise(sigma=0.1, seed=4)))
    assert not np.array_equal(noisy, add_noise(y, Noise(sigma=0.1, seed=5)))


def test_poisson_noise_counts_whole_photons_and_expects_none_from_negative_light():
    y = np.array([0.0, 0.002, 0.05, -0.01])
    photons = 1000.0
    noisy = add_noise(np.repeat(y[None], 20_000, axis=0), Noise(kind="poisson", photons=photons, seed=1))
    counts = noisy * photons
    assert np.allclose(counts, np.round(counts))
    mean = counts.mean(axis=0)
    expected = photons * np.clip(y, 0, None)
    assert np.all(np.abs(mean - expected) <= 5 * np.sqrt(np.maximum(expected, 1) / 20_000))
    assert np.all(counts[:, 3] == 0)


def test_more_photons_than_poisson_sampling_handles_is_refused():
    with pytest.raises(SceneError, match="noise.photons"):
        add_noise(np.ones(3), Noise(kind="poisson", photons=1e308))
    assert np.all(np.isfinite(add_noise(np.ones(3), Noise(kind="poisson", photons=MAX_EXPECTED_PHOTONS))))
