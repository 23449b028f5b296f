"""Total variation: the optimum of an independent conic solve; edges kept."""

import numpy as np
import pytest

from analytic.inversion import reconstruct


def test_tv_solver_reaches_the_optimum_of_an_independent_conic_solve(rng):
    # Reference: the same convex problem in epigraph form, ½||A f - y||² + λ Σ t
    # with t ≥ |∇f| per pixel, solved by SciPy's SLSQP (no code shared); SLSQP
    # stalls slightly above the optimum on the cone's kink, so PDHG must be at
    # least as low, and its optimality is then proved by a dual certificate.
    from scipy.optimize import minimize

    from analytic.inversion.tv import (
        _divergence,
        _gradient,
        _tv_solve,
        _tv_steps,
        reconstruct_tv,
        total_variation,
    )

    pixels, lam = 4, 0.05
    n = pixels * pixels
    matrix = rng.random((24, n))
    truth = np.zeros((pixels, pixels))
    truth[:, 2:] = 1.0
    y = matrix @ truth.ravel() + 0.05 * rng.standard_normal(24)
    # forward differences written out: rows then columns, zero across the far edges
    down, right = np.zeros((n, n)), np.zeros((n, n))
    for r in range(pixels):
        for c in range(pixels):
            p = r * pixels + c
            if r + 1 < pixels:
                down[p, p], down[p, p + pixels] = -1.0, 1.0
            if c + 1 < pixels:
                right[p, p], right[p, p + 1] = -1.0, 1.0

    def objective(v):
        return 0.5 * np.sum((matrix @ v[:n] - y) ** 2) + lam * np.sum(v[n:])

    def objective_gradient(v):
        return np.concatenate([matrix.T @ (matrix @ v[:n] - y), np.full(n, lam)])

    def cone(v):  # t² - |∇f|² ≥ 0 with t ≥ 0 is the second-order cone
        return v[n:] ** 2 - (down @ v[:n]) ** 2 - (right @ v[:n]) ** 2

    def cone_jacobian(v):
        gx, gy = down @ v[:n], right @ v[:n]
        return np.hstack([-2 * gx[:, None] * down - 2 * gy[:, None] * right, np.diag(2 * v[n:])])

    start = np.concatenate([np.full(n, 0.5), np.ones(n)])
    reference = minimize(objective, start, jac=objective_gradient, method="SLSQP",
                         constraints=[{"type": "ineq", "fun": cone, "jac": cone_jacobian},
                                      {"type": "ineq", "fun": lambda v: v[n:],
                                       "jac": lambda v: np.hstack([np.zeros((n, n)), np.eye(n)])}],
                         options={"ftol": 1e-14, "maxiter": 1000})
    result = reconstruct_tv(matrix, y, pixels, rule=lam, iterations=50000, tolerance=1e-12)

    def primal(image):
        return 0.5 * np.sum((matrix @ image.ravel() - y) ** 2) + lam * total_variation(image)
    assert primal(result.image) <= reference.fun + 1e-9
    # and it is optimal: a dual certificate q with |q| ≤ λ, Aᵀ(A f - y) = div q and
    # ⟨q, ∇f⟩ = λ TV(f) proves it for this convex problem, whoever computed q
    f, _, q, _ = _tv_solve(matrix, y, pixels, lam, _tv_steps(matrix, pixels), iterations=50000,
                           tolerance=1e-13)
    assert np.max(np.hypot(q[0], q[1])) <= lam * (1 + 1e-12)
    assert np.allclose(matrix.T @ (matrix @ f - y), _divergence(q).ravel(), atol=1e-8)
    assert np.sum(q * _gradient(f.reshape(pixels, pixels))) == pytest.approx(
        lam * total_variation(f.reshape(pixels, pixels)), rel=1e-8)
    assert np.allclose(f, result.image.ravel(), atol=1e-6)
    image, field = rng.random((pixels, pixels)), rng.random((2, pixels, pixels))
    assert np.sum(_gradient(image) * field) == pytest.approx(-np.sum(image * _divergence(field)))


def test_tv_keeps_edges_that_the_laplacian_blurs(rng):
    # Piecewise-constant image, underdetermined noisy data: TV's oracle error is
    # below the Laplacian's (its prior matches the image).
    pixels = 12
    truth = np.zeros((pixels, pixels))
    truth[3:9, 4:10] = 1.0
    matrix = rng.standard_normal((100, pixels * pixels)) / 10
    y = matrix @ truth.ravel() + 0.02 * rng.standard_normal(100)
    smooth = reconstruct(matrix, y, pixels, rule="oracle", truth=truth)
    edges = reconstruct(matrix, y, pixels, rule="oracle", truth=truth, regularizer="tv")
    assert edges.method == "pdhg"
    assert np.sum((edges.image - truth) ** 2) < 0.5 * np.sum((smooth.image - truth) ** 2)
    with pytest.raises(ValueError, match="rule"):
        reconstruct(matrix, y, pixels, rule="gcv", regularizer="tv")
