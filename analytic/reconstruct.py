"""Image recovery: Laplacian-regularised least squares with a λ rule (paper Sections IV, VI).

    f_λ = argmin_f ||A f - y||² + λ ||D f||²,

D the 5-point discrete Laplacian with reflecting (Neumann) boundaries
(:mod:`analytic.laplacian`). D's null space is the constant images and
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

``method="auto"`` takes ``"svd"`` when its dense matrices fit
``memory_limit`` and ``"lsqr"`` otherwise.

Beyond the paper, :func:`reconstruct_tv` (or ``regularizer="tv"``) solves
½||A f - y||² + λ TV(f) (isotropic total variation) by the diagonally
preconditioned Chambolle–Pock primal-dual method.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
import scipy.sparse
import scipy.sparse.linalg

from .laplacian import dct2, idct2, laplacian_eigenvalues

__all__ = ["RankDeficiencyWarning", "RegularizationWarning", "Reconstruction", "reconstruct",
           "reconstruct_rules", "reconstruct_tv", "total_variation", "image_metrics",
           "structural_similarity", "RULES", "TV_RULES"]

RULES = ("oracle", "gcv", "lcurve", "discrepancy")
METHODS = ("auto", "svd", "lsqr")
DEFAULT_MEMORY_LIMIT = 2 * 2**30  # bytes the dense SVD route may use
DEFAULT_LAMBDA_COUNT = 40
_REFINE_STEPS = 64  # dense sub-grid between neighbouring λ for the closed-form criteria


class RankDeficiencyWarning(RuntimeWarning):
    """A has fewer independent rows than unknowns: the regulariser fills the null space."""


class RegularizationWarning(RuntimeWarning):
    """The λ rule could not do what it was asked (optimum at the edge of the range, no root)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class Reconstruction:
    """The result of :func:`reconstruct`.

    Attributes
    ----------
    image : numpy.ndarray
        ``(M, M)`` reconstructed reflectance (row 0 at the top), units of f.
    lam : float
        Chosen λ, weight of ||D f||² (units of y² per unit of f²; D has unit
        pixel spacing).
    rule : str
        ``"oracle"``, ``"gcv"``, ``"lcurve"``, ``"discrepancy"`` or ``"value"``.
    lambdas : numpy.ndarray
        The λ grid swept, ascending (one value for ``"value"``).
    criterion : numpy.ndarray
        The rule's criterion at each λ of ``lambdas``: squared image error
        (oracle), GCV function ||r||² / trace(I - H)² (gcv), signed curvature of
        (log ||r||, log ||D f||) (lcurve), ||r||² - m σ² (discrepancy);
        NaN for ``"value"``.
    residual_norms, seminorms : numpy.ndarray
        ||A f_λ - y|| and ||D f_λ|| at each λ of ``lambdas``.
    residual_norm, seminorm : float
        The same at the chosen λ.
    method : str
        ``"svd"`` or ``"lsqr"``.
    rank : int or None
        Numerical rank of A (svd method; None for lsqr).
    unknowns : int
        M².
    measurements : int
        m = K N, rows of A (all of them, zero rows included).
    seconds : float
        Wall time of the call, s (A's assembly excluded).
    warnings : tuple of str
        Messages of the warnings issued.
    """

    image: np.ndarray
    lam: float
    rule: str
    lambdas: np.ndarray
    criterion: np.ndarray
    residual_norms: np.ndarray
    seminorms: np.ndarray
    residual_norm: float
    seminorm: float
    method: str
    rank: int | None
    unknowns: int
    measurements: int
    seconds: float
    warnings: tuple = field(default_factory=tuple)


# --------------------------------------------------------------------------- helpers

def _warn(messages: list, message: str, category) -> None:
    messages.append(message)
    warnings.warn(message, category, stacklevel=3)


def _curvature(t, x, y, xt=None, yt=None, xtt=None, ytt=None):
    """Signed curvature of the parametric curve (x(t), y(t)); positive where the
    L-curve turns its corner (x grows, y falls, the curve bends towards the origin)."""
    if xt is None:
        xt = np.gradient(x, t)
        yt = np.gradient(y, t)
        xtt = np.gradient(xt, t)
        ytt = np.gradient(yt, t)
    denominator = np.maximum((xt**2 + yt**2) ** 1.5, np.finfo(float).tiny)
    return (xt * ytt - xtt * yt) / denominator


def _check_data(matrix, data, pixels):
    if not (scipy.sparse.issparse(matrix) or isinstance(matrix, np.ndarray)):
        matrix = np.asarray(matrix, dtype=np.float64)
    if int(pixels) != pixels or pixels < 1:
        raise ValueError(f"pixels: expected a positive whole number, got {pixels!r}")
    pixels = int(pixels)
    rows, columns = matrix.shape
    if columns != pixels * pixels:
        raise ValueError(f"matrix: {columns} columns, expected pixels² = {pixels * pixels}")
    y = np.asarray(data, dtype=np.float64).ravel()
    if y.size != rows:
        raise ValueError(f"data: {y.size} samples, the matrix has {rows} rows")
    if not np.all(np.isfinite(y)):
        raise ValueError("data: contains NaN or infinity")
    return matrix, y, pixels


def _default_grid(largest: float, smallest: float) -> np.ndarray:
    """40 λ log-spaced over the squared singular values of the standard-form
    operator (the smallest floored at 1e-7 of the largest so that the grid
    stays useful on numerically singular problems), widened 100-fold at each
    end so that λ ≫ s_max² (the mean only) and λ ≪ s_min² are both reachable."""
    low = max(smallest, 1e-7 * largest)
    if not low > 0:
        low = 1e-7 * largest
    return np.geomspace(1e-2 * low**2, 1e2 * largest**2, DEFAULT_LAMBDA_COUNT)


# --------------------------------------------------------------------------- SVD route

class _SpectralSolver:
    """Closed-form Tikhonov solutions of the DCT-transformed, projected problem."""

    def __init__(self, matrix, y, pixels):
        dense = matrix.toarray() if scipy.sparse.issparse(matrix) else np.array(matrix, dtype=np.float64)
        self.pixels = pixels
        self.measurements = dense.shape[0]
        live = np.any(dense != 0.0, axis=1)
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
        self.outside = float(outside @ outside) + self.dead_residual
        tol = s[0] * max(self.measurements, pixels * pixels) * np.finfo(float).eps if s.size else 0.0
        # rank(A) = 1 (the constant) + rank(P B)
        self.rank = 1 + int(np.sum(s > tol))
        self.largest = float(s[0]) if s.size else 1.0
        positive = s[s > tol]
        self.smallest = float(positive[-1]) if positive.size else self.largest

    def filters(self, lam):
        lam = np.asarray(lam, dtype=np.float64)[..., None]
        return self.s**2 / (self.s**2 + lam)

    def residual2(self, lam):
        phi = self.filters(lam)
        return np.sum(((1.0 - phi) * self.beta) ** 2, axis=-1) + self.outside

    def seminorm2(self, lam):
        lam = np.asarray(lam, dtype=np.float64)[..., None]
        return np.sum((self.s * self.beta / (self.s**2 + lam)) ** 2, axis=-1)

    def gcv(self, lam):
        phi = self.filters(lam)
        trace = self.measurements - 1.0 - np.sum(phi, axis=-1)
        return self.residual2(lam) / np.maximum(trace, np.finfo(float).tiny) ** 2

    def curvature(self, lam):
        lam = np.asarray(lam, dtype=np.float64)
        phi = self.filters(lam)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(self.s > 0, self.beta**2 / np.maximum(self.s, np.finfo(float).tiny) ** 2, 0.0)
        rho = self.residual2(lam)
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
        return _curvature(None, None, None, xt, yt, xtt, ytt)

    def coefficients(self, lam):
        """DCT coefficients c (M²,) of f_λ; several λ give (len, M²)."""
        lam = np.atleast_1d(np.asarray(lam, dtype=np.float64))
        weights = (self.s * self.beta)[None, :] / (self.s[None, :] ** 2 + lam[:, None])
        z = weights @ self.vt
        c0 = (self.qy - z @ self.w) / self.constant_norm
        return np.concatenate([c0[:, None], z / self.mu], axis=1)

    def image(self, lam):
        return idct2(self.coefficients(lam)[0].reshape(self.pixels, self.pixels))

    def error2(self, lam, truth_coefficients):
        # C is orthonormal: ||f_λ - f||² = ||c_λ - c||²
        return np.sum((self.coefficients(lam) - truth_coefficients) ** 2, axis=1)


# --------------------------------------------------------------------------- LSQR route

class _IterativeSolver:
    """Matrix-free LSQR on the stacked, DCT-scaled system; warm starts along the sweep."""

    def __init__(self, matrix, y, pixels, *, tolerance=1e-10, iteration_limit=None):
        self.matrix = matrix if scipy.sparse.issparse(matrix) else np.asarray(matrix, dtype=np.float64)
        self.y = y
        self.pixels = pixels
        self.measurements = y.size
        self.unknowns = pixels * pixels
        mu = laplacian_eigenvalues(pixels).ravel()
        self.scale = np.ones_like(mu)
        self.scale[1:] = 1.0 / mu[1:]
        self.penalised = np.ones_like(mu)
        self.penalised[0] = 0.0
        self.tolerance = tolerance
        self.iteration_limit = iteration_limit or min(20 * self.unknowns, 10_000)
        self.rank = None
        self._sweeps = {}   # (grid, probes) -> sweep result: one sweep serves every rule
        if not np.any(self.forward_operator(np.eye(1, self.unknowns, 0).ravel())):
            raise ValueError("matrix: A · (constant image) = 0, the sensors see no light from the "
                             "plane, so the Laplacian cannot fix the image's mean")
        operator = self._standard_operator()
        try:
            self.largest = float(scipy.sparse.linalg.svds(operator, k=1, return_singular_vectors=False,
                                                          random_state=0)[0])
        except (ValueError, scipy.sparse.linalg.ArpackError):
            # ARPACK refuses or fails on tiny operators; a dense fallback is cheap there
            self.largest = float(np.linalg.norm(operator @ np.eye(self.unknowns), 2))
        self.smallest = 1e-7 * self.largest

    def to_image(self, v):
        return idct2((self.scale * v).reshape(self.pixels, self.pixels))

    def forward_operator(self, v):
        return self.matrix @ self.to_image(v).ravel()

    def adjoint_operator(self, r):
        return self.scale * dct2((self.matrix.T @ r).reshape(self.pixels, self.pixels)).ravel()

    def _standard_operator(self):
        # the penalised part only, for the largest singular value
        n = self.unknowns
        return scipy.sparse.linalg.LinearOperator(
            (self.measurements, n), dtype=np.float64,
            matvec=lambda v: self.forward_operator(np.ravel(v) * self.penalised),
            rmatvec=lambda r: self.adjoint_operator(np.ravel(r)) * self.penalised)

    def solve(self, lam, rhs=None, start=None):
        m, n = self.measurements, self.unknowns
        root = math.sqrt(lam)
        rhs = self.y if rhs is None else rhs
        stacked = scipy.sparse.linalg.LinearOperator(
            (m + n, n), dtype=np.float64,
            matvec=lambda v: np.concatenate([self.forward_operator(np.ravel(v)),
                                             root * self.penalised * np.ravel(v)]),
            rmatvec=lambda r: (self.adjoint_operator(np.ravel(r)[:m])
                               + root * self.penalised * np.ravel(r)[m:]))
        result = scipy.sparse.linalg.lsqr(stacked, np.concatenate([rhs, np.zeros(n)]),
                                          atol=self.tolerance, btol=self.tolerance, conlim=1e14,
                                          iter_lim=self.iteration_limit, x0=start)
        return result[0], result[1]

    def sweep(self, lambdas, probes=0):
        """Solutions for every λ (descending order solved, warm-started), remembered.

        A sweep made with GCV's trace probes also serves requests without them.
        """
        key = np.asarray(lambdas, dtype=np.float64).tobytes()
        for (grid, made_with), result in self._sweeps.items():
            if grid == key and made_with >= probes:
                return result
        result = self._sweep(lambdas, probes)
        self._sweeps[(key, probes)] = result
        return result

    def _sweep(self, lambdas, probes):
        order = np.argsort(lambdas)[::-1]
        solutions = np.empty((len(lambdas), self.unknowns))
        traces = np.full(len(lambdas), np.nan)
        generator = np.random.default_rng(0)
        vectors = generator.choice([-1.0, 1.0], size=(probes, self.measurements)) if probes else None
        probe_starts = [None] * probes
        start = None
        failed = 0
        for index in order:
            v, stop = self.solve(lambdas[index], start=start)
            failed += stop == 7
            solutions[index] = start = v
            if probes:
                quadratic = 0.0
                for p in range(probes):
                    x, _ = self.solve(lambdas[index], rhs=vectors[p], start=probe_starts[p])
                    probe_starts[p] = x
                    quadratic += vectors[p] @ self.forward_operator(x)
                traces[index] = self.measurements - quadratic / probes
        return solutions, traces, failed

    def residual2(self, v):
        r = self.forward_operator(v) - self.y
        return float(r @ r)

    def seminorm2(self, v):
        return float(np.sum((self.penalised * v) ** 2))  # z = μ c, so ||D f|| = ||z||


# --------------------------------------------------------------------------- public API

def reconstruct(matrix, data, pixels: int, *, rule: str | float = "gcv", truth=None,
                sigma: float | None = None, lambdas=None, method: str = "auto",
                memory_limit: int = DEFAULT_MEMORY_LIMIT, gcv_probes: int = 4,
                regularizer: str = "laplacian") -> Reconstruction:
    """Laplacian-regularised reconstruction of the image from the samples.

    Parameters
    ----------
    matrix : scipy.sparse array or numpy.ndarray
        A, ``(K N, M²)``, row k N + n, column r M + c (``image.ravel()``), as
        from :func:`analytic.system.system_matrix`.
    data : array_like
        y, ``(K, N)`` or ``(K N,)`` samples, units of y.
    pixels : int
        Image side M.
    rule : str or float
        How λ is chosen: ``"oracle"`` (minimises ||f_λ - f_true||, needs
        ``truth``; the paper's choice), ``"gcv"`` (generalised cross-
        validation), ``"lcurve"`` (maximum curvature of the L-curve
        (log ||A f - y||, log ||D f||)), ``"discrepancy"`` (Morozov:
        ||A f - y||² = m σ², m = K N; needs ``sigma``), or a positive number
        used as λ itself.
    truth : array_like, optional
        ``(M, M)`` true image, for ``"oracle"``.
    sigma : float, optional
        Noise standard deviation per sample, units of y, for ``"discrepancy"``.
    lambdas : array_like, optional
        λ grid to sweep (positive). Default: 40 values log-spaced over the
        squared singular values s² of the standard-form operator
        A C diag(1/μ) (s floored at 1e-7 s_max), widened by a factor 100 at
        both ends. With the svd method the
        rule's optimum is then refined between neighbouring grid values.
    method : {"auto", "svd", "lsqr"}
        Solver; ``"auto"`` uses ``"svd"`` when its dense matrices
        (about 3 m M² doubles) fit ``memory_limit``.
    memory_limit : int
        Bytes the svd method may use. Default 2 GiB.
    gcv_probes : int
        Hutchinson probes for GCV's trace with the lsqr method.
    regularizer : {"laplacian", "tv"}
        ``"tv"`` hands over to :func:`reconstruct_tv` (rules ``oracle``,
        ``discrepancy`` or a number; ``method`` and ``memory_limit`` unused).

    Returns
    -------
    Reconstruction

    Warns
    -----
    RankDeficiencyWarning
        When A has rank below M² (fewer independent measurements than
        unknowns): the answer is still unique, its null-space part set by the
        Laplacian prior. The svd method counts the numerical rank (singular
        values above s_max max(m, M²) ε); lsqr sees only structural
        deficiency (fewer non-zero rows than M², or pixels no row sees).
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
        return reconstruct_tv(matrix, data, pixels, rule=rule, truth=truth, sigma=sigma,
                              lambdas=lambdas)
    if regularizer != "laplacian":
        raise ValueError(f"regularizer: must be 'laplacian' or 'tv', got {regularizer!r}")
    return reconstruct_rules(matrix, data, pixels, rules=(rule,), truth=truth, sigma=sigma,
                             lambdas=lambdas, method=method, memory_limit=memory_limit,
                             gcv_probes=gcv_probes)[0]


def reconstruct_rules(matrix, data, pixels: int, *, rules=RULES, truth=None,
                      sigma: float | None = None, lambdas=None, method: str = "auto",
                      memory_limit: int = DEFAULT_MEMORY_LIMIT,
                      gcv_probes: int = 4) -> list[Reconstruction]:
    """:func:`reconstruct` for several λ rules sharing one factorisation.

    Parameters are those of :func:`reconstruct`, with ``rules`` a sequence of
    its ``rule`` values. Returns one :class:`Reconstruction` per rule, in
    order; each one's ``seconds`` includes the shared factorisation.
    """
    started = time.perf_counter()
    matrix, y, pixels = _check_data(matrix, data, pixels)
    if method not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if isinstance(rules, (str, int, float)):
        rules = (rules,)
    parsed = []
    for rule in rules:
        fixed = None
        if isinstance(rule, (int, float, np.integer, np.floating)) and not isinstance(rule, bool):
            fixed = float(rule)
            if not (math.isfinite(fixed) and fixed > 0):
                raise ValueError(f"rule: a numeric λ must be finite and > 0, got {rule!r}")
        elif rule not in RULES:
            raise ValueError(f"rule: must be one of {', '.join(map(repr, RULES))} or a positive "
                             f"number, got {rule!r}")
        parsed.append((rule, fixed))
    truth_image = None
    if "oracle" in rules:
        if truth is None:
            raise ValueError("truth: the oracle rule needs the true image")
        truth_image = np.asarray(truth, dtype=np.float64)
        if truth_image.shape != (pixels, pixels):
            raise ValueError(f"truth: shape {truth_image.shape}, expected ({pixels}, {pixels})")
    if "discrepancy" in rules:
        if sigma is None or not (math.isfinite(float(sigma)) and float(sigma) > 0):
            raise ValueError(f"sigma: the discrepancy rule needs a noise level > 0, got {sigma!r}")
    if lambdas is not None:
        lambdas = np.sort(np.asarray(lambdas, dtype=np.float64).ravel())
        if lambdas.size < 1 or not np.all(np.isfinite(lambdas)) or np.any(lambdas <= 0):
            raise ValueError("lambdas: expected finite values > 0")
    rows = matrix.shape[0]
    unknowns = pixels * pixels
    if method == "auto":
        method = "svd" if 3 * rows * unknowns * 8 <= memory_limit else "lsqr"
    if method == "svd":
        solver = _SpectralSolver(matrix, y, pixels)
    else:
        solver = _IterativeSolver(matrix, y, pixels)
    shared = time.perf_counter() - started
    rank = solver.rank
    rank_message = None
    live_rows = int(np.count_nonzero(np.asarray(abs(matrix).sum(axis=1)).ravel()))
    if (rank is not None and rank < unknowns) or (rank is None and live_rows < unknowns):
        known = f"rank {rank}" if rank is not None else f"only {live_rows} non-zero rows"
        rank_message = (f"A has {known} for {unknowns} unknowns (M = {pixels}): the data fix only "
                        f"part of the image, the Laplacian prior fills the rest")
    elif rank is None:
        dead = np.asarray(abs(matrix).sum(axis=0)).ravel() == 0
        if np.any(dead):
            rank_message = (f"{int(dead.sum())} pixels are seen by no measurement: the Laplacian "
                            f"prior fills them")
    if method != "svd" and "gcv" in [rule for rule, fixed in parsed if fixed is None]:
        # sweep once with GCV's probes first, so the other rules reuse that sweep
        solver.sweep(_default_grid(solver.largest, solver.smallest) if lambdas is None else lambdas,
                     probes=gcv_probes)
    results = []
    warned = False
    for rule, fixed in parsed:
        begun = time.perf_counter()
        messages: list[str] = []
        if method == "svd":
            result = _choose_spectral(solver, y, pixels, rule, fixed, truth_image, sigma, lambdas,
                                      messages)
        else:
            result = _choose_iterative(solver, rule, fixed, truth_image, sigma, lambdas, messages,
                                       gcv_probes)
        if rank_message is not None:
            if warned:            # once per call, recorded with every rule's result
                messages.append(rank_message)
            else:
                _warn(messages, rank_message, RankDeficiencyWarning)
                warned = True
        image, lam, grid, criterion, residuals, seminorms = result
        results.append(Reconstruction(
            image=image, lam=float(lam), rule=rule if fixed is None else "value", lambdas=grid,
            criterion=criterion, residual_norms=np.sqrt(residuals), seminorms=np.sqrt(seminorms),
            residual_norm=float(np.linalg.norm(matrix @ image.ravel() - y)),
            seminorm=float(np.linalg.norm(idct2(-laplacian_eigenvalues(pixels) * dct2(image)))),
            method=method, rank=rank, unknowns=unknowns, measurements=rows,
            seconds=shared + time.perf_counter() - begun, warnings=tuple(messages)))
    return results


def _corner(curvature):
    """Index of the L-curve's corner: the highest interior local maximum of the
    curvature (the ends of a sampled L-curve can show spurious bends where the
    residual or the seminorm saturates); the global maximum if there is none."""
    inner = np.nonzero((curvature[1:-1] > curvature[:-2]) & (curvature[1:-1] >= curvature[2:])
                       & (curvature[1:-1] > 0))[0] + 1
    if inner.size:
        return int(inner[np.argmax(curvature[inner])])
    return int(np.argmax(curvature))


def _edge_warning(index, size, rule, messages):
    if size > 1 and index in (0, size - 1):
        end = "smallest" if index == 0 else "largest"
        _warn(messages, f"the {rule} optimum is at the {end} λ of the grid; widen `lambdas`",
              RegularizationWarning)


def _choose_spectral(solver, y, pixels, rule, fixed, truth, sigma, lambdas, messages):
    if fixed is not None:
        grid = np.array([fixed]) if lambdas is None else lambdas
    else:
        grid = _default_grid(solver.largest, solver.smallest) if lambdas is None else lambdas
    residuals = solver.residual2(grid)
    seminorms = solver.seminorm2(grid)
    if fixed is not None:
        return (solver.image(fixed), fixed, grid, np.full(grid.shape, np.nan), residuals, seminorms)
    log_grid = np.log(grid)
    if rule == "oracle":
        truth_coefficients = dct2(truth).ravel()

        def objective(lam):
            return solver.error2(lam, truth_coefficients)
    elif rule == "gcv":
        objective = solver.gcv
    elif rule == "lcurve":
        def objective(lam):
            return -solver.curvature(lam)
    if rule == "discrepancy":
        target = solver.measurements * float(sigma) ** 2
        criterion = residuals - target
        lam = _discrepancy_root(lambda t: solver.residual2(np.exp(t)) - target, log_grid, criterion,
                                messages)
    else:
        criterion = objective(grid)
        if rule == "lcurve":
            criterion = -criterion
            # curvature is sharply peaked: search a dense sub-grid, not only the given one
            fine = np.linspace(log_grid[0], log_grid[-1], _REFINE_STEPS * max(len(grid) - 1, 1) + 1)
            values = objective(np.exp(fine))
            best = _corner(-values)
            _edge_warning(0 if best == 0 else len(grid) - 1 if best == len(fine) - 1 else -1,
                          len(grid), rule, messages)
            lower = fine[max(best - 1, 0)]
            upper = fine[min(best + 1, len(fine) - 1)]
        else:
            best = int(np.argmin(criterion))
            _edge_warning(best, len(grid), rule, messages)
            lower = log_grid[max(best - 1, 0)]
            upper = log_grid[min(best + 1, len(grid) - 1)]
        if upper > lower:
            found = scipy.optimize.minimize_scalar(lambda t: float(np.ravel(objective(np.exp(t)))[0]),
                                                   bounds=(lower, upper), method="bounded",
                                                   options={"xatol": 1e-6})
            lam = float(np.exp(found.x))
        else:
            lam = float(np.exp(lower))
    return solver.image(lam), lam, grid, criterion, residuals, seminorms


def _discrepancy_root(function, log_grid, criterion, messages):
    """λ with ||r||² = m σ²: the residual grows with λ, so bracket it on the grid."""
    above = np.nonzero(criterion >= 0)[0]
    if above.size == 0:
        _warn(messages, "discrepancy: the residual stays below m σ² over the whole λ grid "
                        "(noise overestimated?); taking the largest λ", RegularizationWarning)
        return float(np.exp(log_grid[-1]))
    first = int(above[0])
    if first == 0:
        _warn(messages, "discrepancy: the residual exceeds m σ² even at the smallest λ "
                        "(noise underestimated, or the data are inconsistent with A); taking the "
                        "smallest λ", RegularizationWarning)
        return float(np.exp(log_grid[0]))
    if function is None:  # lsqr: interpolate the log residual linearly in log λ
        return None, first
    root = scipy.optimize.brentq(function, log_grid[first - 1], log_grid[first], xtol=1e-10)
    return float(np.exp(root))


def _choose_iterative(solver, rule, fixed, truth, sigma, lambdas, messages, probes):
    if fixed is not None:
        grid = np.array([fixed]) if lambdas is None else lambdas
        v, _ = solver.solve(fixed)
        residuals = np.array([solver.residual2(v)])
        seminorms = np.array([solver.seminorm2(v)])
        if lambdas is not None:
            solutions, _, _ = solver.sweep(grid)
            residuals = np.array([solver.residual2(s) for s in solutions])
            seminorms = np.array([solver.seminorm2(s) for s in solutions])
        return (solver.to_image(v), fixed, grid, np.full(grid.shape, np.nan), residuals, seminorms)
    grid = _default_grid(solver.largest, solver.smallest) if lambdas is None else lambdas
    solutions, traces, failed = solver.sweep(grid, probes=probes if rule == "gcv" else 0)
    if failed:
        _warn(messages, f"lsqr stopped at its iteration limit for {failed} of {len(grid)} λ",
              RegularizationWarning)
    residuals = np.array([solver.residual2(s) for s in solutions])
    seminorms = np.array([solver.seminorm2(s) for s in solutions])
    log_grid = np.log(grid)
    if rule == "oracle":
        truth_coefficients = dct2(truth).ravel()
        errors = np.array([np.sum((solver.scale * s - truth_coefficients) ** 2) for s in solutions])
        criterion = errors
    elif rule == "gcv":
        criterion = residuals / np.maximum(traces, np.finfo(float).tiny) ** 2
    elif rule == "lcurve":
        criterion = _curvature(log_grid, np.log(residuals), np.log(np.maximum(seminorms,
                                                                               np.finfo(float).tiny)))
    else:
        target = solver.measurements * float(sigma) ** 2
        criterion = residuals - target
        found = _discrepancy_root(None, log_grid, criterion, messages)
        if not isinstance(found, tuple):
            lam = found
            index = int(np.argmin(np.abs(log_grid - np.log(lam))))
            return solver.to_image(solutions[index]), lam, grid, criterion, residuals, seminorms
        _, first = found
        x0, x1 = np.log(residuals[first - 1]), np.log(residuals[first])
        fraction = (np.log(target) - x0) / (x1 - x0) if x1 > x0 else 0.0
        log_lam = log_grid[first - 1] + fraction * (log_grid[first] - log_grid[first - 1])
        lam = float(np.exp(log_lam))
        v, _ = solver.solve(lam, start=solutions[first])
        return solver.to_image(v), lam, grid, criterion, residuals, seminorms
    best = _corner(criterion) if rule == "lcurve" else int(np.argmin(criterion))
    _edge_warning(best, len(grid), rule, messages)
    return solver.to_image(solutions[best]), float(grid[best]), grid, criterion, residuals, seminorms


# --------------------------------------------------------------------------- metrics

def structural_similarity(estimate, truth, *, data_range: float = 1.0, window: int = 7) -> float:
    """Mean SSIM (Wang et al. 2004) with a uniform ``window`` x ``window`` window.

    Constants K1 = 0.01, K2 = 0.03 on ``data_range``; sample (N - 1)
    covariances; averaged over windows lying wholly inside the image. These
    are scikit-image's ``structural_similarity`` defaults.
    """
    from scipy.ndimage import uniform_filter

    x = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if min(x.shape) < window:
        raise ValueError(f"window: {window} exceeds the image side {min(x.shape)}")
    count = window * window
    correction = count / (count - 1.0)
    mean_x = uniform_filter(x, window)
    mean_t = uniform_filter(t, window)
    var_x = correction * (uniform_filter(x * x, window) - mean_x**2)
    var_t = correction * (uniform_filter(t * t, window) - mean_t**2)
    cov = correction * (uniform_filter(x * t, window) - mean_x * mean_t)
    c1 = (0.01 * data_range) ** 2
    c2 = (0.03 * data_range) ** 2
    ssim = ((2 * mean_x * mean_t + c1) * (2 * cov + c2)) / (
        (mean_x**2 + mean_t**2 + c1) * (var_x + var_t + c2))
    pad = (window - 1) // 2
    return float(ssim[pad:-pad, pad:-pad].mean()) if pad else float(ssim.mean())


def image_metrics(estimate, truth, *, data_range: float = 1.0) -> dict:
    """Error of a reconstructed image against the true one.

    Parameters
    ----------
    estimate, truth : array_like
        ``(M, M)`` images, units of reflectance.
    data_range : float
        Range of valid values used by PSNR and SSIM; 1.0 for reflectance in
        [0, 1] (the estimate is not clipped).

    Returns
    -------
    dict
        ``mse`` (mean squared error), ``psnr`` (10 log10(range² / mse), dB;
        inf when mse = 0), ``ssim`` (see :func:`structural_similarity`),
        ``data_range``.
    """
    x = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if x.shape != t.shape:
        raise ValueError(f"estimate: shape {x.shape} differs from truth's {t.shape}")
    if not data_range > 0:
        raise ValueError(f"data_range: must be > 0, got {data_range!r}")
    mse = float(np.mean((x - t) ** 2))
    psnr = math.inf if mse == 0 else 10.0 * math.log10(data_range**2 / mse)
    ssim = structural_similarity(x, t, data_range=data_range) if min(x.shape) >= 7 else math.nan
    return {"mse": mse, "psnr": psnr, "ssim": ssim, "data_range": float(data_range)}


# --------------------------------------------------------------------------- total variation

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
        As :func:`reconstruct`.
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
        ``method = "pdhg"``, ``seminorms`` hold TV(f_λ), ``rank`` None;
        ``criterion`` as in :func:`reconstruct`. For ``discrepancy`` the
        largest grid λ with ||A f - y||² ≤ m σ² is taken (no root refinement).
    """
    started = time.perf_counter()
    matrix, y, pixels = _check_data(matrix, data, pixels)
    if not scipy.sparse.issparse(matrix):
        matrix = np.asarray(matrix, dtype=np.float64)
    fixed = None
    if isinstance(rule, (int, float, np.integer, np.floating)) and not isinstance(rule, bool):
        fixed = float(rule)
        if not (math.isfinite(fixed) and fixed > 0):
            raise ValueError(f"rule: a numeric λ must be finite and > 0, got {rule!r}")
    elif rule not in TV_RULES:
        raise ValueError(f"rule: TV supports {', '.join(map(repr, TV_RULES))} or a positive number, "
                         f"got {rule!r}")
    if rule == "oracle":
        if truth is None:
            raise ValueError("truth: the oracle rule needs the true image")
        truth = np.asarray(truth, dtype=np.float64)
        if truth.shape != (pixels, pixels):
            raise ValueError(f"truth: shape {truth.shape}, expected ({pixels}, {pixels})")
    if rule == "discrepancy" and (sigma is None or not float(sigma) > 0):
        raise ValueError(f"sigma: the discrepancy rule needs a noise level > 0, got {sigma!r}")
    if int(iterations) < 1:
        raise ValueError(f"iterations: must be >= 1, got {iterations!r}")
    steps = _tv_steps(matrix, pixels)
    if fixed is not None:
        grid = np.array([fixed])
    elif lambdas is None:
        top = float(np.max(np.abs(matrix.T @ y)))
        grid = np.geomspace(1e-4 * top, top, 12)
    else:
        grid = np.sort(np.asarray(lambdas, dtype=np.float64).ravel())
        if grid.size < 1 or not np.all(np.isfinite(grid)) or np.any(grid <= 0):
            raise ValueError("lambdas: expected finite values > 0")
    messages: list[str] = []
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
        _warn(messages, f"TV: {unconverged} of {grid.size} solves stopped at {iterations} "
                        f"iterations before 100 iterations changed the objective by less than "
                        f"{tolerance:g} (relative)",
              RegularizationWarning)
    if fixed is not None:
        best = 0
        criterion = np.full(1, np.nan)
    elif rule == "oracle":
        criterion = np.sum((images - truth.ravel()) ** 2, axis=1)
        best = int(np.argmin(criterion))
        _edge_warning(best, grid.size, "oracle", messages)
    else:
        criterion = residuals - y.size * float(sigma) ** 2
        below = np.nonzero(criterion <= 0)[0]
        if below.size == 0:
            _warn(messages, "discrepancy: the residual exceeds m σ² at every λ; taking the "
                            "smallest", RegularizationWarning)
            best = 0
        else:
            best = int(below[-1])
            if best == grid.size - 1:
                _warn(messages, "discrepancy: the residual stays below m σ² over the whole λ "
                                "grid; taking the largest", RegularizationWarning)
    image = images[best].reshape(pixels, pixels)
    return Reconstruction(
        image=image, lam=float(grid[best]), rule=rule if fixed is None else "value", lambdas=grid,
        criterion=criterion, residual_norms=np.sqrt(residuals), seminorms=variations,
        residual_norm=float(np.sqrt(residuals[best])), seminorm=float(variations[best]),
        method="pdhg", rank=None, unknowns=pixels * pixels, measurements=y.size,
        seconds=time.perf_counter() - started, warnings=tuple(messages))
