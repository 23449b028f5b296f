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
1e-3) on pure noise. Their limits come from the sign flips of R independent
replicas where R resolves the tail α/4 (:func:`replica_null_resolves`),
valid whatever the correlation between bins; otherwise from χ²(D) and
Šidák, which assume independent bins, with a :class:`CorrelationWarning`
where replicas were given (:mod:`validation.null_distribution` derives
both). The verdict and its figures are an
:class:`validation.agreement.Agreement`.

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

import warnings

import numpy as np
from scipy import stats

from analytic.errors import DataError

from validation.agreement import INDEPENDENT, SIGN_FLIP, Agreement, null_note
from validation.null_distribution import (FLIPS, TAIL_PATTERNS, flip_count, independent_limits,
                                          normal_scores, replica_deviations, replica_limits)

__all__ = ["Agreement", "compare_transients", "assert_transients_agree", "normal_scores", "combined_dof",
           "replica_null_resolves", "CorrelationWarning", "MIN_CHECK_SAMPLES", "FLIPS", "MODEL_SHARE",
           "model_tolerance_for", "tighter_model_note"]

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
    smallest relative error, not below :data:`analytic.scene.MIN_TOLERANCE`
    (where the data are more precise still, :func:`tighter_model_note` says
    so).
    """
    from analytic.scene import MIN_TOLERANCE

    values, stderr = np.asarray(values, dtype=np.float64), np.asarray(stderr, dtype=np.float64)
    judged = (stderr > 0) & (stderr < max_relative_stderr * np.abs(values))
    if not np.any(judged):
        return None
    needed = MODEL_SHARE * float(np.min(stderr[judged] / np.abs(values[judged])))
    return None if tolerance <= needed else max(needed, MIN_TOLERANCE)


def tighter_model_note(tolerance: float, scene_tolerance: float) -> str:
    """Why data were judged against the model at ``tolerance`` (:func:`model_tolerance_for`), in words."""
    from analytic.scene import MIN_TOLERANCE

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


def replica_null_resolves(replicas: int, false_alarm: float) -> bool:
    """Whether R replicas have sign patterns enough for the sign-flip null at false-alarm rate α.

    The smallest tail, α/4, must hold at least
    :data:`validation.null_distribution.TAIL_PATTERNS` of the 2^(R-1)
    distinct patterns (flipping every sign gives the same χ² and max |z|):
    R >= 15 at α = 1e-3, R >= 9 at α = 0.1.
    """
    return replicas >= 2 and (false_alarm / 4) * 2.0 ** (replicas - 1) >= TAIL_PATTERNS


# --------------------------------------------------------------------------- the verdict

def _limits(replicas, rendered, stderr, model, judged, false_alarm: float, flips: int | None):
    """(null, patterns drawn, χ²/D interval, z*): from the replicas' sign flips where they resolve α/4."""
    bins = int(judged.sum())
    if replicas is not None and replica_null_resolves(replicas.shape[0], false_alarm):
        drawn = flip_count(false_alarm, flips)
        deviations = replica_deviations(replicas, rendered, stderr, model, judged)
        return (SIGN_FLIP, drawn) + replica_limits(deviations, bins, false_alarm, drawn)
    return (INDEPENDENT, 0) + independent_limits(bins, false_alarm)


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
    note = null_note(null, count, drawn, false_alarm)
    if count is not None and null == INDEPENDENT:
        warnings.warn(f"{note}: correlated bins, and bins lit by a few samples per replica (whose spread can "
                      f"come out near 0), are not accounted for, so the false-alarm rate may exceed α; give at "
                      f"least {_fewest_replicas(false_alarm)} replicas", CorrelationWarning,
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
