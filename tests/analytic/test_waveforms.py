"""Illumination waveforms and their sampling kernels κ_n, against independent computations.

The Butterworth pulse is checked against ``waveform_reference`` (an mpmath
state-space model that shares nothing with the code under test) and, near
t = 0, against that model's own Taylor series h(t) = Σ_j C A^j B t^j / j!
summed in mpmath.
"""

import functools
import math
from fractions import Fraction

import mpmath
import numpy as np
import pytest
from scipy import integrate, signal

from analytic.binning import bin_index
from analytic.scenes.common import Illumination, Sampling, SceneError
from compiled_kernels import compiled_cumulative
from analytic.waveforms import MAX_ORDER, make_waveform
from waveform_reference import ButterworthReference

SAMPLING = Sampling(bin_width_opl=0.1, start_opl=0.0, count=40)
PERIOD = 0.1
DEFAULT_CUTOFF = 0.5 / PERIOD
# What float64 can deliver for S: the exponential sum's terms cancel to
# ~ε Σ|ρ_k| e^{Re q_k x₀} of the area (≤ 1e-14 up to order 20), plus the
# reference's own rounding to float64.
AREA_TOLERANCE = 1e-13
# Below half the series' switch S keeps its relative accuracy (measured ≤ 6e-15).
RELATIVE_TOLERANCE = 1e-13


def test_butterworth_matches_scipy_impulse_response_with_unit_peak():
    waveform = make_waveform(Illumination(waveform="butterworth"), 0.1)
    cutoff = 0.5 / 0.1
    system = signal.lti(*signal.butter(3, 2 * np.pi * cutoff, analog=True))
    t = np.linspace(0, waveform.duration, 3001)
    _, reference = signal.impulse(system, T=t)
    reference = reference / reference.max()
    np.testing.assert_allclose(waveform.intensity(t), reference, atol=2e-4)   # grid peak vs true peak
    fine = np.linspace(0, waveform.duration, 200001)
    assert waveform.intensity(fine).max() == pytest.approx(1.0, abs=1e-9)
    assert waveform.duration == pytest.approx(3 / cutoff)


@pytest.mark.parametrize("name", ["square", "butterworth"])
def test_cumulative_is_the_integral_of_the_intensity(name):
    waveform = make_waveform(Illumination(waveform=name), 0.1)
    for u in [1e-4, 0.003, 0.02, 0.1, 0.33, waveform.duration, 1.0]:
        top = min(u, waveform.duration)
        breaks = [b for b in waveform.breakpoints if 0 < b < top]
        reference = integrate.quad(waveform.intensity, 0, top, points=breaks or None, epsabs=0,
                                   epsrel=1e-12, limit=200)[0]
        assert waveform.cumulative(u) == pytest.approx(reference, rel=1e-9, abs=1e-300)


def test_butterworth_cumulative_keeps_relative_accuracy_near_zero():
    """S(u) ~ u³ near 0: the closed form cancels there, the series must not."""
    waveform = make_waveform(Illumination(waveform="butterworth"), 0.1)
    omega = 2 * np.pi * 0.5 / 0.1
    peak = signal.impulse(signal.lti(*signal.butter(3, omega, analog=True)),
                          T=np.linspace(0, waveform.duration, 200001))[1].max()
    # H(s) = ω³ / (s³ + 2ω s² + 2ω² s + ω³)  =>  h(t) = ω³ (t²/2 - ω t³/3 + ...)
    for u in [1e-7, 1e-5, 1e-4]:
        leading = omega**3 * (u**3 / 6 - omega * u**4 / 12) / peak
        assert waveform.cumulative(u) == pytest.approx(leading, rel=1e-7 + (omega * u) ** 2)


@pytest.mark.parametrize("name", ["impulse", "square", "butterworth"])
def test_kernels_partition_the_pulse_energy(name):
    """Σ_n κ_n(τ) = ∫ s for any τ whose pulse lies inside the window."""
    waveform = make_waveform(Illumination(waveform=name), 0.1)
    tau = np.linspace(0.5, 3.0, 97)
    total = waveform.kernel(tau, SAMPLING).sum(axis=0)
    np.testing.assert_allclose(total, waveform.energy, rtol=1e-12)


def test_square_kernel_is_the_overlap_length():
    waveform = make_waveform(Illumination(waveform="square", width=0.03), 0.1)
    tau = np.array([0.19, 0.28, 0.285, 0.31])
    kernel = waveform.kernel(tau, SAMPLING)
    # overlap of [τ, τ + 0.03] with bin 2 = [0.2, 0.3)
    expected = np.clip(np.minimum(tau + 0.03, 0.3) - np.maximum(tau, 0.2), 0, None)
    np.testing.assert_allclose(kernel[2], expected, atol=1e-15)
    assert waveform.bins_touched(0.1) == 2


def test_impulse_kernel_is_the_one_shared_binning():
    waveform = make_waveform(Illumination(waveform="impulse"), 0.1)
    tau = np.array([-0.05, 0.0, 0.05, 0.1, 3.95, 4.0, 7.0])
    index, inside = bin_index(tau, 0.0, 0.1, 40)
    kernel = waveform.kernel(tau, SAMPLING)
    for i in range(len(tau)):
        if inside[i]:
            assert kernel[int(index[i]), i] == 1.0 and kernel[:, i].sum() == 1.0
        else:
            assert kernel[:, i].sum() == 0.0






# ---------------------------------------------------------------------------
# Butterworth against the independent state-space reference


# Below x = ω_c u = 1 the reference's ∫ = C A⁻¹ (e^{Av} − I) B cancels to S ~ x^n / n!
# (up to 35 of its 40 digits at order 20): there its own Taylor series is used.
TAYLOR_RANGE = 1.0


class Reference:
    """The reference pulse, with the Taylor series of its state-space model near t = 0.

    h(t) = Σ_j C A^j B t^j / j! and S(u) = Σ_j C A^j B u^{j+1} / (j+1)! / peak, in mpmath
    from the reference's matrices, for ω_c u <= TAYLOR_RANGE; the reference's closed
    form beyond. A truncation at ω_c duration <= 1 comes before the first peak
    (x = π / (2√2) at order 2, later for higher orders), so the peak is h(duration)
    there; at order 1 it is h(0) = ω_c.
    """

    def __init__(self, order, cutoff, duration):
        self.model = ButterworthReference(order, cutoff, duration)
        self.order, self.duration = order, duration
        self.omega = 2 * math.pi * cutoff
        with mpmath.workdps(80):
            state, self.markov = self.model.b.copy(), []
            for _ in range(order + 120):
                self.markov.append(mpmath.re((self.model.c * state)[0]))
                state = self.model.a * state
            if order > 1 and self.omega * duration <= TAYLOR_RANGE:
                self.peak = self.taylor(duration, 0)
            else:
                self.peak = self.model.peak
        self.area = self.cumulative(duration)

    def taylor(self, t, shift):
        """Σ_j M_j t^{j+shift} / (j+shift)! (mpmath): h(t) for shift 0, ∫_0^t h for shift 1."""
        with mpmath.workdps(80):
            t = mpmath.mpf(t)
            return mpmath.fsum(m * t ** (j + shift) / mpmath.factorial(j + shift)
                               for j, m in enumerate(self.markov))

    def cumulative(self, u):
        """S(u), metres."""
        v = min(float(u), self.duration)
        if v <= 0.0:
            return 0.0
        if self.omega * v <= TAYLOR_RANGE:
            with mpmath.workdps(80):
                return float(self.taylor(v, 1) / self.peak)
        with mpmath.workdps(80):
            return float(mpmath.mpf(self.model.cumulative(v)) * self.model.peak / self.peak)


@functools.lru_cache(maxsize=None)
def _reference(order, cutoff, duration):
    return Reference(order, cutoff, duration)


def _butterworth(order, cutoff, duration, period=None):
    period = 0.5 / cutoff if period is None else period
    return make_waveform(Illumination(waveform="butterworth", order=order, cutoff=cutoff,
                                      duration=duration), period)


def _switch(waveform):
    """Where the Butterworth pulse's Taylor series hands over to its exponential sum (a piece that is no kink)."""
    terms = waveform.terms
    switches = [float(b) for b, kink in zip(terms.starts, terms.kinks) if not kink]
    return switches[0] if switches else float(np.nextafter(waveform.duration, np.inf))


def _probe_times(waveform, reference):
    """u (metres) over the pulse: geometric from 1e-3/ω_c, linear, and at its landmarks."""
    end = min(reference.duration, float(reference.model.settled))
    probes = [np.geomspace(1e-3 / reference.omega, end, 6), np.linspace(0.0, end, 6)[1:],
              [_switch(waveform) * (1 - 1e-9), _switch(waveform) * (1 + 1e-9),
               waveform.peak_time, end, 2 * end]]
    u = np.unique(np.concatenate(probes))
    return u[u > 0]


def area_error(order, cutoff, duration, period=None):
    """max_u |S(u) - S_ref(u)| / S_ref(duration), and the reference's area."""
    waveform = _butterworth(order, cutoff, duration, period)
    reference = _reference(order, cutoff, duration)
    assert reference.area > 0.0
    u = _probe_times(waveform, reference)
    expected = np.array([reference.cumulative(x) for x in u])
    return float(np.max(np.abs(waveform.cumulative(u) - expected)) / reference.area), reference.area


# (order, cutoff cycles/m, duration m, period m): the user's failing cases, a
# truncation before the peak, far beyond the decay, and the cutoff range's ends
REFERENCE_CASES = [
    (1, DEFAULT_CUTOFF, 1e-6, PERIOD),
    (2, DEFAULT_CUTOFF, 1e300, PERIOD),
    (3, DEFAULT_CUTOFF, 0.6, PERIOD),
    (3, DEFAULT_CUTOFF, 500.0, PERIOD),
    (5, DEFAULT_CUTOFF, 1e10, PERIOD),
    (8, 1e-6, 3e6, 1e3),
    (8, 1e6, 1e-12, 1e-6),
    (13, DEFAULT_CUTOFF, 0.05, PERIOD),
    pytest.param(MAX_ORDER, DEFAULT_CUTOFF, 1e300, PERIOD, marks=pytest.mark.slow),   # 11 s
]


@pytest.mark.parametrize("order, cutoff, duration, period", REFERENCE_CASES)
def test_butterworth_cumulative_matches_the_state_space_reference(order, cutoff, duration, period):
    error, area = area_error(order, cutoff, duration, period)
    assert error <= AREA_TOLERANCE
    assert _butterworth(order, cutoff, duration, period).energy == pytest.approx(area, rel=AREA_TOLERANCE)


SWEEP_DURATIONS = [1e-6, 1e-3, 0.05, 0.6, 10.0, 1e300]      # metres at cutoff 5 cycles/m


@pytest.mark.slow
@pytest.mark.parametrize("order", range(1, MAX_ORDER + 1))
@pytest.mark.parametrize("cutoff, period", [(DEFAULT_CUTOFF, PERIOD), (1e-6, 1e3), (1e6, 1e-6),
                                            (0.05, 1.0)])
def test_butterworth_cumulative_matches_the_reference_for_every_order(order, cutoff, period):
    """Orders 1..MAX_ORDER, durations from 5e-6 to 5e300 / cutoff."""
    for duration in SWEEP_DURATIONS:
        scaled = duration * DEFAULT_CUTOFF / cutoff if duration < 1e300 else duration
        error, _ = area_error(order, cutoff, scaled, period)
        assert error <= AREA_TOLERANCE, (order, cutoff, scaled, error)


@pytest.mark.parametrize("order", [1, 3, 8, MAX_ORDER])
def test_butterworth_series_keeps_relative_accuracy_near_zero(order):
    """S ~ u^order: relative accuracy down to the smallest normal S, and around the switch."""
    waveform = _butterworth(order, DEFAULT_CUTOFF, 1e300)
    reference = _reference(order, DEFAULT_CUTOFF, 1e300)
    # the smallest x = ω u whose S (~x^n / n!) is still a normal float64
    smallest = (1e-290 * math.factorial(order)) ** (1 / order) / reference.omega
    u = np.geomspace(smallest, _switch(waveform) / 2, 8)
    # where the series meets the exponential sum both cancel to ~ε Σ|ρ_k| e^{Re q_k x₀} / S:
    # measured up to 2.5e-12 at orders 19 and 20
    switch = _switch(waveform) * np.array([0.9, 1 - 1e-9, 1 + 1e-9, 1.5])
    with mpmath.workdps(80):
        expected = np.array([float(reference.taylor(x, 1) / reference.peak) for x in u])
        expected_switch = np.array([float(reference.taylor(x, 1) / reference.peak) for x in switch])
    np.testing.assert_allclose(waveform.cumulative(u), expected, rtol=RELATIVE_TOLERANCE, atol=0)
    np.testing.assert_allclose(waveform.cumulative(switch), expected_switch, rtol=1e-11, atol=0)


@pytest.mark.parametrize("order", range(1, MAX_ORDER + 1))
@pytest.mark.parametrize("duration", [1e-5, 0.1, 1e300])
def test_butterworth_peak_is_one_and_found_exactly(order, duration):
    """max s = 1 on a fine grid, reached at ``peak_time``; a truncation before the peak peaks there."""
    waveform = _butterworth(order, DEFAULT_CUTOFF, duration, PERIOD)
    fine = np.linspace(0.0, waveform.duration, 100001)
    values = waveform.intensity(fine)
    assert values.max() <= 1.0 + 1e-13
    assert float(waveform.intensity(waveform.peak_time)) == pytest.approx(1.0, abs=1e-13)
    if np.argmax(values) == fine.size - 1:        # rising up to the truncation
        assert waveform.peak_time == waveform.duration
    else:
        assert waveform.peak_time == pytest.approx(fine[np.argmax(values)], abs=fine[1])


@pytest.mark.parametrize("order", [1, 2, 7, MAX_ORDER])
def test_butterworth_peak_time_matches_the_reference(order):
    waveform = _butterworth(order, DEFAULT_CUTOFF, 1e300)
    reference = _reference(order, DEFAULT_CUTOFF, 1e300)
    assert waveform.peak_time == pytest.approx(float(reference.model.peak_time), rel=1e-7, abs=1e-15)


def test_butterworth_durations_past_the_decay_are_the_untruncated_pulse():
    """500 m, 1e10 m ... 1e308 m: one and the same finite waveform, bounded bin counts."""
    base = _butterworth(MAX_ORDER, DEFAULT_CUTOFF, 500.0, PERIOD)
    u = np.linspace(0, 2.0, 4001)
    for duration in [1e10, 1e100, 1e300, 1.7e308]:
        waveform = _butterworth(MAX_ORDER, DEFAULT_CUTOFF, duration, PERIOD)
        np.testing.assert_array_equal(waveform.cumulative(u), base.cumulative(u))
        assert math.isfinite(waveform.duration) and waveform.duration < 100 / DEFAULT_CUTOFF
        assert all(math.isfinite(b) for b in waveform.breakpoints)
        assert waveform.bins_touched(PERIOD) <= 100 / (DEFAULT_CUTOFF * PERIOD) + 2
    assert base.energy == pytest.approx(_reference(MAX_ORDER, DEFAULT_CUTOFF, 1e300).area,
                                        rel=AREA_TOLERANCE)


@pytest.mark.parametrize("name, options", [("impulse", {}), ("square", {}), ("square", {"width": 1e300}),
                                           ("butterworth", {"order": 1}), ("butterworth", {}),
                                           ("butterworth", {"order": 12, "duration": 0.2}),
                                           ("butterworth", {"order": MAX_ORDER}),
                                           ("butterworth", {"order": MAX_ORDER, "duration": 1e-5})])
def test_numpy_and_numba_evaluate_the_same_closed_form(name, options, rng):
    waveform = make_waveform(Illumination(waveform=name, **options), PERIOD)

    span = max(waveform.duration, PERIOD)
    u = np.concatenate([rng.uniform(-0.2 * span, 1.2 * span, 4000),
                        rng.uniform(0.0, _switch(waveform), 1000),
                        np.geomspace(1e-300, 1e300, 121), [-1e308, 0.0, 1e308]])
    numpy_values = waveform.cumulative(u)
    numba_values = compiled_cumulative(waveform.terms, u)
    assert np.all(np.isfinite(numpy_values))
    np.testing.assert_allclose(numba_values, numpy_values, rtol=0, atol=1e-12 * waveform.energy)
    series = (u > 0) & (u < _switch(waveform))
    np.testing.assert_allclose(numba_values[series], numpy_values[series], rtol=1e-12)


@pytest.mark.parametrize("width", [1e2, 1e100, 1e300, 1.7e308])
def test_square_of_any_width_is_exact(width):
    """S(u) = min(u, width); inside a window shorter than the width every width is the same pulse."""
    waveform = make_waveform(Illumination(waveform="square", width=width), PERIOD)
    u = np.array([-1e308, -1.0, 0.0, 1e-300, 0.3, 99.5, 1e99, 1e299, 1e308])
    np.testing.assert_array_equal(waveform.cumulative(u), np.clip(u, 0.0, width))
    assert waveform.breakpoints == (0.0, width) and waveform.energy == width
    tau = np.linspace(-0.05, 3.9, 80)
    np.testing.assert_array_equal(waveform.kernel(tau, SAMPLING),
                                  make_waveform(Illumination(waveform="square", width=50.0),
                                                PERIOD).kernel(tau, SAMPLING))
    touched = waveform.bins_touched(PERIOD)
    assert touched == math.ceil(Fraction(width) / Fraction(PERIOD)) + 1   # exact, an integer
    assert waveform.bins_touched(PERIOD, SAMPLING.count) == SAMPLING.count
    assert waveform.bins_touched(1e-300, SAMPLING.count) == SAMPLING.count


def test_bins_touched_is_exact_and_refuses_bad_arguments():
    waveform = make_waveform(Illumination(waveform="square", width=0.3), PERIOD)
    # 0.3 / 0.1 rounds to 2.9999999999999996 in float64; the floats' exact ratio is below 3 too
    assert waveform.bins_touched(0.1) == math.ceil(Fraction(0.3) / Fraction(0.1)) + 1
    assert make_waveform(Illumination(waveform="impulse"), PERIOD).bins_touched(PERIOD, 5) == 1
    for bad in [0.0, -1.0, math.inf, math.nan]:
        with pytest.raises(ValueError, match="period"):
            waveform.bins_touched(bad)
    for bad in [0, -3, 2.5, True]:
        with pytest.raises(ValueError, match="count"):
            waveform.bins_touched(PERIOD, bad)


BAD_VALUES = [
    ({"order": 0}, PERIOD, "illumination.order"),
    ({"order": MAX_ORDER + 1}, PERIOD, "illumination.order"),
    ({"order": 1000}, PERIOD, "illumination.order"),
    ({"order": 2**70}, PERIOD, "illumination.order"),
    ({"cutoff": 1e300}, PERIOD, "illumination.cutoff"),
    ({"cutoff": 5e-324}, PERIOD, "illumination.cutoff"),
    ({"cutoff": 2e6}, 1e-6, "illumination.cutoff"),
    ({"cutoff": 5e-7}, 1e3, "illumination.cutoff"),
    ({"cutoff": 1e-3}, PERIOD, "illumination.cutoff"),        # cutoff x period 1e-4
    ({"cutoff": 2e4}, PERIOD, "illumination.cutoff"),         # cutoff x period 2e3
    ({"cutoff": -5.0}, PERIOD, "illumination.cutoff"),
    ({"cutoff": math.nan}, PERIOD, "illumination.cutoff"),
    ({"duration": 1e-300}, PERIOD, "illumination.duration"),
    ({"duration": 5e-324}, PERIOD, "illumination.duration"),
    ({"duration": 1.9e-7}, PERIOD, "illumination.duration"),  # under 1e-6 / cutoff
    ({"duration": math.inf}, PERIOD, "illumination.duration"),
    ({"duration": 0.0}, PERIOD, "illumination.duration"),
    ({}, 1e-9, "sampling.period"),                             # default cutoff 5e8
    ({}, 1e9, "sampling.period"),                              # default cutoff 5e-10
]


@pytest.mark.parametrize("options, period, key", BAD_VALUES)
def test_bad_butterworth_values_are_refused_naming_the_key(options, period, key):
    with pytest.raises(SceneError) as caught:
        make_waveform(Illumination(waveform="butterworth", **options), period)
    assert caught.value.key == key and "\n" not in str(caught.value)


def test_bounds_are_inclusive():
    """The ends of each documented range are accepted."""
    for options, period in [({"order": MAX_ORDER}, PERIOD), ({"cutoff": 1e-6}, 1e3), ({"cutoff": 1e6}, 1e-9),
                            ({"cutoff": 1e6}, 1e-3), ({"cutoff": 1e-2}, PERIOD), ({"cutoff": 1e4}, PERIOD),
                            ({"duration": 1e-6 / DEFAULT_CUTOFF}, PERIOD), ({}, 5e-7), ({}, 5e5)]:
        waveform = make_waveform(Illumination(waveform="butterworth", **options), period)
        assert 0.0 < waveform.energy < math.inf


def test_square_default_width_underflowing_is_refused():
    with pytest.raises(SceneError) as caught:
        make_waveform(Illumination(waveform="square"), 5e-324)
    assert caught.value.key == "sampling.period"


@pytest.mark.parametrize("options", [{"order": 1, "duration": 1e-6}, {"order": MAX_ORDER, "cutoff": 1e6},
                                     {"order": MAX_ORDER, "cutoff": 1e-6},
                                     {"order": MAX_ORDER, "cutoff": 1e6, "duration": 1e-12},
                                     {"order": MAX_ORDER, "cutoff": 1e-6, "duration": 1e300}])
def test_every_stored_coefficient_is_a_normal_float(options):
    """At the corners of the accepted ranges nothing over- or underflows."""
    cutoff = options.get("cutoff", DEFAULT_CUTOFF)
    waveform = make_waveform(Illumination(waveform="butterworth", **options), 0.5 / cutoff)
    terms = waveform.terms
    stored = np.concatenate([terms.coefficients, terms.constants, terms.starts,
                             [waveform.duration, waveform.peak_time]])
    nonzero = np.abs(stored[stored != 0.0])
    assert np.all(np.isfinite(stored)) and np.all(nonzero >= np.finfo(float).tiny)


# ---------------------------------------------------------------------------
# Kernels far in the pulse's tail keep their own relative accuracy


# order 8 is slow (~14 s of mpmath); order 3 keeps the same cutoff, duration and period by default
TAIL_CASES = [(1, 0.5, 12.0, 12.0 / 160), (2, 0.5, 12.0, 12.0 / 160), (3, DEFAULT_CUTOFF, 500.0, PERIOD),
              pytest.param(8, DEFAULT_CUTOFF, 500.0, PERIOD, marks=pytest.mark.slow)]


@pytest.mark.parametrize("order, cutoff, duration, period", TAIL_CASES)
def test_butterworth_kernels_are_accurate_far_in_the_tail(order, cutoff, duration, period):
    """κ_n 1e-11 (and less) below the peak bin is within 1e-12 of itself, against the mpmath reference.

    A kernel taken as the difference of two values of S near the pulse's area
    keeps only their rounding there (1e-16 of the area: 100 % of a 1e-16 kernel);
    the pieces keep the remainder instead.
    """
    waveform = _butterworth(order, cutoff, duration, period)
    reference = _reference(order, cutoff, duration)
    sampling = Sampling(bin_width_opl=period, start_opl=0.0, count=int(waveform.duration / period))
    tau = 0.37 * period
    kernel = waveform.kernel(np.array([tau]), sampling)[:, 0]
    edges = sampling.edges - tau
    expected = np.array([reference.model.kernel(a, b) for a, b in zip(edges[:-1], edges[1:])])
    live = np.abs(expected) > 1e-300
    assert np.max(np.abs(expected)) / np.min(np.abs(expected[live])) > 1e11     # the tail is reached
    np.testing.assert_allclose(kernel[live], expected[live], rtol=1e-12, atol=0)


def test_a_pulse_that_starts_before_zero_is_the_causal_one_moved():
    """A square centred at 0 (lead -w/2) gives the causal square's y with every bin edge moved by w/2."""
    from analytic.scenes.common import default_scene
    from analytic.operator.system import rectangle_matrix
    from analytic.waveforms import Waveform, make_terms
    from analytic.waveforms.pieces import POLYNOMIAL

    width = 0.07
    centred = Waveform("centred square", make_terms([(-width / 2, True, 0.0, POLYNOMIAL, -width / 2, [0.0, 1.0]),
                                                     (width / 2, True, width, POLYNOMIAL, 0.0, [])],
                                                    duration=width / 2, lead=-width / 2), "centred square")
    causal = make_waveform(Illumination(waveform="square", width=width), PERIOD)
    scene = default_scene(pixels=6, noise=None)
    moved = scene.sampling
    shifted = Sampling(bin_width_opl=moved.bin_width_opl, start_opl=moved.start_opl + width / 2, count=moved.count)
    rectangle, pairs = scene.geometry()
    a = rectangle_matrix(rectangle, pairs, moved, centred).toarray()
    b = rectangle_matrix(rectangle, pairs, shifted, causal).toarray()
    assert centred.bins_touched(PERIOD) == causal.bins_touched(PERIOD)
    np.testing.assert_allclose(a, b, rtol=0, atol=2e-6 * np.abs(b).max())
    assert np.abs(a).max() > 0
