"""Is a rendered transient consistent with a modelled one? (DESIGN.md section 6)

Per bin, t = (y_render - y_model) / se_render. If the model is right and
the render unbiased, t follows Student's t with ν degrees of freedom when
se comes from R independent replicas (ν = R - 1: randomised quasi-Monte
Carlo, another renderer's seeds), or the standard normal when se comes from
many independent samples (ν = ∞). Each t is mapped to the normal score with
the same tail probability,

    z = Φ⁻¹(F_ν(t)),

so that the z of the D bins with se > 0 are independent standard normals
under the null hypothesis whatever ν is, and

- χ² = Σ z² follows χ²(D): the model is rejected when χ² leaves the central
  interval [F⁻¹(α/4), F⁻¹(1 - α/4)] of that distribution;
- max |z| exceeds z* = Φ⁻¹(1 - p/2), p = 1 - (1 - α/2)^(1/D) (Šidák), only
  with probability α/2.

Together the two tests raise a false alarm with probability ≤ α (default
1e-3) on pure noise. (With ν small the same |z| needs a larger |t|: a
render's own error estimate is itself uncertain.) z is Gaussian only where the central limit theorem
holds: a bin grazed by a handful of samples (the ends of a response) has a
skewed error and an unreliable se, so only bins with se < 0.1 |y_render|
(roughly 100 samples or more) are judged; the others are counted. Bins where
the render saw no sample (se = 0) fail the check only if the model puts more
there than z* times the largest standard error (light the render should
have seen). The relative L2 error is reported beside the verdict, never
instead of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats

from analytic.errors import DataError

#: Fewest samples for a render that is cross-checked (run, validate, a sweep with cross_check):
#: 128 per replica, so that the bins with light have a standard error to judge them by.
MIN_CHECK_SAMPLES = 2**12

__all__ = ["Agreement", "compare_transients", "assert_transients_agree", "normal_scores", "combined_dof",
           "MIN_CHECK_SAMPLES"]


@dataclass(frozen=True)
class Agreement:
    """The verdict and every figure behind it.

    Attributes
    ----------
    agrees : bool
        True when neither test rejects and no unsampled bin holds model light.
    z : numpy.ndarray
        ``(K, N)`` normal scores of t (equal to t when ν = ∞), NaN where se = 0.
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

    def summary(self) -> str:
        """One paragraph: verdict, χ²/dof, max |z|, thresholds, worst bins."""
        verdict = "AGREE" if self.agrees else "DISAGREE"
        low, high = self.chi2_interval
        worst = ", ".join(f"(sensor {k}, bin {n}, z = {z:+.2f})" for k, n, z in self.worst[:5])
        reference = "normal" if np.isinf(self.dof) else f"Student t, {self.dof:g} degrees of freedom"
        text = (f"{verdict} ({reference}): χ²/dof = {self.chi2_per_dof:.3f} over {self.bins} bins "
                f"({self.skipped} with too few samples not judged) "
                f"(accept [{low:.3f}, {high:.3f}]), max |z| = {self.max_abs_z:.2f} "
                f"(accept ≤ {self.z_threshold:.2f}); false-alarm rate {self.false_alarm:g}; "
                f"relative L2 = {self.relative_l2:.3e}. Worst bins: {worst}")
        if self.unsampled_light:
            text += f". Unsampled bins with model light: {self.unsampled_light[:5]}"
        return text

    def as_dict(self) -> dict:
        """JSON-ready figures (without the z array)."""
        return {"agrees": self.agrees, "dof": float(self.dof), "bins": self.bins, "skipped": self.skipped, "chi2": self.chi2,
                "chi2_per_dof": self.chi2_per_dof, "chi2_interval": list(self.chi2_interval),
                "max_abs_z": self.max_abs_z, "z_threshold": self.z_threshold,
                "false_alarm": self.false_alarm, "relative_l2": self.relative_l2,
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


def compare_transients(rendered, stderr, model, *, dof=np.inf, false_alarm: float = 1e-3,
                       max_relative_stderr: float = 0.1, worst: int = 10) -> Agreement:
    """Judge a render (with its standard error) against a model.

    Parameters
    ----------
    rendered : array_like
        ``(K, N)`` Monte Carlo estimate of y.
    stderr : array_like
        ``(K, N)`` its standard error (same units).
    model : array_like
        ``(K, N)`` the model's y.
    dof : float or array_like
        ν, degrees of freedom of ``stderr``: R - 1 for R replicas
        (``RenderResult.dof``), ``inf`` (default) for errors from many
        independent samples; a ``(K, N)`` array when it differs per bin
        (:func:`combined_dof`).
    false_alarm : float
        α: probability that a correct model fails on pure noise.
    max_relative_stderr : float
        Bins are judged only where se < max_relative_stderr |y_render|.
    worst : int
        How many of the largest |z| to list.

    Returns
    -------
    Agreement
    """
    rendered = np.asarray(rendered, dtype=np.float64)
    stderr = np.asarray(stderr, dtype=np.float64)
    model = np.asarray(model, dtype=np.float64)
    if not rendered.shape == stderr.shape == model.shape:
        raise ValueError(f"shapes differ: render {rendered.shape}, stderr {stderr.shape}, model {model.shape}")
    dof = np.broadcast_to(np.asarray(dof, dtype=np.float64), rendered.shape)
    if np.any(np.isnan(dof)) or np.any(dof <= 0):
        raise ValueError("dof: degrees of freedom must be > 0 (inf for a normal reference)")
    sampled = stderr > 0
    judged = sampled & (stderr < max_relative_stderr * np.abs(rendered))
    bins = int(judged.sum())
    skipped = int(sampled.sum()) - bins
    if bins == 0:
        raise DataError(f"render: no bin has a standard error under {max_relative_stderr:g} of its value "
                        f"({int(sampled.sum())} bins with samples): nothing to judge; render more samples")
    z = np.full(rendered.shape, np.nan)
    z[judged] = normal_scores((rendered[judged] - model[judged]) / stderr[judged], dof[judged])
    chi2 = float(np.sum(z[judged] ** 2))
    half = false_alarm / 2
    interval = (stats.chi2.ppf(half / 2, bins) / bins, stats.chi2.isf(half / 2, bins) / bins)
    per_bin = -np.expm1(np.log1p(-half) / bins)                 # Šidák: 1 - (1 - α/2)^(1/D)
    threshold = float(stats.norm.isf(per_bin / 2))
    max_abs_z = float(np.nanmax(np.abs(z)))
    order = np.argsort(-np.nan_to_num(np.abs(z), nan=-1.0), axis=None)[:worst]
    worst_bins = [(int(i // z.shape[1]), int(i % z.shape[1]), float(z.flat[i])) for i in order
                  if np.isfinite(z.flat[i])]
    # Light the render should have seen: beyond z* standard errors, in t's units.
    limit_t = np.max(np.where(np.isinf(dof), threshold, stats.t.isf(per_bin / 2, np.minimum(dof, 1e300))))
    limit = float(limit_t) * float(stderr.max())
    unsampled = [(int(k), int(n), float(model[k, n])) for k, n in zip(*np.nonzero(~sampled))
                 if abs(model[k, n] - rendered[k, n]) > limit]
    norm = float(np.linalg.norm(model))
    relative_l2 = float(np.linalg.norm(rendered - model) / norm) if norm > 0 else float("inf")
    chi2_per_dof = chi2 / bins
    agrees = (interval[0] <= chi2_per_dof <= interval[1] and max_abs_z <= threshold and not unsampled)
    return Agreement(agrees, z, float(np.min(dof)), bins, skipped, chi2, chi2_per_dof,
                     (float(interval[0]), float(interval[1])), max_abs_z, threshold, false_alarm, relative_l2,
                     worst_bins, unsampled)


def assert_transients_agree(rendered, stderr, model, *, dof=np.inf, false_alarm: float = 1e-3,
                            max_relative_stderr: float = 0.1) -> Agreement:
    """pytest-friendly: raise AssertionError listing the worst bins unless they agree.

    Examples
    --------
    >>> result = render(scene, spp=2**22, seed=1)                  # doctest: +SKIP
    >>> assert_transients_agree(result.mean, result.stderr, forward(scene), dof=result.dof)  # doctest: +SKIP
    """
    agreement = compare_transients(rendered, stderr, model, dof=dof, false_alarm=false_alarm,
                                   max_relative_stderr=max_relative_stderr)
    if not agreement.agrees:
        raise AssertionError(agreement.summary())
    return agreement
