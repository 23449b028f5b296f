"""The lsqr method's stop by the noise and the discrepancy rule's short sweep (analytic.inversion.iterative)."""

import re

import numpy as np
import pytest

from analytic.inversion import reconstruct
from analytic.inversion.iterative import NOISE_FRACTION
from dense_reference import dense_solution, stencil_laplacian, synthetic_problem


def _iterations(result) -> int:
    return int(re.search(r"(\d+) iterations over", result.stopping)[1])


@pytest.mark.parametrize("lam", [1e-6, 1e-4, 1e-2])
def test_a_solve_stopped_by_the_noise_leaves_a_stacked_residual_within_its_stated_margin(rng, lam):
    pixels, sigma = 10, 0.02
    matrix, y, _ = synthetic_problem(rng, pixels=pixels, rows=400, decay=3e-2, noise=sigma)
    exact = dense_solution(matrix, y, pixels, lam)
    # the converged stacked residual ‖A f − y‖² + λ ‖D f‖², by a dense solve
    floor = float(np.sum((matrix @ exact - y) ** 2) + lam * np.sum((stencil_laplacian(pixels) @ exact) ** 2))
    stopped = reconstruct(matrix, y, pixels, rule=lam, method="lsqr", sigma=sigma)
    strict = reconstruct(matrix, y, pixels, rule=lam, method="lsqr")
    margin = NOISE_FRACTION * sigma**2 * np.sqrt(2 * len(y))
    assert "σ² √(2m)" in stopped.stopping and "σ" not in strict.stopping
    stacked = stopped.residual_norm**2 + lam * stopped.seminorm**2
    assert -1e-8 * floor <= stacked - floor <= margin      # the dense reference to ~1e-10
    assert _iterations(stopped) <= _iterations(strict)
    # the image moves by less than the noise moves it: the estimate's spread, from the dense solver
    spread = np.std([dense_solution(matrix, matrix @ exact.ravel() + sigma * rng.standard_normal(len(y)),
                                    pixels, lam) for _ in range(20)], axis=0)
    assert np.sqrt(np.mean((stopped.image.ravel() - exact.ravel()) ** 2)) <= 0.5 * np.sqrt(np.mean(spread**2))


def test_the_discrepancy_sweep_ends_where_the_residual_crosses_m_sigma_squared(rng):
    pixels, sigma = 6, 0.02
    matrix, y, _ = synthetic_problem(rng, pixels=pixels, rows=200, noise=sigma)
    grid = np.geomspace(1e-8, 1e1, 40)
    exact = reconstruct(matrix, y, pixels, rule="discrepancy", sigma=sigma, lambdas=grid, method="svd")
    short = reconstruct(matrix, y, pixels, rule="discrepancy", sigma=sigma, lambdas=grid, method="lsqr")
    step = np.log(grid[1] / grid[0])
    assert abs(np.log(short.lam / exact.lam)) <= 1.01 * step
    solved = np.isfinite(short.residual_norms)
    below = np.nonzero(solved)[0][0]              # the smallest λ solved: its residual is below m σ²
    assert 0 < below and not solved[:below].any() and solved[below:].all()
    assert short.residual_norms[below] ** 2 < len(y) * sigma**2 <= short.residual_norms[below + 1] ** 2


@pytest.mark.parametrize("noise", [0.02, 0.005])
def test_the_discrepancy_search_on_the_default_grid_reaches_the_closed_form_crossing(rng, noise):
    # the svd method's crossing is exact (brentq on the closed-form residual); the search must land where that
    # residual is within its stated slack of m σ² (plus the solves' own margin), in far fewer solves than a sweep
    from analytic.inversion.iterative import CROSSING_FRACTION
    from analytic.inversion.tikhonov import SpectralSolver
    from analytic.inversion.result import Problem

    pixels = 8
    matrix, y, _ = synthetic_problem(rng, pixels=pixels, rows=300, decay=1e-3, noise=noise)
    exact = reconstruct(matrix, y, pixels, rule="discrepancy", sigma=noise, method="svd")
    searched = reconstruct(matrix, y, pixels, rule="discrepancy", sigma=noise, method="lsqr")
    assert not searched.warnings
    problem = Problem.checked(matrix, y, pixels)
    scale = problem.matrix_scale**2
    closed = SpectralSolver(problem)
    target = len(y) * noise**2
    spread = noise**2 * np.sqrt(2 * len(y))
    residual = float(closed.squared_residual(searched.lam / scale)) * problem.data_scale**2
    assert abs(residual - target) <= (CROSSING_FRACTION + 2 * NOISE_FRACTION) * spread
    assert abs(searched.residual_norm**2 - target) <= CROSSING_FRACTION * spread
    assert len(searched.lambdas) < 15 and np.all(np.isfinite(searched.residual_norms))
    assert np.max(np.abs(searched.image - exact.image)) < 0.1 * np.max(np.abs(exact.image))
