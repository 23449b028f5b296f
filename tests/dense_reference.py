"""Independent references for the reconstruction tests: dense least squares in pixel variables.

The Laplacian is written out pixel by pixel, and every solution comes from
numpy.linalg.lstsq on the stacked system [A; √λ D] (no DCT, no SVD of ours).
"""

import numpy as np


def stencil_laplacian(pixels):
    """D written out pixel by pixel: reflecting ghost pixels equal their mirror."""
    size = pixels * pixels
    matrix = np.zeros((size, size))
    for r in range(pixels):
        for c in range(pixels):
            p = r * pixels + c
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                rr, cc = r + dr, c + dc
                if 0 <= rr < pixels and 0 <= cc < pixels:
                    matrix[p, rr * pixels + cc] += 1.0
                else:
                    matrix[p, p] += 1.0  # ghost pixel = the pixel itself
                matrix[p, p] -= 1.0
    return matrix


def dense_solution(matrix, y, pixels, lam):
    """Independent reference: lstsq on the stacked [A; √λ D] in pixel variables."""
    stacked = np.vstack([matrix, np.sqrt(lam) * stencil_laplacian(pixels)])
    rhs = np.concatenate([y, np.zeros(pixels * pixels)])
    return np.linalg.lstsq(stacked, rhs, rcond=None)[0]


def synthetic_problem(rng, *, pixels=6, rows=60, decay=1e-3, noise=0.02):
    """A dense A with known singular values (geometric from 1 to ``decay``) and noisy data."""
    n = pixels * pixels
    k = min(rows, n)
    u, _ = np.linalg.qr(rng.standard_normal((rows, k)))
    v, _ = np.linalg.qr(rng.standard_normal((n, k)))
    matrix = u @ np.diag(np.geomspace(1.0, decay, k)) @ v.T
    x, yy = np.meshgrid(np.linspace(0, 1, pixels), np.linspace(0, 1, pixels))
    truth = 0.5 + 0.3 * np.sin(2 * x) * np.cos(3 * yy)
    y = matrix @ truth.ravel() + noise * rng.standard_normal(rows)
    return matrix, y, truth


def brute_force(matrix, y, pixels, grid):
    solutions = np.array([dense_solution(matrix, y, pixels, lam) for lam in grid])
    residuals = np.sum((solutions @ matrix.T - y) ** 2, axis=1)
    stencil = stencil_laplacian(pixels)
    seminorms = np.sum((solutions @ stencil.T) ** 2, axis=1)
    return solutions, residuals, seminorms

