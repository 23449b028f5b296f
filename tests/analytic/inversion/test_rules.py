"""The λ rules against brute-force searches with a dense solver."""

import numpy as np
import pytest

from analytic.inversion import reconstruct, reconstruct_rules
from dense_reference import brute_force, dense_solution, stencil_laplacian, synthetic_problem


def test_oracle_gcv_and_discrepancy_match_brute_force_searches(rng):
    matrix, y, truth = synthetic_problem(rng)
    m, sigma = len(y), 0.02
    grid = np.geomspace(1e-8, 1e1, 91)
    solutions, residuals, _ = brute_force(matrix, y, 6, grid)
    stacked = [np.vstack([matrix, np.sqrt(lam) * stencil_laplacian(6)]) for lam in grid]
    # H = A (stacked⁺)[:, :m], from lstsq on identity right-hand sides
    traces = np.array([np.trace(matrix @ np.linalg.lstsq(s, np.eye(m + 36)[:, :m], rcond=None)[0])
                       for s in stacked])
    gcv = residuals / (m - traces) ** 2
    errors = np.sum((solutions - truth.ravel()) ** 2, axis=1)
    oracle, gcv_result, discrepancy = reconstruct_rules(
        matrix, y, 6, rules=("oracle", "gcv", "discrepancy"), truth=truth, sigma=sigma,
        lambdas=grid)
    for result, values in ((oracle, errors), (gcv_result, gcv)):
        best = int(np.argmin(values))
        assert 0 < best < len(grid) - 1  # an interior optimum, so the test means something
        assert grid[best - 1] <= result.lam <= grid[best + 1]
        assert np.allclose(result.criterion, values, rtol=1e-7)
    refined = dense_solution(matrix, y, 6, oracle.lam)
    assert np.sum((refined - truth.ravel()) ** 2) <= errors.min() * (1 + 1e-9)
    # discrepancy: bisection in log λ with the dense solver
    low, high = np.log(grid[0]), np.log(grid[-1])
    for _ in range(60):
        middle = 0.5 * (low + high)
        f = dense_solution(matrix, y, 6, np.exp(middle))
        low, high = (middle, high) if np.sum((matrix @ f - y) ** 2) < m * sigma**2 else (low, middle)
    assert discrepancy.lam == pytest.approx(np.exp(low), rel=1e-6)
    assert discrepancy.residual_norm**2 == pytest.approx(m * sigma**2, rel=1e-8)


def test_lcurve_corner_matches_finite_differences_of_brute_force_curve(rng):
    matrix, y, _ = synthetic_problem(rng, noise=0.05)
    grid = np.geomspace(1e-7, 1e2, 181)
    _, residuals, seminorms = brute_force(matrix, y, 6, grid)
    t, x, z = np.log(grid), np.log(residuals), np.log(seminorms)
    xt, zt = np.gradient(x, t), np.gradient(z, t)
    curvature = (xt * np.gradient(zt, t) - np.gradient(xt, t) * zt) / (xt**2 + zt**2) ** 1.5
    interior = [i for i in range(2, len(grid) - 2)
                if curvature[i] > curvature[i - 1] and curvature[i] >= curvature[i + 1]]
    corner = grid[max(interior, key=lambda i: curvature[i])]
    result = reconstruct(matrix, y, 6, rule="lcurve", lambdas=grid)
    assert np.allclose(result.criterion[5:-5], curvature[5:-5], rtol=2e-2, atol=1e-3)
    assert abs(np.log(result.lam / corner)) < 2 * (t[1] - t[0])


def test_lsqr_sweep_chooses_the_same_lambdas_as_the_closed_forms(rng):
    # lsqr picks on the grid (GCV's trace by a 4-probe Hutchinson estimate), the
    # svd route refines between grid points: they must agree to about a grid step.
    matrix, y, truth = synthetic_problem(rng, rows=200)
    grid = np.geomspace(1e-8, 1e1, 40)
    step = np.log(grid[1] / grid[0])
    kwargs = dict(truth=truth, sigma=0.02, lambdas=grid)
    svd = reconstruct_rules(matrix, y, 6, method="svd", **kwargs)
    lsqr = reconstruct_rules(matrix, y, 6, method="lsqr", **kwargs)
    for exact, iterative in zip(svd, lsqr):
        allowed = 3 * step if exact.rule == "gcv" else 1.01 * step
        assert abs(np.log(iterative.lam / exact.lam)) <= allowed, exact.rule
        assert iterative.method == "lsqr" and np.all(np.isfinite(iterative.image))
