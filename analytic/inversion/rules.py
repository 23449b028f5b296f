"""How λ is chosen: oracle, GCV, L-curve and discrepancy, on the SVD route's closed forms or on an LSQR sweep.

Every rule sweeps a grid of λ (default: :func:`default_grid`; a caller may
give its own, the command line through ``--lambda-range MIN MAX`` and
``--lambda-count``) and picks one by its criterion:

- ``oracle``: the squared image error ||f_λ − f||² (needs the true image;
  a bound, not a method);
- ``gcv``: generalised cross-validation ||r_λ||² / trace(I − H_λ)² over the
  rows of A that see the plane. Rows that see nothing carry no information
  about f, and a render leaves them exactly 0: counted, they let the
  residual vanish while the trace does not, and GCV collapses to the
  smallest λ of any grid;
- ``lcurve``: the corner (largest interior curvature) of
  (log ||r_λ||, log ||D f_λ||);
- ``discrepancy``: Morozov's ||r_λ||² = m σ² (needs σ).

On the SVD route the criteria are closed forms in λ and the optimum is
refined between grid points; on the LSQR route they are evaluated at the
grid's solutions.
"""

from __future__ import annotations

import numpy as np
import scipy.optimize

from .laplacian import dct2
from .result import RegularizationWarning, record_warning

__all__ = ["RULES", "DEFAULT_LAMBDA_COUNT", "default_grid", "lambda_grid", "curvature",
           "sampled_curvature", "corner", "edge_warning", "discrepancy_bracket", "choose_spectral",
           "choose_iterative"]

RULES = ("oracle", "gcv", "lcurve", "discrepancy")
DEFAULT_LAMBDA_COUNT = 40
_REFINE_STEPS = 64  # dense sub-grid between neighbouring λ for the closed-form criteria


def default_grid(largest: float, smallest: float, count: int = DEFAULT_LAMBDA_COUNT) -> np.ndarray:
    """λ log-spaced over the squared singular values of the standard-form operator.

    The smallest singular value is floored at 1e-7 of the largest, so that
    the grid stays useful on numerically singular problems; the range is
    widened 100-fold at each end so that λ ≫ s_max² (the mean only) and
    λ ≪ s_min² are both reachable.

    Parameters
    ----------
    largest, smallest : float
        Largest and smallest non-zero singular values s of the operator
        (``largest`` 0 when the operator is 0: a grid around 1).
    count : int
        Number of λ values.
    """
    if not largest > 0:         # the data see only the image's mean: λ changes nothing
        largest = 1.0
    low = max(smallest, 1e-7 * largest)
    if not low > 0:
        low = 1e-7 * largest
    return np.geomspace(1e-2 * low**2, 1e2 * largest**2, count)


def lambda_grid(minimum: float, maximum: float, count: int) -> np.ndarray:
    """``count`` λ log-spaced over [minimum, maximum]; ValueError naming the bad one.

    Parameters
    ----------
    minimum, maximum : float
        Ends of the grid, 0 < minimum <= maximum, units of λ.
    count : int
        Values, >= 1 (1 needs minimum = maximum).
    """
    if not (np.isfinite(minimum) and np.isfinite(maximum) and 0 < minimum <= maximum):
        raise ValueError(f"lambda range: need 0 < MIN <= MAX, both finite, got {minimum!r}, {maximum!r}")
    if isinstance(count, bool) or int(count) != count or count < 1 or count > 10_000:
        raise ValueError(f"lambda count: need a whole number in [1, 10000], got {count!r}")
    if count == 1 and minimum != maximum:
        raise ValueError("lambda count: 1 value needs MIN = MAX")
    return np.geomspace(minimum, maximum, int(count))


def curvature(xt, yt, xtt, ytt):
    """Signed curvature of a parametric curve from its first and second derivatives.

    Positive where the L-curve turns its corner (x grows, y falls, the curve
    bends towards the origin): κ = (x' y'' − x'' y') / (x'² + y'²)^{3/2}.
    """
    denominator = np.maximum((xt**2 + yt**2) ** 1.5, np.finfo(float).tiny)
    return (xt * ytt - xtt * yt) / denominator


def sampled_curvature(t, x, y):
    """:func:`curvature` of a curve sampled at parameters ``t``, by finite differences."""
    xt = np.gradient(x, t)
    yt = np.gradient(y, t)
    return curvature(xt, yt, np.gradient(xt, t), np.gradient(yt, t))


def corner(values):
    """Index of the L-curve's corner in a sampled curvature.

    The highest interior local maximum (the ends of a sampled L-curve can
    show spurious bends where the residual or the seminorm saturates); the
    global maximum if there is none.
    """
    inner = np.nonzero((values[1:-1] > values[:-2]) & (values[1:-1] >= values[2:])
                       & (values[1:-1] > 0))[0] + 1
    if inner.size:
        return int(inner[np.argmax(values[inner])])
    return int(np.argmax(values))


def edge_warning(index: int, size: int, rule: str, messages: list) -> None:
    """Warn when a rule's optimum sits at an end of the λ grid."""
    if size > 1 and index in (0, size - 1):
        end = "smallest" if index == 0 else "largest"
        record_warning(messages, f"the {rule} optimum is at the {end} λ of the grid; widen the grid "
                                 f"(`lambdas`; on the command line --lambda-range MIN MAX)",
                       RegularizationWarning)


def discrepancy_bracket(criterion, messages: list) -> tuple[int, int]:
    """Grid indices (i − 1, i) between which ||r||² − m σ² changes sign.

    The residual grows with λ. When it stays on one side over the whole
    grid, a warning is issued and the bracket collapses onto the nearer
    end: (0, 0) or (last, last).
    """
    above = np.nonzero(criterion >= 0)[0]
    last = len(criterion) - 1
    if above.size == 0:
        record_warning(messages, "discrepancy: the residual stays below m σ² over the whole λ grid "
                                 "(noise overestimated?); taking the largest λ", RegularizationWarning)
        return last, last
    first = int(above[0])
    if first == 0:
        record_warning(messages, "discrepancy: the residual exceeds m σ² even at the smallest λ "
                                 "(noise underestimated, or the data are inconsistent with A); "
                                 "taking the smallest λ", RegularizationWarning)
        return 0, 0
    return first - 1, first


def choose_spectral(solver, rule, fixed, truth, sigma, grid, messages):
    """λ and the solution on the SVD route.

    Returns
    -------
    tuple
        (image, λ, grid, criterion at the grid, squared residuals, squared
        seminorms), in the scaled problem's units.
    """
    residuals = solver.squared_residual(grid)
    seminorms = solver.squared_seminorm(grid)
    if fixed is not None:
        return solver.image(fixed), fixed, grid, np.full(grid.shape, np.nan), residuals, seminorms
    log_grid = np.log(grid)
    if rule == "discrepancy":
        target = solver.measurements * float(sigma) ** 2
        criterion = residuals - target
        lower, upper = discrepancy_bracket(criterion, messages)
        if lower == upper:
            lam = float(grid[lower])
        else:
            root = scipy.optimize.brentq(lambda t: float(solver.squared_residual(np.exp(t))) - target,
                                         log_grid[lower], log_grid[upper], xtol=1e-10)
            lam = float(np.exp(root))
        return solver.image(lam), lam, grid, criterion, residuals, seminorms
    if rule == "oracle":
        truth_coefficients = dct2(truth).ravel()

        def objective(lam):
            return solver.squared_error(lam, truth_coefficients)
    elif rule == "gcv":
        objective = solver.gcv
    else:
        def objective(lam):
            return -solver.curvature(lam)
    criterion = objective(grid)
    if rule == "lcurve":
        criterion = -criterion
        # curvature is sharply peaked: search a dense sub-grid, not only the given one
        fine = np.linspace(log_grid[0], log_grid[-1], _REFINE_STEPS * max(len(grid) - 1, 1) + 1)
        best = corner(-objective(np.exp(fine)))
        edge_warning(0 if best == 0 else len(grid) - 1 if best == len(fine) - 1 else -1,
                     len(grid), rule, messages)
        lower, upper = fine[max(best - 1, 0)], fine[min(best + 1, len(fine) - 1)]
    else:
        best = int(np.argmin(criterion))
        edge_warning(best, len(grid), rule, messages)
        lower, upper = log_grid[max(best - 1, 0)], log_grid[min(best + 1, len(grid) - 1)]
    if upper > lower:
        found = scipy.optimize.minimize_scalar(lambda t: float(np.ravel(objective(np.exp(t)))[0]),
                                               bounds=(lower, upper), method="bounded",
                                               options={"xatol": 1e-6})
        lam = float(np.exp(found.x))
    else:
        lam = float(np.exp(lower))
    return solver.image(lam), lam, grid, criterion, residuals, seminorms


def choose_iterative(solver, rule, fixed, truth, sigma, grid, messages, probes, search=False):
    """λ and the solution on the LSQR route; returns as :func:`choose_spectral`.

    With ``search`` (the default grid: no grid was asked for), the discrepancy rule searches its crossing
    between the grid's ends instead of sweeping the grid (:meth:`.iterative.IterativeSolver.discrepancy_search`);
    the result's grid is then the λ it solved.
    """
    if fixed is not None:
        solution, _ = solver.solve(fixed)
        if len(grid) == 1:
            residuals = np.array([solver.squared_residual_of(solution)])
            seminorms = np.array([solver.squared_seminorm_of(solution)])
        else:
            solutions, _, _ = solver.sweep(grid)
            residuals = np.array([solver.squared_residual_of(s) for s in solutions])
            seminorms = np.array([solver.squared_seminorm_of(s) for s in solutions])
        return solver.to_image(solution), fixed, grid, np.full(grid.shape, np.nan), residuals, seminorms
    # the residual grows with λ: the discrepancy rule's sweep ends where it crosses m σ² (NaN below)
    target = solver.measurements * float(sigma) ** 2 if rule == "discrepancy" else None
    if rule == "discrepancy" and search:
        return _searched_discrepancy(solver, float(sigma), target, grid, messages)
    solutions, traces, failed = solver.sweep(grid, probes=probes if rule == "gcv" else 0, until=target)
    if failed:
        record_warning(messages, f"lsqr stopped at its iteration limit for {failed} of {len(grid)} λ",
                       RegularizationWarning)
    residuals = np.array([solver.squared_residual_of(s) for s in solutions])
    seminorms = np.array([solver.squared_seminorm_of(s) for s in solutions])
    log_grid = np.log(grid)
    if rule == "discrepancy":
        criterion = residuals - target
        lower, upper = discrepancy_bracket(criterion, messages)
        if lower == upper:
            return (solver.to_image(solutions[lower]), float(grid[lower]), grid, criterion, residuals,
                    seminorms)
        # interpolate the log residual linearly in log λ, then solve there
        x0, x1 = np.log(residuals[lower]), np.log(residuals[upper])
        fraction = (np.log(target) - x0) / (x1 - x0) if x1 > x0 else 0.0
        lam = float(np.exp(log_grid[lower] + fraction * (log_grid[upper] - log_grid[lower])))
        solution, _ = solver.solve(lam, start=solutions[upper])
        return solver.to_image(solution), lam, grid, criterion, residuals, seminorms
    if rule == "oracle":
        truth_coefficients = dct2(truth).ravel()
        criterion = np.array([np.sum((solver.scale * s - truth_coefficients) ** 2) for s in solutions])
    elif rule == "gcv":
        live_residuals = np.array([solver.squared_residual_of(s, live_only=True) for s in solutions])
        criterion = live_residuals / np.maximum(traces, np.finfo(float).tiny) ** 2
    else:
        criterion = sampled_curvature(log_grid, np.log(residuals),
                                      np.log(np.maximum(seminorms, np.finfo(float).tiny)))
    best = corner(criterion) if rule == "lcurve" else int(np.argmin(criterion))
    edge_warning(best, len(grid), rule, messages)
    return solver.to_image(solutions[best]), float(grid[best]), grid, criterion, residuals, seminorms


def _searched_discrepancy(solver, sigma, target, grid, messages):
    """:func:`choose_iterative`'s discrepancy rule by the search (its λ solved as the grid)."""
    from .iterative import CROSSING_FRACTION

    lambdas, solutions, index, failed = solver.discrepancy_search(float(grid[0]), float(grid[-1]), target)
    if failed:
        record_warning(messages, f"lsqr stopped at its iteration limit for {failed} of {len(lambdas)} λ",
                       RegularizationWarning)
    residuals = np.array([solver.squared_residual_of(s) for s in solutions])
    seminorms = np.array([solver.squared_seminorm_of(s) for s in solutions])
    criterion = residuals - target
    slack = CROSSING_FRACTION * sigma**2 * np.sqrt(2.0 * solver.measurements)
    if abs(criterion[index]) > slack:
        lower, upper = discrepancy_bracket(criterion, messages)     # warns when it stays on one side
        if lower != upper:
            record_warning(messages, f"discrepancy: the search stopped after {len(lambdas)} solves with "
                                     f"‖A f − y‖² / m σ² = {residuals[index] / target:.6g}, not within "
                                     f"{CROSSING_FRACTION:g} σ² √(2m) of m σ²", RegularizationWarning)
    return (solver.to_image(solutions[index]), float(lambdas[index]), lambdas, criterion, residuals, seminorms)
