"""Each fast quadrature route of the system matrix agrees with the adaptive one.

A's entries are computed by three routes (analytic.operator.system): the tensor rule
on a whole pixel that no kernel breakpoint crosses ("smooth"), the tensor
rule in (τ, φ) on each τ-piece of a cut pixel ("isochrone"), and adaptive
φ-integrals inside adaptive τ-integrals ("adaptive", the slowest and most
general). Each fast route can go through the pixel's moments and the kernels'
Taylor coefficients (analytic.kernels.taylor, what assembly does) or evaluate every
kernel at every node; the reference is the adaptive route evaluating the
kernels directly, which shares neither. On random scenes, pixels, sensors and
waveforms every route must give its entries to 1e-9 of the pair's largest.
"""

import warnings

import numpy as np
import pytest

from analytic.kernels.isochrone import first_arrival_point, make_frame
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.system import QuadratureWarning, pair_entries

AGREEMENT = 1e-9
TOLERANCE = 1e-10


def _random_scene(rng, waveform):
    """A plane seen by two sensors at random places and heights, sampled over its whole response."""
    source = (rng.uniform(-0.3, 1.3), rng.uniform(-0.3, 1.3), rng.uniform(0.15, 1.5))
    sensors = [(rng.uniform(-0.3, 1.3), rng.uniform(-0.3, 1.3), rng.uniform(0.15, 1.5)) for _ in range(2)]
    corners = np.array([(0, 0), (1, 0), (0, 1), (1, 1), (0.5, 0.5)], dtype=float)
    lengths = [np.hypot(np.hypot(*(corners - np.array(p[:2])).T), p[2]) for p in [source]]
    reach = max(np.max(lengths[0] + np.hypot(np.hypot(*(corners - np.array(s[:2])).T), s[2]))
                for s in sensors)
    period = rng.uniform(0.02, 0.3)
    return Scene(pixels=int(rng.integers(4, 40)), source=source, sensors=sensors,
                 illumination=Illumination(waveform=waveform),
                 sampling=Sampling(bin_width_opl=period, start_opl=0.0,
                                   count=int(np.ceil((reach + 1.0) / period))))


def _pairs(rng, count):
    """(scene, sensor, pixel) triples over random scenes and all three waveforms."""
    triples = []
    while len(triples) < count:
        scene = _random_scene(rng, str(rng.choice(["impulse", "square", "butterworth"])))
        for _ in range(4):
            triples.append((scene, int(rng.integers(scene.sensor_count)), int(rng.integers(scene.pixels**2))))
    return triples[:count]


def _clear_of_feet_and_birth(scene, sensor, pixel):
    """Whether the (τ, φ) tensor rule applies: no foot within a pixel side, x* outside the pixel."""
    delta, _ = scene.pixel_size
    r, c = divmod(pixel, scene.pixels)
    x0, x1, y0, y1 = c * delta, (c + 1) * delta, scene.size - (r + 1) * delta, scene.size - r * delta
    for point in (scene.source, scene.sensors[sensor]):
        dx = max(x0 - point[0], 0.0, point[0] - x1)
        dy = max(y0 - point[1], 0.0, point[1] - y1)
        if dx * dx + dy * dy + point[2] ** 2 < delta**2:
            return False
    xs, ys = first_arrival_point(make_frame(np.asarray(scene.source, float),
                                            np.asarray(scene.sensors[sensor], float), 0))
    return not (x0 <= xs <= x1 and y0 <= ys <= y1)


def _assert_agree(fast, adaptive, label):
    first_fast, values_fast = fast
    first_adaptive, values_adaptive = adaptive
    assert first_fast == first_adaptive and len(values_fast) == len(values_adaptive), label
    scale = np.max(np.abs(values_adaptive)) if len(values_adaptive) else 0.0
    assert np.max(np.abs(values_fast - values_adaptive), initial=0.0) <= AGREEMENT * scale, label


def _reference(scene, sensor, pixel):
    """The adaptive route with every kernel evaluated at every node (no moments)."""
    return pair_entries(scene, sensor, pixel, method="adaptive", tolerance=TOLERANCE, taylor=False)


@pytest.mark.parametrize("taylor", [True, False])
def test_smooth_route_agrees_with_adaptive(rng, taylor):
    checked = 0
    for scene, sensor, pixel in _pairs(rng, 120):
        try:
            smooth = pair_entries(scene, sensor, pixel, method="smooth", tolerance=TOLERANCE, taylor=taylor)
        except ValueError:      # a breakpoint crosses this pixel, a foot is near, or the moments do not apply
            continue
        _assert_agree(smooth, _reference(scene, sensor, pixel), (scene.illumination.waveform, sensor, pixel))
        checked += 1
    assert checked >= 20


@pytest.mark.parametrize("method, taylor", [("isochrone", True), ("isochrone", False), ("adaptive", True)])
def test_cut_routes_agree_with_adaptive(rng, method, taylor):
    checked = 0
    for scene, sensor, pixel in _pairs(rng, 40 if (method, taylor) == ("isochrone", True) else 24):
        if method == "isochrone" and not _clear_of_feet_and_birth(scene, sensor, pixel):
            continue
        fast = pair_entries(scene, sensor, pixel, method=method, tolerance=TOLERANCE, taylor=taylor)
        _assert_agree(fast, _reference(scene, sensor, pixel), (scene.illumination.waveform, sensor, pixel))
        checked += 1
    assert checked >= 12


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_assembly_route_agrees_with_adaptive(rng, waveform):
    """What system_matrix does (whichever route each pair takes) against the adaptive route."""
    scene = _random_scene(rng, waveform)
    for sensor in range(scene.sensor_count):
        for pixel in rng.choice(scene.pixels**2, size=8, replace=False):
            auto = pair_entries(scene, sensor, int(pixel), method="auto", tolerance=TOLERANCE)
            _assert_agree(auto, _reference(scene, sensor, int(pixel)), (waveform, sensor, pixel))


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_assembly_route_on_fine_pixels_agrees_with_adaptive(rng, waveform):
    """Fine pixels, where assembly settles most pairs from d and ∇d at the pixel's centre and takes
    the smooth ones through their moments over that bound (analytic.kernels.assembly): the same run of bins
    as the exact range gives, and the adaptive route's entries."""
    for _ in range(3):
        scene = _random_scene(rng, waveform).replace(pixels=int(rng.integers(200, 1500)), reflectance=1.0)
        for _ in range(10):
            sensor, pixel = int(rng.integers(scene.sensor_count)), int(rng.integers(scene.pixels**2))
            auto = pair_entries(scene, sensor, pixel, method="auto", tolerance=TOLERANCE)
            _assert_agree(auto, _reference(scene, sensor, pixel), (waveform, scene.pixels, sensor, pixel))


def test_unknown_route_and_inapplicable_smooth_route_are_refused():
    scene = Scene(pixels=4, source=(0.5, 0.5, 1.0), sensors=[(0.5, 0.5, 1.0)],
                  sampling=Sampling(bin_width_opl=0.001, start_opl=1.9, count=400))
    with pytest.raises(ValueError, match="method"):
        pair_entries(scene, 0, 0, method="fast")
    with pytest.raises(ValueError, match="does not apply"):     # 1 mm bins cross every pixel
        pair_entries(scene, 0, 5, method="smooth")


def _fine_scene(rng, waveform):
    """A plane with small pixels (M = 40 ... 400) and bins that cut many of them: the strip route's ground."""
    scene = _random_scene(rng, waveform)
    return scene.replace(pixels=int(rng.integers(40, 400)), reflectance=1.0)


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_strip_route_agrees_with_adaptive(rng, waveform):
    """Cut pixels by slabs with conic sides (analytic.kernels.strips) against the (τ, φ) adaptive route."""
    served = 0
    for _ in range(6):
        scene = _fine_scene(rng, waveform)
        for _ in range(40):
            sensor, pixel = int(rng.integers(scene.sensor_count)), int(rng.integers(scene.pixels**2))
            try:
                strip = pair_entries(scene, sensor, pixel, method="strip", tolerance=TOLERANCE)
            except ValueError:     # near x* or a foot, or G_3 and G_4 disagree: another route serves
                continue
            _assert_agree(strip, _reference(scene, sensor, pixel), (waveform, scene.pixels, sensor, pixel))
            served += len(strip[1]) > 1      # a cut pixel: more than one bin
    assert served >= 10


def test_strip_route_keeps_its_limits_with_a_far_focus():
    """A sensor 1 km away: the conic about the foci's midpoint loses its constant term to rounding,
    which moved slab edges by 1e-6 of a bin (entries off by 3e-5 of the run's largest); the limits
    are polished on d itself. The reference is the adaptive route, which never uses the conic."""
    scene = Scene(size=1.0, pixels=2000, source=(0.5, 0.5, 1e-3), sensors=[(1000.0, 3.0, 1e-3)],
                  illumination=Illumination(waveform="impulse"),
                  sampling=Sampling(bin_width_opl=1e-5, start_opl=999.5031000000001, count=199999))
    first, strip = pair_entries(scene, 0, 2313169, method="strip", tolerance=1e-6)
    with warnings.catch_warnings():     # a few of its pieces stop at float64's rounding, far below 1e-6
        warnings.simplefilter("ignore", QuadratureWarning)
        reference = _reference(scene, 0, 2313169)
    assert first == reference[0] and len(strip) > 1
    assert np.max(np.abs(strip - reference[1])) <= 1e-6 * np.max(np.abs(reference[1]))
