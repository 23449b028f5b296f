"""The photon-counting detector: expected histograms against a direct simulation, draws, Coates' inversion.

The direct simulation is written here and shares nothing with
``analytic.measurement.detector``: per laser cycle, the photons of each bin are drawn
(Poisson), and a dead-time detector keeps the first one. Thresholds come
from the simulation's own standard errors; a detector model that forgets
the pile-up (or the background) must fail them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from analytic.measurement.detector import Detector, coates_estimate, detection_probabilities, draw_counts, expected_counts
from analytic.errors import DataError, SceneError
from analytic.scenes.scene_file import scene_from_dict, scene_to_tables

# a pulse over 12 bins, high enough that pile-up matters (Σλ ≈ 1.4 photons per cycle)
Y = np.array([[0.0, 0.1, 0.8, 2.0, 3.0, 2.2, 1.2, 0.6, 0.3, 0.1, 0.0, -0.2]])
Z_LIMIT = 4.5       # per-bin |z| (Šidák over 12 bins at ~1e-4)


def _simulate(y, detector, cycles, rng):
    """Per cycle: Poisson photons per bin; every one counted, or only the cycle's first (dead time)."""
    lam = detector.photons * np.maximum(y, 0) + detector.background
    photons = rng.poisson(lam, size=(cycles, lam.size))
    if detector.dead_time == "none":
        return photons.sum(axis=0)
    fired = photons > 0
    first = np.where(fired.any(axis=1), fired.argmax(axis=1), -1)
    return np.bincount(first[first >= 0], minlength=lam.size)


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_expected_histogram_matches_a_direct_simulation(dead_time):
    rng = np.random.default_rng(7)
    detector = Detector(photons=0.1, background=0.02, cycles=200_000, dead_time=dead_time)
    simulated = _simulate(Y[0], detector, 200_000, rng)
    expected = expected_counts(Y, detector)[0]
    z = (simulated - expected) / np.sqrt(expected)
    assert np.max(np.abs(z)) < Z_LIMIT, z
    if dead_time == "cycle":
        # pile-up is seen: the dead-time-free histogram is wrong by many standard errors
        wrong = expected_counts(Y, Detector(photons=0.1, background=0.02, cycles=200_000))[0]
        assert np.max(np.abs(simulated - wrong) / np.sqrt(wrong)) > 20
    without_background = expected_counts(Y, Detector(photons=0.1, cycles=200_000, dead_time=dead_time))[0]
    assert np.max(np.abs(simulated - without_background) / np.sqrt(expected)) > 20


def test_coates_probabilities_sum_to_one_and_keep_small_rates_exact():
    lam = np.array([1e-300, 1e-12, 0.5, 3.0, 40.0, 800.0, 0.0])
    p, none = detection_probabilities(lam)
    assert np.sum(p) + none == pytest.approx(1.0, abs=1e-15)
    assert p[0] == 1e-300 and p[1] == pytest.approx(1e-12, rel=1e-15)
    assert p[-1] == 0.0 and none == 0.0
    # photons x y per bin far below one: the dead time changes nothing to first order
    faint = expected_counts(Y * 1e-9, Detector(photons=1.0, cycles=1e6, dead_time="cycle"))
    np.testing.assert_allclose(faint, 1e6 * 1e-9 * np.maximum(Y, 0), rtol=2e-8)


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_draws_have_the_expected_mean_and_spread(dead_time):
    detector = Detector(photons=0.2, background=0.01, cycles=5000, dead_time=dead_time, seed=3)
    draws = np.array([draw_counts(Y, detector, np.random.default_rng(seed)) for seed in range(400)])[:, 0]
    expected = expected_counts(Y, detector)[0]
    mean_z = (draws.mean(axis=0) - expected) / np.sqrt(expected / len(draws))
    assert np.max(np.abs(mean_z)) < Z_LIMIT
    if dead_time == "cycle":    # multinomial: the variance is C p (1 - p), and the counts never exceed C
        variance = expected * (1 - expected / detector.cycles)
        assert np.all(draws.sum(axis=1) <= detector.cycles)
    else:
        variance = expected
    ratio = draws.var(axis=0, ddof=1) / variance
    # the sample variance of 400 draws: chi2(399)/399, |ratio - 1| < 5 sigma = 5 sqrt(2/399)
    assert np.all(np.abs(ratio - 1) < 5 * np.sqrt(2 / 399))
    assert np.array_equal(draw_counts(Y, detector), draw_counts(Y, detector))       # the scene's seed


def test_coates_inversion_recovers_the_rates():
    detector = Detector(photons=0.3, background=0.005, cycles=400_000, dead_time="cycle", seed=11)
    counts = draw_counts(Y, detector)[0]
    estimate, variance = coates_estimate(counts, detector.cycles)
    truth = detector.photons * np.maximum(Y[0], 0) + detector.background
    z = (estimate - truth) / np.sqrt(variance)
    assert np.max(np.abs(z)) < Z_LIMIT
    # the raw histogram divided by the cycles is biased low late in the pulse: Coates' correction is needed
    raw = counts / detector.cycles
    assert np.max(np.abs(raw - truth) / np.sqrt(variance)) > 20
    # exactly: the expected histogram inverts to the rates
    exact, _ = coates_estimate(expected_counts(Y, detector)[0], detector.cycles)
    np.testing.assert_allclose(exact, truth, rtol=1e-12)


def test_detector_table_is_read_checked_and_written_back():
    tables = {"sensors": {"positions": [[0.2, 0.7, 1.0]]},
              "detector": {"photons": 0.05, "background": 1e-4, "cycles": 1e6, "dead_time": "cycle", "seed": 4}}
    scene = scene_from_dict(tables)
    assert scene.detector == Detector(photons=0.05, background=1e-4, cycles=1e6, dead_time="cycle", seed=4)
    assert scene_from_dict(scene_to_tables(scene)).detector == scene.detector
    for key, value, message in (("photons", -1.0, "detector.photons: must be > 0"),
                                ("cycles", 2.5, "detector.cycles: must be a whole number"),
                                ("dead_time", "paralyzable", "detector.dead_time: must be one of"),
                                ("background", float("nan"), "detector.background: must be finite"),
                                ("seed", 2**32, "detector.seed: must be <="),
                                ("dwell", 1.0, "detector.dwell: unknown key")):
        bad = {"sensors": tables["sensors"], "detector": dict(tables["detector"], **{key: value})}
        with pytest.raises(SceneError, match=message):
            scene_from_dict(bad)
    with pytest.raises(SceneError, match="detector.photons: required"):
        scene_from_dict({"detector": {"cycles": 10}})


def test_relay_wall_scenes_take_a_detector():
    scene = scene_from_dict({"relay_wall": {"size": [2.0, 2.0]}, "detector": {"photons": 2.0}})
    assert scene.detector == Detector(photons=2.0)
    assert scene_to_tables(scene)["detector"]["photons"] == 2.0


def test_negative_y_brings_no_photons_and_huge_means_are_refused():
    detector = Detector(photons=1.0, cycles=10)
    assert expected_counts(np.array([-5.0]), detector)[0] == 0.0
    with pytest.raises(SceneError, match="detector.photons"):
        draw_counts(np.array([1e20]), detector)


def _first_photon_reference(lam):
    """p_n with Λ_n summed by ``math.fsum`` (correctly rounded, from the start), in plain Python floats."""
    p = []
    for n, rate in enumerate(lam):
        before = math.fsum(lam[:n])
        p.append(0.0 if before == math.inf else math.exp(-before) * -math.expm1(-rate))
    return np.array(p)


@pytest.mark.parametrize("lam", [
    [1.0, 1.0, 1e300, 1.0, 1.0],                 # one bin of extreme pile-up after a background
    [1e-3, 1e-3, 1e300, 1e300, 1e-3],            # Λ beyond float64 after it
    [0.5, 3e16, 0.25, 1e-12, 2.0],               # a rate that swallows the ones before it in a running sum
    [1e-300, 1e-300, 1e-300, 2.0, 1e-300],
])
def test_first_photon_probabilities_keep_the_photons_before_each_bin(lam):
    p, none = detection_probabilities(np.array(lam))
    reference = _first_photon_reference(lam)
    np.testing.assert_allclose(p, reference, rtol=1e-14, atol=0)
    assert math.fsum(p) <= 1.0 and 0.0 <= none <= 1.0


def test_extreme_pile_up_never_counts_more_than_the_cycles():
    # issue 38: photons 1e300 made the first lit bin take every cycle again
    rng = np.random.default_rng(5)
    y = np.concatenate([np.zeros((3, 4)), rng.uniform(0.0, 1.0, (3, 6)), np.zeros((3, 2))], axis=1)
    for photons in (1e300, 1e200, 1e20, 3.0):
        for background in (0.0, 1.0, 1e-6):
            detector = Detector(photons=photons, background=background, cycles=1e5, dead_time="cycle")
            expected = expected_counts(y, detector)
            assert np.all(np.isfinite(expected)) and np.all(expected >= 0)
            assert np.all(expected.sum(axis=1) <= detector.cycles)
            assert all(math.fsum(row) <= detector.cycles for row in expected)
            np.testing.assert_allclose(expected[0], 1e5 * _first_photon_reference(list(
                detector.photons * y[0] + background)), rtol=1e-13)
            drawn = draw_counts(y, detector)
            assert np.all(drawn.sum(axis=1) <= detector.cycles)
    # the first lit bin after 4 bins of background 1: e^-4 (1 - 0) of the cycles reach it
    detector = Detector(photons=1e300, background=1.0, cycles=1e5, dead_time="cycle")
    assert expected_counts(y, detector)[0, 4] == pytest.approx(1e5 * math.exp(-4.0), rel=1e-14)


def test_counts_beyond_float64_without_dead_time_are_refused():
    detector = Detector(photons=1e306, cycles=1e5)
    with pytest.raises(SceneError, match="detector.photons: an expected count is beyond"):
        expected_counts(np.array([[0.0, 0.5]]), detector)
    with pytest.raises(SceneError, match="detector.photons"):
        draw_counts(np.array([[0.0, 0.5]]), detector)


def test_coates_inversion_keeps_the_cycles_armed_with_huge_counts():
    # a running sum minus the bin cancels when one count dwarfs the ones before it
    counts = np.array([3.0, 2.0**60, 5.0])
    cycles = 2.0**61
    estimate, variance = coates_estimate(counts, cycles)
    armed = [cycles, cycles - 3.0, cycles - 3.0 - 2.0**60]
    reference = [-math.log1p(-c / r) for c, r in zip(counts, armed)]
    np.testing.assert_allclose(estimate, reference, rtol=1e-14)
    assert np.all(np.isfinite(variance)) and np.all(variance > 0)
    huge, huge_variance = coates_estimate(np.array([1e300, 1e299]), 1e301)
    assert np.all(np.isfinite(huge)) and np.all(np.isfinite(huge_variance))
    with pytest.raises(DataError, match="cycles must be finite"):
        coates_estimate(counts, float("nan"))


def test_counts_past_the_limit_name_the_background_when_it_alone_is_the_cause():
    detector = Detector(photons=1e-300, background=1e305, cycles=1e5)        # 1e310 expected per bin
    for count in (expected_counts, draw_counts):
        with pytest.raises(SceneError) as caught:
            count(np.array([[0.0, 0.5]]), detector)
        assert caught.value.key == "detector.background" and "lower background or cycles" in str(caught.value)
    with pytest.raises(SceneError) as caught:
        draw_counts(np.array([[0.0, 0.5]]), Detector(photons=1e30, background=1.0, cycles=1e5))
    assert caught.value.key == "detector.photons"
