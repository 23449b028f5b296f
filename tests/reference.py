"""Independent high-precision references for the analytic model's tests.

Nothing here shares code with ``analytic``: distances and attenuation are
written out again, pixel boxes follow docs/design.md section 1 directly,
isochrone crossings are found by bracketing root search on d along each
line (not from the ellipse formulas), integrals use SciPy's adaptive
QUADPACK instead of the model's Gauss ladders, and the waveforms' S(u) comes
from ``waveform_reference`` (the Butterworth pulse as an mpmath state-space
model, interpolated here by Chebyshev polynomials for speed and checked
against it), not from ``analytic.waveforms``.

A[(k, n), p] = ∫_{x0}^{x1} dx ∫_{y ∈ [y0, y1]} a(x, y) κ_n(d(x, y)) dy, where
for fixed x the inner integrand is smooth between the roots of
d(x, ·) = b for every breakpoint b of κ_n (adaptive 1-D quadrature between
the roots of the line–ellipse intersection).
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
from scipy import integrate, optimize
from waveform_reference import ButterworthReference


def pixel_box(size, pixels, p):
    """(x0, x1, y0, y1) of pixel p = r M + c: image[r, c] covers x in [cΔ, (c+1)Δ), y in [L-(r+1)Δ, L-rΔ)."""
    delta = size / pixels
    r, c = divmod(int(p), pixels)
    return c * delta, (c + 1) * delta, size - (r + 1) * delta, size - r * delta


def _clenshaw(coefficients, scale, shift, u):
    """Σ c_j T_j(x) at x = scale u + shift, by Clenshaw's recurrence (scalar, pure Python)."""
    x = scale * u + shift
    twice = 2.0 * x
    upper = lower = 0.0
    for c in coefficients[:0:-1]:
        upper, lower = twice * upper - lower + c, upper
    return x * upper - lower + coefficients[0]


def _chebyshev(function, low, high, degree):
    """Coefficients, scale and shift of the Chebyshev interpolant of ``function`` on [low, high]."""
    nodes = np.polynomial.chebyshev.chebpts1(degree + 1)
    scale = 2.0 / (high - low)
    shift = -1.0 - scale * low
    values = [function((x - shift) / scale) for x in nodes]
    return [float(c) for c in np.polynomial.chebyshev.chebfit(nodes, values, degree)], scale, shift


@functools.lru_cache(maxsize=16)
def _butterworth_cumulative(order, cutoff, duration):
    """S(u) on [0, duration] from the mpmath reference, checked to 1e-13 relative.

    An all-pole filter of order n starts as t^(n-1), so S(u) = u^n g(u) with
    g smooth: on the first quarter g is interpolated (keeping S relatively
    accurate as u -> 0, where the first-arrival bins sample it), on the rest
    S itself, each by a Chebyshev series.
    """
    pulse = ButterworthReference(order, cutoff, duration)
    split = 0.25 * duration
    head = _chebyshev(lambda u: pulse.cumulative(u) / u**order, 0.0, split, 32)
    tail = _chebyshev(pulse.cumulative, split, duration, 32)

    def function(u):
        if u < split:
            return u**order * _clenshaw(*head, u)
        return _clenshaw(*tail, u)

    for u in np.concatenate([np.geomspace(1e-9, 1e-2, 5), np.linspace(0.0, 1.0, 13)[1:] - 1 / 29]) * duration:
        exact = pulse.cumulative(u)
        assert abs(function(u) - exact) <= 1e-13 * abs(exact), "Chebyshev interpolant of S(u) too coarse"
    return function


def cumulative(illumination, period):
    """S(u) of a scene's ``[illumination]`` (defaults resolved from ``period`` as docs/design.md states), and its duration.

    Returns
    -------
    function, float
        S as a scalar function of u (metres), and the pulse's duration (0
        for the impulse): S has breakpoints at 0 and at the duration.
    """
    if illumination.waveform == "impulse":
        return (lambda u: 1.0 if u > 0 else 0.0), 0.0
    if illumination.waveform == "square":
        width = period / 5.0 if illumination.width is None else illumination.width
        return (lambda u: min(max(u, 0.0), width)), width
    cutoff = 0.5 / period if illumination.cutoff is None else illumination.cutoff
    duration = 3.0 / cutoff if illumination.duration is None else illumination.duration
    order = 3 if illumination.order is None else illumination.order
    inside = _butterworth_cumulative(int(order), float(cutoff), float(duration))
    end = inside(duration)
    return (lambda u: 0.0 if u <= 0 else end if u >= duration else inside(u)), duration


def bin_kernel(illumination, start, period, n):
    """κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) with t_n = start + n period, and where it is not smooth.

    Returns
    -------
    function, list of float
        κ_n as a scalar function of τ (metres), and its breakpoints.
    """
    lower = start + period * n
    upper = start + period * (n + 1)
    function, duration = cumulative(illumination, period)

    def kernel(tau):
        return function(upper - tau) - function(lower - tau)

    breakpoints = [lower, upper] + ([lower - duration, upper - duration] if duration > 0 else [])
    return kernel, breakpoints


def distance_sum(x, y, source, sensor):
    return (math.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
            + math.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2))


def attenuation(x, y, source, sensor, kind):
    ds = math.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
    dk = math.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2)
    cos_s = source[2] / ds
    cos_k = sensor[2] / dk
    if kind == "lambertian":
        return cos_s * cos_k / (math.pi * ds**2 * dk**2)
    return cos_s / (ds**2 * dk**2)


def _least(function, lo, hi, xatol):
    """(x, function(x)) where a convex ``function`` is least on [lo, hi], the ends included.

    The bounded minimiser never evaluates the ends and stops about sqrt(eps) |x| short of
    one: a level set that only touches the interval there would be lost.
    """
    found = optimize.minimize_scalar(function, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    return min(((x, function(x)) for x in (lo, found.x, hi)), key=lambda pair: pair[1])


def _line_roots(x, y0, y1, level, source, sensor):
    """y in [y0, y1] with d(x, y) = level (d is convex in y: at most two)."""
    def f(y):
        return distance_sum(x, y, source, sensor) - level

    y_min, f_min = _least(f, y0, y1, 1e-15 * max(1.0, abs(y1)))
    roots = []
    if f_min >= 0:
        return roots
    if f(y0) > 0:
        roots.append(optimize.brentq(f, y0, y_min, xtol=1e-15, rtol=1e-15))
    if f(y1) > 0:
        roots.append(optimize.brentq(f, y_min, y1, xtol=1e-15, rtol=1e-15))
    return roots


def _quiet(function):
    """QUADPACK warns of roundoff when asked for 1e-10; the comparison itself judges the result."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", integrate.IntegrationWarning)
            return function(*args, **kwargs)
    return wrapper


@_quiet
def pixel_entry(box, source, sensor, kernel, breakpoints, kind="lambertian", epsrel=1e-10, weight=None):
    """∫_box a(x) kernel(d(x)) dx by nested adaptive quadrature.

    Parameters
    ----------
    box : (x0, x1, y0, y1)
        Pixel, metres.
    source, sensor : sequence of 3 floats
    kernel : callable
        κ(τ) for one bin (scalar).
    breakpoints : sequence of float
        Path lengths where κ is not smooth.
    kind : {"lambertian", "paper"}
    weight : callable, optional
        ``weight(x, y)`` in place of the attenuation of ``kind`` (e.g. with a relay wall's cosines).
    """
    x0, x1, y0, y1 = box

    def inner(x):
        cuts = [y0, y1]
        for level in breakpoints:
            cuts.extend(_line_roots(x, y0, y1, level, source, sensor))
        cuts = sorted(set(cuts))
        total = 0.0
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            if hi <= lo:
                continue
            value, _ = integrate.quad(
                lambda y: (attenuation(x, y, source, sensor, kind) if weight is None else weight(x, y))
                * kernel(distance_sum(x, y, source, sensor)),
                lo, hi, epsabs=0.0, epsrel=epsrel, limit=200)
            total += value
        return total

    # Cut the outer range where each level set {d < level} begins and ends in x
    # (roots of the convex m(x) = min_y d(x, y)), so a region far narrower than
    # the pixel (a just-born isochrone) is not missed by the first rule.
    def lowest(x):
        return _least(lambda y: distance_sum(x, y, source, sensor), y0, y1, 1e-14)[1]

    x_best = _least(lowest, x0, x1, 1e-14)[0]
    cuts = {x0, x1, x_best}
    for level in breakpoints:
        if lowest(x_best) >= level:
            continue
        for end in (x0, x1):
            if lowest(end) > level:
                cuts.add(optimize.brentq(lambda x: lowest(x) - level, *sorted((x_best, end)),
                                         xtol=1e-15))
    cuts = sorted(cuts)
    value = 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        if hi > lo:
            value += integrate.quad(inner, lo, hi, epsabs=0.0, epsrel=epsrel, limit=400)[0]
    return value


@_quiet
def contour_response(t, image, size, source, sensor, kind="lambertian", epsrel=1e-10):
    """g(t) = ∮_{d = t} f a / |∇d| ds, by adaptive quadrature in the polar angle about x*.

    The isochrone is star-shaped about the first-arrival point x*; along each
    ray from x* the radius r(θ) with d = t is found by root search, and
    ds / |∇d| = r dθ / (∇d · r̂) (independent of the ellipse formulas).
    """
    source = np.asarray(source, float)
    sensor = np.asarray(sensor, float)
    ratio = source[2] / (source[2] + sensor[2])
    star = source[:2] + (sensor[:2] - source[:2]) * ratio
    pixels = image.shape[0]
    delta = size / pixels

    def radius(theta):
        direction = np.array([math.cos(theta), math.sin(theta)])

        def f(r):
            p = star + r * direction
            return distance_sum(p[0], p[1], source, sensor) - t
        high = 1.0
        while f(high) < 0:
            high *= 2
        return optimize.brentq(f, 0.0, high, xtol=1e-15, rtol=1e-15), direction

    def integrand(theta):
        r, direction = radius(theta)
        p = star + r * direction
        if not (0 <= p[0] < size and 0 <= p[1] < size):
            return 0.0
        c = min(int(p[0] / delta), pixels - 1)
        row = min(int((size - p[1]) / delta), pixels - 1)
        point = np.array([p[0], p[1], 0.0])
        grad = ((point - source) / np.linalg.norm(point - source)
                + (point - sensor) / np.linalg.norm(point - sensor))[:2]
        return image[row, c] * attenuation(p[0], p[1], source, sensor, kind) * r / abs(grad @ direction)

    # break the angle range where the contour crosses pixel edges (found by sampling)
    thetas = np.linspace(0, 2 * math.pi, 4097)
    cells = []
    for theta in thetas:
        r, direction = radius(theta)
        p = star + r * direction
        inside = 0 <= p[0] < size and 0 <= p[1] < size
        cells.append((min(int(p[0] / delta), pixels - 1), min(int((size - p[1]) / delta), pixels - 1))
                     if inside else None)
    points = []
    for i in range(len(thetas) - 1):
        if cells[i] != cells[i + 1]:
            points.append(optimize.brentq(
                lambda th: _cell_change(th, thetas[i], radius, star, size, delta, pixels, cells[i]),
                thetas[i], thetas[i + 1], xtol=1e-15))
    cuts = [0.0] + points + [2 * math.pi]
    total = 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        value, _ = integrate.quad(integrand, lo, hi, epsabs=0.0, epsrel=epsrel, limit=200)
        total += value
    return total


def _cell_change(theta, start, radius, star, size, delta, pixels, cell):
    r, direction = radius(theta)
    p = star + r * direction
    inside = 0 <= p[0] < size and 0 <= p[1] < size
    here = ((min(int(p[0] / delta), pixels - 1), min(int((size - p[1]) / delta), pixels - 1))
            if inside else None)
    return -1.0 if here == cell else 1.0
