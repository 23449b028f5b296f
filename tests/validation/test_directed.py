"""The directed tests of a stated scale and offset (docs/design.md section 6): their false-alarm rate, their
power, and the `detectable` errors they state, by Monte Carlo over seeds with our own model and noise."""

from __future__ import annotations

import numpy as np
import pytest

from analytic.operator.matrix_free import forward
from check_cases import WIDTH, shifted, small_scene
from validation.judging.compare import compare_transients

ALPHA = 0.1           # large, so that each test's share α/4 is seen often enough to count


@pytest.fixture(scope="module")
def model():
    """The small scene's y over the bins that hold light, and its derivatives along a scale and an offset."""
    scene = small_scene()
    y = forward(scene)
    step = 1e-3 * WIDTH
    return scene, y, np.stack([y, (shifted(scene, step) - y) / step])


def _sigma(y, relative=0.01):
    """A standard error of ``relative`` of each bin (0 where there is no light): every lit bin is judged,
    whatever its noise, so that no bin is chosen by its own draw."""
    return relative * np.abs(y)


def _failures(agreement) -> np.ndarray:
    """(χ², max |z|, scale, offset): which test rejected."""
    low, high = agreement.chi2_interval
    directed = agreement.directed
    return np.array([not low <= agreement.chi2_per_dof <= high, agreement.max_abs_z > agreement.z_threshold,
                     abs(directed.scale_t) > directed.limit, abs(directed.shift_t) > directed.limit])


def _binomial(trials, rate):
    return 3 * np.sqrt(trials * rate * (1 - rate))


def test_each_test_keeps_its_share_with_given_standard_errors(model, rng):
    """Normal errors given per bin: each of the four tests fails at its share α/4, the union at most α."""
    _, y, directions = model
    sigma = _sigma(y)
    trials = 2000
    counts, union = np.zeros(4), 0
    for _ in range(trials):
        agreement = compare_transients(y + sigma * rng.standard_normal(y.shape), sigma, y, directions=directions,
                                       false_alarm=ALPHA)
        counts += _failures(agreement)
        union += not agreement.agrees
    share = ALPHA / 4
    assert np.all(np.abs(counts - share * trials) <= _binomial(trials, share)), counts
    assert union <= ALPHA * trials + _binomial(trials, ALPHA), union


def test_each_test_keeps_its_share_with_replicas(model, rng):
    """R = 16 replicas (Student t, weights from the other replicas; sign-flip limits for χ² and max |z|)."""
    _, y, directions = model
    sigma = 4 * _sigma(y)
    trials = 600
    counts, union = np.zeros(4), 0
    for _ in range(trials):
        replicas = y + sigma * rng.standard_normal((16,) + y.shape)
        agreement = compare_transients(replicas.mean(axis=0), replicas.std(axis=0, ddof=1) / 4, y,
                                       replicas=replicas, directions=directions, false_alarm=ALPHA, flips=1024)
        assert agreement.null == "sign-flip" and agreement.directed.dof == 15
        counts += _failures(agreement)
        union += not agreement.agrees
    share = ALPHA / 4
    assert np.all(np.abs(counts[2:] - share * trials) <= _binomial(trials, share)), counts
    assert union <= ALPHA * trials + _binomial(trials, ALPHA), union


def test_a_one_percent_scale_error_is_caught_where_chi2_cannot_see_it(rng):
    """A smooth response over 800 bins, noise at which 1 % lies 6 standard errors of the scale from the
    truth: χ² and max |z| (which spread those 6 over every bin) pass it, the directed scale test fails it."""
    time = np.linspace(0.0, 1.0, 200)
    y = np.array([np.exp(-((time - centre) / 0.2) ** 2) for centre in (0.3, 0.4, 0.5, 0.6)])
    directions = np.stack([y, np.gradient(y, time, axis=1)])
    sigma = 0.01 * np.sqrt(y.size) / 6 * y           # Σ (0.01 y / σ)² = 6²
    caught = omnibus = 0
    for _ in range(50):
        agreement = compare_transients(1.01 * y + sigma * rng.standard_normal(y.shape), sigma, y,
                                       directions=directions)
        failures = _failures(agreement)
        caught += bool(failures[2])
        omnibus += bool(failures[0] or failures[1])
        # the offset, fitted beside it, takes a little of the scale's information: a little above 1/6 of 1 %
        assert agreement.detectable["scale"] == pytest.approx(0.01 * agreement.directed.limit / 6, rel=0.05)
    assert caught >= 47 and omnibus <= 5, (caught, omnibus)


@pytest.mark.parametrize("kind", ["scale", "shift_opl"])
def test_an_error_of_exactly_detectable_is_flagged_half_the_time(model, rng, kind):
    """`detectable` is the error flagged with probability 1/2: given standard errors, exact (normal t, Fisher
    information); the omnibus tests add a little (allowed: 0.08)."""
    scene, y, directions = model
    sigma = _sigma(y, 0.02)
    null = compare_transients(y, sigma, y, directions=directions)
    size = null.detectable[kind]
    truth = (1 + size) * y if kind == "scale" else shifted(scene, -size)   # data reading path lengths long
    trials = 400
    flagged = directed = 0
    for _ in range(trials):
        agreement = compare_transients(truth + sigma * rng.standard_normal(y.shape), sigma, y, directions=directions)
        assert agreement.detectable[kind] == pytest.approx(size)
        flagged += not agreement.agrees
        directed += _failures(agreement)[2 if kind == "scale" else 3]
    spread = _binomial(trials, 0.5)
    assert abs(directed - trials / 2) <= spread, directed
    assert trials / 2 - spread <= flagged <= trials * 0.58 + spread, flagged


def test_detectable_with_replicas_is_flagged_half_the_time(model, rng):
    """With replicas the standard error is estimated (Student t): an error of the typical `detectable` is
    still flagged about half the time."""
    _, y, directions = model
    sigma = 4 * _sigma(y)

    def judged(truth):
        replicas = truth + sigma * rng.standard_normal((16,) + y.shape)
        return compare_transients(replicas.mean(axis=0), replicas.std(axis=0, ddof=1) / 4, y, replicas=replicas,
                                  directions=directions, false_alarm=ALPHA, flips=1024)

    size = np.median([judged(y).detectable["scale"] for _ in range(40)])
    trials = 300
    directed = sum(_failures(judged((1 + size) * y))[2] for _ in range(trials))
    assert abs(directed - trials / 2) <= _binomial(trials, 0.5) + 0.04 * trials, directed


def test_detectable_falls_as_one_over_the_square_root_of_the_samples(model):
    """Four times the samples (half the standard error): half the detectable error."""
    _, y, directions = model
    sigma = _sigma(y)
    once = compare_transients(y, sigma, y, directions=directions).detectable
    four = compare_transients(y, sigma / 2, y, directions=directions).detectable
    assert four["scale"] == pytest.approx(once["scale"] / 2, rel=1e-9)
    assert four["shift_opl"] == pytest.approx(once["shift_opl"] / 2, rel=1e-9)


def test_without_directions_there_are_two_tests_and_no_stated_power(model, rng):
    _, y, directions = model
    sigma = _sigma(y)
    data = y + sigma * rng.standard_normal(y.shape)
    plain = compare_transients(data, sigma, y)
    directed = compare_transients(data, sigma, y, directions=directions)
    assert plain.directed is None and plain.detectable is None and "detectable" not in plain.summary()
    # four tests share α: χ² and max |z| get half of what they get alone
    assert directed.z_threshold > plain.z_threshold
    assert "detectable" in directed.summary() and directed.as_dict()["detectable"] == directed.detectable


def test_an_offset_that_cannot_be_told_from_the_scale_is_not_tested(rng):
    """A response whose shift moves no light between the judged bins: the scale alone, at α/3."""
    y = np.full((1, 12), 2.0)
    sigma = np.full(y.shape, 0.01)
    directions = np.stack([y, np.zeros_like(y)])
    agreement = compare_transients(y + sigma * rng.standard_normal(y.shape), sigma, y, directions=directions)
    assert agreement.directed.count == 1 and agreement.detectable["shift_opl"] is None
    assert agreement.directed.false_alarm_each == pytest.approx(1e-3 / 3)
