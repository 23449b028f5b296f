"""Normal scores of t, and the null distribution that the cross-check's limits come from.

:func:`validation.judging.compare.compare_transients` judges two statistics of the
normal scores z of its D bins (:func:`normal_scores`): χ² = Σ z² inside a
central interval, and max |z| under a limit z*. Where those limits come
from (the *null distribution*) depends on what is known about the noise:

- **R independent replicas** (each a complete estimate of y; their mean is
  the render): the null of χ² and max |z| is taken from the replicas
  themselves by sign flips (:func:`replica_limits`). Under the hypothesis,
  each replica's deviation d_r = y_r - y_model is a noise vector over the
  bins, independent of the other replicas and (to the accuracy of the
  central limit theorem) symmetric: d_r and -d_r are equally likely,
  *whatever the correlation between bins*. So the data are one of 2^R
  equally likely sign patterns s_r d_r, and recomputing χ² and max |z| for
  random patterns (mean (1/R) Σ s_r d_r, standard error from the same
  flipped replicas) draws from their exact null distribution (a
  randomisation test). A square pulse wider than the window or a long
  Butterworth tail deposits each sample into many bins at once, so the
  bins are strongly correlated and χ² is far from χ²(D); the flips follow
  that. The limits are order statistics of :data:`FLIPS` (or more)
  patterns drawn from a fixed seed. The flips see the deviations from the
  model judged, so a model off by δ standard errors in every bin widens
  its own limits a little (the flipped χ²/D grows by about δ² q / R,
  q ≈ 13 the χ²(1) quantile at α/4 = 2.5e-4, against δ² for the data):
  most of the power against a global scale error is kept.
- **Per-bin standard errors only** (no replicas), or too few replicas for
  2^(R-1) patterns to resolve the tail α/4
  (:func:`validation.judging.compare.replica_null_resolves`): the bins are
  *assumed* independent, so the z are independent standard normals and χ²
  follows χ²(D) (interval [F⁻¹(α/4), F⁻¹(1 - α/4)]) and max |z| the Šidák
  limit z* = Φ⁻¹(1 - p/2), p = 1 - (1 - α/2)^(1/D)
  (:func:`independent_limits`). Correlated bins then raise false alarms
  above α; the verdict says which null it used
  (:attr:`validation.judging.agreement.Agreement.null`), and too few replicas raise
  a :class:`validation.judging.compare.CorrelationWarning`.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import special, stats

from analytic.errors import DataError, OptionError

__all__ = ["normal_scores", "independent_limits", "replica_limits", "replica_deviations", "flip_count", "flips_needed",
           "FLIPS", "MAX_FLIPS", "TAIL_PATTERNS", "FLIP_SEED"]

#: Fewest sign patterns drawn for the replicas' null distribution (more when α/4 needs them).
FLIPS = 2**14

#: Most sign patterns drawn (a few seconds for a thousand bins): a false-alarm rate whose smallest tail needs
#: more is judged with the independent-bins limits.
MAX_FLIPS = 2**20

#: The smallest tail, α/4, must hold at least this many sign patterns, of those drawn and of the
#: 2^(R-1) distinct ones R replicas have, for the replicas' null to resolve it.
TAIL_PATTERNS = 4

#: Seed of the sign patterns: the same data always get the same limits.
FLIP_SEED = 20240611


def normal_scores(t, dof) -> np.ndarray:
    """z = Φ⁻¹(F_ν(t)): the standard normal quantile with the same tail probability as Student's t.

    Parameters
    ----------
    t : array_like
        t statistics.
    dof : float or array_like
        ν > 0 per value (broadcast); ``inf`` returns t unchanged.

    Returns
    -------
    numpy.ndarray
        Accurate far into the tails: the tail probability is carried as a
        logarithm, so |t| = 1e3 with ν = 3 still gives a finite z.
    """
    t = np.asarray(t, dtype=np.float64)
    dof = np.broadcast_to(np.asarray(dof, dtype=np.float64), t.shape)
    z = t.copy()
    finite = np.isfinite(t) & np.isfinite(dof)
    if np.any(finite):
        log_tail = stats.t.logsf(np.abs(t[finite]), dof[finite])       # log P(T > |t|)
        z[finite] = np.sign(t[finite]) * -special.ndtri_exp(log_tail)
    return z


def flips_needed(false_alarm: float) -> int:
    """Fewest patterns whose tail α/4 holds :data:`TAIL_PATTERNS` of them (α: the share of χ² and max |z|)."""
    return math.ceil(TAIL_PATTERNS / (false_alarm / 4))


def flip_count(false_alarm: float, flips: int | None) -> int:
    """Patterns to draw: :data:`FLIPS`, or more so that α/4 of them is :data:`TAIL_PATTERNS`.

    Raises
    ------
    OptionError
        ``flips`` not a whole number in [needed, :data:`MAX_FLIPS`].
    """
    needed = flips_needed(false_alarm)
    if flips is None:
        return max(FLIPS, needed)
    if (isinstance(flips, bool) or not isinstance(flips, (int, np.integer)) or not needed <= flips <= MAX_FLIPS):
        raise OptionError(f"flips: must be a whole number in [{needed}, {MAX_FLIPS}] (α/4 = {false_alarm / 4:g} "
                          f"of them must be {TAIL_PATTERNS} patterns), got {flips!r}")
    return int(flips)


def independent_limits(bins: int, false_alarm: float) -> tuple[tuple[float, float], float]:
    """χ²/D interval and z* for D independent standard normal z (χ²(D) and Šidák)."""
    half = false_alarm / 2
    interval = (stats.chi2.ppf(half / 2, bins) / bins, stats.chi2.isf(half / 2, bins) / bins)
    per_bin = -np.expm1(np.log1p(-half) / bins)                 # Šidák: 1 - (1 - α/2)^(1/D)
    return (float(interval[0]), float(interval[1])), float(stats.norm.isf(per_bin / 2))


class _SquaredScores:
    """q = t² / (ν + t²) -> z² of :func:`normal_scores`, for one ν, interpolated.

    Millions of flipped t go through it per check, too many for Student's
    tail function itself. q lies in [0, 1] (q ~ Beta(1/2, ν/2) under the
    hypothesis); in w = -log(1 - q), z² is smooth and close to linear
    (z² ≈ ν w near 0 and far out), so it is tabulated at 2^16 points
    uniform in w up to |t| = 10^10 or w = 1000 / ν, whichever comes first,
    linearly interpolated, and extrapolated beyond (z² > 40 there, far
    beyond every limit). The interpolation error, ~1e-8 in z, is far below
    the Monte Carlo error of the limits it serves.
    """

    POINTS = 2**16

    def __init__(self, dof: float):
        # z² ≈ ν w: beyond ~1000 (z ≈ 32) no limit is near, and Student's tail underflows soon after
        largest_w = min(math.log1p(1e20 / dof), 1000.0 / dof)
        self.step = largest_w / (self.POINTS - 1)
        w = np.arange(self.POINTS) * self.step
        self.values = normal_scores(np.sqrt(dof * np.expm1(w)), dof) ** 2
        self.slopes = np.append(np.diff(self.values), self.values[-1] - self.values[-2])

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """z² for q (any shape), in place of a scratch array."""
        with np.errstate(divide="ignore"):
            position = np.log1p(-np.minimum(q, 1.0), out=q)        # -w
        np.multiply(position, -1.0 / self.step, out=position)
        index = np.minimum(position, self.POINTS - 2).astype(np.intp)
        position -= index
        return np.add(self.values[index], position * self.slopes[index], out=position)


@functools.lru_cache(maxsize=8)
def _squared_scores(dof: float) -> _SquaredScores:
    """One table per ν (a check judges many transients with the same replica count)."""
    return _SquaredScores(dof)


def _flipped_statistics(deviations: np.ndarray, dof: float, flips: int) -> tuple[np.ndarray, np.ndarray]:
    """χ² and max |z| of ``flips`` random sign patterns of the replicas' deviations.

    Parameters
    ----------
    deviations : numpy.ndarray
        ``(R, D)`` d_r = y_r - y_model over the judged bins, each bin scaled
        by a positive constant (t is scale-free).
    dof : float
        R - 1.
    flips : int
        Patterns drawn, from :data:`FLIP_SEED`.

    Notes
    -----
    A pattern s gives the mean m = Σ s_r d_r / R and, since Σ (s_r d_r)² =
    Σ d_r² whatever s, the standard error se² = (Σ d_r² - R m²) / (R (R - 1)),
    so t² / (ν + t²) = (Σ s_r d_r)² / (R Σ d_r²): one ``(B, R) x (R, D)``
    product and a few elementwise steps per block of patterns.
    """
    replicas, bins = deviations.shape
    denominator = replicas * np.sum(deviations * deviations, axis=0)
    squared_scores = _squared_scores(dof)
    rng = np.random.default_rng(FLIP_SEED)
    block = max(1, 2**18 // bins)            # ~2 MB of float64 per array: stays in cache
    chi2 = np.empty(flips)
    largest = np.empty(flips)
    for first in range(0, flips, block):
        count = min(block, flips - first)
        signs = rng.integers(0, 2, size=(count, replicas)).astype(np.float64) * 2.0 - 1.0
        # einsum's own loop, not BLAS: many small products, where BLAS threads contend for the cores
        q = np.einsum("br,rd->bd", signs, deviations, optimize=False)
        np.multiply(q, q, out=q)
        np.divide(q, denominator, out=q)
        z2 = squared_scores(q)
        chi2[first:first + count] = np.sum(z2, axis=1)
        largest[first:first + count] = np.sqrt(np.max(z2, axis=1))
    return chi2, largest


def replica_limits(deviations: np.ndarray, bins: int, false_alarm: float,
                    flips: int) -> tuple[tuple[float, float], float]:
    """χ²/D interval and z* from the sign-flip null: order statistics of the flipped values.

    With B patterns and tail a, the k = ⌊a (B + 1)⌋-th largest value is the
    limit: data beyond it are beaten by fewer than k of B patterns, so the
    Monte Carlo p-value (1 + beaten) / (B + 1) is <= a (exact for a
    randomisation test).
    """
    chi2, largest = _flipped_statistics(deviations, deviations.shape[0] - 1, flips)
    chi2.sort()
    largest.sort()
    k_chi2 = int(math.floor(false_alarm / 4 * (flips + 1)))
    k_max = int(math.floor(false_alarm / 2 * (flips + 1)))
    interval = (float(chi2[k_chi2 - 1]) / bins, float(chi2[flips - k_chi2]) / bins)
    return interval, float(largest[flips - k_max])


def replica_deviations(replicas, rendered, stderr, model, judged) -> np.ndarray:
    """``(R, D)`` deviations y_r - y_model over the judged bins, each bin scaled by its largest.

    Raises DataError when the replicas' mean and standard error are not
    ``rendered`` and ``stderr`` (replicas of another render).
    """

    count = replicas.shape[0]
    mean = replicas.mean(axis=0)
    spread = replicas.std(axis=0, ddof=1) / math.sqrt(count)
    scale = np.maximum(np.abs(rendered), stderr)
    if np.any(np.abs(mean - rendered) > 1e-9 * scale) or np.any(np.abs(spread - stderr) > 1e-6 * scale):
        raise DataError("replicas: their mean and standard error are not `rendered` and `stderr`; "
                        "pass the replicas of the same render")
    deviations = replicas[:, judged] - model[judged]
    largest = np.max(np.abs(deviations), axis=0)
    return deviations / np.where(largest > 0, largest, 1.0)
