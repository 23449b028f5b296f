"""How many numbers of the image the data fix: without noise, at their noise, and in the chosen fit.

Three counts, each a different question (every reconstruction reports them
beside one another, as far as they can be known):

- ``rank``: the numerical rank of A, singular values above
  s_1 max(m, M²) ε. What noiseless data would fix.
- ``effective_rank``: singular values of A / σ above 1. A unit-norm image
  component along A's right singular vector v_i reaches the data with
  amplitude s_i; it stands above white noise of standard deviation σ only
  when s_i > σ. What the data fix at their noise (the figure ``crb``
  reports for the whitened A, docs/design.md section 9). Needs σ and a
  dense SVD of A.
- ``degrees_of_freedom``: trace(H_λ), H_λ the influence matrix of the
  chosen fit (its filter factors summed, the unpenalised mean counted as
  one). How many numbers the chosen λ lets the data set.

Neither of the first two is warned about merely for being below the M²
unknowns: the letter's own set-up measures fewer numbers than it has pixels
(16 sensors x 12 bins for 50² pixels) and lets the Laplacian prior fill the
rest, which is the method, stated in every report. What is warned about is
what a user can act on: data that fix well under what their measurements
could (:func:`information_warning`), and pixels that no measurement sees.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse

from .result import NoiseLimitWarning, Problem, RankDeficiencyWarning

__all__ = ["DEFAULT_MEMORY_LIMIT", "singular_values_of", "numerical_rank", "count_above_noise", "information_warning",
           "unseen_pixels_warning", "degrees_of_freedom", "information_summary"]


DEFAULT_MEMORY_LIMIT = 2 * 2**30  # bytes the dense SVD route may use (Tikhonov's and TV's)


def singular_values_of(problem: Problem, memory_limit: int) -> np.ndarray | None:
    """Singular values of the scaled A (``problem.matrix``), descending, or None when a dense copy exceeds
    ``memory_limit`` bytes (then no count that needs them is reported, rather than an estimate)."""
    matrix = problem.matrix
    rows = int(problem.live.sum())
    columns = matrix.shape[1]
    if 2 * rows * columns * 8 > memory_limit:
        return None
    dense = (matrix[problem.live].toarray() if scipy.sparse.issparse(matrix)
             else matrix.toarray()[problem.live] if hasattr(matrix, "toarray")     # an operator's
             else np.asarray(matrix, dtype=np.float64)[problem.live])
    return np.linalg.svd(dense, compute_uv=False)   # zero rows add no singular value: left out


def numerical_rank(values: np.ndarray, rows: int, unknowns: int) -> int:
    """Singular values above s_1 max(rows, unknowns) ε (numpy's ``matrix_rank`` rule)."""
    if values.size == 0 or not values[0] > 0:
        return 0
    return int(np.sum(values > values[0] * max(rows, unknowns) * np.finfo(float).eps))


def count_above_noise(values: np.ndarray, sigma: float) -> int:
    """How many singular values of A / σ exceed 1 (``values`` and ``sigma`` in the same units)."""
    return int(np.sum(values > sigma))


def information_warning(*, rank: int | None, effective_rank: int | None, live_rows: int, unknowns: int,
                        sigma: float | None) -> tuple[str, type] | None:
    """The warning (message, category) when the data fix well under what their measurements could, or None.

    The most that ``live_rows`` measurements of M² unknowns can fix is
    min(live_rows, M²). The data fix ``effective_rank`` numbers at their
    noise (``rank`` when σ is unknown). At half of that or fewer, either the
    noise hides most of what was measured (the effective rank at most half
    of A's rank: :class:`NoiseLimitWarning`, act by a stronger source or
    lower noise) or the measurements repeat one another (A's rank at most
    half of the most: :class:`RankDeficiencyWarning`, e.g. sensors in line
    with the source see an image and its mirror alike; act by moving them).
    """
    if rank is None:
        return None
    most = min(live_rows, unknowns)
    fixed = rank if effective_rank is None else effective_rank
    if 2 * fixed > most:
        return None
    if effective_rank is not None and 2 * effective_rank <= rank:
        return (f"at σ = {sigma:g} the data fix about {effective_rank} of the image's {unknowns} numbers "
                f"(singular values of A/σ above 1), at most half of the {rank} that A fixes without noise: "
                f"the noise hides most of what these {live_rows} measurements carry and the prior fills the "
                f"rest; a stronger source (y scales with its intensity) or lower noise recovers "
                f"more", NoiseLimitWarning)
    return (f"A has rank {rank}, at most half of the {most} numbers that {live_rows} measurements of "
            f"{unknowns} unknowns could fix: the measurements repeat one another (a symmetry of the "
            f"set-up, e.g. sensors in line with the source see an image and its mirror alike), and the "
            f"prior fills the rest", RankDeficiencyWarning)


def unseen_pixels_warning(problem: Problem) -> tuple[str, type] | None:
    """The warning (message, category) when some pixels are seen by no measurement (their values are the
    prior's alone), or None."""
    seen = problem.seen
    unseen = int(seen.size - np.count_nonzero(seen))
    if unseen == 0:
        return None
    return (f"{unseen} of {seen.size} pixels are seen by no measurement (no path through them falls in "
            f"the window): the prior alone sets them", RankDeficiencyWarning)


def degrees_of_freedom(filters: np.ndarray) -> float:
    """trace(H_λ) of the SVD route: 1 (the unpenalised mean) plus the filter factors' sum."""
    value = 1.0 + float(np.sum(filters))
    return value if math.isfinite(value) else math.nan


def information_summary(*, rank: int | None, effective_rank: int | None, sigma: float | None,
                        unknowns: int) -> str:
    """How many numbers of the image the data fix, as a clause ("" when neither count is known).

    Parameters are a :class:`.result.Reconstruction`'s fields of the same names.
    """
    if effective_rank is not None:
        return (f"the data fix about {effective_rank} of the image's {unknowns} numbers at σ = {sigma:g} "
                f"(singular values of A/σ above 1; A's rank, what noiseless data would fix, is {rank})")
    if rank is not None:
        return f"noiseless data would fix {rank} of the image's {unknowns} numbers (A's rank; no Gaussian σ known)"
    return ""
