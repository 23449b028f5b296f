"""A pixel that one bin edge cuts, for a step-function waveform (analytic.strips.single_cut).

Assembly serves such a (pixel, pair) by the two parts' ∫ a alone (a G_n x G_n
ladder between the conic side's closed-form limits), their kernels once per
part. Held here, on hand-placed hard cuts (an edge through the middle, one
grazing a corner, an isochrone tangent to a side near x*, pixels near x* and
near a foot), to the adaptive (τ, φ) route, which shares none of its code, and
to tests/reference.py's nested QUADPACK integrals with their own root search.
"""

import math
import warnings

import numpy as np
import pytest
from scipy import optimize

from analytic.isochrone import PixelBox, first_arrival_point, make_frame
from analytic.scene import Illumination, Sampling, Scene
from analytic.strips import single_cut
from analytic.system import QuadratureWarning, pair_entries
from reference import bin_kernel, distance_sum, pixel_box, pixel_entry

TOLERANCE = 1e-10
AGREEMENT = 1e-9
PIXELS = 128
PERIOD = 0.1


def _pixel_of(x, y, pixels=PIXELS, size=1.0):
    """p = r M + c of the pixel holding (x, y) (row r from the top)."""
    delta = size / pixels
    return (pixels - 1 - int(y // delta)) * pixels + int(x // delta)


def _side_minimum(box, source, sensor):
    """The least d along the pixel's lower side (its value where an isochrone touches that side)."""
    x0, x1, y0, _ = box
    found = optimize.minimize_scalar(lambda x: distance_sum(x, y0, source, sensor), bounds=(x0, x1),
                                     method="bounded", options={"xatol": 1e-14})
    return found.fun


def _range(box, source, sensor):
    """d's least and greatest value over the pixel, on a fine grid (for placing the edges only)."""
    xs = np.linspace(box[0], box[1], 201)
    ys = np.linspace(box[2], box[3], 201)
    values = [distance_sum(x, y, source, sensor) for x in xs for y in ys]
    return min(values), max(values)


def _cases():
    """(name, source, sensor, pixel, edge): an edge placed in the pixel's range of d, metres."""
    far = ((0.3, 0.4, 0.5), (0.7, 0.6, 0.5))            # x* = (0.5, 0.5), far from both feet
    low = ((0.31, 0.42, 0.004), (0.8, 0.7, 0.6))       # a source foot 4 mm below, under a 7.8 mm pixel
    delta = 1.0 / PIXELS
    cases = []
    middle = _pixel_of(0.21, 0.83)
    for name, source, sensor, pixel, where in (
            ("middle", *far, middle, 0.5),
            ("grazing", *far, middle, 0.02),
            ("near x*", *far, _pixel_of(0.5 + 2.5 * delta, 0.5), 0.5),
            ("next to x*", *far, _pixel_of(0.5 + delta, 0.5 + delta), 0.5),
            ("over a foot", *low, _pixel_of(0.31, 0.42), 0.5),
            ("beside a foot", *low, _pixel_of(0.31 + 1.5 * delta, 0.42), 0.3)):
        lowest, highest = _range(pixel_box(1.0, PIXELS, pixel), source, sensor)
        cases.append((name, source, sensor, pixel, lowest + where * (highest - lowest)))
    # an isochrone just past touching the lower side of a pixel two rows above x*: a thin lens
    pixel = _pixel_of(0.5, 0.5 + 2.5 * delta)
    touch = _side_minimum(pixel_box(1.0, PIXELS, pixel), *far)
    cases.append(("tangent", *far, pixel, touch + 1e-7))
    return cases


CASES = _cases()


def _scene(source, sensor, edge, waveform):
    """One sensor; bins of 0.1 m with an edge at ``edge`` (the square pulse's are its two ends' too)."""
    illumination = Illumination(waveform=waveform, **({"width": 0.25} if waveform == "square" else {}))
    return Scene(pixels=PIXELS, source=source, sensors=[sensor], illumination=illumination,
                 sampling=Sampling(bin_width_opl=PERIOD, start_opl=edge - 20 * PERIOD, count=60))


@pytest.mark.parametrize("name, source, sensor, pixel, edge", CASES, ids=[case[0] for case in CASES])
def test_single_cut_parts_match_the_reference(name, source, sensor, pixel, edge):
    """Both parts' ∫ a against nested QUADPACK with its own root search, where the route applies."""
    x0, x1, y0, y1 = pixel_box(1.0, PIXELS, pixel)
    frame = make_frame(np.asarray(source, float), np.asarray(sensor, float), 0)
    below, above, served = single_cut(frame, PixelBox(x0, x1, y0, y1), edge, TOLERANCE)
    side = x1 - x0
    xs, ys = first_arrival_point(frame)
    near = (math.hypot(max(x0 - xs, 0, xs - x1), max(y0 - ys, 0, ys - y1)) < side
            or math.hypot(max(x0 - source[0], 0, source[0] - x1), max(y0 - source[1], 0, source[1] - y1),
                          source[2]) < side)
    if near:        # assembly does not ask it there (the other routes serve: the next test)
        return
    # the common case (a small pixel far from x*) is served; near x* or a tangency the ladder may give up
    assert served or name not in ("middle", "grazing"), name
    if not served:
        assert below == above == 0.0, name
        return
    for value, inside in ((below, lambda tau: float(tau < edge)), (above, lambda tau: float(tau > edge))):
        reference = pixel_entry((x0, x1, y0, y1), source, sensor, inside, [edge])
        assert abs(value - reference) <= 1e-8 * abs(reference), (name, value, reference)


@pytest.mark.parametrize("waveform", ["impulse", "square"])
@pytest.mark.parametrize("name, source, sensor, pixel, edge", CASES, ids=[case[0] for case in CASES])
def test_cut_pixel_entries_match_adaptive_and_reference(name, source, sensor, pixel, edge, waveform):
    """What assembly computes for the pixel (single_cut where it applies) against both references."""
    scene = _scene(source, sensor, edge, waveform)
    with warnings.catch_warnings():     # next to a tangency a few (τ, φ) pieces stop at float64's rounding
        warnings.simplefilter("ignore", QuadratureWarning)
        first, values = pair_entries(scene, 0, pixel, method="auto", tolerance=TOLERANCE)
        adaptive_first, adaptive = pair_entries(scene, 0, pixel, method="adaptive", tolerance=TOLERANCE,
                                                taylor=False)
    assert first == adaptive_first and len(values) == len(adaptive) >= 2, name
    scale = np.max(np.abs(adaptive))
    assert np.max(np.abs(values - adaptive)) <= AGREEMENT * scale, name
    for i, value in enumerate(values):
        kernel, breakpoints = bin_kernel(scene.illumination, scene.sampling.start_opl, PERIOD, first + i)
        reference = scene.intensity * pixel_entry(pixel_box(1.0, PIXELS, pixel), source, sensor, kernel,
                                                  breakpoints)
        assert abs(value - reference) <= 1e-8 * abs(reference) + AGREEMENT * scale, (name, i, value, reference)
