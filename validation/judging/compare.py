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

- χ² = Σ z², accepted inside a central interval;
- max |z|, accepted up to a limit z*;

and, given the model's derivatives along a scale and a time offset
(``directions``), by the two directed tests of :mod:`validation.judging.directed`,
which see a global scale error that χ² cannot at that count. The tests
share the false-alarm rate α (default 1e-3) equally (Bonferroni: α/2 each
without directed tests, α/4 each with them), so together they raise a
false alarm with probability ≤ α on pure noise. The limits of χ² and
max |z| come from the sign flips of R independent replicas where R
resolves χ²'s smallest tail (:func:`replica_null_resolves`), valid
whatever the correlation between bins; otherwise from χ²(D) and Šidák,
which assume independent bins, with a :class:`CorrelationWarning` where
replicas were given (:mod:`validation.judging.null_distribution` derives both).
The verdict and its figures are an :class:`validation.judging.agreement.Agreement`.

(With ν small the same |z| needs a larger |t|: a render's own error
estimate is itself uncertain.) z is Gaussian only where the central limit theorem
holds: a bin grazed by a handful of samples (the ends of a response) has a
skewed error and an unreliable se, so only bins with se < 0.1 |y_render|
(roughly 100 samples or more) are judged; with replicas, the bins that
hold about 100 samples and whose replicas differ by at least one sample's
weight (:func:`judged_bins`); the others are counted. Bins where the render saw no sample (se = 0) fail
the check only if the model puts more there than z* times the largest
standard error (light the render should have seen). The relative L2 error
is reported beside the verdict, never instead of it.
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np
from scipy import stats

from analytic.errors import DataError, OptionError

from validation.judging.agreement import INDEPENDENT, SIGN_FLIP, Agreement, null_note
from validation.judging.arrays import false_alarm_rate, real_array, whole_number
from validation.judging.directed import directed_columns, directed_tests
from validation.judging.null_distribution import (FLIPS, MAX_FLIPS, TAIL_PATTERNS, flip_count, flips_needed,
                                          independent_limits, normal_scores, replica_deviations, replica_limits)

__all__ = ["Agreement", "compare_transients", "normal_scores", "combined_dof", "replica_null_resolves",
           "fewest_replicas", "sample_weight", "judged_bins", "CorrelationWarning", "MIN_CHECK_SAMPLES", "FLIPS",
           "MODEL_SHARE", "model_tolerance_for", "tighter_model_note"]

#: Fewest samples for a render that is cross-checked (run, validate, a sweep with cross_check):
#: 128 per replica, so that the bins with light have a standard error to judge them by.
MIN_CHECK_SAMPLES = 2**12

#: The model's own error (up to its tolerance x |y|) may move z by at most this many standard errors.
MODEL_SHARE = 0.1


def model_tolerance_for(tolerance: float, values, stderr, max_relative_stderr: float = 0.1) -> float | None:
    """The tolerance a model must be evaluated at to judge these data, or None when ``tolerance`` serves.

    A scene's tolerance bounds each system-matrix entry relative to its
    row's largest; the model's per-bin error measured on the examples stays
    under 0.34 x tolerance of the bin's value (docs/check.md). So where a
    judged bin's standard error is under tolerance / :data:`MODEL_SHARE` of
    its value, the model's own error could fail data that are right (a 1 mm
    hidden square renders to 1e-12). Then: :data:`MODEL_SHARE` x the data's
    smallest relative error, not below :data:`analytic.scenes.common.MIN_TOLERANCE`
    (where the data are more precise still, :func:`tighter_model_note` says
    so).
    """
    from analytic.scenes.common import MIN_TOLERANCE

    values, stderr = np.asarray(values, dtype=np.float64), np.asarray(stderr, dtype=np.float64)
    judged = (stderr > 0) & (stderr < max_relative_stderr * np.abs(values))
    if not np.any(judged):
        return None
    needed = MODEL_SHARE * float(np.min(stderr[judged] / np.abs(values[judged])))
    return None if tolerance <= needed else max(needed, MIN_TOLERANCE)


def tighter_model_note(tolerance: float, scene_tolerance: float) -> str:
    """Why data were judged against the model at ``tolerance`` (:func:`model_tolerance_for`), in words."""
    from analytic.scenes.common import MIN_TOLERANCE

    note = (f"model evaluated at tolerance {tolerance:g}, tighter than the scene's {scene_tolerance:g}: some bins' "
            f"standard errors are under {1 / MODEL_SHARE:g} x the scene's tolerance of their values")
    if tolerance <= MIN_TOLERANCE:
        note += (f"; {MIN_TOLERANCE:g} is as tight as the model goes, so in bins more precise than "
                 f"{MIN_TOLERANCE / MODEL_SHARE:g} of their values part of a difference may be the model's own")
    return note


class CorrelationWarning(UserWarning):
    """Replicas too few for the sign-flip null: the limits assume independent bins."""


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


def replica_null_resolves(replicas: int, false_alarm: float, tests: int = 2) -> bool:
    """Whether R replicas have sign patterns enough for the sign-flip null at false-alarm rate α.

    χ² and max |z| share α with the other tests (``tests`` in all: 2
    without directed tests, 4 with them), each α / tests, and χ²'s smallest
    tail is α / (2 tests). It must hold at least
    :data:`validation.judging.null_distribution.TAIL_PATTERNS` of the 2^(R-1)
    distinct patterns (flipping every sign gives the same χ² and max |z|),
    and the patterns it needs must not exceed
    :data:`validation.judging.null_distribution.MAX_FLIPS`: R >= 15 at α = 1e-3
    without directed tests, R >= 16 with them; R >= 9 at α = 0.1.
    """
    omnibus = 2 * false_alarm / tests
    return (replicas >= 2 and (omnibus / 4) * 2.0 ** (replicas - 1) >= TAIL_PATTERNS
            and flips_needed(omnibus) <= MAX_FLIPS)


def fewest_replicas(false_alarm: float, tests: int = 2) -> int:
    """The fewest replicas whose sign flips give the limits (:func:`replica_null_resolves`), or 0 when
    no number does (α too small for :data:`validation.judging.null_distribution.MAX_FLIPS` patterns)."""
    if flips_needed(2 * false_alarm / tests) > MAX_FLIPS:
        return 0
    count = 2
    while not replica_null_resolves(count, false_alarm, tests):
        count += 1
    return count


def sample_weight(replicas, stderr, precise) -> np.ndarray:
    """``(K,)`` the weight of one sample in each row's bins (sensor or pair), estimated from the replicas.

    A Monte Carlo bin holds a random number of samples' weights w: a
    compound Poisson count of λ samples has variance λ E[w²] and mean
    λ E[w], so per-replica variance / mean = E[w²] / E[w] >= E[w]. Its
    median over the row's ``precise`` bins (those whose own standard error
    is under the judged share of their value), which a few bins whose
    spread came out small do not move; a row without such bins takes the
    median over all rows; NaN where there are none.
    """
    count = replicas.shape[0]
    mean = np.abs(replicas.mean(axis=0))
    ratio = np.full(mean.shape, np.nan)
    usable = precise & (mean > 0)
    ratio[usable] = count * stderr[usable] ** 2 / mean[usable]
    if not np.any(usable):
        return np.full(mean.shape[0], np.nan)
    pooled = float(np.median(ratio[usable]))
    return np.array([float(np.median(row[np.isfinite(row)])) if np.any(np.isfinite(row)) else pooled
                     for row in ratio])


def judged_bins(rendered, stderr, max_relative_stderr: float, replicas=None) -> np.ndarray:
    """``(K, N)`` bool: the bins judged (see Notes).

    Parameters
    ----------
    rendered, stderr : numpy.ndarray
        ``(K, N)`` the data (the replicas' mean) and its standard error.
    max_relative_stderr : float
        The largest standard error judged, relative to the value.
    replicas : numpy.ndarray, optional
        ``(R, K, N)`` the replicas ``rendered`` and ``stderr`` come from.

    Notes
    -----
    z is near Gaussian only where many samples landed. Given standard
    errors, a bin is judged where 0 < se < ``max_relative_stderr`` |y|
    (about 100 samples or more). With replicas the standard error is itself
    estimated from R values, and judging a bin because its own spread came
    out small selects exactly the bins whose |t| is too large (with R = 3,
    Gaussian replicas and a response whose bins cross that line, χ² failed
    8 times as often as stated). So with replicas a bin is judged on
    quantities its own spread does not set: the samples it holds, R |ȳ| / w
    with w the row's weight of one sample (:func:`sample_weight`), at least
    1 / max_relative_stderr² (100); and only where the replicas' range
    (largest - smallest) reaches one sample's weight w: where every replica
    holds the same number of samples (each one hit, say), their spread is
    only the weights' variation, far below the true error (a probe: spread
    4.7e-12 against a true 3.9e-10, z = 7.04), while a count that differs
    moves a replica by about one weight. For data with a smooth noise (a
    measurement, or many samples per bin) the range spans several standard
    errors, far above w. Where the weight of a sample varies along a row
    (a sensor 1 mm above the plane), bins of light samples count fewer
    than they hold and may be left out: power lost, never a false alarm.
    """
    sampled = stderr > 0
    precise = sampled & (stderr < max_relative_stderr * np.abs(rendered))
    if replicas is None:
        return precise
    unit = float(np.max(np.abs(replicas)))              # y ~ 1e-300: its squares would underflow
    replicas, stderr, rendered = replicas / unit, stderr / unit, rendered / unit
    weight = sample_weight(replicas, stderr, precise)[:, None]
    if not np.all(np.isfinite(weight)):
        return precise                      # nothing precise: nothing judged either way
    samples = replicas.shape[0] * np.abs(rendered) / weight
    spread = replicas.max(axis=0) - replicas.min(axis=0)
    return sampled & (samples >= 1.0 / max_relative_stderr**2) & (spread >= weight)


# --------------------------------------------------------------------------- the verdict

def _limits(replicas, rendered, stderr, model, judged, false_alarm: float, tests: int, flips: int | None):
    """(null, patterns drawn, χ²/D interval, z*) at χ² and max |z|'s share of α: from the replicas' sign
    flips where they resolve its smallest tail."""
    bins = int(judged.sum())
    omnibus = 2 * false_alarm / tests
    if replicas is not None and replica_null_resolves(replicas.shape[0], false_alarm, tests):
        drawn = flip_count(omnibus, flips)
        deviations = replica_deviations(replicas, rendered, stderr, model, judged)
        return (SIGN_FLIP, drawn) + replica_limits(deviations, bins, omnibus, drawn)
    return (INDEPENDENT, 0) + independent_limits(bins, omnibus)


def _checked_dof(dof, replicas, shape) -> np.ndarray:
    """ν per bin: as given, ``inf`` by default, R - 1 (and only that) with replicas."""
    if replicas is not None:
        if dof is not None and np.any(np.asarray(dof, dtype=np.float64) != replicas.shape[0] - 1):
            raise OptionError(f"dof: {replicas.shape[0]} replicas have {replicas.shape[0] - 1} degrees of "
                              f"freedom; give that or none")
        dof = replicas.shape[0] - 1
    dof = real_array("dof", np.inf if dof is None else dof, finite=False)
    try:
        dof = np.broadcast_to(dof, shape)
    except ValueError:
        raise OptionError(f"dof: shape {dof.shape}, expected one number or {shape}") from None
    if np.any(np.isnan(dof)) or np.any(dof <= 0):
        raise OptionError("dof: degrees of freedom must be > 0 (inf for a normal reference)")
    return dof


def _checked_arrays(rendered, stderr, model, replicas, directions):
    """The arrays of :func:`compare_transients`, checked (DataError in one line otherwise)."""
    rendered, stderr, model = (real_array(name, value) for name, value in
                               (("rendered", rendered), ("stderr", stderr), ("model", model)))
    if not (rendered.ndim == 2 and rendered.shape == stderr.shape == model.shape and rendered.size):
        raise DataError(f"shapes: rendered {rendered.shape}, stderr {stderr.shape}, model {model.shape}; give "
                        f"three (K, N) arrays of one shape, K rows (sensors or pairs) by N bins")
    if np.any(stderr < 0):
        raise DataError(f"stderr: {int(np.sum(stderr < 0))} negative value(s); give each bin's standard error "
                        f"(>= 0)")
    if replicas is not None:
        replicas = real_array("replicas", replicas)
        if replicas.ndim != 3 or replicas.shape[1:] != rendered.shape or replicas.shape[0] < 2:
            raise DataError(f"replicas: shape {replicas.shape}, expected (R >= 2,) + {rendered.shape}")
    if directions is not None:
        directions = real_array("directions", directions)
        if directions.shape != (2,) + rendered.shape:
            raise DataError(f"directions: shape {directions.shape}, expected (2,) + {rendered.shape}: the "
                            f"model's derivatives along a relative scale and a time offset")
    return rendered, stderr, model, replicas, directions


def _checked_options(false_alarm, max_relative_stderr, worst) -> tuple[float, float, int]:
    if isinstance(max_relative_stderr, bool) or not (isinstance(max_relative_stderr, numbers.Real)
                                                     and 0 < max_relative_stderr <= 1):
        raise OptionError(f"max_relative_stderr: must be a number in (0, 1], got {max_relative_stderr!r}")
    return false_alarm_rate(false_alarm), float(max_relative_stderr), whole_number("worst", worst, smallest=0)


def compare_transients(rendered, stderr, model, *, dof=None, replicas=None, false_alarm: float = 1e-3,
                       max_relative_stderr: float = 0.1, worst: int = 10, flips: int | None = None,
                       directions=None) -> Agreement:
    """Judge a render (with its standard error) against a model.

    Parameters
    ----------
    rendered : array_like
        ``(K, N)`` Monte Carlo estimate of y.
    stderr : array_like
        ``(K, N)`` its standard error (same units).
    model : array_like
        ``(K, N)`` the model's y (or a stated convention's: scale x the
        shifted model).
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
        limits are used and a :class:`CorrelationWarning` says so. Bins
        are then judged by the samples they hold, not by their own spread
        (:func:`judged_bins`).
    false_alarm : float
        α: probability that a correct model fails on pure noise, in
        [1e-12, 0.5].
    max_relative_stderr : float
        Bins are judged only where se < max_relative_stderr |y_render|.
    worst : int
        How many of the largest |z| to list.
    flips : int, optional
        Sign patterns drawn for the replicas' null (default :data:`FLIPS`,
        or more where the smallest tail needs them).
    directions : array_like, optional
        ``(2, K, N)`` the model's derivatives along a relative scale error
        (the model itself, less any stated additive part) and a time offset
        (per metre of path): the data's scale and offset are then tested
        against the model's too (:mod:`validation.judging.directed`), and the
        verdict states the errors it can detect
        (:attr:`Agreement.detectable`).

    Returns
    -------
    Agreement

    Raises
    ------
    DataError
        Arrays that are not real and finite, shapes that differ, negative
        standard errors, replicas of another render; every standard error
        zero, or none under ``max_relative_stderr`` of its value: nothing to
        judge.
    OptionError
        ``false_alarm``, ``dof``, ``max_relative_stderr``, ``worst`` or
        ``flips`` out of range.

    Notes
    -----
    The tests share α equally (Bonferroni: their union's rate is at most α
    whatever their dependence): χ² (two-sided) and max |z|, α/2 each; with
    ``directions`` α/4 each and α/4 to each directed test (α/3 when the
    offset cannot be told from the scale, a response within one bin).
    """
    rendered, stderr, model, replicas, directions = _checked_arrays(rendered, stderr, model, replicas, directions)
    false_alarm, max_relative_stderr, worst = _checked_options(false_alarm, max_relative_stderr, worst)
    dof = _checked_dof(dof, replicas, rendered.shape)
    # in units of the largest value: squares of y ~ 1e-300 (or 1e200) neither underflow nor overflow
    unit = max(float(np.max(np.abs(rendered))), float(np.max(np.abs(model))), float(np.max(stderr)))
    unit = unit if unit > 0 else 1.0
    rendered, stderr, model = rendered / unit, stderr / unit, model / unit
    replicas = None if replicas is None else replicas / unit
    directions = None if directions is None else directions / unit
    sampled = stderr > 0
    if not np.any(sampled):
        raise DataError("stderr: the standard errors are all zero, so no bin has an error to judge it by; "
                        "give each bin's standard error (zero only where no sample landed)")
    judged = judged_bins(rendered, stderr, max_relative_stderr, replicas)
    bins = int(judged.sum())
    skipped = int(sampled.sum()) - bins
    if bins == 0:
        raise DataError(f"render: no bin has a standard error under {max_relative_stderr:g} of its value "
                        f"({int(sampled.sum())} bins with samples): too noisy to judge; render more samples")
    columns = None if directions is None else directed_columns(directions, stderr, judged)
    tests = 2 + (0 if columns is None else columns.shape[0])
    z = np.full(rendered.shape, np.nan)
    z[judged] = normal_scores((rendered[judged] - model[judged]) / stderr[judged], dof[judged])
    chi2 = float(np.sum(z[judged] ** 2))
    count = None if replicas is None else replicas.shape[0]
    null, drawn, interval, threshold = _limits(replicas, rendered, stderr, model, judged, false_alarm, tests, flips)
    note = null_note(null, count, drawn, false_alarm)
    if count is not None and null == INDEPENDENT:
        fewest = fewest_replicas(false_alarm, tests)
        warnings.warn(f"{note}: correlated bins are not accounted for, so the false-alarm rate may exceed α"
                      + (f"; give at least {fewest} replicas" if fewest else ""), CorrelationWarning, stacklevel=2)
    directed = None
    if columns is not None:
        directed = directed_tests(rendered[judged] - model[judged], stderr[judged], columns,
                                  dof=float(np.min(dof[judged])), false_alarm_each=false_alarm / tests,
                                  deviations=None if replicas is None else replicas[:, judged] - model[judged])
    max_abs_z = float(np.nanmax(np.abs(z)))
    order = np.argsort(-np.nan_to_num(np.abs(z), nan=-1.0), axis=None)[:worst]
    worst_bins = [(int(i // z.shape[1]), int(i % z.shape[1]), float(z.flat[i])) for i in order
                  if np.isfinite(z.flat[i])]
    unsampled = [(k, n, value * unit) for k, n, value in _unsampled_light(rendered, stderr, model, dof, sampled,
                                                                           threshold)]
    norm = float(np.linalg.norm(model))
    relative_l2 = float(np.linalg.norm(rendered - model) / norm) if norm > 0 else float("inf")
    chi2_per_dof = chi2 / bins
    agrees = (interval[0] <= chi2_per_dof <= interval[1] and max_abs_z <= threshold and not unsampled
              and (directed is None or directed.agrees))
    return Agreement(agrees, z, float(np.min(dof)), bins, skipped, chi2, chi2_per_dof,
                     (float(interval[0]), float(interval[1])), max_abs_z, threshold, false_alarm, relative_l2,
                     worst_bins, unsampled, null, note, drawn, directed)


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
