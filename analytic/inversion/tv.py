"""Total-variation regularised reconstruction (beyond the paper).

    f_λ = argmin_f ½ ||A f - y||² + λ TV(f),

TV the isotropic total variation with forward differences and reflecting
(Neumann) edges, solved by the diagonally preconditioned Chambolle–Pock
primal-dual method. It keeps edges that the Laplacian smooths away; it is
nonlinear, so only the ``oracle``, ``discrepancy`` and numeric rules apply.
"""

from __future__ import annotations

import time

import numpy as np

from .information import (DEFAULT_MEMORY_LIMIT, count_above_noise, information_warning, numerical_rank,
                          singular_values_of, unseen_pixels_warning)
from .result import Problem, Reconstruction, RegularizationWarning, parse_rule, record_warning
from .rules import edge_warning

__all__ = ["reconstruct_tv", "total_variation", "TV_RULES"]


TV_RULES = ("oracle", "discrepancy")
_TV_WINDOW = 100  # iterations between convergence checks


def _gradient(image):
    """Forward differences, zero across the far edges (Neumann): (2, M, M)."""
    gradient = np.zeros((2,) + image.shape)
    gradient[0, :-1, :] = image[1:, :] - image[:-1, :]
    gradient[1, :, :-1] = image[:, 1:] - image[:, :-1]
    return gradient


def _divergence(field):
    """Minus the adjoint of :func:`_gradient`: ⟨∇f, p⟩ = -⟨f, div p⟩."""
    rows, columns = field[0], field[1]
    divergence = np.zeros(rows.shape)
    divergence[:-1, :] += rows[:-1, :]
    divergence[1:, :] -= rows[:-1, :]
    divergence[:, :-1] += columns[:, :-1]
    divergence[:, 1:] -= columns[:, :-1]
    return divergence


def total_variation(image) -> float:
    """Isotropic TV: Σ sqrt((∂_r f)² + (∂_c f)²), forward differences, Neumann edges."""
    gradient = _gradient(np.asarray(image, dtype=np.float64))
    return float(np.sum(np.sqrt(gradient[0] ** 2 + gradient[1] ** 2)))


def _tv_solve(matrix, y, pixels, lam, steps, start=None, *, iterations, tolerance):
    """Diagonally preconditioned Chambolle–Pock (PDHG) for ½||A f - y||² + λ TV(f).

    K = [A; ∇]; steps (Pock and Chambolle 2011, α = 1): τ_j = 1 / Σ_i |K_ij|
    per pixel, σ_i = 1 / Σ_j |K_ij| per row (1/2 for the gradient rows).
    The data term's conjugate has prox p = (v - σ y) / (1 + σ); the TV
    term's conjugate is the indicator of {|q_ij| ≤ λ}, whose prox is a
    pointwise projection.
    """
    tau, sigma_data = steps
    sigma_gradient = 0.5
    shape = (pixels, pixels)
    f = np.zeros(pixels * pixels) if start is None else start[0].copy()
    p = np.zeros(y.size) if start is None else start[1].copy()
    q = np.zeros((2,) + shape) if start is None else start[2].copy()
    bar = f.copy()

    def objective(x):
        r = matrix @ x - y
        return 0.5 * float(r @ r) + lam * total_variation(x.reshape(shape))

    last = objective(f)
    for iteration in range(iterations):
        p = (p + sigma_data * (matrix @ bar - y)) / (1.0 + sigma_data)
        q = q + sigma_gradient * _gradient(bar.reshape(shape))
        magnitude = np.sqrt(q[0] ** 2 + q[1] ** 2)
        q = q / np.maximum(1.0, magnitude / lam)
        previous = f
        f = f - tau * (matrix.T @ p - _divergence(q).ravel())
        bar = 2.0 * f - previous
        if (iteration + 1) % _TV_WINDOW == 0:
            # PDHG's objective creeps down slowly near the optimum: stop when a
            # whole window of iterations changes it by less than `tolerance`
            current = objective(f)
            if abs(last - current) <= tolerance * max(abs(current), 1e-300):
                break
            last = current
    return f, p, q, iteration + 1


def _tv_steps(matrix, pixels):
    absolute = abs(matrix)
    rows = np.asarray(absolute.sum(axis=1)).ravel()
    columns = np.asarray(absolute.sum(axis=0)).ravel()
    # each pixel enters up to 4 forward differences with coefficient ±1
    neighbours = np.full((pixels, pixels), 4.0)
    neighbours[0, :] -= 1
    neighbours[-1, :] -= 1
    neighbours[:, 0] -= 1
    neighbours[:, -1] -= 1
    tau = 1.0 / (columns + neighbours.ravel())
    sigma = np.where(rows > 0, 1.0 / np.where(rows > 0, rows, 1.0), 0.0)  # dead rows: p stays 0
    return tau, sigma


def reconstruct_tv(matrix, data, pixels: int, *, rule: str | float = "oracle", truth=None,
                   sigma: float | None = None, lambdas=None, iterations: int = 5000,
                   tolerance: float = 1e-5) -> Reconstruction:
    """Total-variation regularised reconstruction (beyond the paper).

    f_λ = argmin_f ½ ||A f - y||² + λ TV(f), TV the isotropic total variation
    with forward differences and reflecting (Neumann) edges, solved by the
    Chambolle–Pock primal-dual algorithm (Chambolle and Pock 2011,
    Algorithm 1) on the operator [A; ∇] with the diagonal step sizes of
    Pock and Chambolle (ICCV 2011). It keeps edges that the
    Laplacian smooths away; it is nonlinear, so only the ``oracle``,
    ``discrepancy`` and numeric rules apply (GCV and the L-curve's closed
    forms do not).

    Parameters
    ----------
    matrix, data, pixels, truth, sigma
        As :func:`.tikhonov.reconstruct`.
    rule : {"oracle", "discrepancy"} or float
        λ rule, or λ itself (units of y² per unit of TV).
    lambdas : array_like, optional
        Grid swept from large to small λ with warm starts. Default: 12
        values log-spaced over [1e-4, 1] x ||Aᵀ y||_∞ (at ||Aᵀ y||_∞ the
        answer is already nearly constant).
    iterations : int
        PDHG iterations per λ at most.
    tolerance : float
        Stop when 100 iterations change the objective by less than
        ``tolerance`` relative; an unconverged solve is reported by a
        RegularizationWarning.

    Returns
    -------
    Reconstruction
        ``method = "pdhg"``, ``seminorms`` hold TV(f_λ), ``rank`` and
        ``effective_rank`` from A's singular values when ``sigma`` is given
        (else None), ``degrees_of_freedom`` None (the fit is nonlinear);
        ``criterion`` as in :func:`reconstruct`. For ``discrepancy`` the
        largest grid λ with ||A f - y||² ≤ m σ² is taken (no root refinement).
    """
    started = time.perf_counter()
    problem = Problem.checked(matrix, data, pixels)
    matrix, y, pixels = problem.matrix, problem.y, problem.pixels
    # scaled problem: ½||A'g - y'||² + λ' TV(g) with f = (c/a) g and λ' = λ / (a c)
    to_caller = problem.matrix_scale * problem.data_scale
    fixed = parse_rule(rule, TV_RULES)
    if rule == "oracle":
        if truth is None:
            raise ValueError("truth: the oracle rule needs the true image")
        truth = np.asarray(truth, dtype=np.float64)
        if truth.shape != (pixels, pixels):
            raise ValueError(f"truth: shape {truth.shape}, expected ({pixels}, {pixels})")
        truth = truth / problem.image_scale
    if rule == "discrepancy" and sigma is None:
        raise ValueError(f"sigma: the discrepancy rule needs a noise level > 0, got {sigma!r}")
    if sigma is not None and not (np.isfinite(float(sigma)) and float(sigma) > 0):
        raise ValueError(f"sigma: the noise level must be finite and > 0, got {sigma!r}")
    if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 1:
        raise ValueError(f"iterations: must be a whole number >= 1, got {iterations!r}")
    steps = _tv_steps(matrix, pixels)
    if fixed is not None:
        grid = np.array([fixed / to_caller])
    elif lambdas is None:
        top = float(np.max(np.abs(matrix.T @ y)))
        grid = np.geomspace(1e-4 * top, top, 12)
    else:
        grid = np.sort(np.asarray(lambdas, dtype=np.float64).ravel())
        if grid.size < 1 or not np.all(np.isfinite(grid)) or np.any(grid <= 0):
            raise ValueError("lambdas: expected finite values > 0")
        grid = grid / to_caller
    messages: list[str] = []
    # what the data fix (module .information): A's singular values, when σ is given and A fits in memory
    values = None if sigma is None else singular_values_of(problem, DEFAULT_MEMORY_LIMIT)
    rank = None if values is None else numerical_rank(values, y.size, pixels * pixels)
    effective = None if values is None else count_above_noise(values * problem.matrix_scale, float(sigma))
    for notice in (information_warning(rank=rank, effective_rank=effective, live_rows=int(problem.live.sum()),
                                       unknowns=pixels * pixels, sigma=sigma), unseen_pixels_warning(problem)):
        if notice is not None:
            record_warning(messages, *notice)
    images = np.empty((grid.size, pixels * pixels))
    residuals = np.empty(grid.size)
    variations = np.empty(grid.size)
    start = None
    unconverged = 0
    for index in range(grid.size - 1, -1, -1):  # large λ first: smooth, then warm starts
        f, p, q, used = _tv_solve(matrix, y, pixels, grid[index], steps, start,
                                  iterations=int(iterations), tolerance=tolerance)
        unconverged += used >= iterations
        start = (f, p, q)
        images[index] = f
        residuals[index] = float(np.sum((matrix @ f - y) ** 2))
        variations[index] = total_variation(f.reshape(pixels, pixels))
    if unconverged:
        record_warning(messages, f"TV: {unconverged} of {grid.size} solves stopped at {iterations} "
                        f"iterations before 100 iterations changed the objective by less than "
                        f"{tolerance:g} (relative)",
              RegularizationWarning)
    if fixed is not None:
        best = 0
        criterion = np.full(1, np.nan)
    elif rule == "oracle":
        criterion = np.sum((images - truth.ravel()) ** 2, axis=1)
        best = int(np.argmin(criterion))
        edge_warning(best, grid.size, "oracle", messages)
    else:
        criterion = residuals - y.size * (float(sigma) / problem.data_scale) ** 2
        below = np.nonzero(criterion <= 0)[0]
        if below.size == 0:
            record_warning(messages, "discrepancy: the residual exceeds m σ² at every λ; taking the "
                            "smallest", RegularizationWarning)
            best = 0
        else:
            best = int(below[-1])
            if best == grid.size - 1:
                record_warning(messages, "discrepancy: the residual stays below m σ² over the whole λ "
                                "grid; taking the largest", RegularizationWarning)
    image = images[best].reshape(pixels, pixels)
    # back to the caller's units: f = (c/a) g, λ = a c λ', r = c r', TV(f) = (c/a) TV(g)
    c, scale = problem.data_scale, problem.image_scale
    criterion_scale = 1.0 if fixed is not None else scale**2 if rule == "oracle" else c**2
    return Reconstruction(
        image=scale * image, lam=float(grid[best]) * to_caller,
        rule=rule if fixed is None else "value", lambdas=grid * to_caller,
        criterion=criterion * criterion_scale, residual_norms=c * np.sqrt(residuals),
        seminorms=scale * variations, residual_norm=c * float(np.sqrt(residuals[best])),
        seminorm=scale * float(variations[best]), method="pdhg", rank=rank, effective_rank=effective,
        sigma=None if sigma is None else float(sigma),
        unknowns=pixels * pixels, measurements=y.size, seconds=time.perf_counter() - started,
        warnings=tuple(messages))
