"""Bin kernels as Taylor series: the polynomial kept matches the kernel itself within the tolerance."""

import numpy as np
import pytest

from analytic.kernels.bins import BinRun, TimeAxis
from analytic.scenes.common import Illumination, Sampling
from analytic.kernels.taylor import MAX_TERMS, kernel_taylor
from analytic.waveforms import make_waveform

PERIOD = 0.1
RTOL = 1e-7


def _kinks(waveform, sampling):
    """Every path length where some κ_n has a kink: t_n shifted back by each kink of the pulse."""
    return np.add.outer(sampling.edges, -np.asarray(waveform.breakpoints)).ravel()


def _ranges(waveform, sampling, rng, count):
    """Random (centre, half) ranges of path length that no kink crosses."""
    kinks = np.sort(_kinks(waveform, sampling))
    found = []
    while len(found) < count:
        centre = rng.uniform(sampling.edges[1], sampling.edges[-3])
        room = np.min(np.abs(kinks - centre))
        half = room * rng.uniform(0.05, 0.999)
        found.append((centre, half))
    return found


@pytest.mark.parametrize("illumination", [Illumination(waveform="impulse"), Illumination(waveform="square", width=0.07),
                                          Illumination(waveform="butterworth"),
                                          Illumination(waveform="butterworth", order=1),
                                          Illumination(waveform="butterworth", order=8, cutoff=2.0)])
def test_taylor_polynomials_match_the_kernels(illumination, rng):
    """Σ_j c_{n,j} (τ - c)^j against κ_n(τ) from NumPy's piecewise evaluation, all over the range."""
    waveform = make_waveform(illumination, PERIOD)
    sampling = Sampling(bin_width_opl=PERIOD, start_opl=0.0, count=40)
    axis = TimeAxis(sampling.start_opl, sampling.bin_width_opl, sampling.count)
    run = BinRun(0, sampling.count)
    coefficients = np.zeros((sampling.count, MAX_TERMS))
    scratch = np.zeros(MAX_TERMS + 1), np.zeros(MAX_TERMS + 1)
    counts = []          # terms of each range the polynomials serve
    for centre, half in _ranges(waveform, sampling, rng, 40):
        count = kernel_taylor(waveform.terms, axis, run, centre, half, RTOL, coefficients, *scratch)
        if count == 0:
            continue
        counts.append(count)
        tau = centre + half * np.linspace(-1.0, 1.0, 21)
        series = np.polynomial.polynomial.polyval(tau - centre, coefficients[:, :count].T)   # (N, 21)
        exact = waveform.kernel(tau, sampling)
        scale = np.max(np.abs(exact), axis=1, keepdims=True)
        assert np.all(np.abs(series - exact) <= RTOL * scale + 1e-15 * np.max(scale))
    assert len(counts) >= 30
    if waveform.terms.degree >= 0:       # polynomial pieces: exactly degree + 1 terms, never more, in every range
        assert set(counts) == {waveform.terms.degree + 1}, counts


def test_a_range_far_longer_than_the_pulse_needs_too_many_terms():
    """A kernel across a whole ringing Butterworth pulse is no low-degree polynomial: 0, the caller goes direct."""
    waveform = make_waveform(Illumination(waveform="butterworth", order=4, cutoff=50.0, duration=0.06), 0.01)
    axis = TimeAxis(0.0, 1.0, 4)
    coefficients = np.zeros((4, MAX_TERMS))
    # τ in [1.9406, 1.9994]: u = 2 - τ runs over the whole pulse [0, 0.06] (its kinks just outside)
    count = kernel_taylor(waveform.terms, axis, BinRun(0, 4), 1.97, 0.0294, RTOL, coefficients,
                          np.zeros(MAX_TERMS + 1), np.zeros(MAX_TERMS + 1))
    assert count == 0
