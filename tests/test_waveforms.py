"""Illumination waveforms and their sampling kernels κ_n, against independent computations."""

import numpy as np
import pytest
from scipy import integrate, signal

from analytic.binning import bin_index
from analytic.noise import add_noise
from analytic.scene import Illumination, Noise, Sampling
from analytic.waveforms import make_waveform

SAMPLING = Sampling(bin_width_opl=0.1, start_opl=0.0, count=40)


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


def test_gaussian_noise_has_the_stated_sigma_and_is_seeded():
    y = np.zeros((16, 4000))
    noisy = add_noise(y, Noise(kind="gaussian", sigma=0.1, seed=3))
    assert abs(noisy.std() - 0.1) < 4 * 0.1 / np.sqrt(2 * y.size)
    assert abs(noisy.mean()) < 4 * 0.1 / np.sqrt(y.size)
    np.testing.assert_array_equal(noisy, add_noise(y, Noise(kind="gaussian", sigma=0.1, seed=3)))
    assert not np.array_equal(noisy, add_noise(y, Noise(kind="gaussian", sigma=0.1, seed=4)))


def test_poisson_noise_counts_photons():
    y = np.full(200000, 0.02)
    noisy = add_noise(y, Noise(kind="poisson", photons=500.0, seed=1))
    counts = noisy * 500.0
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)      # whole photons
    mean = 0.02 * 500.0
    assert abs(counts.mean() - mean) < 4 * np.sqrt(mean / y.size)
    assert abs(counts.var() / mean - 1) < 4 * np.sqrt(2 / y.size)
