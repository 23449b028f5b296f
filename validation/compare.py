"""Is a rendered transient consistent with a modelled one? (DESIGN.md section 6)

Per bin, z = (y_render - y_model) / se_render. If the model is right and the
render unbiased, the z of the D bins with se > 0 are (for large sample
counts) independent standard normals, so

- χ² = Σ z² follows χ²(D): the model is rejected when χ² leaves the central
  interval [F⁻¹(α/4), F⁻¹(1 - α/4)] of that distribution;
- max |z| exceeds z* = Φ⁻¹(1 - p/2), p = 1 - (1 - α/2)^(1/D) (Šidák), only
  with probability α/2.

Together the two tests raise a false alarm with probability ≤ α (default
1e-3) on pure noise. z is Gaussian only where the central limit theorem
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
from scipy import stats

__all__ = ["Agreement", "compare_transients", "assert_transients_agree"]


@dataclass(frozen=True)
class Agreement:
    """The verdict and every figure behind it.

    Attributes
    ----------
    agrees : bool
        True when neither test rejects and no unsampled bin holds model light.
    z : numpy.ndarray
        ``(K, N)`` z-scores, NaN where se = 0.
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
        text = (f"{verdict}: χ²/dof = {self.chi2_per_dof:.3f} over {self.bins} bins "
                f"({self.skipped} with too few samples not judged) "
                f"(accept [{low:.3f}, {high:.3f}]), max |z| = {self.max_abs_z:.2f} "
                f"(accept ≤ {self.z_threshold:.2f}); false-alarm rate {self.false_alarm:g}; "
                f"relative L2 = {self.relative_l2:.3e}. Worst bins: {worst}")
        if self.unsampled_light:
            text += f". Unsampled bins with model light: {self.unsampled_light[:5]}"
        return text

    def as_dict(self) -> dict:
        """JSON-ready figures (without the z array)."""
        return {"agrees": self.agrees, "bins": self.bins, "skipped": self.skipped, "chi2": self.chi2,
                "chi2_per_dof": self.chi2_per_dof, "chi2_interval": list(self.chi2_interval),
                "max_abs_z": self.max_abs_z, "z_threshold": self.z_threshold,
                "false_alarm": self.false_alarm, "relative_l2": self.relative_l2,
                "worst": [list(map(float, w)) for w in self.worst],
                "unsampled_light": [list(map(float, w)) for w in self.unsampled_light]}


def compare_transients(rendered, stderr, model, *, false_alarm: float = 1e-3,
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
    sampled = stderr > 0
    judged = sampled & (stderr < max_relative_stderr * np.abs(rendered))
    bins = int(judged.sum())
    skipped = int(sampled.sum()) - bins
    z = np.full(rendered.shape, np.nan)
    z[judged] = (rendered[judged] - model[judged]) / stderr[judged]
    if bins == 0:
        raise ValueError("no bin has a positive standard error: nothing to judge")
    chi2 = float(np.sum(z[judged] ** 2))
    half = false_alarm / 2
    interval = (stats.chi2.ppf(half / 2, bins) / bins, stats.chi2.isf(half / 2, bins) / bins)
    per_bin = -np.expm1(np.log1p(-half) / bins)                 # Šidák: 1 - (1 - α/2)^(1/D)
    threshold = float(stats.norm.isf(per_bin / 2))
    max_abs_z = float(np.nanmax(np.abs(z)))
    order = np.argsort(-np.nan_to_num(np.abs(z), nan=-1.0), axis=None)[:worst]
    worst_bins = [(int(i // z.shape[1]), int(i % z.shape[1]), float(z.flat[i])) for i in order
                  if np.isfinite(z.flat[i])]
    limit = threshold * float(stderr.max())
    unsampled = [(int(k), int(n), float(model[k, n])) for k, n in zip(*np.nonzero(~sampled))
                 if abs(model[k, n] - rendered[k, n]) > limit]
    norm = float(np.linalg.norm(model))
    relative_l2 = float(np.linalg.norm(rendered - model) / norm) if norm > 0 else float("inf")
    chi2_per_dof = chi2 / bins
    agrees = (interval[0] <= chi2_per_dof <= interval[1] and max_abs_z <= threshold and not unsampled)
    return Agreement(agrees, z, bins, skipped, chi2, chi2_per_dof, (float(interval[0]), float(interval[1])),
                     max_abs_z, threshold, false_alarm, relative_l2, worst_bins, unsampled)


def assert_transients_agree(rendered, stderr, model, *, false_alarm: float = 1e-3,
                            max_relative_stderr: float = 0.1) -> Agreement:
    """pytest-friendly: raise AssertionError listing the worst bins unless they agree.

    Examples
    --------
    >>> result = render(scene, spp=2**22, seed=1)                  # doctest: +SKIP
    >>> assert_transients_agree(result.mean, result.stderr, forward(scene))  # doctest: +SKIP
    """
    agreement = compare_transients(rendered, stderr, model, false_alarm=false_alarm,
                                   max_relative_stderr=max_relative_stderr)
    if not agreement.agrees:
        raise AssertionError(agreement.summary())
    return agreement
