"""The measured-response waveforms (gaussian, emg, sampled) against independent references.

S(u), s(t), the bin kernels (relative accuracy far in both tails), the
derivatives and derivative bounds the moments route uses, the Taylor
polynomials, erfcx and its Taylor coefficients: each against mpmath, SciPy
quadrature of s(t) written here, or ``irf_reference`` (which shares no
code with ``analytic``).
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from irf_reference import EmgReference, GaussianReference, SampledReference, Sech2Reference, sigma_of
from scipy import integrate

from analytic.kernels.bins import BinRun, TimeAxis
from analytic.errors import SceneError
from analytic.scenes.common import Illumination, Sampling
from analytic.kernels.taylor import MAX_TERMS, kernel_taylor
from analytic.waveforms import make_waveform
from analytic.waveforms.measured import METRES_PER_PICOSECOND, read_samples
from analytic.kernels.formulas import erfcx_array
from analytic.kernels.pieces import piece_derivative_bound, piece_derivatives, piece_of
from analytic.kernels.special import erfcx_scalar, erfcx_taylor
from analytic.waveforms.pieces import kernel_array

FWHM = 20 * METRES_PER_PICOSECOND          # a SPAD's jitter: 20 ps
TAIL = 50 * METRES_PER_PICOSECOND          # and its tail: 50 ps
# tail / fwhm at both ends of the accepted range and in between
EMG_CASES = [(FWHM, TAIL), (FWHM, 1.0001e-4 * FWHM), (FWHM, 0.9999e4 * FWHM), (FWHM, 0.3 * FWHM)]


def test_erfcx_and_its_taylor_coefficients_match_mpmath():
    v = np.concatenate([np.linspace(0.0, 12.0, 481), np.geomspace(1e-300, 1e8, 200), [0.46875, 4.0]])
    with mpmath.workdps(40):
        exact = np.array([float(mpmath.exp(mpmath.mpf(x) ** 2) * mpmath.erfc(mpmath.mpf(x))) for x in v])
    assert np.max(np.abs(erfcx_array(v) / exact - 1)) < 2e-15
    assert np.max(np.abs(np.array([erfcx_scalar(x) for x in v]) / exact - 1)) < 2e-15
    out = np.empty(13)
    with mpmath.workdps(60):
        for x in [0.0, 0.3, 0.99, 1.0, 1.01, 1.7, 3.0, 6.5, 40.0, 3e3, 1e6]:
            erfcx_taylor(x, 13, out)
            exact = [float(c) for c in mpmath.taylor(lambda t: mpmath.exp(t**2) * mpmath.erfc(t), mpmath.mpf(x), 12)]
            # within 1e-15 of the largest coefficient (the Taylor sum's scale)
            assert np.max(np.abs(out - exact)) <= 1e-15 * np.max(np.abs(exact)), x


def test_gaussian_is_its_definition_with_unit_peak():
    waveform = make_waveform(Illumination(waveform="gaussian", fwhm=FWHM), 0.01)
    sigma = sigma_of(FWHM)
    reference = GaussianReference(FWHM)
    t = np.linspace(-5 * sigma, 5 * sigma, 101)
    np.testing.assert_allclose(waveform.intensity(t), [reference.intensity(x) for x in t], rtol=1e-14, atol=0)
    assert waveform.intensity(np.array([FWHM / 2, -FWHM / 2])) == pytest.approx([0.5, 0.5], rel=1e-14)
    for u in [-3 * sigma, -0.1 * sigma, 0.0, sigma, 4 * sigma]:
        expected = integrate.quad(reference.intensity, -np.inf, u, epsabs=0, epsrel=1e-13)[0]
        assert waveform.cumulative(u) == pytest.approx(expected, rel=1e-12)
    # the truncation: 2^-60 of the area beyond each end (|t| <= 8.77 sigma)
    assert waveform.lead == -waveform.duration == pytest.approx(-8.7733 * sigma, rel=1e-4)
    assert waveform.energy == pytest.approx(sigma * math.sqrt(2 * math.pi), rel=2e-16 * 8)


def _kernel_pairs(waveform, count=60):
    """(lower, upper) windows all over the pulse and far into both tails, a tenth of the pulse wide or less."""
    span = waveform.duration - waveform.lead
    lower = np.linspace(waveform.lead, waveform.duration, count)
    return lower, lower + span * np.geomspace(1e-4, 0.1, count)


def _check_kernels(waveform, reference, rtol):
    lower, upper = _kernel_pairs(waveform)
    upper = np.minimum(upper, waveform.duration)
    keep = upper > lower
    lower, upper = lower[keep], upper[keep]
    got = kernel_array(waveform.terms, lower, upper)
    exact = np.array([float(reference.kernel_mp(a, b)) for a, b in zip(lower, upper)])
    # each kernel to its own relative accuracy, down to 1e-300 (beyond the cut ends only the truncated
    # 2^-60 of the area is missing)
    lost = 2.0**-60 * waveform.energy
    error = np.abs(got - exact)
    assert np.all(error <= rtol * np.abs(exact) + lost), np.max(error / np.abs(exact))
    assert np.min(exact) < 1e-15 * waveform.energy          # far-tail kernels were judged


def test_gaussian_kernels_keep_relative_accuracy_in_both_tails():
    waveform = make_waveform(Illumination(waveform="gaussian", fwhm=FWHM), 0.01)
    _check_kernels(waveform, GaussianReference(FWHM), 1e-12)


@pytest.mark.parametrize("fwhm", [FWHM, 1e-6, 3.0])
def test_sech2_is_its_definition_with_unit_peak_its_fwhm_and_its_area(fwhm):
    waveform = make_waveform(Illumination(waveform="sech2", fwhm=fwhm), 0.01)
    reference = Sech2Reference(fwhm)
    tau = reference.tau
    t = np.linspace(-15 * tau, 15 * tau, 121)
    np.testing.assert_allclose(waveform.intensity(t), [reference.intensity(x) for x in t], rtol=1e-13, atol=0)
    # unit peak at 0, half of it at ±fwhm/2
    assert waveform.intensity(np.array([0.0]))[0] == pytest.approx(1.0, rel=1e-15)
    assert waveform.intensity(np.array([fwhm / 2, -fwhm / 2])) == pytest.approx([0.5, 0.5], rel=1e-14)
    # the area 2τ (unit area once divided by it), by QUADPACK over the pulse (e^-80 of it beyond ±40τ)
    area = sum(integrate.quad(reference.intensity, a * tau, b * tau, epsabs=0, epsrel=1e-13)[0]
               for a, b in ((-40, -1), (-1, 1), (1, 40)))
    assert waveform.energy == pytest.approx(area, rel=1e-13)
    assert waveform.energy == pytest.approx(2 * tau, rel=1e-15)
    for u in [-12 * tau, -0.1 * tau, 0.0, tau, 9 * tau]:
        assert waveform.cumulative(u) == pytest.approx(float(reference.cumulative_mp(u)), rel=1e-13)
    # the truncation: 2^-60 of the area beyond each end
    assert waveform.lead == -waveform.duration == pytest.approx(-30 * math.log(2) * tau, rel=1e-14)
    assert waveform.cumulative(waveform.lead) == 0.0


def test_sech2_kernels_keep_relative_accuracy_in_both_tails():
    waveform = make_waveform(Illumination(waveform="sech2", fwhm=FWHM), 0.01)
    _check_kernels(waveform, Sech2Reference(FWHM), 1e-12)


def test_sech2_needs_its_fwhm_and_takes_nothing_else():
    with pytest.raises(SceneError, match="illumination.fwhm: required"):
        make_waveform(Illumination(waveform="sech2"), 0.01)
    with pytest.raises(SceneError, match="illumination.tail: does not apply"):
        Illumination(waveform="sech2", fwhm=FWHM, tail=TAIL)
    with pytest.raises(SceneError, match="illumination.fwhm"):
        Illumination(waveform="sech2", fwhm=-1.0)


@pytest.mark.parametrize("fwhm, tail", EMG_CASES)
def test_emg_is_its_definition(fwhm, tail):
    waveform = make_waveform(Illumination(waveform="emg", fwhm=fwhm, tail=tail), 0.01)
    reference = EmgReference(fwhm, tail)
    assert waveform.peak_time == pytest.approx(reference.peak_time, abs=1e-6 * (fwhm + tail))
    assert waveform.intensity(np.array([waveform.peak_time]))[0] == pytest.approx(1.0, abs=1e-14)
    sigma = sigma_of(fwhm)
    # relative rounding on the left grows as ~ε w tail/σ (the module docstring): 2e-11 at tail = 1e4 fwhm
    rtol = 5e-11 if tail > 10 * fwhm else 1e-12
    t = np.concatenate([np.linspace(-6 * sigma, 6 * sigma, 25), tail * np.array([1.0, 5.0, 20.0])])
    np.testing.assert_allclose(waveform.intensity(t), [reference.intensity(x) for x in t], rtol=rtol, atol=1e-300)
    u = np.concatenate([np.linspace(-6 * sigma, 6 * sigma, 13), tail * np.array([1.0, 5.0, 20.0])])
    np.testing.assert_allclose(waveform.cumulative(u), [reference.cumulative_mp(x) for x in u], rtol=0,
                               atol=1e-14 * waveform.energy)
    _check_kernels(waveform, reference, rtol)


def test_emg_accepts_only_the_tail_ratios_float64_delivers():
    for tail in (0.99e-4 * FWHM, 1.01e4 * FWHM):
        with pytest.raises(SceneError, match="illumination.tail: tail / fwhm"):
            make_waveform(Illumination(waveform="emg", fwhm=FWHM, tail=tail), 0.01)
    for name, keys in (("gaussian", {}), ("emg", {"fwhm": FWHM})):
        with pytest.raises(SceneError, match="required"):
            make_waveform(Illumination(waveform=name, **keys), 0.01)


def test_sampled_interpolates_linearly_with_unit_peak(tmp_path):
    samples = np.array([0.0, 0.0, 3.0, 12.0, 7.5, 2.0, 0.5, 0.0, 0.0])
    np.save(tmp_path / "irf.npy", samples)
    illumination = Illumination(waveform="sampled", samples=read_samples(tmp_path / "irf.npy"), sample_width_ps=4.0,
                                start=-0.002)
    waveform = make_waveform(illumination, 0.01)
    width = 4.0 * METRES_PER_PICOSECOND
    reference = SampledReference(samples, width, -0.002)
    t = np.linspace(-0.003, 0.012, 301)
    np.testing.assert_allclose(waveform.intensity(t), [reference.intensity(x) for x in t], rtol=1e-13, atol=1e-15)
    for u in t[::7]:
        quadrature = integrate.quad(reference.intensity, -0.003, u, points=reference.breakpoints, epsabs=0,
                                    epsrel=1e-13, limit=200)[0]
        assert waveform.cumulative(u) == pytest.approx(quadrature, rel=1e-12, abs=1e-18)
        assert waveform.cumulative(u) == pytest.approx(reference.cumulative(u), rel=1e-13, abs=1e-18)
    assert waveform.peak_time == pytest.approx(-0.002 + 3 * width)
    assert waveform.terms.degree == 2 and np.all(waveform.terms.kinks)
    # runs of zeros dropped: one zero kept at each end
    assert len(waveform.terms.starts) == 7 and waveform.terms.starts[0] == pytest.approx(-0.002 + width)


def test_sampled_files_and_their_refusals(tmp_path):
    (tmp_path / "irf.csv").write_text("# measured IRF\n0\n0.5\n\n1.0\n0.25\n0\n")
    assert read_samples(tmp_path / "irf.csv").tolist() == [0, 0.5, 1.0, 0.25, 0]
    bad = {"two.csv": "0,1\n1,2\n", "word.csv": "0\nabc\n", "negative.csv": "0\n-1\n1\n", "zero.csv": "0\n0\n",
           "one.csv": "1\n", "nan.csv": "0\nnan\n"}
    for name, text in bad.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(SceneError, match="illumination.file"):
            read_samples(tmp_path / name)
    np.save(tmp_path / "table.npy", np.ones((3, 2)))
    for name in ("table.npy", "missing.npy", "irf.png"):
        with pytest.raises(SceneError, match="illumination.file"):
            read_samples(tmp_path / name)
    with pytest.raises(SceneError, match="exactly one of sample_width"):
        Illumination(waveform="sampled", samples=[0, 1, 0], sample_width=1e-3, sample_width_ps=3.0)
    with pytest.raises(SceneError, match="illumination.file: required"):
        Illumination(waveform="sampled", sample_width=1e-3)


def _derivative_cases():
    """(waveform, a scalar S(u) in mpmath) for the non-polynomial pieces."""
    gaussian = GaussianReference(FWHM)
    with mpmath.workdps(50):
        s = mpmath.mpf(gaussian.sigma)
    yield (make_waveform(Illumination(waveform="gaussian", fwhm=FWHM), 0.01),
           lambda u: s * mpmath.sqrt(mpmath.pi / 2) * mpmath.erfc(-u / (s * mpmath.sqrt(2))), 1.0)
    sech2 = Sech2Reference(FWHM)
    yield (make_waveform(Illumination(waveform="sech2", fwhm=FWHM), 0.01),
           lambda u: sech2.tau_mp * (1 + mpmath.tanh(u / sech2.tau_mp)), 1.0)
    for fwhm, tail in EMG_CASES[:2] + EMG_CASES[3:]:
        reference = EmgReference(fwhm, tail)
        yield (make_waveform(Illumination(waveform="emg", fwhm=fwhm, tail=tail), 0.01),
               lambda u, r=reference: r._cdf_mp(u) / r.peak, 1.0)


def test_derivatives_and_their_bounds_hold():
    """piece_derivatives against mpmath's derivatives of S; piece_derivative_bound above |S^(j)| over ranges."""
    count = MAX_TERMS
    out = np.zeros(count)
    checked = 0
    for waveform, exact_s, _ in _derivative_cases():
        terms = waveform.terms
        span = waveform.duration - waveform.lead
        for u in np.linspace(waveform.lead, waveform.duration, 9)[1:-1]:
            piece = piece_of(terms, u)
            piece_derivatives(terms, piece, u, count, out)
            with mpmath.workdps(50):
                exact = [float(mpmath.diff(exact_s, mpmath.mpf(u), j)) for j in range(1, 7)]
            for j in range(1, 7):
                scale = max(abs(e) * (span / 20) ** (k - j) for k, e in enumerate(exact, 1))
                assert abs(out[j] - exact[j - 1]) <= 1e-11 * scale, (waveform.name, u, j)
            for half in (span * 1e-3, span * 1e-2):
                low, high = max(u - half, terms.starts[piece]), u + half
                if piece + 1 < len(terms.starts):
                    high = min(high, terms.starts[piece + 1])
                for order in (1, 3, 6):
                    bound = piece_derivative_bound(terms, piece, low, high, order)
                    with mpmath.workdps(50):
                        worst = max(abs(float(mpmath.diff(exact_s, mpmath.mpf(x), order)))
                                    for x in np.linspace(low, high, 5))
                    assert worst <= bound < math.inf, (waveform.name, u, order)
                    checked += 1
    assert checked > 100


@pytest.mark.parametrize("illumination", [Illumination(waveform="gaussian", fwhm=0.03),
                                          Illumination(waveform="sech2", fwhm=0.03),
                                          Illumination(waveform="emg", fwhm=0.02, tail=0.05),
                                          Illumination(waveform="sampled", samples=[0, 2, 5, 3, 1, 0],
                                                       sample_width=0.011, start=-0.01)])
def test_taylor_polynomials_match_the_kernels(illumination, rng):
    """The moments route's Taylor polynomials of every bin kernel against the kernels, over kink-free ranges."""
    period, rtol = 0.02, 1e-7
    waveform = make_waveform(illumination, period)
    sampling = Sampling(bin_width_opl=period, start_opl=0.0, count=40)
    axis = TimeAxis(sampling.start_opl, sampling.bin_width_opl, sampling.count)
    kinks = np.sort(np.add.outer(sampling.edges, -np.asarray(waveform.breakpoints)).ravel())
    coefficients = np.zeros((sampling.count, MAX_TERMS))
    scratch = np.zeros(MAX_TERMS + 1), np.zeros(MAX_TERMS + 1)
    kept = tried = 0
    while tried < 60:
        centre = rng.uniform(sampling.edges[6], sampling.edges[-8])
        half = min(np.min(np.abs(kinks - centre)) * rng.uniform(0.05, 0.999), period * rng.uniform(0.02, 1.0))
        tried += 1
        count = kernel_taylor(waveform.terms, axis, BinRun(0, sampling.count), centre, half, rtol, coefficients,
                              *scratch)
        if count == 0:
            continue
        kept += 1
        tau = centre + half * np.linspace(-1.0, 1.0, 21)
        series = np.polynomial.polynomial.polyval(tau - centre, coefficients[:, :count].T)
        exact = waveform.kernel(tau, sampling)
        scale = np.max(np.abs(exact), axis=1, keepdims=True)
        assert np.all(np.abs(series - exact) <= rtol * scale + 1e-15 * np.max(scale))
    assert kept >= 10           # the route serves these pulses


def _tal_histogram(path, counts, delta_t, t_start):
    """A tal capture of one histogram, written with h5py alone (tal's dataset names)."""
    import h5py

    with h5py.File(path, "w") as stream:
        stream["H"] = np.asarray(counts, dtype=float)[:, None]
        stream["delta_t"] = delta_t
        stream["t_start"] = t_start


def test_a_tal_histogram_is_a_sampled_response(tmp_path):
    """Its counts are the samples, at its bins' centres, delta_t apart; the scene's width must agree."""
    from analytic.scenes.scene_file import load_scene

    counts = [0, 3, 40, 100, 61, 20, 7, 2, 0]
    _tal_histogram(tmp_path / "irf.hdf5", counts, 0.0015, -0.003)
    scene = ("[plane]\nsize = 1.0\npixels = 2\n[source]\nposition = [0.5, 0.5, 1.0]\n"
             "[sensors]\npositions = [[0.2, 0.7, 1.0]]\n[sampling]\nperiod = 0.01\nstart = 1.9\ncount = 60\n"
             "[illumination]\nwaveform = \"sampled\"\nfile = \"irf.hdf5\"\n")
    (tmp_path / "s.toml").write_text(scene)
    illumination = load_scene(tmp_path / "s.toml").illumination
    assert list(illumination.samples) == counts
    assert illumination.sample_width == 0.0015
    assert illumination.start == pytest.approx(-0.003 + 0.0015 / 2, abs=1e-15)
    (tmp_path / "own_start.toml").write_text(scene + "start = 0.001\nsample_width_ps = 5.003461427972\n")
    assert load_scene(tmp_path / "own_start.toml").illumination.start == 0.001      # the scene's start wins
    (tmp_path / "wider.toml").write_text(scene + "sample_width = 0.002\n")
    with pytest.raises(SceneError, match="illumination.sample_width: 0.002 m differs from the file's delta_t"):
        load_scene(tmp_path / "wider.toml")
    with h5py_file(tmp_path / "irf.hdf5") as stream:
        del stream["H"]
        stream["H"] = np.ones((9, 2))
    with pytest.raises(SceneError, match="holds 2 histograms"):
        load_scene(tmp_path / "s.toml")


def h5py_file(path):
    import h5py

    return h5py.File(path, "r+")


@pytest.mark.parametrize("ratio", [9.999999999999999e-05, 10000.000000000002])
def test_a_tail_ratio_just_outside_its_bounds_is_shown_with_every_digit(ratio):
    # "got 0.0001" would not say why 9.999999999999999e-05 is refused
    fwhm = 1e-3
    tail = ratio * fwhm
    with pytest.raises(SceneError) as caught:
        make_waveform(Illumination(waveform="emg", fwhm=fwhm, tail=tail), 0.01)
    assert f"got {tail / fwhm!r}" in str(caught.value) and float(repr(tail / fwhm)) == tail / fwhm


@pytest.mark.parametrize("samples, index, shown", [
    ([0, "1", 0], 1, "'1'"), ([0, 1, True], 2, "True"), ([None, 1, 0], 0, "None"), ([0, [1.0], 0], 1, "[1.0]"),
    ([0, 10**400, 0], 1, "about 401 digits"),
])
def test_inline_samples_that_are_not_numbers_are_refused_naming_the_sample(samples, index, shown):
    with pytest.raises(SceneError) as caught:
        Illumination(waveform="sampled", samples=samples, sample_width=1e-3)
    assert caught.value.key == f"illumination.samples[{index}]" and shown in str(caught.value)
    with pytest.raises(SceneError, match="expected numbers, got an array of dtype <U"):
        Illumination(waveform="sampled", samples=np.array(["0", "1", "0"]), sample_width=1e-3)


def test_a_csv_with_a_byte_order_mark_is_read(tmp_path):
    # Excel and Windows Notepad start a UTF-8 CSV with U+FEFF
    (tmp_path / "irf.csv").write_text("\ufeff0\n0.5\n1.0\n0.25\n0\n", encoding="utf-8")
    assert read_samples(tmp_path / "irf.csv").tolist() == [0, 0.5, 1.0, 0.25, 0]
    (tmp_path / "commented.csv").write_bytes(b"\xef\xbb\xbf# IRF\n0\n1\n0\n")
    assert read_samples(tmp_path / "commented.csv").tolist() == [0, 1, 0]
