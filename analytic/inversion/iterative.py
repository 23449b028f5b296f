"""The ``"lsqr"`` method: matrix-free LSQR on the stacked, DCT-scaled Tikhonov system (:mod:`.tikhonov`).

Each λ solves ‖[A C S; √λ W] v − [y; 0]‖ → min with :func:`scipy.sparse.linalg.lsqr`, warm-started by
the solution of the λ before it (the sweep runs from the largest λ down). Write B for the stacked operator
and r for its residual.

When to stop a solve. Without σ, LSQR runs to atol = btol = 1e-10 (or its iteration limit). With the
noise level σ known, a solve stops once what is left to gain cannot matter beside the noise: the stacked
squared residual it leaves, ‖A f − y‖² + λ ‖D f‖², exceeds the converged one by about ‖Bᵀr‖² / λ at
most (BᵀB ≥ λ on the penalised coefficients; the image's mean is not penalised), and it stops when
that is at most κ σ² √(2m), κ = :data:`NOISE_FRACTION`: a tenth of the standard deviation of the
noise's own ‖e‖² (m σ² ± σ² √(2m)), what the discrepancy rule compares with. LSQR estimates ‖Bᵀr‖
at its last iterate; a solve runs 10 of its iterations, then 20, 40, ... (each run warm-started by
the last) until that holds (or LSQR's own 1e-10, or the iteration limit). Small λ thus keep a strict
stop, the λ near the discrepancy one a loose one (docs/tal.md: a 64 x 64 relay-wall capture).

The discrepancy rule needs the residual only where it crosses m σ², and the residual grows with λ: its
sweep stops at the first λ (from the top) whose residual is below m σ², and the λ below it are not
solved (NaN in the result's residuals and criterion). On the default grid (no grid given), the rule does not
sweep at all but searches the crossing (:meth:`IterativeSolver.discrepancy_search`):
log(‖A f − y‖² − F), F = (m − M²) σ² about the residual's floor as λ → 0 (the crossing may lie just above
it), is close to linear in log λ near the crossing, so a secant from the largest λ down (steps of at most
:data:`SEARCH_STEP_DECADES`), then regula falsi (Illinois) inside the bracket, each solve warm-started by
the nearest one, reach |‖A f − y‖² − m σ²| ≤ :data:`CROSSING_FRACTION` σ² √(2m), half the noise's own
spread, in a handful of solves. A capture of pixel offsets (its operator says ``translation_invariant``)
has its solves stopped by the noise made by CGLS, preconditioned by the diagonal of :meth:`_normal_spectrum`,
the same test made on the exact gradient at every iteration (:meth:`_preconditioned`). A progress bar (``progress``) counts the λ solved and the iterations; Ctrl-C stops between two products with A (each well under a second at that size).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from .laplacian import dct2, idct2, laplacian_eigenvalues
from .result import Problem

__all__ = ["IterativeSolver", "NOISE_FRACTION", "CROSSING_FRACTION", "SEARCH_STEP_DECADES"]

#: LSQR iterations of the first run of a solve stopped by the noise (then twice as many each run).
_FIRST_RUN = 10
#: κ: a solve with σ known stops once its ‖A f − y‖² + λ ‖D f‖² can exceed the converged one by at most
#: κ σ² √(2m) (the noise's ‖e‖² varies by σ² √(2m)).
NOISE_FRACTION = 0.1
#: The discrepancy search's λ is accepted once |‖A f − y‖² − m σ²| ≤ this × σ² √(2m) (the noise's ‖e‖² spread).
CROSSING_FRACTION = 0.5
#: Largest step of the discrepancy search down from the largest λ before the crossing is bracketed (decades):
#: a solve far below the crossing costs many iterations.
SEARCH_STEP_DECADES = 2.0
#: The search's value for a residual at or below the floor it subtracts (a log: far below the crossing).
_BELOW_FLOOR = 50.0
#: Most solves of one discrepancy search (each a warm-started LSQR).
_MOST_SEARCH_SOLVES = 40


class IterativeSolver:
    """Matrix-free LSQR on the stacked, DCT-scaled system; warm starts along the sweep.

    Parameters
    ----------
    problem : Problem
    tolerance : float
        LSQR's atol and btol without σ (btol always).
    iteration_limit : int, optional
        Iterations per solve at most. Default min(20 M², 10 000).
    sigma : float, optional
        Noise standard deviation per sample in the scaled problem's units: each solve of the data stops
        by the noise (module docstring).
    progress : bool
        A progress bar on stderr over the λ of a sweep.
    """

    def __init__(self, problem: Problem, *, tolerance=1e-10, iteration_limit=None, sigma=None, progress=False):
        matrix, y, pixels = problem.matrix, problem.y, problem.pixels
        self.matrix = (matrix if scipy.sparse.issparse(matrix) or isinstance(matrix, scipy.sparse.linalg.LinearOperator)
                       else np.asarray(matrix, dtype=np.float64))
        self.y = y
        self.live = problem.live
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
        self.sigma = None if sigma is None else float(sigma)
        self.progress = progress
        self.iterations = 0     # LSQR iterations of every solve so far
        self.solves = 0
        self._bar = None
        self.rank = None
        self._sweeps = {}   # (grid, probes) -> sweep result: one sweep serves every rule
        # a capture of pixel offsets (its operator says so) has AᵀA close to a convolution: its solves stopped
        # by the noise run preconditioned (_preconditioned)
        self.spectrum = (self._normal_spectrum() if self.sigma is not None
                         and getattr(matrix, "translation_invariant", False) else None)
        if not np.any(self.forward_operator(np.eye(1, self.unknowns, 0).ravel())):
            raise ValueError("matrix: A · (constant image) = 0, the sensors see no light from the "
                             "plane, so the Laplacian cannot fix the image's mean")
        operator = self._standard_operator()
        try:
            self.largest = float(scipy.sparse.linalg.svds(operator, k=1, return_singular_vectors=False,
                                                          rng=np.random.default_rng(0))[0])
        except (ValueError, scipy.sparse.linalg.ArpackError):
            # ARPACK refuses or fails on tiny operators; a dense fallback is cheap there
            self.largest = float(np.linalg.norm(operator @ np.eye(self.unknowns), 2))
        self.smallest = 1e-7 * self.largest

    def stopping(self) -> str:
        """How each solve stopped, in words, with the iterations spent (for the result)."""
        rule = (f"each λ's solve stopped once its ‖A f − y‖² + λ ‖D f‖² could exceed the converged one by at most "
                f"{NOISE_FRACTION:g} σ² √(2m), ‖Bᵀr‖² / λ (a tenth of the noise's own spread; "
                f"analytic.inversion.iterative), or at LSQR's atol = btol = {self.tolerance:g}"
                if self.sigma is not None else f"LSQR atol = btol = {self.tolerance:g}")
        how = ("" if self.spectrum is None else
               " (solved by CGLS preconditioned by AᵀA's DCT diagonal, the gradient tested every iteration)")
        return (f"lsqr: {rule}, at most {self.iteration_limit} iterations{how}; {self.iterations} iterations "
                f"over {self.solves} solves")

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

    def _counted_adjoint(self, r):
        # LSQR applies Bᵀ once per iteration
        self.iterations += 1
        if self._bar is not None:
            self._bar.set_postfix_str(f"{self.iterations} iterations", refresh=True)
        return self.adjoint_operator(r)

    def _lsqr(self, stacked, b, start, limit):
        result = scipy.sparse.linalg.lsqr(stacked, b, atol=self.tolerance, btol=self.tolerance, conlim=1e14,
                                          iter_lim=limit, x0=start)
        return result[0], result[1], result[2], result[7]       # v, istop, iterations, ‖Bᵀr‖

    def solve(self, lam, rhs=None, start=None):
        m, n = self.measurements, self.unknowns
        root = math.sqrt(lam)
        data = rhs is None
        rhs = self.y if rhs is None else rhs
        stacked = scipy.sparse.linalg.LinearOperator(
            (m + n, n), dtype=np.float64,
            matvec=lambda v: np.concatenate([self.forward_operator(np.ravel(v)),
                                             root * self.penalised * np.ravel(v)]),
            rmatvec=lambda r: (self._counted_adjoint(np.ravel(r)[:m])
                               + root * self.penalised * np.ravel(r)[m:]))
        b = np.concatenate([rhs, np.zeros(n)])
        self.solves += 1
        if self.sigma is None or not data:
            v, stop, _, _ = self._lsqr(stacked, b, start, self.iteration_limit)
            return v, stop
        # by the noise (module docstring): runs of LSQR, each warm-started by the last and twice as long,
        # until ‖Bᵀr‖² / λ ≤ κ σ² √(2m) (LSQR's estimate of ‖Bᵀr‖ at its last iterate)
        enough = NOISE_FRACTION * self.sigma**2 * math.sqrt(2.0 * m) * lam
        if self.spectrum is not None:
            return self._preconditioned(stacked, b, lam, start, enough)
        spent, run, v = 0, _FIRST_RUN, start
        while True:
            v, stop, used, gradient = self._lsqr(stacked, b, v, min(run, self.iteration_limit - spent))
            spent += used
            if gradient**2 <= enough:
                return v, 2             # LSQR's code for a least-squares solution to its tolerance
            if stop != 7 or spent >= self.iteration_limit:
                return v, stop
            run *= 2

    def _preconditioned(self, stacked, b, lam, start, enough):
        """A solve stopped by the noise by CGLS on the stacked system scaled on the right by the diagonal D of
        :meth:`_normal_spectrum` (v = D w): the same minimiser, fewer iterations where BᵀB is close to diagonal
        in the DCT basis. CGLS forms (B D)ᵀr every iteration, so the exact gradient Bᵀr = D⁻¹ (B D)ᵀr is
        tested at every one (LSQR's runs restart, and lose their Krylov space, at every test)."""
        diagonal = 1.0 / np.sqrt(self.spectrum + lam * self.penalised)
        w = np.zeros(self.unknowns) if start is None else start / diagonal
        residual = b - stacked.matvec(diagonal * w)
        s = diagonal * stacked.rmatvec(residual)
        direction = s.copy()
        gamma = float(s @ s)
        for _ in range(self.iteration_limit):
            gradient = s / diagonal
            if gradient @ gradient <= enough:
                return diagonal * w, 2
            q = stacked.matvec(diagonal * direction)
            alpha = gamma / float(q @ q)
            w += alpha * direction
            residual -= alpha * q
            s = diagonal * stacked.rmatvec(residual)
            previous, gamma = gamma, float(s @ s)
            direction = s + (gamma / previous) * direction
        return diagonal * w, 7          # LSQR's code for its iteration limit

    def _normal_spectrum(self):
        """BᵀB's diagonal in the DCT basis, as if AᵀA were the convolution with its own response at the image's
        centre (of a capture of pixel offsets it nearly is): (AᵀA δ)'s cosine transform, times S²."""
        pixels = self.pixels
        delta = np.zeros((pixels, pixels))
        delta[pixels // 2, pixels // 2] = 1.0
        response = (self.matrix.T @ (self.matrix @ delta.ravel())).reshape(pixels, pixels)
        # Σ_u K(u) cos(π p u / M), u the offset from the centre: the real part of a 2M-point DFT
        wrapped = np.zeros((2 * pixels, 2 * pixels))
        places = (np.arange(pixels) - pixels // 2) % (2 * pixels)
        wrapped[np.ix_(places, places)] = response
        values = np.abs(np.fft.fft2(wrapped).real[:pixels, :pixels]).ravel()
        values = np.maximum(values, 1e-12 * values.max())
        return values * self.scale**2

    def sweep(self, lambdas, probes=0, until=None):
        """Solutions for every λ (descending order solved, warm-started), remembered.

        A sweep made with GCV's trace probes also serves requests without them. With ``until`` (a squared
        residual), the sweep ends at the first λ whose residual ‖A f − y‖² is below it: the smaller λ
        have NaN solutions (such a sweep is not remembered; a whole one serves it).
        """
        key = np.asarray(lambdas, dtype=np.float64).tobytes()
        for (grid, made_with), result in self._sweeps.items():
            if grid == key and made_with >= probes:
                return result
        result = self._sweep(lambdas, probes, until)
        if until is None:
            self._sweeps[(key, probes)] = result
        return result

    def _sweep(self, lambdas, probes, until=None):
        order = np.argsort(lambdas)[::-1]
        solutions = np.full((len(lambdas), self.unknowns), np.nan)
        traces = np.full(len(lambdas), np.nan)
        generator = np.random.default_rng(0)
        # Rademacher probes on the live rows only: GCV's trace counts those (see .rules)
        vectors = (generator.choice([-1.0, 1.0], size=(probes, self.measurements)) * self.live
                   if probes else None)
        probe_starts = [None] * probes
        start = None
        failed = 0
        if self.progress:
            from tqdm import tqdm

            self._bar = tqdm(total=len(lambdas), desc="reconstruct: λ sweep (lsqr)", unit="λ", leave=False)
        try:
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
                    traces[index] = int(self.live.sum()) - quadratic / probes
                if self._bar is not None:
                    self._bar.update(1)
                if until is not None and self.squared_residual_of(v) < until:
                    break
        finally:
            if self._bar is not None:
                self._bar.close()
                self._bar = None
        return solutions, traces, failed

    def discrepancy_search(self, low: float, high: float, target: float):
        """The discrepancy λ in [low, high] by a secant search (module docstring), σ known.

        Returns
        -------
        (lambdas, solutions, index, failed)
            Every λ solved (ascending), their solutions, the index of the chosen one (its residual within
            :data:`CROSSING_FRACTION` σ² √(2m) of ``target``, or the end of the range nearest the crossing
            when the residual stays on one side of it over the whole range, or the closest when the solves
            run out), and how many solves stopped at the iteration limit.
        """
        slack = CROSSING_FRACTION * self.sigma**2 * math.sqrt(2.0 * self.measurements)
        # the residual falls towards its floor, about (m − M²) σ², as λ → 0, and the crossing m σ² may lie just
        # above it: log(‖A f − y‖² − F) is far closer to linear in log λ there than log ‖A f − y‖²
        floor = max(self.measurements - self.unknowns, 0) * self.sigma**2
        solved = {}                       # log λ -> (solution, log of (‖A f − y‖² − F) / (m σ² − F), stop code)

        def solve(t):
            start = None if not solved else solved[min(solved, key=lambda s: abs(s - t))][0]
            v, stop = self.solve(math.exp(t), start=start)
            residual = self.squared_residual_of(v)
            gap = (residual - floor) / (target - floor)
            solved[t] = (v, math.log(gap) if gap > 0 else -_BELOW_FLOOR, stop)
            if self._bar is not None:
                self._bar.update(1)
                self._bar.set_postfix_str(f"{self.iterations} iterations, λ = {math.exp(t):.3g}, "
                                          f"‖A f − y‖² / m σ² = {residual / target:.4g}", refresh=True)
            return abs(residual - target) <= slack

        def result(t):
            keys = sorted(solved)
            return (np.exp(keys), np.array([solved[k][0] for k in keys]), keys.index(t),
                    sum(solved[k][2] == 7 for k in keys))

        bottom, top = math.log(low), math.log(high)
        step = SEARCH_STEP_DECADES * math.log(10.0)
        if self.progress:
            from tqdm import tqdm

            self._bar = tqdm(desc="reconstruct: discrepancy λ search (lsqr)", unit="solve", leave=False)
        try:
            if solve(top) or solved[top][1] <= 0 or top == bottom:
                return result(top)
            above = top                   # the smallest log λ whose residual is above the target
            while True:                   # down from the top, by secant steps of at most `step`
                previous = [t for t in solved if t > above]
                guess = above - step
                if previous:
                    slope = (solved[previous[0]][1] - solved[above][1]) / (previous[0] - above)
                    if slope > 0:
                        guess = max(guess, above - solved[above][1] / slope)
                t = max(bottom, min(guess, above - 0.1 * step))
                if solve(t):
                    return result(t)
                if solved[t][1] < 0:
                    below = t
                    break
                above = t
                if t == bottom or len(solved) >= _MOST_SEARCH_SOLVES:
                    return result(t)
            side = 0                      # regula falsi, Illinois: halve the value of an end kept twice
            h_below, h_above = solved[below][1], solved[above][1]
            while len(solved) < _MOST_SEARCH_SOLVES and above - below > 1e-9:
                t = (below * h_above - above * h_below) / (h_above - h_below)
                if solve(t):
                    return result(t)
                if solved[t][1] < 0:
                    below, h_below = t, solved[t][1]
                    h_above = h_above / 2 if side == -1 else h_above
                    side = -1
                else:
                    above, h_above = t, solved[t][1]
                    h_below = h_below / 2 if side == 1 else h_below
                    side = 1
            return result(min(solved, key=lambda s: abs(solved[s][1])))
        finally:
            if self._bar is not None:
                self._bar.close()
                self._bar = None

    def squared_residual_of(self, v, live_only=False):
        """||A f - y||² of the solution v, over every row or over the live rows (NaN for a λ not solved)."""
        if np.isnan(v[0]):
            return math.nan
        r = self.forward_operator(v) - self.y
        if live_only:
            r = r[self.live]
        return float(r @ r)

    def squared_seminorm_of(self, v):
        """||D f||² of the solution v."""
        return float(np.sum((self.penalised * v) ** 2))  # z = μ c, so ||D f|| = ||z||
