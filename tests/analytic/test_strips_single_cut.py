"""A pixel that one bin edge cuts, for a step-function waveform (analytic.kernels.strips.single_cut).

Assembly serves such a (pixel, pair) by the two parts' ∫ a alone (a G_n x G_n
ladder between the conic side's closed-form limits), their kernels once per
part. Held here, on hand-placed hard cuts (an edge through the middle, one
grazing a corner, an isochrone tangent to a side near x*, pixels near x* and
near a foot) and at three tolerances, to a converged reference written here
(composite Gauss-Legendre between the isochrone's crossings of the pixel's
sides, found by root search: no conic formula), to the adaptive (τ, φ) route,
which shares none of its code, and to tests/reference.py's nested QUADPACK
integrals with their own root search. A pixel that several edges cut (short bins
over a larger pixel: analytic.kernels.cuts.multi_cut, each slab from the parts below
its two isochrones) is held to the same references, its thin slabs included.
"""

import math
import warnings

import numpy as np
import pytest
from scipy import optimize

from analytic.kernels.isochrone import PixelBox, make_frame
from analytic.kernels.routes import clear_of_birth, clear_of_feet
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.kernels.strips import single_cut
from analytic.kernels.cuts import CUT_COLUMNS, PART, TAU, multi_cut
import analytic.operator.system as system
from analytic.operator.system import QuadratureWarning, pair_entries
from reference import attenuation, bin_kernel, distance_sum, pixel_box, pixel_entry

TOLERANCE = 1e-10
AGREEMENT = 1e-9
RTOLS = (1e-3, 1e-6, 1e-10)
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


# The rtols at which single_cut serves each case (its G_3 ... G_6 ladder agrees); it declines the
# rest. Every hard case is served at some rtol; near x* and a foot the ladder gives up at tight
# ones, and around x* (the isochrone closes inside the pixel) it must decline at every rtol.
SERVED = {"middle": RTOLS, "grazing": RTOLS, "near x*": (1e-3, 1e-6), "next to x*": (1e-3,),
          "over a foot": (1e-3,), "beside a foot": (1e-3, 1e-6), "tangent": (1e-3, 1e-6), "around x*": ()}
# The cases assembly asks single_cut (clear of the feet and of x*)
ASKED = {"middle", "grazing", "near x*", "next to x*", "tangent"}


def _around_star():
    """A small isochrone closed inside the pixel holding x* = (0.505, 0.505) (no side crosses it)."""
    source, sensor = (0.3, 0.4, 0.5), (0.71, 0.61, 0.5)
    pixel = _pixel_of(0.505, 0.505)
    lowest, highest = _range(pixel_box(1.0, PIXELS, pixel), source, sensor)
    return "around x*", source, sensor, pixel, lowest + 0.05 * (highest - lowest)


CUT_CASES = CASES + [_around_star()]
GAUSS = {n: np.polynomial.legendre.leggauss(n) for n in (24, 48)}


def _least(function, lo, hi):
    """(x, function(x)) at the least of a convex function on [lo, hi], the ends included."""
    found = optimize.minimize_scalar(function, bounds=(lo, hi), method="bounded", options={"xatol": 1e-15})
    return min(((x, function(x)) for x in (lo, found.x, hi)), key=lambda pair: pair[1])


def _zeros(function, lo, hi):
    """The zeros of a convex function on [lo, hi] (at most two)."""
    best, least = _least(function, lo, hi)
    if least >= 0.0:
        return []
    return [optimize.brentq(function, *sorted((best, end)), xtol=1e-17, rtol=8.9e-16)
            for end in (lo, hi) if function(end) > 0.0]


def _column_minimum(x, y0, y1, source, sensor):
    """The y in [y0, y1] where d(x, ·) is least: the unfolded straight path's, clamped."""
    a = math.hypot(x - source[0], source[2])
    b = math.hypot(x - sensor[0], sensor[2])
    return min(max(source[1] + (sensor[1] - source[1]) * a / (a + b), y0), y1)


def _column_parts(x, y0, y1, tau, source, sensor):
    """The column's y-intervals where d < τ and where d > τ (d is convex along it)."""
    def excess(y):
        return distance_sum(x, y, source, sensor) - tau

    y_m = _column_minimum(x, y0, y1, source, sensor)
    if excess(y_m) >= 0.0:
        return [], [(y0, y1)]
    lo = optimize.brentq(excess, y0, y_m, xtol=1e-17, rtol=8.9e-16) if excess(y0) > 0.0 else y0
    hi = optimize.brentq(excess, y_m, y1, xtol=1e-17, rtol=8.9e-16) if excess(y1) > 0.0 else y1
    return [(lo, hi)], [(y0, lo), (hi, y1)]


def _parts_by_gauss(box, tau, source, sensor, n):
    """[∫_{d<τ} a, ∫_{d>τ} a] over the pixel by composite G_n x G_n.

    x is cut where the isochrone crosses the lower and upper sides and where it
    is born or dies in the pixel (min over the column of d equals τ: a vertical
    tangent, a square-root end, smoothed by x = p + (q - p)(3s² - 2s³)), and at
    the feet and x*; each column is cut at its roots of d = τ and the feet.
    """
    x0, x1, y0, y1 = box
    ratio = source[2] / (source[2] + sensor[2])
    star = [s + (k - s) * ratio for s, k in zip(source[:2], sensor[:2])]
    cuts = {x0, x1} | {x for x in (source[0], sensor[0], star[0]) if x0 < x < x1}
    for level in (lambda x: distance_sum(x, y0, source, sensor) - tau,
                  lambda x: distance_sum(x, y1, source, sensor) - tau,
                  lambda x: distance_sum(x, _column_minimum(x, y0, y1, source, sensor), source, sensor) - tau):
        cuts.update(_zeros(level, x0, x1))
    cuts = sorted(cuts)
    nodes, weights = GAUSS[n]
    totals = np.zeros(2)
    for p, q in zip(cuts[:-1], cuts[1:]):
        for t, w in zip(nodes, weights):
            s = 0.5 * (1.0 + t)
            x = p + (q - p) * s * s * (3.0 - 2.0 * s)
            weight_x = 3.0 * w * (q - p) * s * (1.0 - s)
            for part, intervals in enumerate(_column_parts(x, y0, y1, tau, source, sensor)):
                for lo, hi in intervals:
                    rows = sorted({lo, hi} | {y for y in (source[1], sensor[1]) if lo < y < hi})
                    for a, b in zip(rows[:-1], rows[1:]):
                        half = 0.5 * (b - a)
                        totals[part] += weight_x * half * sum(
                            v * attenuation(x, a + half * (1.0 + u), source, sensor, "lambertian")
                            for u, v in zip(nodes, weights))
    return totals


def converged_parts(box, tau, source, sensor):
    """[∫_{d<τ} a, ∫_{d>τ} a] by G_48 and its relative change from G_24 (the reference's own error)."""
    coarse = _parts_by_gauss(box, tau, source, sensor, 24)
    fine = _parts_by_gauss(box, tau, source, sensor, 48)
    return fine, np.abs(fine - coarse) / np.abs(fine)


def test_converged_parts_match_quadpack():
    """The converged reference against reference.py's nested QUADPACK on a plain cut and a grazing one."""
    for name, source, sensor, pixel, edge in CASES[:2]:
        box = pixel_box(1.0, PIXELS, pixel)
        parts, change = converged_parts(box, edge, source, sensor)
        assert np.all(change <= 1e-12), name
        for value, inside in zip(parts, (lambda tau: float(tau < edge), lambda tau: float(tau > edge))):
            reference = pixel_entry(box, source, sensor, inside, [edge])
            assert abs(value - reference) <= 1e-11 * value, (name, value, reference)


@pytest.fixture(scope="module")
def converged():
    """Each cut case's converged parts and their own error (computed once for all rtols)."""
    return {case[0]: converged_parts(pixel_box(1.0, PIXELS, case[3]), case[4], case[1], case[2])
            for case in CUT_CASES}


@pytest.mark.parametrize("rtol", RTOLS)
@pytest.mark.parametrize("name, source, sensor, pixel, edge", CUT_CASES, ids=[case[0] for case in CUT_CASES])
def test_single_cut_serves_within_rtol(name, source, sensor, pixel, edge, rtol, converged):
    """Served exactly where SERVED says, and then both parts within rtol of the converged reference."""
    x0, x1, y0, y1 = pixel_box(1.0, PIXELS, pixel)
    frame = make_frame(np.asarray(source, float), np.asarray(sensor, float), 0)
    box = PixelBox(x0, x1, y0, y1)
    assert clear_of_birth(frame, box, clear_of_feet(frame, box)) == (name in ASKED), name
    below, above, served = single_cut(frame, box, edge, rtol)
    assert served == (rtol in SERVED[name]), (name, rtol)
    if not served:
        assert below == above == 0.0, name
        return
    parts, change = converged[name]
    assert np.all(change <= 1e-2 * rtol), (name, change)
    for value, reference in zip((below, above), parts):
        assert abs(value - reference) <= rtol * reference, (name, rtol, value, reference)


@pytest.fixture(scope="module")
def adaptive_entries():
    """The adaptive route's entries at 1e-10 for each (case, waveform), computed once for all rtols."""
    cache = {}

    def entries(name, source, sensor, pixel, edge, waveform):
        if (name, waveform) not in cache:
            with warnings.catch_warnings():     # next to a tangency a few (τ, φ) pieces stop at float64's rounding
                warnings.simplefilter("ignore", QuadratureWarning)
                cache[name, waveform] = pair_entries(_scene(source, sensor, edge, waveform), 0, pixel,
                                                     method="adaptive", tolerance=TOLERANCE, taylor=False)
        return cache[name, waveform]
    return entries


@pytest.mark.parametrize("rtol", RTOLS)
@pytest.mark.parametrize("waveform", ["impulse", "square"])
@pytest.mark.parametrize("name, source, sensor, pixel, edge", CASES, ids=[case[0] for case in CASES])
def test_cut_pixel_entries_match_adaptive_and_reference(name, source, sensor, pixel, edge, waveform, rtol,
                                                       adaptive_entries):
    """What assembly computes for the pixel at rtol (single_cut where it serves) against both references."""
    scene = _scene(source, sensor, edge, waveform)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadratureWarning)
        first, values = pair_entries(scene, 0, pixel, method="auto", tolerance=rtol)
    adaptive_first, adaptive = adaptive_entries(name, source, sensor, pixel, edge, waveform)
    assert first == adaptive_first and len(values) == len(adaptive) >= 2, name
    scale = np.max(np.abs(adaptive))
    assert np.max(np.abs(values - adaptive)) <= (rtol + AGREEMENT) * scale, name
    for i, value in enumerate(values):
        kernel, breakpoints = bin_kernel(scene.illumination, scene.sampling.start_opl, PERIOD, first + i)
        reference = scene.intensity * pixel_entry(pixel_box(1.0, PIXELS, pixel), source, sensor, kernel,
                                                  breakpoints)
        assert abs(value - reference) <= rtol * abs(reference) + AGREEMENT * scale, (name, i, value, reference)


def _several_cuts():
    """(name, source, sensor, pixel, edges): several edges in one pixel's range of d, as fractions of it."""
    far = ((0.3, 0.4, 0.5), (0.7, 0.6, 0.5))
    middle = _pixel_of(0.21, 0.83)
    return [("three", *far, middle, (0.2, 0.5, 0.8)), ("sliver and middle", *far, middle, (0.02, 0.5)),
            ("thin slab", *far, middle, (0.3, 0.33, 0.7)), ("five", *far, middle, (0.1, 0.3, 0.5, 0.7, 0.9)),
            ("near x*", *far, _pixel_of(0.5 + 2.5 / PIXELS, 0.5), (0.4, 0.6))]


SEVERAL = _several_cuts()


@pytest.mark.parametrize("rtol", RTOLS)
@pytest.mark.parametrize("name, source, sensor, pixel, fractions", SEVERAL, ids=[case[0] for case in SEVERAL])
def test_multi_cut_slabs_within_rtol(name, source, sensor, pixel, fractions, rtol):
    """Each slab between consecutive edges within rtol of the converged reference's (G_48 by root search, no
    conic); served at every rtol away from x*, and where one edge cuts, single_cut's numbers exactly."""
    box = pixel_box(1.0, PIXELS, pixel)
    lowest, highest = _range(box, source, sensor)
    edges = [lowest + f * (highest - lowest) for f in fractions]
    frame = make_frame(np.asarray(source, float), np.asarray(sensor, float), 0)
    cuts = np.zeros((len(edges) + 1, CUT_COLUMNS))
    cuts[:len(edges), TAU] = edges
    served = multi_cut(frame, PixelBox(*box), cuts, len(edges), rtol)
    assert served or name == "near x*", (name, rtol)
    if not served:
        return
    below = [0.0] + [converged_parts(box, edge, source, sensor)[0][0] for edge in edges]
    whole = below[-1] + converged_parts(box, edges[-1], source, sensor)[0][1]
    reference = np.diff(below + [whole])
    slabs = cuts[:len(edges) + 1, PART]
    assert np.all(np.abs(slabs - reference) <= rtol * reference + 1e-13 * whole), (name, rtol, slabs, reference)
    one = np.zeros((2, CUT_COLUMNS))
    one[0, TAU] = edges[0]
    assert multi_cut(frame, PixelBox(*box), one, 1, rtol) == single_cut(frame, PixelBox(*box), edges[0], rtol)[2]
    if one[0, PART] != 0.0 or one[1, PART] != 0.0:
        assert tuple(one[:2, PART]) == single_cut(frame, PixelBox(*box), edges[0], rtol)[:2]


@pytest.mark.parametrize("rtol", (1e-6, 1e-10))
def test_pixel_of_short_bins_is_served_by_assembly_and_matches_the_references(rtol, monkeypatch):
    """A pixel over which four impulse bins' edges pass: assembly's first pass serves it (the general routes are
    never called), every entry within rtol of QUADPACK's and of the adaptive route's."""
    name, source, sensor, pixel, _ = SEVERAL[0]
    box = pixel_box(1.0, PIXELS, pixel)
    lowest, highest = _range(box, source, sensor)
    period = (highest - lowest) / 3.5
    scene = Scene(pixels=PIXELS, source=source, sensors=[sensor],
                  sampling=Sampling(bin_width_opl=period, start_opl=lowest + 0.2 * period - 10 * period, count=30))

    def refused(*arguments):
        raise AssertionError("the general routes were asked")

    with monkeypatch.context() as patch:
        patch.setattr(system, "run_left", refused)
        first, values = pair_entries(scene, 0, pixel, method="auto", tolerance=rtol)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadratureWarning)
        adaptive_first, adaptive = pair_entries(scene, 0, pixel, method="adaptive", tolerance=TOLERANCE, taylor=False)
    assert first == adaptive_first and len(values) == len(adaptive) == 5
    assert np.all(np.abs(values - adaptive) <= rtol * adaptive + AGREEMENT * np.max(adaptive))
    for i, value in enumerate(values):
        kernel, breakpoints = bin_kernel(scene.illumination, scene.sampling.start_opl, period, first + i)
        reference = scene.intensity * pixel_entry(box, source, sensor, kernel, breakpoints)
        assert abs(value - reference) <= rtol * abs(reference) + AGREEMENT * np.max(adaptive), (i, value, reference)
