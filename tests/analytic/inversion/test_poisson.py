"""Reconstruction from counts: the weighted least-squares rule against the exact Poisson MAP, and its gradient."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from analytic.measurement.detector import Detector, draw_counts, expected_counts
from analytic.errors import DataError
from analytic.inversion import image_metrics
from analytic.inversion.poisson import (compare_to_map, negative_log_likelihood, rate_estimate,
                                        reconstruct_counts)

PIXELS = 6


@pytest.fixture(scope="module")
def problem():
    """A random non-negative A (3 sensors x 30 bins of a 6 x 6 image) and a smooth image."""
    rng = np.random.default_rng(3)
    matrix = scipy.sparse.csr_array(rng.uniform(0.0, 1.0, (90, PIXELS**2)) ** 4 * 0.02)
    x = np.linspace(0, 1, PIXELS)
    truth = 0.3 + 0.5 * np.outer(np.sin(2 * x), np.cos(x))
    return matrix, truth


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_gradient_is_the_likelihoods(problem, dead_time):
    matrix, truth = problem
    detector = Detector(photons=30.0, background=0.01, cycles=2000, dead_time=dead_time, seed=1)
    counts = draw_counts((matrix @ truth.ravel()).reshape(3, -1), detector)
    f = truth.ravel() * 0.9 + 0.05
    value, gradient = negative_log_likelihood(matrix, counts, detector, f)
    rng = np.random.default_rng(0)
    for _ in range(5):
        direction = rng.normal(size=f.size)
        h = 1e-6
        numeric = (negative_log_likelihood(matrix, counts, detector, f + h * direction)[0]
                   - negative_log_likelihood(matrix, counts, detector, f - h * direction)[0]) / (2 * h)
        assert gradient @ direction == pytest.approx(numeric, rel=1e-6, abs=1e-6 * abs(value))


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_rate_estimates_are_unbiased_where_counts_are_many(problem, dead_time):
    matrix, truth = problem
    y = (matrix @ truth.ravel()).reshape(3, -1)
    detector = Detector(photons=1.0, background=0.01, cycles=1e6, dead_time=dead_time)
    estimate, variance = rate_estimate(expected_counts(y, detector), detector)
    # at the expected histogram the estimate is y itself (exactly: Coates inverts the expectation)
    np.testing.assert_allclose(estimate, np.maximum(y, 0), rtol=1e-9, atol=1e-12)
    assert np.all(variance > 0)


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_weighted_rule_is_close_to_the_exact_map(problem, dead_time):
    """The Gaussian approximation's image within a few % of the exact MAP at the same λ, both near the truth."""
    matrix, truth = problem
    y = (matrix @ truth.ravel()).reshape(3, -1)
    detector = Detector(photons=2.0, background=0.01, cycles=1e5, dead_time=dead_time, seed=2)
    counts = draw_counts(y, detector)
    approximation = reconstruct_counts(matrix, counts, detector, PIXELS)
    found = compare_to_map(matrix, counts, detector, PIXELS, approximation)
    assert found["relative_difference"] < 0.05, found["relative_difference"]
    assert image_metrics(found["map_image"], truth)["psnr"] > 20
    assert image_metrics(approximation.image, truth)["psnr"] > 20
    # the rule's λ is the discrepancy principle's: a whitened residual of about one per row
    assert approximation.rule == "discrepancy"


def test_counts_that_cannot_be_are_refused(problem):
    matrix, _ = problem
    with pytest.raises(DataError, match="counts"):
        reconstruct_counts(matrix, np.full((3, 30), 0.5), Detector(photons=1.0), PIXELS)
    with pytest.raises(DataError, match="rows"):
        reconstruct_counts(matrix, np.ones((3, 29)), Detector(photons=1.0), PIXELS)


def test_likelihood_keeps_the_photons_before_a_bin_that_dwarfs_them():
    """Λ_n = Σ_{m<n} λ_m summed from the start: ``cumsum(λ) - λ`` cancelled to 0 in the bin of λ = 1e20 (issue
    38, cause 1's class). Reference: the multinomial's -log L written here term by term with math.fsum."""
    import math

    lam = [1e-3, 1e-3, 1e20, 1e-3]
    counts = np.array([[1.0, 2.0, 97.0, 0.0]])        # every one of the 100 cycles detected: none missed
    detector = Detector(photons=1.0, background=0.0, cycles=100, dead_time="cycle")
    value, _ = negative_log_likelihood(scipy.sparse.identity(4, format="csr"), counts, detector, np.array(lam))
    reference = math.fsum(c * (math.fsum(lam[:n]) - math.log(-math.expm1(-lam[n])))
                          for n, c in enumerate(counts[0]))
    assert value == pytest.approx(reference, rel=1e-12)
