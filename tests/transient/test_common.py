"""transient.common: the physics once per backend, the sample points, the deposit.

S(u) and the attenuation exist in NumPy (analytic), Numba (analytic) and
Dr.Jit (transient.common): the three must agree to 1e-12 on random inputs,
including the Butterworth pulse's series branch near u = 0. The jittered
points must stratify, replica indices must be exact, and the deposit must
give the sums of a direct per-sample binning whatever scatter strategy it
uses.
"""

from __future__ import annotations

import numpy as np
import pytest

from analytic.scenes.common import Illumination, Sampling
from analytic.waveforms import make_waveform
from compiled_kernels import compiled_cumulative, compiled_kernels
from deposited_kernels import deposited_kernels, traced_cumulative
from transient import backend

WAVEFORMS = ["impulse", "square", "butterworth"]


@pytest.fixture(scope="module")
def mitsuba():
    backend.select_variant()
    import mitsuba

    return mitsuba


def _first_piece_end(waveform):
    """Where the waveform's first piece ends (the Butterworth pulse's series hands over), metres."""
    starts = waveform.terms.starts
    return float(starts[1]) if len(starts) > 1 else waveform.duration


def _arguments(waveform, rng, size=4000):
    """Random u over the pulse, plus points inside the first piece and on every piece's start."""
    span = max(waveform.duration, 1e-3)
    return np.concatenate([rng.uniform(-0.5 * span, 1.5 * span, size),
                           span * 10.0 ** rng.uniform(-12, 0, size),           # near 0: S ~ u^order
                           np.asarray(waveform.terms.starts, dtype=np.float64), [0.0, -0.0, 1e-300],
                           rng.uniform(0.0, _first_piece_end(waveform), size)])


@pytest.mark.parametrize("name", WAVEFORMS)
@pytest.mark.parametrize("period", [1e-3, 0.1, 10.0])
def test_cumulative_agrees_in_numpy_numba_and_drjit(mitsuba, rng, name, period):
    waveform = make_waveform(Illumination(waveform=name), period)
    u = _arguments(waveform, rng)
    numpy_values = waveform.cumulative(u)
    terms = waveform.terms
    numba_values = compiled_cumulative(terms, u)
    drjit_values = traced_cumulative(mitsuba, terms, u)
    np.testing.assert_allclose(numba_values, numpy_values, rtol=1e-12, atol=0)
    np.testing.assert_allclose(drjit_values, numpy_values, rtol=1e-12, atol=0)
    if name == "butterworth":
        inside = (u > 1e-30) & (u < _first_piece_end(waveform))      # S ~ u³ stays above the underflow
        assert inside.sum() > 1000                      # the series branch was exercised
        assert np.all(drjit_values[inside] > 0)


def test_attenuation_agrees_in_numpy_numba_and_drjit(mitsuba, rng):
    from analytic.attenuation import attenuation as numpy_attenuation
    from analytic.kernels.formulas import LAMBERTIAN
    from analytic.kernels.isochrone import attenuation_at, make_frame
    from transient.common import attenuation

    for _ in range(20):
        source = np.array([*rng.uniform(-1, 2, 2), 10.0 ** rng.uniform(-3, 2)])
        sensor = np.array([*rng.uniform(-1, 2, 2), 10.0 ** rng.uniform(-3, 2)])
        points = rng.uniform(0, 1, (500, 2))
        expected = numpy_attenuation(points, source, sensor, "lambertian")
        frame = make_frame(source, sensor, LAMBERTIAN)
        compiled = np.array([attenuation_at(frame, x, y) for x, y in points])
        traced = np.array(attenuation(mitsuba.Float64(points[:, 0]), mitsuba.Float64(points[:, 1]),
                                      source, sensor), dtype=np.float64)
        np.testing.assert_allclose(compiled, expected, rtol=1e-12, atol=0)
        np.testing.assert_allclose(traced, expected, rtol=1e-12, atol=0)


@pytest.mark.parametrize("count", [1, 2, 7, 64, 1000, 2**12 + 2**5 + 1])
def test_jittered_points_stratify_each_power_of_two_block(mitsuba, rng, count):
    """Each block of 2^p points has exactly one point per cell of its 2^⌈p/2⌉ x 2^⌊p/2⌋ grid."""
    from transient.common import jittered_point

    u, v = jittered_point(mitsuba.UInt32(np.arange(count, dtype=np.uint32)), mitsuba.UInt32(count),
                          mitsuba.Float64(rng.random(count)), mitsuba.Float64(rng.random(count)))
    u, v = np.array(u), np.array(v)
    assert np.all((u >= 0) & (u < 1) & (v >= 0) & (v < 1))
    start = 0
    for bit in range(31, -1, -1):
        if not count >> bit & 1:
            continue
        size = 2**bit
        columns, rows = 2 ** ((bit + 1) // 2), 2 ** (bit // 2)
        block = slice(start, start + size)
        cells = np.floor(u[block] * columns).astype(int) * rows + np.floor(v[block] * rows).astype(int)
        assert sorted(cells.tolist()) == list(range(size))
        start += size
    assert start == count


def test_jittered_points_are_coherent(mitsuba):
    """Morton order: the 32 lanes of a warp (and an LLVM packet) cover an 8 x 4 patch of cells."""
    from transient.common import jittered_point

    count = 2**20
    u, v = jittered_point(mitsuba.UInt32(np.arange(count, dtype=np.uint32)), mitsuba.UInt32(count),
                          mitsuba.Float64(np.zeros(count)), mitsuba.Float64(np.zeros(count)))
    u, v = np.array(u).reshape(-1, 32), np.array(v).reshape(-1, 32)
    cell = 1.0 / 1024
    assert np.allclose(u.max(axis=1) - u.min(axis=1), 7 * cell) and np.allclose(v.max(axis=1) - v.min(axis=1),
                                                                                  3 * cell)


def test_replica_of_is_exact_at_every_boundary(mitsuba):
    from transient.common import replica_of

    for size in (1, 3, 2**20 - 1, 2**32 - 1):
        positions = np.unique(np.concatenate([np.arange(5) * size + offset for offset in (-1, 0, 1)]))
        positions = positions[positions >= 0].astype(np.float64)
        replica, index = replica_of(mitsuba.Float64(positions), mitsuba.Float64(size))
        np.testing.assert_array_equal(np.array(replica), positions // size)
        np.testing.assert_array_equal(np.array(index), positions % size)


# 5 sensors with butterworth is slow (~9 s): [1-butterworth] keeps its terms, [5-square] and [5-impulse]
# the sensors' histogram rows, in the default suite
@pytest.mark.parametrize("sensors, count, name", [
    pytest.param(sensors, count, name, marks=[pytest.mark.slow] if (sensors, name) == (5, "butterworth") else [])
    for sensors, count in ((1, 30), (5, 30), (2, 1)) for name in WAVEFORMS])
def test_deposit_gives_the_sums_of_a_direct_binning(mitsuba, rng, name, sensors, count):
    """Every scatter strategy gives the sums of NumPy's np.add.at over Waveform.kernel (to rounding).

    The taps are capped at the window's bins as the integrators cap them: a one-bin window caps every
    pulse at one tap, which must still be integrated as the pulse, not taken for the impulse.
    """
    import drjit as dr

    from transient.common import deposit, reduce_mode

    sampling = Sampling(bin_width_opl=0.05, start_opl=1.0 if count > 1 else 1.7, count=count)
    waveform = make_waveform(Illumination(waveform=name), sampling.bin_width_opl)
    samples = 20000
    replicas = 3
    length = rng.uniform(0.9, 2.6, (sensors, samples))              # some before and after the window
    weight = rng.exponential(1.0, (sensors, samples))
    replica = rng.integers(0, replicas, samples)
    expected = np.zeros((replicas, sensors, sampling.count))
    kernel = waveform.kernel(length, sampling)                       # (N, K, S)
    for k in range(sensors):
        for n in range(sampling.count):
            np.add.at(expected[:, k, n], replica, weight[k] * kernel[n, k])
    for mode in (dr.ReduceMode.Direct, dr.ReduceMode.Local, reduce_mode()):
        histogram = dr.zeros(mitsuba.Float64, replicas * sensors * sampling.count)
        for k in range(sensors):
            deposit(histogram, mitsuba.UInt32(replica * sensors + k), mitsuba.Float64(weight[k]),
                    mitsuba.Float64(length[k]), mitsuba.Bool(True), bins=sampling.count,
                    start_opl=sampling.start_opl, bin_width_opl=sampling.bin_width_opl, terms=waveform.terms,
                    taps=waveform.bins_touched(sampling.bin_width_opl, sampling.count), mode=mode)
        result = np.array(histogram).reshape(expected.shape)
        np.testing.assert_allclose(result, expected, rtol=1e-12, atol=1e-12 * expected.max())


def test_sample_streams_depend_on_seed_and_index_only(mitsuba):
    from transient.common import sample_stream

    index = np.arange(2**10, dtype=np.uint64) + 2**32 - 2**9                # across 2^32
    low, high = (index & 0xFFFFFFFF).astype(np.uint32), (index >> 32).astype(np.uint32)

    def draw(seed, low, high):
        stream = sample_stream(mitsuba.UInt32(seed), mitsuba.UInt32(low), mitsuba.UInt32(high))
        return np.array(stream.next_float64())

    whole = draw(3, low, high)
    np.testing.assert_array_equal(np.concatenate([draw(3, low[:100], high[:100]), draw(3, low[100:], high[100:])]),
                                  whole)
    assert len(np.unique(whole)) == len(whole)
    assert not np.any(np.isin(draw(4, low, high), whole))
    # index 2^32 + i is not index i again
    assert not np.any(np.isin(draw(3, low, np.zeros_like(high)), whole[high == 1]))


def test_is_diffuse(mitsuba):
    from transient.common import is_diffuse

    assert is_diffuse(mitsuba.load_dict({"type": "diffuse"}))
    assert not is_diffuse(mitsuba.load_dict({"type": "conductor"}))
    assert not is_diffuse(mitsuba.load_dict({"type": "roughplastic"}))
    assert not is_diffuse(None)


def test_kernels_far_in_the_tail_agree_in_numba_and_drjit(mitsuba):
    """κ 1e-15 of the area below the peak: Dr.Jit's piece-wise difference keeps the digits Numba's does."""
    waveform = make_waveform(Illumination(waveform="butterworth", order=1, cutoff=0.5, duration=12.0), 0.075)
    lower = np.linspace(0.5, 11.9, 400)
    upper = lower + 0.075
    expected = compiled_kernels(waveform.terms, lower, upper)
    traced = deposited_kernels(mitsuba, waveform.terms, lower, 0.075)
    closed_form = (np.exp(-np.pi * lower) * -np.expm1(-np.pi * 0.075)) / np.pi     # s = e^{-πt}, unit peak
    assert expected.min() < 1e-15 * expected.max()
    np.testing.assert_allclose(expected, closed_form, rtol=1e-12, atol=0)
    np.testing.assert_allclose(traced, closed_form, rtol=1e-12, atol=0)
