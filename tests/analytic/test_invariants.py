"""Physical invariants of the analytic model (no reference values needed)."""

import warnings

import numpy as np
import pytest
from reference import contour_response
from scipy import integrate

from analytic.attenuation import LAMBERTIAN, PAPER, attenuation
from analytic.kernels.attenuation import attenuation_at
from analytic.kernels.isochrone import make_frame
from analytic.scenes.common import MIN_HEIGHT_FRACTION, scene_extent
from analytic.operator.response import impulse_response
from analytic.scenes.common import Illumination, Sampling, Scene, SceneError, default_scene
from analytic.operator.system import system_matrix
from analytic.waveforms import make_waveform


def _whole_response_scene(waveform="impulse", **changes):
    """A window that holds every path length of the response (and the pulse's tail)."""
    base = dict(pixels=12, source=(0.4, 0.55, 0.7), sensors=[(0.8, 0.3, 0.5), (-0.3, 1.2, 0.2)],
                illumination=Illumination(waveform=waveform),
                sampling=Sampling(bin_width_opl=0.07, start_opl=0.5, count=60))
    base.update(changes)
    return Scene(**base)


def _plane_integral(source, sensor, size=1.0, kind="lambertian"):
    """∫_{[0, L]²} a(x) dx by SciPy's adaptive dblquad (independent of the model)."""
    value, _ = integrate.dblquad(
        lambda y, x: float(attenuation(np.array([x, y]), source, sensor, kind)),
        0.0, size, 0.0, size, epsabs=0.0, epsrel=1e-10)
    return value


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_time_integral_equals_steady_response(waveform):
    """Σ_n (A 1)_k = (∫ s dt) ∫_plane a_k dx when the window covers the whole response."""
    scene = _whole_response_scene(waveform)
    matrix = system_matrix(scene)
    energy = make_waveform(scene.illumination, scene.sampling.bin_width_opl).energy
    totals = (matrix @ np.ones(scene.pixels**2)).reshape(scene.sensor_count, -1).sum(axis=1)
    for k in range(scene.sensor_count):
        steady = energy * _plane_integral(scene.source, scene.sensors[k])
        assert totals[k] == pytest.approx(steady, rel=1e-6)


def test_mirror_symmetric_sensors_give_equal_traces():
    scene = Scene(pixels=15, source=(0.5, 0.37, 0.8), sensors=[(0.2, 0.6, 0.9), (0.8, 0.6, 0.9)],
                  sampling=Sampling(bin_width_opl=0.03, start_opl=1.4, count=50))
    matrix = system_matrix(scene)
    image = np.random.default_rng(4).uniform(size=(15, 15))
    image = 0.5 * (image + image[:, ::-1])            # symmetric under x -> L - x
    y = (matrix @ image.ravel()).reshape(2, -1)
    assert np.max(np.abs(y[0] - y[1])) <= 1e-6 * y.max()
    # and a mirrored image seen by the mirrored sensor
    image = np.random.default_rng(5).uniform(size=(15, 15))
    left = (matrix @ image.ravel()).reshape(2, -1)[0]
    right = (matrix @ image[:, ::-1].ravel()).reshape(2, -1)[1]
    assert np.max(np.abs(left - right)) <= 1e-6 * left.max()


@pytest.mark.parametrize("pixel", [(0, 0), (3, 7), (9, 2)])
def test_single_bright_pixel_lights_exactly_its_path_length_bins(pixel):
    scene = Scene(pixels=10, source=(0.3, 0.6, 0.5), sensors=[(0.7, 0.2, 0.4)],
                  sampling=Sampling(bin_width_opl=0.01, start_opl=0.8, count=150))
    image = np.zeros((10, 10))
    image[pixel] = 1.0
    y = system_matrix(scene) @ image.ravel()
    # the pixel's path-length range by brute force over a dense grid of the pixel
    r, c = pixel
    delta = 0.1
    u = np.linspace(0, 1, 801)
    x = (c + u)[None, :] * delta
    yy = (1.0 - (r + u) * delta)[:, None]
    d = (np.sqrt((x - 0.3) ** 2 + (yy - 0.6) ** 2 + 0.25) + np.sqrt((x - 0.7) ** 2 + (yy - 0.2) ** 2 + 0.16))
    first = int(np.floor((d.min() - 0.8) / 0.01))
    last = int(np.floor((d.max() - 0.8) / 0.01))
    lit = np.nonzero(y > 0)[0]
    assert lit.min() >= first - 1 and lit.max() <= last + 1     # grid resolution: ±1 bin
    assert np.all(y[first + 1:last] > 0)                         # every bin strictly inside is lit


def test_paper_and_lambertian_differ_by_pi_over_cos(rng):
    source = np.array([0.3, 0.4, 0.7])
    sensor = np.array([0.9, -0.2, 0.35])
    points = rng.uniform(-1, 2, size=(200, 2))
    ratio = attenuation(points, source, sensor, "paper") / attenuation(points, source, sensor, "lambertian")
    d_sensor = np.sqrt(((points - sensor[:2]) ** 2).sum(axis=1) + sensor[2] ** 2)
    np.testing.assert_allclose(ratio, np.pi * d_sensor / sensor[2], rtol=1e-13)
    # the compiled (Numba) form used by the quadrature agrees pointwise
    for mode, kind in ((LAMBERTIAN, "lambertian"), (PAPER, "paper")):
        frame = make_frame(source, sensor, mode)
        compiled = np.array([attenuation_at(frame, *p) for p in points])
        np.testing.assert_allclose(compiled, attenuation(points, source, sensor, kind), rtol=1e-13)


@pytest.mark.slow      # 13 s; the entries are held to independent references in test_system.py
def test_bin_integral_of_impulse_response_equals_sample():
    """∫_bin g_k(t) dt (contour form with the coarea factor) = y_k[n] for the impulse."""
    scene = default_scene(pixels=20, noise=None)
    y = (system_matrix(scene) @ scene.reflectance.ravel()).reshape(16, -1)
    edges = scene.sampling.edges
    for k in (0, 5):
        for n in np.argsort(y[k])[-2:]:
            with warnings.catch_warnings():   # QUADPACK's roundoff notes; the comparison judges
                warnings.simplefilter("ignore", integrate.IntegrationWarning)
                value, _ = integrate.quad(lambda t: impulse_response(scene, k, [t])[0], edges[n],
                                          edges[n + 1], limit=200, epsabs=0.0, epsrel=1e-9)
            assert value == pytest.approx(y[k, n], abs=1e-6 * y[k].max())


def test_coarea_contour_matches_independent_polar_reference():
    scene = Scene(pixels=6, reflectance=np.random.default_rng(1).uniform(size=(6, 6)),
                  source=(0.45, 0.5, 0.6), sensors=[(0.8, 0.2, 0.7)])
    first = np.hypot(np.hypot(0.35, 0.3), 1.3)
    for t in first + np.array([0.01, 0.1, 0.3]):
        ours = impulse_response(scene, 0, [t])[0]
        reference = contour_response(t, scene.reflectance, 1.0, scene.source, scene.sensors[0])
        assert ours == pytest.approx(reference, rel=1e-7)


def test_paper_contour_without_coarea_factor_is_measurably_wrong():
    """Eq. (3) (unit speed, no 1/|∇d|) is not the impulse response: the gap is large."""
    scene = default_scene(pixels=10, noise=None)
    times = np.linspace(2.15, 2.45, 8)   # inside the response of sensor 3
    right = impulse_response(scene, 3, times)
    wrong = impulse_response(scene, 3, times, coarea=False)
    assert np.max(np.abs(wrong / right - 1)) > 0.3


def test_image_orientation_top_left_pixel_is_nearest_to_a_sensor_above_it():
    """image[0, 0] covers x ∈ [0, Δ), y ∈ [L - Δ, L): a sensor above (0, L) sees it first."""
    scene = Scene(pixels=8, source=(0.05, 0.95, 0.3), sensors=[(0.0, 1.0, 0.3)],
                  sampling=Sampling(bin_width_opl=0.01, start_opl=0.5, count=200))
    matrix = system_matrix(scene).toarray()
    first_bins = np.array([np.nonzero(matrix[:, p])[0].min() for p in range(64)])
    assert np.argmin(first_bins) == 0
    assert first_bins[0] < first_bins[7] and first_bins[0] < first_bins[56]


def _foot_scene(height, *, low="source", pixels=10):
    """A uniform plane (ρ = 0.5) over its whole response, with the source or the sensor at ``height``."""
    low_point, other = (0.37, 0.52, height), (0.8, 0.3, 0.7)
    source, sensor = (low_point, other) if low == "source" else (other, low_point)
    return Scene(pixels=pixels, reflectance=0.5, source=source, sensors=[sensor],
                 sampling=Sampling(bin_width_opl=0.05, start_opl=0.5, count=40))


@pytest.mark.parametrize("low", ["source", "sensor"])
def test_response_tends_to_its_limit_as_a_point_nears_the_plane(low):
    """Σ_n y[n] -> 2 ρ cos θ / d² (d, θ from the foot to the other point) as the height -> 0.

    Under a point at height h the attenuation is a peak of area 2π h_other /
    (π d³) whatever h; the rest of the plane contributes O(h). The model must
    reach the limit down to the smallest supported height, MIN_HEIGHT_FRACTION
    of the scene's extent (just above it here).
    """
    foot, other = np.array([0.37, 0.52]), np.array([0.8, 0.3, 0.7])
    distance = np.sqrt(np.sum((foot - other[:2]) ** 2) + other[2] ** 2)
    limit = 2.0 * 0.5 * other[2] / distance**3
    deviations = []
    for height in (1e-3, 1e-6, 2 * MIN_HEIGHT_FRACTION):
        scene = _foot_scene(height, low=low)
        total = float(np.sum(system_matrix(scene) @ scene.reflectance.ravel()))
        deviations.append(abs(total / limit - 1.0))
    assert deviations[-1] <= 1e-5
    assert deviations == sorted(deviations, reverse=True)


@pytest.mark.parametrize("low", ["source", "sensor"])
@pytest.mark.parametrize("height", [1e-300, 5e-324, 0.5 * MIN_HEIGHT_FRACTION])
def test_heights_below_the_supported_floor_are_refused(low, height):
    assert MIN_HEIGHT_FRACTION * scene_extent(1.0, (0.5, 0.5, 1.0), [(0.2, 0.7, 1.0)]) > height
    key = "source.position" if low == "source" else r"sensors.positions\[0\]"
    with pytest.raises(SceneError, match=key + ".*smallest height supported"):
        _foot_scene(height, low=low)
