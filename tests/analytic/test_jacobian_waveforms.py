"""The exact route of analytic.jacobian under waveforms other than the impulse, against independent references.

1. Richardson central differences of the model at tolerance 1e-10 (``route="differences"``, the model's
   own quadrature, sharing nothing with the route's cell integrals; step 2e-5 of the scene's extent, good
   to ~2e-6 of a column's largest entry), on the hard cases: an isochrone born inside a bin, a sensor near
   the plane, a grazing source (paper attenuation), tiny pixels and bins, and a pulse wider than the
   window; the square (s jumps: κ_n' does), Gaussian and EMG waveforms.
2. A point-like plane's closed form (side s): d ≈ L + g·u over the plane, whose density of g·u is a
   trapezoid p, so ∂y_n/∂θ ≈ I s² [∂a/∂θ ∫ p(v) κ_n(L + v) dv + a ∂L/∂θ ∫ p(v) κ_n'(L + v) dv], the
   v-integrals by Gauss rules on the trapezoid's three linear pieces (relative error O(s / distance)).
3. The waveform's width by the differences (the exact route's: tests/analytic/test_jacobian_widths.py):
   y is analytic in ``illumination.fwhm`` (and ``tail``), so they are adequate there; held to the scaling
   law of a unit-peak pulse (S_λ(u) = λ S(u/λ) when every width is
   scaled by λ): Σ_w w ∂y/∂w = y - I ∫ f a [u s(u)]_{u = t_n - d}^{t_{n+1} - d} dx, the last from the
   exact route's time-zero column and moment.
"""

import warnings

import numpy as np
import pytest

from analytic.operator.derivatives import jacobian
from analytic.operator.matrix_free import forward
from analytic.operator.system import QuadratureWarning
from analytic.operator.waveform_sensitivity import waveform_derivatives
from analytic.scenes.common import Illumination, Sampling, default_scene
from analytic.waveforms import cumulative_array, derivative_array, make_waveform
from point_plane import centre_and_spread, expected_columns, trapezoid

_POSITIONS = ["source.position.x", "source.position.y", "source.position.z", "sensors.positions.{k}.x",
              "sensors.positions.{k}.y", "sensors.positions.{k}.z", "sampling.start"]
_STEP = 2e-5
_PULSES = {"square": dict(width=0.05), "gaussian": dict(fwhm=0.06), "emg": dict(fwhm=0.04, tail=0.05)}


def _image(pixels, seed=1):
    return np.random.default_rng(seed).uniform(0.2, 1.0, (pixels, pixels))


def _column_errors(computed, reference):
    """max_n |computed - reference| / max_n |reference| per (sensor, key), over columns that are not all zero."""
    scale = np.abs(reference).max(axis=1)
    gap = np.abs(computed - reference).max(axis=1)
    assert np.all(gap[scale == 0.0] < 1e-12 * scale.max())
    return np.where(scale > 0.0, gap / np.where(scale > 0.0, scale, 1.0), 0.0)


def _reference(call, *args, **options):
    """A reference from the model at tolerance 1e-10, which may stop a few pieces short of it (a square
    pulse, a sensor 4 cm up): it is then good to a little less, which the bounds leave room for."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadratureWarning)
        return call(*args, **options)


def _against_differences(scene, sensor=0, bound=1e-5):
    keys = [key.format(k=sensor) for key in _POSITIONS]
    exact = jacobian(scene, keys)
    reference = _reference(jacobian, scene, keys, route="differences", step=_STEP)
    errors = _column_errors(exact, reference)
    assert errors.max() < bound, errors


@pytest.mark.parametrize("pulse", sorted(_PULSES))
def test_an_isochrone_born_inside_a_bin(pulse):
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                          illumination=Illumination(waveform=pulse, **_PULSES[pulse]), noise=None,
                          sampling=Sampling(bin_width_opl=0.07, start_opl=1.75, count=14))
    _against_differences(scene, sensor=1)


@pytest.mark.parametrize("pulse", ["square", pytest.param("emg", marks=pytest.mark.slow)])
def test_a_sensor_near_the_plane(pulse):
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.37, 0.61, 0.04]], noise=None,
                          illumination=Illumination(waveform=pulse, **_PULSES[pulse]),
                          sampling=Sampling(bin_width_opl=0.09, start_opl=1.0, count=14))
    _against_differences(scene)


@pytest.mark.parametrize("pulse", ["square", "gaussian"])
def test_a_grazing_source_with_the_papers_attenuation(pulse):
    scene = default_scene(pixels=8, reflectance=_image(8), source=(2.5, 0.4, 0.08), sensors=[[0.5, 0.5, 0.7]],
                          attenuation="paper", illumination=Illumination(waveform=pulse, **_PULSES[pulse]),
                          sampling=Sampling(bin_width_opl=0.08, start_opl=2.3, count=14), noise=None)
    _against_differences(scene)


@pytest.mark.slow
def test_tiny_pixels_and_bins_with_a_square_pulse_of_two_bins():
    scene = default_scene(size=0.1, pixels=24, reflectance=_image(24), source=(0.05, 0.04, 0.3),
                          sensors=[[0.02, 0.07, 0.25]], illumination=Illumination(waveform="square", width=0.008),
                          sampling=Sampling(bin_width_opl=0.004, start_opl=0.548, count=16), noise=None)
    _against_differences(scene)


@pytest.mark.parametrize("pulse", ["gaussian", "square"])
def test_a_pulse_wider_than_the_window(pulse):
    """Every cell reaches every bin; κ_n' is a difference of two nearly equal values of s."""
    widths = {"gaussian": dict(fwhm=2.0), "square": dict(width=1.5)}[pulse]
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.3, 0.6, 0.8]], noise=None,
                          illumination=Illumination(waveform=pulse, **widths),
                          sampling=Sampling(bin_width_opl=0.05, start_opl=2.0, count=12))
    _against_differences(scene)


@pytest.mark.parametrize("pulse", ["square", pytest.param("emg", marks=pytest.mark.slow)])
def test_the_scenes_tolerance_bounds_each_column_entry(pulse):
    """At the default 1e-6, every entry within 1e-6 of its column's largest of the route at 1e-9; and the
    same integrals give the model's samples (the model at 1e-10)."""
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.2, 0.3, 0.6], [0.7, 0.9, 0.05]],
                          illumination=Illumination(waveform=pulse, **_PULSES[pulse]), noise=None,
                          sampling=Sampling(bin_width_opl=0.05, start_opl=1.5, count=20))
    keys = [key.format(k=1) for key in _POSITIONS] + ["plane.size"]
    tight = scene.replace(tolerance=1e-9)
    assert _column_errors(jacobian(scene, keys), jacobian(tight, keys)).max() < scene.tolerance
    y, reference = waveform_derivatives(scene)[0], _reference(forward, scene.replace(tolerance=1e-10))
    assert np.abs(y - reference).max() < 1e-6 * np.abs(reference).max()


def test_the_plane_moving_and_growing_under_a_gaussian_pulse():
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                          illumination=Illumination(waveform="gaussian", fwhm=0.06), noise=None,
                          sampling=Sampling(bin_width_opl=0.07, start_opl=1.75, count=14))
    keys = ["plane.translation.y", "plane.rotation.z", "plane.rotation.x", "plane.size"]
    reference = _reference(jacobian, scene, keys, route="differences", step=_STEP)
    assert _column_errors(jacobian(scene, keys), reference).max() < 1e-5


# -- a point-like plane, by hand ------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["lambertian", "paper"])
@pytest.mark.parametrize("pulse", ["gaussian", "emg"])
def test_a_point_like_plane_against_its_closed_form(mode, pulse):
    side = 2e-4
    source, sensor = np.array([0.3, -0.2, 0.7]), np.array([-0.4, 0.5, 0.9])
    centre = np.array([0.5 * side, 0.5 * side, 0.0])
    length = np.linalg.norm(centre - source) + np.linalg.norm(centre - sensor)
    widths = {"gaussian": dict(fwhm=side / 2.0), "emg": dict(fwhm=side / 3.0, tail=side / 4.0)}[pulse]
    scene = default_scene(size=side, pixels=1, reflectance=np.ones((1, 1)), source=tuple(source),
                          sensors=[tuple(sensor)], attenuation=mode, noise=None,
                          illumination=Illumination(waveform=pulse, **widths),
                          sampling=Sampling(bin_width_opl=side / 3.0, start_opl=length - 1.5 * side, count=10))
    computed = jacobian(scene, [key.format(k=0) for key in _POSITIONS])[0]
    _, length, alpha, beta = centre_and_spread(scene)
    # K_n and K'_n by a G_40 on each of the trapezoid's three linear pieces (the pulses are smooth over them)
    ends = np.sort([-alpha - beta, -abs(alpha - beta), abs(alpha - beta), alpha + beta])
    x, w = np.polynomial.legendre.leggauss(40)
    v = np.concatenate([0.5 * (b + a) + 0.5 * (b - a) * x for a, b in zip(ends[:-1], ends[1:])])
    weight = trapezoid(v, alpha, beta)[0] * np.concatenate([0.5 * (b - a) * w for a, b in zip(ends[:-1], ends[1:])])
    terms = make_waveform(scene.illumination, scene.sampling.bin_width_opl).terms
    u = scene.sampling.edges[:, None] - length - v[None, :]                         # t_e - d
    kernel = (cumulative_array(terms, u[1:]) - cumulative_array(terms, u[:-1])) @ weight
    slope = (derivative_array(terms, u[:-1]) - derivative_array(terms, u[1:])) @ weight
    expected = expected_columns(scene, kernel, slope)
    errors = np.abs(computed - expected).max(axis=0) / np.abs(expected).max(axis=0)
    assert errors.max() < 2e-3, errors


# -- the waveform's width ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("pulse", ["gaussian", "emg"])
def test_the_widths_differences_against_the_scaling_law_of_a_unit_peak_pulse(pulse):
    widths = {"gaussian": dict(fwhm=0.06), "emg": dict(fwhm=0.04, tail=0.05)}[pulse]
    # the window opens before any light arrives (first arrivals 1.81 m and 1.58 m, the pulses' leads
    # -0.22 m and -0.15 m), so R(t_0) = I ∫ f a s(t_0 - d) = 0
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                          illumination=Illumination(waveform=pulse, **widths), noise=None,
                          sampling=Sampling(bin_width_opl=0.07, start_opl=1.2, count=24))
    keys = [f"illumination.{name}" for name in widths]
    columns = _reference(jacobian, scene, keys, route="differences")
    scaled = sum(value * columns[..., i] for i, value in enumerate(widths.values()))
    y, _, _, start, moment, _ = waveform_derivatives(scene.replace(tolerance=1e-9))
    assert np.all(y[:, 0] == 0.0)
    # R(t_e) = I ∫ f a s(t_e - d) from ∂y_n/∂t_0 = R(t_{n+1}) - R(t_n); I ∫ f a [u s(u)] = t_e R(t_e) - ∫ f a d s
    response = np.concatenate([np.zeros((y.shape[0], 1)), np.cumsum(start, axis=1)], axis=1)
    edges = scene.sampling.edges
    expected = y - (edges[1:] * response[:, 1:] - edges[:-1] * response[:, :-1]) + moment
    assert _column_errors(scaled[..., None], expected[..., None]).max() < 1e-6
