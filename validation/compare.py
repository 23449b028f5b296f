"""Is a rendered transient consistent with a modelled one? (docs/design.md section 6)

Per bin, t = (y_render - y_model) / se_render. If the model is right and
the render unbiased, t follows Student's t with ν degrees of freedom when
se comes from R independent replicas (ν = R - 1: randomised quasi-Monte
Carlo, another renderer's seeds), or the standard normal when se comes from
many independent samples (ν = ∞). Each t is mapped to the normal score with
the same tail probability,

    z = Φ⁻¹(F_ν(t)),

and the D judged bins are summarised by two statistics, each with its own
acceptance limits:

- χ² = Σ z², accepted inside a central interval that holds it with
  probability 1 - α/2;
- max |z|, accepted up to a limit z* that it exceeds with probability α/2.

Together the two tests raise a false alarm with probability ≤ α (default
1e-3) on pure noise. Where those limits come from (the *null distribution*)
depends on what is known about the noise:

- **R independent replicas** (each a complete estimate of y; their mean is
  the render): the null of χ² and max |z| is taken from the replicas
  themselves by sign flips. Under the hypothesis, each replica's deviation
  d_r = y_r - y_model is a noise vector over the bins, independent of the
  other replicas and (to the accuracy of the central limit theorem)
  symmetric: d_r and -d_r are equally likely, *whatever the correlation
  between bins*. So the data are one of 2^R equally likely sign patterns
  s_r d_r, and recomputing χ² and max |z| for random patterns (mean
  (1/R) Σ s_r d_r, standard error from the same flipped replicas) draws
  from their exact null distribution (a randomisation test). A square
  pulse wider than the window or a long Butterworth tail deposits each
  sample into many bins at once, so the bins are strongly correlated and
  χ² is far from χ²(D); the flips follow that. The limits are order
  statistics of :data:`FLIPS` (or more) patterns drawn from a fixed seed.
  The flips see the deviations from the model judged, so a model off by
  δ standard errors in every bin widens its own limits a little (the
  flipped χ²/D grows by about δ² q / R, q ≈ 13 the χ²(1) quantile at
  α/4 = 2.5e-4, against δ² for the data): most of the power against a
  global scale error is kept.
- **Per-bin standard errors only** (no replicas), or too few replicas for
  2^(R-1) patterns to resolve the tail α/4: the bins are *assumed*
  independent, so the z are independent standard normals and χ² follows
  χ²(D) (interval [F⁻¹(α/4), F⁻¹(1 - α/4)]) and max |z| the Šidák limit
  z* = Φ⁻¹(1 - p/2), p = 1 - (1 - α/2)^(1/D). Correlated bins then raise
  false alarms above α; the result says which null it used
  (:attr:`Agreement.null`), and too few replicas raise a
  :class:`CorrelationWarning`.

(With ν small the same |z| needs a larger |t|: a render's own error
estimate is itself uncertain.) z is Gaussian only where the central limit theorem
holds: a bin grazed by a handful of samples (the ends of a response) has a
skewed error and an unreliable se, so only bins with se < 0.1 |y_render|
(roughly 100 samples or more) are judged; the others are counted. Bins where
the render saw no sample (se = 0) fail the check only if the model puts more
there than z* times the largest standard error (light the render should
have seen). The relative L2 error is reported beside the verdict, never
instead of it.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats

from analytic.errors import DataError

#: Fewest samples for a render that is cross-checked (run, validate, a sweep with cross_check):
#: 128 per replica, so that the bins with light have a standard error to judge them by.
MIN_CHECK_SAMPLES = 2**12

#: Fewest sign patterns drawn for the replicas' null distribution (more when α/4 needs them).
FLIPS = 2**14

#: The smallest tail, α/4, must hold at least this many sign patterns, of those drawn and of the
#: 2^(R-1) distinct ones R replicas have, for the replicas' null to resolve it.
TAIL_PATTERNS = 4

#: Seed of the sign patterns: the same data always get the same limits.
FLIP_SEED = 20240611

__all__ = ["Agreement", "compare_transients", "assert_transients_agree", "normal_scores", "combined_dof",
           "replica_null_resolves", "CorrelationWarning", "MIN_CHECK_SAMPLES", "FLIPS"]

#: Names of the null distributions (Agreement.null).
SIGN_FLIP, INDEPENDENT = "sign-flip", "independent"


class CorrelationWarning(UserWarning):
    """Replicas too few for the sign-flip null: the limits assume independent bins."""


@dataclass(frozen=True)
class Agreement:
    """The verdict and every figure behind it.

    Attributes
    ----------
    agrees : bool
        True when neither test rejects and no unsampled bin holds model light.
    z : numpy.ndarray
        ``(K, N)`` normal scores of t (equal to t when ν = ∞), NaN where the
        bin is not judged.
    dof : float
        ν, the standard errors' degrees of freedom (``inf``: normal; the
        smallest when they differ per bin).
    bins : int
        D, bins judged (0 < se < max_relative_stderr |y_render|).
    skipped : int
        Bins with 0 < se but too few samples to judge.
    chi2, chi2_per_dof : float
        Σ z² and Σ z² / D.
    chi2_interval : (float, float)
        Acceptance interval of χ² / D.
    max_abs_z, z_threshold : float
        Largest |z| and its acceptance limit z*.
    false_alarm : float
        α, the probability that pure noise fails the check.
    relative_l2 : float
        ||y_render - y_model|| / ||y_model||.
    worst : list of (sensor, bin, z)
        The largest |z|, worst first.
    unsampled_light : list of (sensor, bin, model value)
        Bins with se = 0 but model light above z* x max(se).
    null : {"sign-flip", "independent"}
        Where the limits come from: sign flips of the replicas (valid
        whatever the correlation between bins), or χ²(D) and Šidák, which
        assume independent bins.
    null_note : str
        One sentence saying so, for reports.
    flips : int
        Sign patterns drawn (0 for the independent-bins null).
    """

    agrees: bool
    z: np.ndarray
    dof: float
    bins: int
    skipped: int
    chi2: float
    chi2_per_dof: float
    chi2_interval: tuple
    max_abs_z: float
    z_threshold: float
    false_alarm: float
    relative_l2: float
    worst: list = field(default_factory=list)
    unsampled_light: list = field(default_factory=list)
    null: str = INDEPENDENT
    null_note: str = ""
    flips: int = 0

    def summary(self) -> str:
        """One paragraph: verdict, χ²/dof, max |z|, thresholds and their null, worst bins."""
        verdict = "AGREE" if self.agrees else "DISAGREE"
        low, high = self.chi2_interval
        worst = ", ".join(f"(sensor {k}, bin {n}, z = {z:+.2f})" for k, n, z in self.worst[:5])
        reference = "normal" if np.isinf(self.dof) else f"Student t, {self.dof:g} degrees of freedom"
        text = (f"{verdict} ({reference}): χ²/dof = {self.chi2_per_dof:.3f} over {self.bins} bins "
                f"({self.skipped} with too few samples not judged) "
                f"(accept [{low:.3f}, {high:.3f}]), max |z| = {self.max_abs_z:.2f} "
                f"(accept ≤ {self.z_threshold:.2f}); false-alarm rate {self.false_alarm:g}, {self.null_note}; "
                f"relative L2 = {self.relative_l2:.3e}. Worst bins: {worst}")
        if self.unsampled_light:
            text += f". Unsampled bins with model light: {self.unsampled_light[:5]}"
        return text

    def as_dict(self) -> dict:
        """JSON-ready figures (without the z array)."""
        return {"agrees": self.agrees, "dof": float(self.dof), "bins": self.bins, "skipped": self.skipped, "chi2": self.chi2,
                "chi2_per_dof": self.chi2_per_dof, "chi2_interval": list(self.chi2_interval),
                "max_abs_z": self.max_abs_z, "z_threshold": self.z_threshold,
                "false_alarm": self.false_alarm, "null": self.null, "null_note": self.null_note,
                "flips": self.flips, "relative_l2": self.relative_l2,
                "worst": [list(map(float, w)) for w in self.worst],
                "unsampled_light": [list(map(float, w)) for w in self.unsampled_light]}


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


def combined_dof(stderr_a, dof_a, stderr_b, dof_b) -> np.ndarray:
    """Welch–Satterthwaite degrees of freedom of a difference of two independent estimates.

    ν = (s_a² + s_b²)² / (s_a⁴ / ν_a + s_b⁴ / ν_b); ``inf`` for a normal side.
    Use it with se = sqrt(s_a² + s_b²) to compare two renders (ours and
    another tool's, each with its own replicas).
    """
    a2, b2 = np.square(np.asarray(stderr_a, float)), np.square(np.asarray(stderr_b, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        denominator = a2**2 / np.asarray(dof_a, float) + b2**2 / np.asarray(dof_b, float)
        dof = np.where(denominator > 0, (a2 + b2) ** 2 / denominator, np.inf)
    return dof


# --------------------------------------------------------------------------- the null distributions

def replica_null_resolves(replicas: int, false_alarm: float) -> bool:
    """Whether R replicas have sign patterns enough for the sign-flip null at false-alarm rate α.

    The smallest tail, α/4, must hold at least :data:`TAIL_PATTERNS` of the
    2^(R-1) distinct patterns (flipping every sign gives the same χ² and
    max |z|): R >= 15 at α = 1e-3, R >= 9 at α = 0.1.
    """
    return replicas >= 2 and (false_alarm / 4) * 2.0 ** (replicas - 1) >= TAIL_PATTERNS


def _flip_count(false_alarm: float, flips: int | None) -> int:
    """Patterns to draw: :data:`FLIPS`, or more so that α/4 of them is :data:`TAIL_PATTERNS`."""
    needed = math.ceil(TAIL_PATTERNS / (false_alarm / 4))
    if flips is None:
        return max(FLIPS, needed)
    if isinstance(flips, bool) or not isinstance(flips, (int, np.integer)) or flips < needed:
        raise ValueError(f"flips: must be an integer >= {needed} (α/4 = {false_alarm / 4:g} of them must be "
                         f"{TAIL_PATTERNS} patterns), got {flips!r}")
    return int(flips)


def _independent_limits(bins: int, false_alarm: float) -> tuple[tuple[float, float], float]:
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


def _replica_limits(deviations: np.ndarray, bins: int, false_alarm: float,
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


def _replica_deviations(replicas, rendered, stderr, model, judged) -> np.ndarray:
    """``(R, D)`` deviations y_r - y_model over the judged bins, each bin scaled by its largest.

    Raises ValueError when the replicas' mean and standard error are not
    ``rendered`` and ``stderr`` (replicas of another render).
    """
    count = replicas.shape[0]
    mean = replicas.mean(axis=0)
    spread = replicas.std(axis=0, ddof=1) / math.sqrt(count)
    scale = np.maximum(np.abs(rendered), stderr)
    if np.any(np.abs(mean - rendered) > 1e-9 * scale) or np.any(np.abs(spread - stderr) > 1e-6 * scale):
        raise ValueError("replicas: their mean and standard error are not `rendered` and `stderr`; "
                         "pass the replicas of the same render")
    deviations = replicas[:, judged] - model[judged]
    largest = np.max(np.abs(deviations), axis=0)
    return deviations / np.where(largest > 0, largest, 1.0)


# --------------------------------------------------------------------------- the verdict

def _limits(replicas, rendered, stderr, model, judged, false_alarm: float, flips: int | None):
    """(null, patterns drawn, χ²/D interval, z*): from the replicas' sign flips where they resolve α/4."""
    bins = int(judged.sum())
    if replicas is not None and replica_null_resolves(replicas.shape[0], false_alarm):
        drawn = _flip_count(false_alarm, flips)
        deviations = _replica_deviations(replicas, rendered, stderr, model, judged)
        return (SIGN_FLIP, drawn) + _replica_limits(deviations, bins, false_alarm, drawn)
    return (INDEPENDENT, 0) + _independent_limits(bins, false_alarm)


def _null_note(null: str, replicas: int | None, flips: int, false_alarm: float) -> str:
    if null == SIGN_FLIP:
        return (f"limits from {flips} sign flips of the {replicas} replicas' deviations from the model judged, "
                f"valid whatever the correlation between bins")
    if replicas is None:
        return "limits χ²(D) and Šidák, which assume independent bins (no replicas given)"
    return (f"limits χ²(D) and Šidák, which assume independent bins ({replicas} replicas are too few for "
            f"sign flips at α = {false_alarm:g})")


def _checked_dof(dof, replicas, shape) -> np.ndarray:
    """ν per bin: as given, ``inf`` by default, R - 1 (and only that) with replicas."""
    if replicas is not None:
        if dof is not None and np.any(np.asarray(dof, dtype=np.float64) != replicas.shape[0] - 1):
            raise ValueError(f"dof: {replicas.shape[0]} replicas have {replicas.shape[0] - 1} degrees of "
                             f"freedom; give that or none")
        dof = replicas.shape[0] - 1
    dof = np.broadcast_to(np.asarray(np.inf if dof is None else dof, dtype=np.float64), shape)
    if np.any(np.isnan(dof)) or np.any(dof <= 0):
        raise ValueError("dof: degrees of freedom must be > 0 (inf for a normal reference)")
    return dof


def compare_transients(rendered, stderr, model, *, dof=None, replicas=None, false_alarm: float = 1e-3,
                       max_relative_stderr: float = 0.1, worst: int = 10, flips: int | None = None) -> Agreement:
    """Judge a render (with its standard error) against a model.

    Parameters
    ----------
    rendered : array_like
        ``(K, N)`` Monte Carlo estimate of y.
    stderr : array_like
        ``(K, N)`` its standard error (same units).
    model : array_like
        ``(K, N)`` the model's y.
    dof : float or array_like, optional
        ν, degrees of freedom of ``stderr``: R - 1 for R replicas
        (``RenderResult.dof``), ``inf`` (the default without replicas) for
        errors from many independent samples; a ``(K, N)`` array when it
        differs per bin (:func:`combined_dof`). With ``replicas`` it is
        R - 1, given or not.
    replicas : array_like, optional
        ``(R, K, N)`` the independent replicas whose mean is ``rendered``
        and whose standard error of the mean is ``stderr``
        (``RenderResult.replica_means``): the limits then come from their
        sign flips, valid for correlated bins, when R is large enough
        (:func:`replica_null_resolves`); with fewer, the independent-bins
        limits are used and a :class:`CorrelationWarning` says so.
    false_alarm : float
        α: probability that a correct model fails on pure noise.
    max_relative_stderr : float
        Bins are judged only where se < max_relative_stderr |y_render|.
    worst : int
        How many of the largest |z| to list.
    flips : int, optional
        Sign patterns drawn for the replicas' null (default :data:`FLIPS`,
        or more where α/4 needs them).

    Returns
    -------
    Agreement

    Raises
    ------
    DataError
        Every standard error is zero, or none is under
        ``max_relative_stderr`` of its value: nothing to judge.
    ValueError
        Shapes that differ, bad ``dof``, replicas of another render.
    """
    rendered = np.asarray(rendered, dtype=np.float64)
    stderr = np.asarray(stderr, dtype=np.float64)
    model = np.asarray(model, dtype=np.float64)
    if not rendered.shape == stderr.shape == model.shape:
        raise ValueError(f"shapes differ: render {rendered.shape}, stderr {stderr.shape}, model {model.shape}")
    if replicas is not None:
        replicas = np.asarray(replicas, dtype=np.float64)
        if replicas.ndim != 3 or replicas.shape[1:] != rendered.shape or replicas.shape[0] < 2:
            raise ValueError(f"replicas: shape {replicas.shape}, expected (R >= 2,) + {rendered.shape}")
    dof = _checked_dof(dof, replicas, rendered.shape)
    sampled = stderr > 0
    judged = sampled & (stderr < max_relative_stderr * np.abs(rendered))
    bins = int(judged.sum())
    skipped = int(sampled.sum()) - bins
    if not np.any(sampled):
        raise DataError("stderr: the standard errors are all zero, so no bin has an error to judge it by; "
                        "give each bin's standard error (zero only where no sample landed)")
    if bins == 0:
        raise DataError(f"render: no bin has a standard error under {max_relative_stderr:g} of its value "
                        f"({int(sampled.sum())} bins with samples): too noisy to judge; render more samples")
    z = np.full(rendered.shape, np.nan)
    z[judged] = normal_scores((rendered[judged] - model[judged]) / stderr[judged], dof[judged])
    chi2 = float(np.sum(z[judged] ** 2))
    count = None if replicas is None else replicas.shape[0]
    null, drawn, interval, threshold = _limits(replicas, rendered, stderr, model, judged, false_alarm, flips)
    note = _null_note(null, count, drawn, false_alarm)
    if count is not None and null == INDEPENDENT:
        warnings.warn(f"{note}: correlated bins are not accounted for, so the false-alarm rate may exceed "
                      f"α; give at least {_fewest_replicas(false_alarm)} replicas", CorrelationWarning,
                      stacklevel=2)
    max_abs_z = float(np.nanmax(np.abs(z)))
    order = np.argsort(-np.nan_to_num(np.abs(z), nan=-1.0), axis=None)[:worst]
    worst_bins = [(int(i // z.shape[1]), int(i % z.shape[1]), float(z.flat[i])) for i in order
                  if np.isfinite(z.flat[i])]
    unsampled = _unsampled_light(rendered, stderr, model, dof, sampled, threshold)
    norm = float(np.linalg.norm(model))
    relative_l2 = float(np.linalg.norm(rendered - model) / norm) if norm > 0 else float("inf")
    chi2_per_dof = chi2 / bins
    agrees = (interval[0] <= chi2_per_dof <= interval[1] and max_abs_z <= threshold and not unsampled)
    return Agreement(agrees, z, float(np.min(dof)), bins, skipped, chi2, chi2_per_dof,
                     (float(interval[0]), float(interval[1])), max_abs_z, threshold, false_alarm, relative_l2,
                     worst_bins, unsampled, null, note, drawn)


def _fewest_replicas(false_alarm: float) -> int:
    count = 2
    while not replica_null_resolves(count, false_alarm):
        count += 1
    return count


def _unsampled_light(rendered, stderr, model, dof, sampled, threshold: float) -> list:
    """Bins the render saw no sample in (se = 0) where the model puts light beyond z* standard errors.

    z* is turned into t's units per bin (the same tail probability), and
    the largest standard error stands for the unknown one.
    """
    tail = stats.norm.sf(threshold)
    limit_t = np.max(np.where(np.isinf(dof), threshold, stats.t.isf(tail, np.minimum(dof, 1e300))))
    limit = float(limit_t) * float(stderr.max())
    return [(int(k), int(n), float(model[k, n])) for k, n in zip(*np.nonzero(~sampled))
            if abs(model[k, n] - rendered[k, n]) > limit]


def assert_transients_agree(rendered, stderr, model, *, dof=None, replicas=None, false_alarm: float = 1e-3,
                            max_relative_stderr: float = 0.1) -> Agreement:
    """pytest-friendly: raise AssertionError listing the worst bins unless they agree.

    Examples
    --------
    >>> result = render(scene, spp=2**22, seed=1)                  # doctest: +SKIP
    >>> assert_transients_agree(result.mean, result.stderr, forward(scene), dof=result.dof,
    ...                         replicas=result.replica_means)     # doctest: +SKIP
    """
    agreement = compare_transients(rendered, stderr, model, dof=dof, replicas=replicas, false_alarm=false_alarm,
                                   max_relative_stderr=max_relative_stderr)
    if not agreement.agrees:
        raise AssertionError(agreement.summary())
    return agreement
