"""The null distributions behind the cross-check's limits, against independent references: simulation of
independent normal bins, and every sign pattern of a few replicas enumerated."""

from __future__ import annotations

import itertools

import numpy as np
from scipy import stats

from validation.judging.null_distribution import flip_count, independent_limits, replica_limits


def test_independent_limits_hold_the_stated_tails_of_independent_normal_bins(rng):
    bins, alpha, trials = 30, 0.1, 40000
    (low, high), threshold = independent_limits(bins, alpha)
    z = rng.standard_normal((trials, bins))
    chi2 = np.sum(z * z, axis=1) / bins
    largest = np.max(np.abs(z), axis=1)
    spread = 5 * np.sqrt(alpha / 4 / trials)
    assert abs(np.mean(chi2 < low) - alpha / 4) < spread
    assert abs(np.mean(chi2 > high) - alpha / 4) < spread
    assert abs(np.mean(largest > threshold) - alpha / 2) < 5 * np.sqrt(alpha / 2 / trials)


def _every_pattern(deviations):
    """χ² and max |z| of every sign pattern, from the definition: t of the flipped replicas, z = Φ⁻¹(F_ν(t))."""
    replicas = deviations.shape[0]
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=replicas)))
    flipped = signs[:, :, None] * deviations[None, :, :]
    t = flipped.mean(axis=1) / (flipped.std(axis=1, ddof=1) / np.sqrt(replicas))
    z = stats.norm.isf(stats.t.sf(t, replicas - 1))
    return np.sum(z * z, axis=1), np.max(np.abs(z), axis=1)


def test_sign_flip_limits_are_the_quantiles_of_every_pattern_of_the_replicas(rng):
    replicas, bins, alpha = 12, 6, 0.1
    # correlated bins, the case the sign flips exist for
    mixing = np.eye(bins) + 0.8 * np.eye(bins, k=1) + 0.5 * np.eye(bins, k=-1)
    deviations = rng.standard_normal((replicas, bins)) @ mixing
    drawn = flip_count(alpha, None)
    (low, high), threshold = replica_limits(deviations, bins, alpha, drawn)
    chi2, largest = _every_pattern(deviations)
    # the limits are order statistics of `drawn` random patterns: their tails are α/4 and α/2 up to the
    # binomial spread of that many draws
    for tail, observed in ((alpha / 4, np.mean(chi2 <= low * bins)), (alpha / 4, np.mean(chi2 >= high * bins)),
                           (alpha / 2, np.mean(largest >= threshold))):
        assert abs(observed - tail) < 5 * np.sqrt(tail * (1 - tail) / drawn) + 2.0 / len(chi2)
