"""Image recovery: Laplacian-regularised least squares with a λ rule (paper Sections IV, VI).

    f_λ = argmin_f ||A f - y||² + λ ||D f||²,

D the 5-point discrete Laplacian with reflecting (Neumann) boundaries
(:mod:`.laplacian`). D's null space is the constant images and
A · 1 ≠ 0 for any scene whose sensors see the plane, so the problem has a
unique solution for every λ > 0 even when A itself is rank-deficient.

Two solvers, neither forms AᵀA (which would square the condition number):

``"svd"`` (exact; small and medium problems)
    Write f = C c with C the orthonormal inverse 2-D DCT-II, which
    diagonalises D: ||D f||² = Σ μ_ij² c_ij². The constant coefficient c_00
    is not penalised and is eliminated by projecting the data orthogonally
    to A · (constant image); the other coefficients are scaled, z = μ c, to
    give a standard-form problem ||P (B z - y)||² + λ ||z||² with
    B = A C diag(1/μ). One thin SVD of the dense P B (zero rows of A
    dropped) then gives, for every λ in closed form, the solution, the
    residual, the seminorm, GCV's trace and the L-curve's curvature
    (filter factors φ_i = s_i² / (s_i² + λ), all bounded for λ > 0).
``"lsqr"`` (large problems, matrix-free)
    :func:`scipy.sparse.linalg.lsqr` on the stacked system
    [A C S; √λ W] v = [y; 0] in the same variables v = (c_00, z), where
    S = diag(1, 1/μ) and W zeroes c_00: the operator is applied with sparse
    A and fast DCTs, never densified, and the DCT scaling makes it far better
    conditioned than [A; √λ D] in pixel variables (the same minimiser).
    The λ sweep runs from large λ to small with warm starts. GCV's trace is
    then estimated by Hutchinson's method (fixed-seed Rademacher probes).
    With σ known each solve stops by the noise, and the discrepancy rule's
    sweep ends where the residual crosses m σ² (:mod:`.iterative`).

``method="auto"`` takes ``"svd"`` when its dense matrices fit
``memory_limit`` and ``"lsqr"`` otherwise.

λ is chosen by a rule of :mod:`.rules`. Beyond the paper,
``regularizer="tv"`` hands over to :func:`.tv.reconstruct_tv`.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse

from ..errors import ResourceError
from .iterative import IterativeSolver
from .information import (DEFAULT_MEMORY_LIMIT, count_above_noise, degrees_of_freedom, information_warning,
                          numerical_rank, singular_values_of, unseen_pixels_warning)
from .laplacian import dct2, idct2, laplacian_eigenvalues
from .result import (Problem, RankDeficiencyWarning, Reconstruction, RegularizationWarning, parse_rule,
                     record_warning)
from .rules import RULES, choose_iterative, choose_spectral, curvature, default_grid

__all__ = ["reconstruct", "reconstruct_rules", "METHODS", "DEFAULT_MEMORY_LIMIT"]

METHODS = ("auto", "svd", "lsqr")
DEFAULT_GCV_PROBES = 4


class SpectralSolver:
    """Closed-form Tikhonov solutions of the DCT-transformed, projected problem."""

    def __init__(self, problem: Problem):
        matrix, y, pixels = problem.matrix, problem.y, problem.pixels
        dense = (matrix.toarray() if scipy.sparse.issparse(matrix) or hasattr(matrix, "toarray")    # or an operator's
                 else np.array(matrix, dtype=np.float64))
        self.pixels = pixels
        self.measurements = dense.shape[0]
        live = problem.live
        self.live_count = int(live.sum())
        # rows that see nothing carry only noise: a constant in the residual
        self.dead_residual = float(np.sum(y[~live] ** 2))
        rows = dense[live].reshape(-1, pixels, pixels)
        transformed = dct2(rows).reshape(rows.shape[0], -1)  # A C, one row at a time
        del rows, dense
        mu = laplacian_eigenvalues(pixels).ravel()
        self.mu = mu[1:]
        constant = transformed[:, 0]
        self.constant_norm = float(np.linalg.norm(constant))
        if self.constant_norm == 0.0:
            raise ValueError("matrix: A · (constant image) = 0, the sensors see no light from the "
                             "plane, so the Laplacian cannot fix the image's mean")
        self.q = constant / self.constant_norm
        scaled = transformed[:, 1:] / self.mu
        del transformed
        self.w = self.q @ scaled  # qᵀB, to recover c_00 from z
        scaled -= np.outer(self.q, self.w)  # P B
        y_live = y[live]
        self.qy = float(self.q @ y_live)
        projected = y_live - self.q * self.qy
        u, s, vt = np.linalg.svd(scaled, full_matrices=False)
        del scaled
        self.s = s
        self.vt = vt
        self.beta = u.T @ projected
        # the data's part outside range(P B), formed directly (no ||y||² - ||β||²
        # cancellation when the fit is nearly exact)
        outside = projected - u @ self.beta
        self.outside_live = float(outside @ outside)
        self.outside = self.outside_live + self.dead_residual
        tol = s[0] * max(self.measurements, pixels * pixels) * np.finfo(float).eps if s.size else 0.0
        # rank(A) = 1 (the constant) + rank(P B)
        self.rank = 1 + int(np.sum(s > tol))
        self.largest = float(s[0]) if s.size else 1.0
        positive = s[s > tol]
        self.smallest = float(positive[-1]) if positive.size else self.largest

    def filters(self, lam):
        lam = np.asarray(lam, dtype=np.float64)[..., None]
        return self.s**2 / (self.s**2 + lam)

    def squared_residual(self, lam):
        """||A f_λ - y||² over every row."""
        phi = self.filters(lam)
        return np.sum(((1.0 - phi) * self.beta) ** 2, axis=-1) + self.outside

    def squared_seminorm(self, lam):
        """||D f_λ||²."""
        lam = np.asarray(lam, dtype=np.float64)[..., None]
        return np.sum((self.s * self.beta / (self.s**2 + lam)) ** 2, axis=-1)

    def gcv(self, lam):
        """GCV over the live rows (see :mod:`.rules`): the dead rows' residual is left out."""
        phi = self.filters(lam)
        trace = self.live_count - 1.0 - np.sum(phi, axis=-1)
        live_residual = np.sum(((1.0 - phi) * self.beta) ** 2, axis=-1) + self.outside_live
        return live_residual / np.maximum(trace, np.finfo(float).tiny) ** 2

    def curvature(self, lam):
        lam = np.asarray(lam, dtype=np.float64)
        phi = self.filters(lam)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(self.s > 0, self.beta**2 / np.maximum(self.s, np.finfo(float).tiny) ** 2, 0.0)
        rho = self.squared_residual(lam)
        eta = np.sum(phi**2 * g, axis=-1)
        s1 = np.sum(phi**2 * (1 - phi) * g, axis=-1)
        s1t = -np.sum(phi**2 * (1 - phi) * (2 - 3 * phi) * g, axis=-1)
        # t = ln λ; dρ/dt = 2 λ S1, dη/dt = -2 S1 (closed-form derivatives)
        xt = 2 * lam * s1 / rho
        yt = -2 * s1 / eta
        rhot = 2 * lam * s1
        etat = -2 * s1
        xtt = 2 * lam * s1 / rho + 2 * lam * s1t / rho - 2 * lam * s1 * rhot / rho**2
        ytt = -2 * s1t / eta + 2 * s1 * etat / eta**2
        return curvature(xt, yt, xtt, ytt)

    def coefficients(self, lam):
        """DCT coefficients c (M²,) of f_λ; several λ give (len, M²)."""
        lam = np.atleast_1d(np.asarray(lam, dtype=np.float64))
        weights = (self.s * self.beta)[None, :] / (self.s[None, :] ** 2 + lam[:, None])
        z = weights @ self.vt
        c0 = (self.qy - z @ self.w) / self.constant_norm
        return np.concatenate([c0[:, None], z / self.mu], axis=1)

    def image(self, lam):
        return idct2(self.coefficients(lam)[0].reshape(self.pixels, self.pixels))

    def squared_error(self, lam, truth_coefficients):
        # C is orthonormal: ||f_λ - f||² = ||c_λ - c||²
        return np.sum((self.coefficients(lam) - truth_coefficients) ** 2, axis=1)


def reconstruct(matrix, data, pixels: int, *, rule: str | float = "gcv", truth=None,
                sigma: float | None = None, lambdas=None, method: str | None = None,
                memory_limit: int | None = None, gcv_probes: int | None = None,
                regularizer: str = "laplacian", progress: bool = False) -> Reconstruction:
    """Regularised reconstruction of the image from the samples.

    Parameters
    ----------
    matrix : scipy.sparse array or numpy.ndarray
        A, ``(K N, M²)``, row k N + n, column r M + c (``image.ravel()``), as
        from :func:`analytic.system_matrix`.
    data : array_like
        y, ``(K, N)`` or ``(K N,)`` samples, units of y.
    pixels : int
        Image side M.
    rule : str or float
        How λ is chosen (:mod:`.rules`): ``"oracle"`` (minimises
        ||f_λ - f_true||, needs ``truth``; the paper's choice), ``"gcv"``
        (generalised cross-validation over the rows that see the plane),
        ``"lcurve"`` (maximum curvature of the L-curve
        (log ||A f - y||, log ||D f||)), ``"discrepancy"`` (Morozov:
        ||A f - y||² = m σ², m = K N; needs ``sigma``), or a positive number
        used as λ itself.
    truth : array_like, optional
        ``(M, M)`` true image, for ``"oracle"``.
    sigma : float, optional
        Noise standard deviation per sample, units of y: needed by
        ``"discrepancy"``; with any rule it gives the result's
        ``effective_rank``, how many numbers of the image the data fix at
        that noise (:mod:`.information`).
    lambdas : array_like, optional
        λ grid to sweep (positive). Default: 40 values log-spaced over the
        squared singular values s² of the standard-form operator
        A C diag(1/μ) (s floored at 1e-7 s_max), widened by a factor 100 at
        both ends (:func:`.rules.default_grid`). With the svd method the
        rule's optimum is then refined between neighbouring grid values.
    method : {"auto", "svd", "lsqr"}, optional
        Laplacian only. Default ``"auto"``: ``"svd"`` when its dense
        matrices (about 3 m M² doubles) fit ``memory_limit``.
    memory_limit : int, optional
        Laplacian only: bytes the svd method may use (``"svd"`` beyond it
        is a ResourceError; ``"auto"`` then takes ``"lsqr"``). Default 2 GiB.
    gcv_probes : int, optional
        Laplacian only: Hutchinson probes for GCV's trace with the lsqr
        method. Default 4.
    regularizer : {"laplacian", "tv"}
        ``"tv"`` hands over to :func:`.tv.reconstruct_tv` (rules ``oracle``,
        ``discrepancy`` or a number); giving it ``method``,
        ``memory_limit`` or ``gcv_probes`` is an error, not ignored.
    progress : bool
        Laplacian, lsqr method: a progress bar on stderr over the λ solved
        (the command line shows it on a terminal).

    Returns
    -------
    Reconstruction

    Warns
    -----
    NoiseLimitWarning
        (a RankDeficiencyWarning) When, at ``sigma``, the data fix at most
        half of what A fixes without noise and at most half of what their
        measurements could (:func:`.information.information_warning`).
    RankDeficiencyWarning
        When A's numerical rank (singular values above s_max max(m, M²) ε;
        svd method, or any with ``sigma``) is at most half of
        min(measurements, M²): the measurements repeat one another; or when
        pixels are seen by no row. Fewer measurements than unknowns alone is
        the method (the Laplacian prior fills the rest) and is not warned
        about: the result's ``rank``, ``effective_rank`` and
        ``degrees_of_freedom`` say how many numbers the data fix.
    RegularizationWarning
        When the rule's optimum lies at an end of the λ grid, or the
        discrepancy equation has no root inside it.

    Notes
    -----
    f_λ = argmin ||A f - y||² + λ ||D f||², D the Neumann 5-point Laplacian
    (unit pixel spacing). GCV(λ) = ||A f_λ - y||² / trace(I - H_λ)², H_λ the
    influence matrix (its trace counts the unpenalised constant as one).
    """
    if regularizer == "tv":
        given = [name for name, value in (("method", method), ("memory_limit", memory_limit),
                                          ("gcv_probes", gcv_probes)) if value is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: apply to the Laplacian regulariser only, "
                             f"not to regularizer='tv'")
        from .tv import reconstruct_tv

        return reconstruct_tv(matrix, data, pixels, rule=rule, truth=truth, sigma=sigma,
                              lambdas=lambdas)
    if regularizer != "laplacian":
        raise ValueError(f"regularizer: must be 'laplacian' or 'tv', got {regularizer!r}")
    return reconstruct_rules(matrix, data, pixels, rules=(rule,), truth=truth, sigma=sigma,
                             lambdas=lambdas, method=method, memory_limit=memory_limit,
                             gcv_probes=gcv_probes, progress=progress)[0]


def reconstruct_rules(matrix, data, pixels: int, *, rules=RULES, truth=None,
                      sigma: float | None = None, lambdas=None, method: str | None = None,
                      memory_limit: int | None = None,
                      gcv_probes: int | None = None, progress: bool = False) -> list[Reconstruction]:
    """:func:`reconstruct` (Laplacian) for several λ rules sharing one factorisation.

    Parameters are those of :func:`reconstruct`, with ``rules`` a sequence of
    its ``rule`` values. Returns one :class:`Reconstruction` per rule, in
    order; each one's ``seconds`` includes the shared factorisation.
    """
    started = time.perf_counter()
    method = "auto" if method is None else method
    memory_limit = DEFAULT_MEMORY_LIMIT if memory_limit is None else int(memory_limit)
    gcv_probes = DEFAULT_GCV_PROBES if gcv_probes is None else int(gcv_probes)
    problem = Problem.checked(matrix, data, pixels)
    pixels = problem.pixels
    if method not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if isinstance(rules, (str, int, float)):
        rules = (rules,)
    parsed = [(rule, parse_rule(rule, RULES)) for rule in rules]
    a, c = problem.matrix_scale, problem.data_scale
    truth_image = None
    if "oracle" in rules:
        if truth is None:
            raise ValueError("truth: the oracle rule needs the true image")
        truth_image = np.asarray(truth, dtype=np.float64)
        if truth_image.shape != (pixels, pixels):
            raise ValueError(f"truth: shape {truth_image.shape}, expected ({pixels}, {pixels})")
        truth_image = truth_image / problem.image_scale
    if "discrepancy" in rules and sigma is None:
        raise ValueError(f"sigma: the discrepancy rule needs a noise level > 0, got {sigma!r}")
    if sigma is not None and not (math.isfinite(float(sigma)) and float(sigma) > 0):
        raise ValueError(f"sigma: the noise level must be finite and > 0, got {sigma!r}")
    scaled_sigma = None if sigma is None else float(sigma) / c
    if lambdas is not None:
        lambdas = np.sort(np.asarray(lambdas, dtype=np.float64).ravel())
        if lambdas.size < 1 or not np.all(np.isfinite(lambdas)) or np.any(lambdas <= 0):
            raise ValueError("lambdas: expected finite values > 0")
        lambdas = lambdas / a**2
    rows = problem.matrix.shape[0]
    unknowns = pixels * pixels
    svd_bytes = 3 * rows * unknowns * 8
    if method == "auto":
        method = "svd" if svd_bytes <= memory_limit else "lsqr"
    elif method == "svd" and svd_bytes > memory_limit:
        raise ResourceError(f"method svd: its dense matrices need {svd_bytes / 2**30:.2f} GiB, more than "
                            f"memory_limit ({memory_limit / 2**30:.2f} GiB); use method lsqr or raise the limit")
    solver = (SpectralSolver(problem) if method == "svd" else
              IterativeSolver(problem, sigma=scaled_sigma, progress=progress))
    live_rows = int(problem.live.sum())
    # what the data fix at their noise needs A's own singular values (the solver's are of A C diag(1/μ))
    values = None if sigma is None else singular_values_of(problem, memory_limit)
    rank = solver.rank if method == "svd" else None if values is None else numerical_rank(values, rows, unknowns)
    effective = None if values is None else count_above_noise(values * a, float(sigma))
    notices = [warning for warning in (
        information_warning(rank=rank, effective_rank=effective, live_rows=live_rows, unknowns=unknowns,
                            sigma=sigma), unseen_pixels_warning(problem)) if warning is not None]
    shared = time.perf_counter() - started
    default = default_grid(solver.largest, solver.smallest) if lambdas is None else lambdas
    if method != "svd" and "gcv" in [rule for rule, fixed in parsed if fixed is None]:
        # sweep once with GCV's probes first, so the other rules reuse that sweep
        solver.sweep(default, probes=gcv_probes)
    # rank 1: the data fix one number (the image's mean, or one weighted sum of it), which the constant
    # image meets at every λ; a rule would search a flat criterion (and the L-curve divide 0 by 0)
    one_number = method == "svd" and solver.rank <= 1
    results = []
    warned = False
    for rule, fixed in parsed:
        begun = time.perf_counter()
        messages: list[str] = []
        scaled_fixed = None if fixed is None else fixed / a**2
        if one_number and fixed is None:
            record_warning(messages, f"A has rank 1: the data fix one number of the image, every λ gives "
                                     f"the same flat image, and the {rule} rule has nothing to choose",
                           RegularizationWarning)
            scaled_fixed = 1.0
        grid = default if (fixed is None or lambdas is not None) else np.array([scaled_fixed])
        if method == "svd":
            result = choose_spectral(solver, rule, scaled_fixed, truth_image, scaled_sigma, grid,
                                     messages)
        else:
            result = choose_iterative(solver, rule, scaled_fixed, truth_image, scaled_sigma, grid,
                                      messages, gcv_probes, search=lambdas is None)
        for text, category in notices:     # once per call, recorded with every rule's result
            if warned:
                messages.append(text)
            else:
                record_warning(messages, text, category)
        warned = True
        image, lam, grid, criterion, residuals, seminorms = result
        # back to the caller's units: f = (c/a) g, λ = a² λ', r = c r', D f = (c/a) D g
        results.append(Reconstruction(
            image=problem.image_scale * image, lam=float(lam) * a**2,
            rule=rule if fixed is None else "value", lambdas=grid * a**2,
            criterion=criterion * _criterion_scale(rule, fixed, problem),
            residual_norms=c * np.sqrt(residuals),
            seminorms=problem.image_scale * np.sqrt(seminorms),
            residual_norm=c * float(np.linalg.norm(problem.matrix @ image.ravel() - problem.y)),
            seminorm=problem.image_scale * float(np.linalg.norm(
                idct2(-laplacian_eigenvalues(pixels) * dct2(image)))),
            method=method, rank=rank, effective_rank=effective, sigma=None if sigma is None else float(sigma),
            degrees_of_freedom=degrees_of_freedom(solver.filters(lam)) if method == "svd" else None,
            unknowns=unknowns, measurements=rows, stopping=None if method == "svd" else solver.stopping(),
            seconds=shared + time.perf_counter() - begun, warnings=tuple(messages)))
    return results


def _criterion_scale(rule, fixed, problem: Problem) -> float:
    """Factor from the scaled problem's criterion to the caller's units."""
    if fixed is not None or rule == "lcurve":   # NaN, or a log-log curvature (scale-free)
        return 1.0
    if rule == "oracle":
        return problem.image_scale**2
    return problem.data_scale**2                   # gcv and discrepancy: squared residuals
