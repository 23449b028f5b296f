"""The Tikhonov estimate's exact bias and variance (analytic.inversion.tikhonov_error) against Monte Carlo.

The estimates are the reconstruction users run (analytic.inversion.reconstruct with a fixed λ, its own DCT/SVD
solver), over many fixed-seed noise draws; the thresholds come from each statistic's own standard error, and a
deliberately wrong λ must fail them.
"""

import math

import numpy as np
from dense_reference import synthetic_problem

from analytic.inversion import reconstruct
from analytic.inversion.tikhonov_error import data_variance, tikhonov_error
from analytic.measurement.noise import add_noise
from analytic.scenes.common import Noise

DRAWS = 1500
LIMIT = 5.0        # standard errors


def _monte_carlo(matrix, truth, lam, noise_draw, rng):
    clean = matrix @ truth.ravel()
    return np.array([reconstruct(matrix, noise_draw(clean, rng), truth.shape[0], rule=lam).image.ravel()
                     for _ in range(DRAWS)])


def _agrees(estimates, truth, error):
    mean, spread = estimates.mean(axis=0), estimates.std(axis=0, ddof=1)
    variance_ok = np.abs(spread / error.stddev.ravel() - 1) < LIMIT / math.sqrt(2 * (DRAWS - 1))
    bias_ok = np.abs(mean - truth.ravel() - error.bias.ravel()) < LIMIT * spread / math.sqrt(DRAWS)
    return bool(np.all(variance_ok) and np.all(bias_ok))


def test_gaussian_bias_and_variance_match_monte_carlo(rng):
    matrix, _, truth = synthetic_problem(rng, pixels=5, rows=18, decay=1e-2)    # fewer rows than pixels
    sigma, lam = 0.002, 3e-4
    estimates = _monte_carlo(matrix, truth, lam, lambda y, g: y + sigma * g.standard_normal(y.shape), rng)
    error = tikhonov_error(matrix, truth, lam, variance=sigma**2)
    assert np.sqrt(np.mean(error.bias**2)) > 10 * error.stddev.max() / math.sqrt(DRAWS)   # a bias to see
    assert _agrees(estimates, truth, error)
    assert not _agrees(estimates, truth, tikhonov_error(matrix, truth, 2 * lam, variance=sigma**2))


def test_poisson_variance_matches_monte_carlo(rng):
    matrix, _, truth = synthetic_problem(rng, pixels=4, rows=30, decay=0.1)
    matrix = np.abs(matrix)                       # light is non-negative: every sample expects photons
    noise = Noise(kind="poisson", photons=400.0)
    lam = 1e-3
    estimates = _monte_carlo(matrix, truth, lam, lambda y, g: add_noise(y, noise, rng=g), rng)
    clean = matrix @ truth.ravel()
    error = tikhonov_error(matrix, truth, lam, variance=data_variance(clean, noise))
    assert _agrees(estimates, truth, error)
    assert not _agrees(estimates, truth, tikhonov_error(matrix, truth, lam, variance=clean / 800.0))   # twice the photons


def test_without_penalty_weight_the_variance_tends_to_the_cramer_rao_bound(rng):
    matrix, _, truth = synthetic_problem(rng, pixels=4, rows=40, decay=0.1)      # full rank
    error = tikhonov_error(matrix, truth, 1e-12, variance=0.01**2)
    np.testing.assert_allclose(error.stddev.ravel(), 0.01 * np.sqrt(np.diag(np.linalg.inv(matrix.T @ matrix))),
                               rtol=1e-6)
    assert np.max(np.abs(error.bias)) < 1e-8


def test_the_scene_error_is_skipped_with_its_reason_where_a_dense_a_would_not_fit(monkeypatch):
    # the exact error holds A dense with its gain (2 rows M² doubles) and the (M², M²) normal matrix twice:
    # beyond the limit it must say so rather than allocate them (a 64 x 64 scan's A: 2 million x 4096)
    from analytic import system_matrix
    from analytic.inversion import tikhonov_error as module
    from analytic.scenes.common import Sampling, default_scene

    scene = default_scene(pixels=4, reflectance=np.full((4, 4), 0.5), noise=Noise(kind="gaussian", sigma=0.05),
                          sampling=Sampling(bin_width_opl=0.1, start_opl=2.0, count=8))
    matrix = system_matrix(scene)
    rows = matrix.shape[0]
    need = 8 * max(2 * rows * 16 + 2 * 16**2, 3 * rows * 16)
    assert module.tikhonov_error_skipped(scene, matrix, need) is None
    reason = module.tikhonov_error_skipped(scene, matrix, need - 1)
    assert reason.startswith("not computed") and f"{rows:,} x 16" in reason
    assert module.scene_tikhonov_error(scene, matrix, 1e-3) is not None
    monkeypatch.setattr(module, "DEFAULT_MEMORY_LIMIT", need - 1)
    assert module.scene_tikhonov_error(scene, matrix, 1e-3) is None
