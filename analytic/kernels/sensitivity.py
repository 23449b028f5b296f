"""Exact derivatives of a plane's samples: cell integrals cut at one isochrone (compiled).

For one source-sensor pair over the plane z = 0 (world frame), with
d(x) = |x - p_s| + |x - p_k| and a cell [x0, x1] x [y0, y1] of constant
reflectance, two integrals of the :data:`AMPLITUDES` amplitudes w_j
(:func:`amplitudes`: a, ∂a/∂p_s, ∂a/∂p_k, a ∂d/∂p_s, a ∂d/∂p_k; a relay
wall's pair adds ∂a/∂n and the stretch's moments, :data:`RELAY_AMPLITUDES`)
at each bin edge t:

    F_j(t) = ∫_{cell, d < t} w_j dx        H_j(t) = ∫_{cell} w_j δ(d - t) dx = dF_j/dt

:mod:`analytic.operator.sensitivity` turns them into ∂y/∂θ. The region
d < t is the inside of the isochrone's ellipse (d is convex), so a cell
whose four corners have d < t lies wholly in it (one tensor rule). In a
cell the ellipse crosses, F is an outer integral in x of the y-interval
clipped by the ellipse's two roots at x, and H the outer integral of
Σ_roots w / |∂d/∂y|; the outer integrand is analytic between the
ellipse's x-extremes (square-root ends, where ∂d/∂y = 0) and the x where
the ellipse crosses the cell's lower and upper edges, which cut the outer
interval; every piece is mapped by x = c_x - reach cos(πv), the ellipse's
x-extremes at v = 0 and 1 (its square-root ends become analytic, in every
piece, whether the extreme ends it or lies just beyond it; a piece far from
them stays nearly linear in v), its roots taken from v (no discriminant
that cancels near an extreme), and integrated by a G_n
judged by the order below it (the same order in v and in y: G_2, G_3, G_4, G_6,
G_8, G_11 in turn until two agree), bisected in v when none do, each
amplitude to ``rtol`` of the whole cell's ∫ |w_j| (for F_j, and for the
derivatives at least ∫ a over the first arrival, their column's scale; for
H, a's over the cell's diagonal, ≥ half the range of d over it); the tensor
rule on whole cells the same way, split in four.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .cache import njit

__all__ = ["PairGeometry", "AMPLITUDES", "RELAY_AMPLITUDES", "amplitudes", "isochrone_ellipse", "pair_sums"]

#: a, ∂a/∂p_s (x, y, z), ∂a/∂p_k (x, y, z), a ∂d/∂p_s (x, y, z), a ∂d/∂p_k (x, y, z).
AMPLITUDES = 13
#: A relay wall's pairs (``PairGeometry.surfaces``) add seven (:func:`amplitudes`): ∂a/∂n (x, y, z), the
#: ends' normals turning together, and the stretch's moments (x - m_x)(∂a/∂p_s + ∂a/∂p_k)_x, the same along
#: y, (x - m_x) a (∂d/∂p_s + ∂d/∂p_k)_x and along y. Buffers hold this many.
RELAY_AMPLITUDES = 20
#: F (the area integrals) takes a and ∂a/∂θ (the plane's first seven), H (the coarea ones) a and a ∂d/∂θ.
_AREA = 7
_AREA_INDEX = np.array([0, 1, 2, 3, 4, 5, 6, 13, 14, 15, 16, 17])
_EDGE_INDEX = np.array([0, 7, 8, 9, 10, 11, 12, 18, 19])
#: The Gauss orders climbed, one after the other, until two consecutive ones agree.
_LADDER = np.array([2, 3, 4, 6, 8, 11])
#: Where a cut piece's climb starts (G_2 judged by G_3, as a whole cell's).
_CUT_START = 0
_MAX_DEPTH = 24
#: Rule applications per cell (cut piece or whole cell) before the rest is kept as it is, and counted.
_MAX_RULES = 2000
_STACK = 64


def _unit_rules(orders):
    nodes, weights = np.zeros((len(orders), max(orders))), np.zeros((len(orders), max(orders)))
    for i, order in enumerate(orders):
        x, w = np.polynomial.legendre.leggauss(order)
        nodes[i, :order], weights[i, :order] = 0.5 * (x + 1.0), 0.5 * w
    return nodes, weights


_NODES, _WEIGHTS = _unit_rules(_LADDER)


class PairGeometry(NamedTuple):
    """A source-sensor pair above z = 0: positions (metres), attenuation, and its isochrones' axis."""

    sx: float
    sy: float
    sh: float
    kx: float
    ky: float
    kh: float
    lambertian: bool
    ex: float           # unit vector from the source's foot to the sensor's ((1, 0) if they coincide)
    ey: float
    distance: float     # D, between the feet
    first: float        # t_min = sqrt(D² + (h_s + h_k)²), the first arrival
    second: float       # sqrt(D² + (h_s - h_k)²)
    # the ends' own surfaces (a relay wall's points): a is multiplied by n·(x - p) / |x - p| at each end,
    # unit normals in this frame, fixed when the points move; none for the plane
    surfaces: bool = False
    snx: float = 0.0
    sny: float = 0.0
    snz: float = 0.0
    knx: float = 0.0
    kny: float = 0.0
    knz: float = 0.0
    # a relay wall's stretch moments are taken about (mx, my) (frame metres); mscale (metres) the weight's
    # scale in their accuracy (a coordinate's reach from there over the rectangle)
    mx: float = 0.0
    my: float = 0.0
    mscale: float = 1.0


@njit(cache=True, error_model="numpy", inline="always")
def _counts(g):
    """How many amplitudes the pair has, and how many of them F and H take (:data:`_AREA_INDEX`, :data:`_EDGE_INDEX`)."""
    if g.surfaces:
        return RELAY_AMPLITUDES, 12, 9
    return AMPLITUDES, _AREA, _AREA


@njit(cache=True, error_model="numpy", inline="always")
def _floor(g, j):
    """Area amplitude j's accuracy floor in units of ∫ a over the cell: a column's own scale."""
    if j == 0 or 13 <= j <= 15:
        return 1.0
    if j >= 16:
        return g.mscale / g.first
    return 1.0 / g.first


@njit(cache=True, error_model="numpy", inline="always")
def amplitudes(g, x, y, out):
    """The :data:`AMPLITUDES` amplitudes at plane point (x, y) into ``out`` (1/m⁴ and 1/m⁵)."""
    rsx, rsy, rkx, rky = g.sx - x, g.sy - y, g.kx - x, g.ky - y
    ds2 = rsx * rsx + rsy * rsy + g.sh * g.sh
    dk2 = rkx * rkx + rky * rky + g.kh * g.kh
    ds, dk = math.sqrt(ds2), math.sqrt(dk2)
    if g.lambertian:
        a = g.sh * g.kh / (math.pi * ds2 * ds * dk2 * dk)
        power, own = 3.0 / dk2, 1.0 / g.kh
    else:
        a = g.sh / (ds2 * ds * dk2)
        power, own = 2.0 / dk2, 0.0
    out[0] = a
    # ∂ log a/∂p_s = e_z / h_s - 3 (p_s - x) / d_s²;  ∂ log a/∂p_k = e_z / h_k - 3 (p_k - x) / d_k² (paper: -2 ..., no e_z)
    out[1] = -3.0 * a * rsx / ds2
    out[2] = -3.0 * a * rsy / ds2
    out[3] = a * (1.0 / g.sh - 3.0 * g.sh / ds2)
    out[4] = -power * a * rkx
    out[5] = -power * a * rky
    out[6] = a * (own - power * g.kh)
    # ∂d/∂p = (p - x) / |p - x|
    out[7] = a * rsx / ds
    out[8] = a * rsy / ds
    out[9] = a * g.sh / ds
    out[10] = a * rkx / dk
    out[11] = a * rky / dk
    out[12] = a * g.kh / dk
    if g.surfaces:
        _surfaces(g, (x, y, rsx, rsy, rkx, rky, ds, dk), out)


# not inlined (every rule inlines amplitudes: the relay wall's part compiled once, not in each of them)
@njit(cache=True, error_model="numpy")
def _surfaces(g, point, out):
    """Multiply the amplitudes by the ends' cosines c = n·(x - p) / |x - p| (and ∂a/∂p by the product rule),
    and add a relay wall's seven (:data:`RELAY_AMPLITUDES`)."""
    x, y, rsx, rsy, rkx, rky, ds, dk = point
    # x - p_s = (-rsx, -rsy, -h_s);  ∂c/∂p_j = (-n_j + c (x - p)_j / |x - p|) / |x - p|
    cs = -(g.snx * rsx + g.sny * rsy + g.snz * g.sh) / ds
    ck = -(g.knx * rkx + g.kny * rky + g.knz * g.kh) / dk
    a, both = out[0], cs * ck
    slopes = ((-g.snx - cs * rsx / ds) / ds, (-g.sny - cs * rsy / ds) / ds, (-g.snz - cs * g.sh / ds) / ds,
              (-g.knx - ck * rkx / dk) / dk, (-g.kny - ck * rky / dk) / dk, (-g.knz - ck * g.kh / dk) / dk)
    for j in range(3):
        out[1 + j] = out[1 + j] * both + a * ck * slopes[j]
        out[4 + j] = out[4 + j] * both + a * cs * slopes[3 + j]
    # ∂a/∂n, both ends' normals moving together: a (c_k ∂c_s/∂n + c_s ∂c_k/∂n), ∂c/∂n = (x - p) / |x - p|
    out[13] = -a * (ck * rsx / ds + cs * rkx / dk)
    out[14] = -a * (ck * rsy / ds + cs * rky / dk)
    out[15] = -a * (ck * g.sh / ds + cs * g.kh / dk)
    out[0] = a * both
    for j in range(7, AMPLITUDES):
        out[j] *= both
    mx, my = x - g.mx, y - g.my
    out[16] = mx * (out[1] + out[4])
    out[17] = my * (out[2] + out[5])
    out[18] = mx * (out[7] + out[10])
    out[19] = my * (out[8] + out[11])


@njit(cache=True, error_model="numpy", inline="always")
def _path(g, x, y):
    return (math.sqrt((x - g.sx) ** 2 + (y - g.sy) ** 2 + g.sh * g.sh)
            + math.sqrt((x - g.kx) ** 2 + (y - g.ky) ** 2 + g.kh * g.kh))


@njit(cache=True, error_model="numpy", inline="always")
def _path_dy(g, x, y):
    return ((y - g.sy) / math.sqrt((x - g.sx) ** 2 + (y - g.sy) ** 2 + g.sh * g.sh)
            + (y - g.ky) / math.sqrt((x - g.kx) ** 2 + (y - g.ky) ** 2 + g.kh * g.kh))


@njit(cache=True, error_model="numpy")
def isochrone_ellipse(g, t):
    """Centre (x, y) and semi-axes a (along e), b (across) of d = t, for t > t_min (docs of :mod:`.isochrone`)."""
    D = g.distance
    q = (t * t - g.first * g.first) * (t * t - g.second * g.second)
    span = t * t - D * D
    along = D * (t * t - D * D + g.sh * g.sh - g.kh * g.kh) / (2.0 * span)
    return (g.sx + along * g.ex, g.sy + along * g.ey, math.sqrt(t * t * q) / (2.0 * span),
            math.sqrt(q / (4.0 * span)))


@njit(cache=True, error_model="numpy", inline="always")
def _roots(quadratic, linear, constant):
    """Both roots of q u² + 2 l u + c = 0, sorted, without cancellation; NaN without real roots."""
    disc = linear * linear - quadratic * constant
    if not disc >= 0.0:
        return math.nan, math.nan
    big = -(linear + math.copysign(math.sqrt(disc), linear))
    if big == 0.0:
        return 0.0, 0.0
    first, second = big / quadratic, constant / big
    return min(first, second), max(first, second)


@njit(cache=True, error_model="numpy", inline="always")
def _line_roots(g, ellipse, along_y, level):
    """The free coordinate where the ellipse meets x = level (``along_y``) or y = level; NaN if it does not."""
    cx, cy, a, b = ellipse
    ex, ey = g.ex, g.ey
    # a point c + u e + v e⊥, e⊥ = (-ey, ex); on the line u = pu + qu η, v = pv + qv η
    if along_y:
        fixed = level - cx
        pu, pv, qu, qv, centre = fixed * ex, -fixed * ey, ey, ex, cy
    else:
        fixed = level - cy
        pu, pv, qu, qv, centre = fixed * ey, fixed * ex, ex, -ey, cx
    ia, ib = 1.0 / (a * a), 1.0 / (b * b)
    low, high = _roots(qu * qu * ia + qv * qv * ib, pu * qu * ia + pv * qv * ib, pu * pu * ia + pv * pv * ib - 1.0)
    return centre + low, centre + high


@njit(cache=True, error_model="numpy", inline="always")
def _slice(g, x, roots, rows, weight, rung, area, edge, amp):
    """Add weight x (∫ w dy over the cell's y-interval ``rows`` inside the ellipse, whose ``roots`` at x are
    (low, high); Σ_roots w / |∂d/∂y|)."""
    low, high = roots
    y0, y1 = rows
    bottom, top = max(y0, low), min(y1, high)
    _, areas, edges = _counts(g)
    if top > bottom:
        height = top - bottom
        for i in range(_LADDER[rung]):
            amplitudes(g, x, bottom + height * _NODES[rung, i], amp)
            scale = weight * height * _WEIGHTS[rung, i]
            for k in range(areas):          # F needs a and ∂a/∂θ
                area[_AREA_INDEX[k]] += scale * amp[_AREA_INDEX[k]]
    for root in (low, high):
        if y0 <= root <= y1:
            slope = abs(_path_dy(g, x, root))
            if slope > 0.0:
                amplitudes(g, x, root, amp)
                for k in range(edges):      # H needs a and a ∂d/∂θ
                    edge[_EDGE_INDEX[k]] += weight * amp[_EDGE_INDEX[k]] / slope


@njit(cache=True, error_model="numpy")
def _piece_rule(g, chords, rows, part, rung, area, edge, amp):
    """One rung's F and H of the slices at x(v) = c_x - reach cos(πv), v in ``part`` = (v0, v1), each over
    ``rows`` = (y0, y1). ``chords`` = (c_x, reach, c_y, tilt, half): the ellipse meets the line x = x(v)
    at y = c_y + tilt (x - c_x) ± half sin(πv). The ellipse's x-extremes, its roots' square-root branch
    points, are v = 0 and 1 whatever the piece, so that every slice is analytic in v (a piece far from
    them is nearly linear in v, and low orders suffice); the roots, taken from v rather than from a
    discriminant that cancels near an extreme, are exact to rounding however near one a node is."""
    cx, reach, cy, tilt, half = chords
    v0, v1 = part
    for j in range(RELAY_AMPLITUDES):
        area[j] = 0.0
        edge[j] = 0.0
    for i in range(_LADDER[rung]):
        v = v0 + (v1 - v0) * _NODES[rung, i]
        sine = math.sin(math.pi * v)
        offset = -reach * math.cos(math.pi * v)
        middle, chord = cy + tilt * offset, half * sine
        weight = (v1 - v0) * _WEIGHTS[rung, i] * math.pi * reach * sine
        _slice(g, cx + offset, (middle - chord, middle + chord), rows, weight, rung, area, edge, amp)


@njit(cache=True, error_model="numpy", inline="always")
def _within(low, high, limits, scale):
    """Whether |low_j - high_j| <= scale x limits_j for every amplitude j with a limit (limits_j >= 0)."""
    for j in range(RELAY_AMPLITUDES):
        if limits[j] >= 0.0 and abs(low[j] - high[j]) > scale * limits[j]:
            return False
    return True


@njit(cache=True, error_model="numpy")
def _cut_cell(g, ellipse, box, rtol, magnitude, area, edge, work):
    """Add F and H of one cell the ellipse crosses to ``area`` and ``edge``.

    ``magnitude``: ∫_cell |w_j| of each amplitude (from the tensor rule), the scale of F_j's accuracy, and
    of H's (|a ∂d/∂θ| <= a) over the cell's diagonal (times the moments' scale for theirs); ``work``:
    float64[7, 20]. Returns how many pieces were kept unconverged (the depth or :data:`_MAX_RULES` reached).
    """
    x0, x1, y0, y1 = box[0], box[1], box[2], box[3]
    failures = 0
    limit_area, limit_edge = work[5], work[6]
    diagonal = math.hypot(x1 - x0, y1 - y0)
    _, areas, edges = _counts(g)
    limit_area[:] = -1.0
    limit_edge[:] = -1.0
    for k in range(areas):
        # a derivative's scale at least a's over the first arrival (a column's own scale), so that a
        # derivative vanishing over the cell does not ask for more than its column needs
        j = _AREA_INDEX[k]
        limit_area[j] = rtol * max(magnitude[j], magnitude[0] * _floor(g, j))
    for k in range(edges):
        j = _EDGE_INDEX[k]
        limit_edge[j] = rtol * magnitude[0] / diagonal * (g.mscale if j >= 18 else 1.0)
    cx, cy, a, b = ellipse
    reach = math.sqrt((a * g.ex) ** 2 + (b * g.ey) ** 2)
    xa, xb = max(x0, cx - reach), min(x1, cx + reach)
    if not xb > xa:
        return 0
    cuts = np.empty(6)
    cuts[0], cuts[1] = xa, xb
    count = 2
    for level in (y0, y1):
        low, high = _line_roots(g, ellipse, False, level)
        for root in (low, high):
            if xa < root < xb:
                cuts[count] = root
                count += 1
    cuts[:count].sort()
    first_end, last_end = cx - reach >= x0, cx + reach <= x1
    # the ellipse's chords along y: midpoints on a line, half-lengths sqrt(reach² - (x - c_x)²) / (reach √q)
    q = (g.ey / a) ** 2 + (g.ex / b) ** 2
    chords = (cx, reach, cy, g.ex * g.ey * (1.0 / (b * b) - 1.0 / (a * a)) / q, 1.0 / math.sqrt(q))
    amp, low_area, low_edge, high_area, high_edge = work[0], work[1], work[2], work[3], work[4]
    lows, highs, depths = np.empty(_STACK), np.empty(_STACK), np.empty(_STACK, dtype=np.int64)
    for p in range(count - 1):
        if not cuts[p + 1] > cuts[p]:
            continue
        # the piece in the map's v; an extreme exactly at v = 0 or 1 (acos there is off by √ε, which
        # would leave out a sliver of H's integrand as large: 5e-7 of a cell's H, seen)
        ends = min(1.0, max(-1.0, (cx - cuts[p]) / reach)), min(1.0, max(-1.0, (cx - cuts[p + 1]) / reach))
        vstart = 0.0 if p == 0 and first_end else math.acos(ends[0]) / math.pi
        vend = 1.0 if p == count - 2 and last_end else math.acos(ends[1]) / math.pi
        lows[0], highs[0], depths[0] = vstart, vend, 0
        top = 1
        rules = 0
        while top > 0:
            top -= 1
            rules += 1
            v0, v1, depth = lows[top], highs[top], depths[top]
            _piece_rule(g, chords, (y0, y1), (v0, v1), _CUT_START, high_area, high_edge, amp)
            done = False
            for rung in range(_CUT_START + 1, _LADDER.size):
                low_area[:] = high_area
                low_edge[:] = high_edge
                _piece_rule(g, chords, (y0, y1), (v0, v1), rung, high_area, high_edge, amp)
                if _within(low_area, high_area, limit_area, 1.0) and _within(low_edge, high_edge, limit_edge, 1.0):
                    done = True
                    break
            if done or depth >= _MAX_DEPTH or top + 2 > _STACK or rules >= _MAX_RULES:
                if not done:
                    failures += 1
                for j in range(RELAY_AMPLITUDES):
                    area[j] += high_area[j]
                    edge[j] += high_edge[j]
                continue
            middle = 0.5 * (v0 + v1)
            lows[top], highs[top], depths[top] = v0, middle, depth + 1
            lows[top + 1], highs[top + 1], depths[top + 1] = middle, v1, depth + 1
            top += 2
    return failures


@njit(cache=True, error_model="numpy")
def _box_rule(g, x0, x1, y0, y1, rung, out, absolute, amp):
    for j in range(RELAY_AMPLITUDES):
        out[j] = 0.0
        absolute[j] = 0.0
    order, areas = _LADDER[rung], _counts(g)[1]
    for i in range(order):
        x = x0 + (x1 - x0) * _NODES[rung, i]
        for m in range(order):
            amplitudes(g, x, y0 + (y1 - y0) * _NODES[rung, m], amp)
            scale = (x1 - x0) * (y1 - y0) * _WEIGHTS[rung, i] * _WEIGHTS[rung, m]
            for k in range(areas):
                j = _AREA_INDEX[k]
                out[j] += scale * amp[j]
                absolute[j] += scale * abs(amp[j])


@njit(cache=True, error_model="numpy")
def _full_cell(g, box, rtol, out, magnitude, work):
    """Add ∫ w_j over the whole cell to ``out`` and ∫ |w_j| to ``magnitude``: G_n x G_n up the ladder until
    two agree in every amplitude (to ``rtol`` of its ∫ |w_j|), else split in four. Returns how many
    parts were kept unconverged."""
    amp, low, high, absolute, limits = work[0], work[1], work[3], work[5], work[6]
    limits[:] = -1.0
    areas = _counts(g)[1]
    boxes = np.empty((_STACK, 4))
    depths = np.empty(_STACK, dtype=np.int64)
    boxes[0, :] = box[:4]
    depths[0] = 0
    top = 1
    rules = failures = 0
    while top > 0:
        top -= 1
        rules += 1
        x0, x1, y0, y1 = boxes[top, 0], boxes[top, 1], boxes[top, 2], boxes[top, 3]
        depth = depths[top]
        _box_rule(g, x0, x1, y0, y1, 0, high, absolute, amp)
        done = False
        for rung in range(1, _LADDER.size):
            low[:] = high
            _box_rule(g, x0, x1, y0, y1, rung, high, absolute, amp)
            for k in range(areas):
                j = _AREA_INDEX[k]
                limits[j] = max(absolute[j], absolute[0] * _floor(g, j))
            if _within(low, high, limits, rtol):
                done = True
                break
        if done or depth >= _MAX_DEPTH or top + 4 > _STACK or rules >= _MAX_RULES:
            if not done:
                failures += 1
            for j in range(RELAY_AMPLITUDES):
                out[j] += high[j]
                magnitude[j] += absolute[j]
            continue
        xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        for qx0, qx1 in ((x0, xm), (xm, x1)):
            for qy0, qy1 in ((y0, ym), (ym, y1)):
                boxes[top, 0], boxes[top, 1], boxes[top, 2], boxes[top, 3] = qx0, qx1, qy0, qy1
                depths[top] = depth + 1
                top += 1
    return failures


@njit(cache=True, error_model="numpy", nogil=True)
def pair_sums(g, cells, edges, rtol, F, H):
    """Σ_cells f F_j(t_e) into ``F[e]`` and Σ_cells f H_j(t_e) into ``H[e]`` (both (E, J), zeroed by the caller;
    J = :data:`AMPLITUDES`, or :data:`RELAY_AMPLITUDES` for a pair with ``surfaces``).

    Returns how many cell integrals were kept before meeting ``rtol`` (0 normally).

    Parameters
    ----------
    g : PairGeometry
    cells : float64[C, 5]
        x0, x1, y0, y1 (metres) and the reflectance f of each cell.
    edges : float64[E]
        Bin edges t_e, metres of path length.
    rtol : float
        Relative accuracy of each cell's (piece's) integrals.
    F, H : float64[E, J]
        Outputs: m⁻² and m⁻³ (times the amplitudes' units).
    """
    failures = 0
    count, width = cells.shape[0], _counts(g)[0]
    work = np.zeros((7, RELAY_AMPLITUDES))
    full = np.zeros((count, RELAY_AMPLITUDES))
    deepest = np.empty(count)
    magnitude = np.zeros((count, RELAY_AMPLITUDES))
    area, edge = np.zeros(RELAY_AMPLITUDES), np.zeros(RELAY_AMPLITUDES)
    nearest = np.empty(count)
    done = np.zeros(count, dtype=np.bool_)
    for c in range(count):
        x0, x1, y0, y1 = cells[c, 0], cells[c, 1], cells[c, 2], cells[c, 3]
        deepest[c] = max(max(_path(g, x0, y0), _path(g, x1, y0)), max(_path(g, x0, y1), _path(g, x1, y1)))
        # |∇d| <= 2 on the plane: no point of the cell is nearer than this
        nearest[c] = _path(g, 0.5 * (x0 + x1), 0.5 * (y0 + y1)) - math.hypot(x1 - x0, y1 - y0)
    for e in range(edges.size):
        t = edges[e]
        if not t > g.first:
            continue
        ellipse = isochrone_ellipse(g, t)
        cx, cy, a, b = ellipse
        rx = math.sqrt((a * g.ex) ** 2 + (b * g.ey) ** 2)
        ry = math.sqrt((a * g.ey) ** 2 + (b * g.ex) ** 2)
        for c in range(count):
            f = cells[c, 4]
            if nearest[c] >= t:
                continue
            if not done[c]:
                failures += _full_cell(g, cells[c], rtol, full[c], magnitude[c], work)
                done[c] = True
            if deepest[c] < t:
                for j in range(width):
                    F[e, j] += f * full[c, j]
            elif cells[c, 1] > cx - rx and cells[c, 0] < cx + rx and cells[c, 3] > cy - ry and cells[c, 2] < cy + ry:
                for j in range(RELAY_AMPLITUDES):
                    area[j] = 0.0
                    edge[j] = 0.0
                failures += _cut_cell(g, ellipse, cells[c], rtol, magnitude[c], area, edge, work)
                for j in range(width):
                    F[e, j] += f * area[j]
                    H[e, j] += f * edge[j]
    return failures
