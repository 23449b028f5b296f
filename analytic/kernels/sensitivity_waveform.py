"""Exact derivatives of a plane's samples under any waveform but the impulse: cell integrals (compiled).

For one source-sensor pair over z = 0 (:class:`.sensitivity.PairGeometry`)
and a cell of constant reflectance, with d(x) the path length and
κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ), κ_n'(τ) = s(t_n - τ) - s(t_{n+1} - τ),
the :data:`OUTPUTS` integrals of each bin n reached (:func:`_point`):

    0      ∫ a κ_n(d)                                      (y)
    1..3   ∫ ∂a/∂p_s κ_n(d) + a ∂d/∂p_s κ_n'(d)            (∂y/∂p_s: interior + bin-edge term)
    4..6   ∫ ∂a/∂p_k κ_n(d) + a ∂d/∂p_k κ_n'(d)            (∂y/∂p_k)
    7      -∫ a κ_n'(d)                                    (∂y/∂t_0: every edge moving)
    8      -∫ a d κ_n'(d)                                  (the moment the scaling law of plane.size needs)
    9      ∫ a [S(u) - u s(u)]_{u = t_n - d}^{t_{n+1} - d}    (a unit-peak pulse's widths: its scaling law)
    10     ∫ a [s'(u)]_{u = t_n - d}^{t_{n+1} - d}             (the EMG's Gaussian width: the heat equation)
    11..13 ∫ ∂a/∂n κ_n(d)                                  (a relay wall's pair: its ends' normals turning)
    14, 15 ∫ m_j κ_n(d) + m'_j κ_n'(d)                     (its stretch's moments, amplitudes 16..19)

The integrand is analytic on the cell except on the isochrones d = t_e - b_i
(a bin edge shifted back by a kink b_i of the waveform, where κ_n has a kink
and κ_n' may jump). A cell no such isochrone crosses takes a tensor Gauss
ladder G_n x G_n (G_2, G_3, G_4, G_6, G_8, G_11 until two agree), split in
four otherwise. A cell they cross is integrated in x (outer) and y (inner):
at each x the y-interval is cut at every such ellipse's roots, so each
inner piece is analytic; the outer integrand is analytic between the
ellipses' x-extremes (square-root ends) and the x where they cross the
cell's lower and upper edges, which cut it, each piece mapped by
x = x_a + span sin²(πv/2) and bisected in v until two rungs agree. Each
output c is judged to ``rtol`` of the cell's scale of it, ∫_cell |w_j| times
the waveform's (:func:`_limits`), as :mod:`.sensitivity` judges the impulse's.
"""

from __future__ import annotations

import math

import numpy as np

from .bins import bin_edge, pixel_bins
from .cache import njit
from .pieces import piece_derivatives, piece_of, piece_value
from .sensitivity import (RELAY_AMPLITUDES, _LADDER, _NODES, _WEIGHTS, _line_roots, _path, amplitudes,
                          isochrone_ellipse)

__all__ = ["OUTPUTS", "waveform_pair_sums"]

#: y, ∂y/∂p_s (x, y, z), ∂y/∂p_k (x, y, z), ∂y/∂t_0, -∫ a d κ_n'(d), the pulse's two, and a relay wall's
#: ∂y/∂n (x, y, z) and stretch's moments (x, y) (module docstring; zero for the plane).
OUTPUTS = 16
_MAX_DEPTH = 24
#: Rule applications per cell before the rest is kept as it is, and counted.
_MAX_RULES = 4000
_STACK = 96


@njit(cache=True, error_model="numpy", inline="always")
def _edge_values(terms, u, scratch):
    """(K_i, F_i(u), s(u), s'(u)) of the piece i holding u (zeros before the waveform starts)."""
    piece = piece_of(terms, u)
    if piece < 0:
        return 0.0, 0.0, 0.0, 0.0
    value = piece_value(terms, piece, u)[0]
    piece_derivatives(terms, piece, u, 3, scratch)
    return terms.constants[piece], value, scratch[1], scratch[2]


@njit(cache=True, error_model="numpy")
def _point(g, terms, axis, run, xy, weight, out, work):
    """Add weight x the :data:`OUTPUTS` integrands at plane point ``xy`` for the bins of ``run`` to ``out``.

    κ_n = (K_j - K_i) + (F_j - F_i) at the bin's two edges (the constants cancel exactly within a piece,
    as :func:`.bins.kernel_values` takes them); ``work``: (amplitudes, scratch, five rows of edge values).
    """
    amp, scratch, values = work[0], work[1], work[2:7]
    x, y = xy
    amplitudes(g, x, y, amp)
    d = _path(g, x, y)
    for e in range(run.bins + 1):
        u = bin_edge(axis, run.first + e) - d
        constant, form, density, curve = _edge_values(terms, u, scratch)
        values[0, e], values[1, e], values[2, e] = constant, form, density
        values[3, e], values[4, e] = u * density, curve
    a = amp[0]
    for i in range(run.bins):
        wk = weight * ((values[0, i + 1] - values[0, i]) + (values[1, i + 1] - values[1, i]))
        ws = weight * (values[2, i] - values[2, i + 1])          # κ_n'(d) = s(t_n - d) - s(t_{n+1} - d)
        out[i, 0] += wk * a
        for j in range(3):
            out[i, 1 + j] += wk * amp[1 + j] + ws * amp[7 + j]
            out[i, 4 + j] += wk * amp[4 + j] + ws * amp[10 + j]
        out[i, 7] -= ws * a
        out[i, 8] -= ws * a * d
        out[i, 9] += (wk - weight * (values[3, i + 1] - values[3, i])) * a
        out[i, 10] += weight * (values[4, i + 1] - values[4, i]) * a
        if g.surfaces:
            for j in range(3):
                out[i, 11 + j] += wk * amp[13 + j]
            out[i, 14] += wk * amp[16] + ws * amp[18]
            out[i, 15] += wk * amp[17] + ws * amp[19]


@njit(cache=True, error_model="numpy")
def _box_rule(g, terms, axis, run, box, rung, out, work):
    """One rung's G_n x G_n of the outputs over ``box`` = (x0, x1, y0, y1) into ``out`` (zeroed here)."""
    out[:run.bins] = 0.0
    x0, x1, y0, y1 = box
    for i in range(_LADDER[rung]):
        x = x0 + (x1 - x0) * _NODES[rung, i]
        for m in range(_LADDER[rung]):
            weight = (x1 - x0) * (y1 - y0) * _WEIGHTS[rung, i] * _WEIGHTS[rung, m]
            _point(g, terms, axis, run, (x, y0 + (y1 - y0) * _NODES[rung, m]), weight, out, work)


@njit(cache=True, error_model="numpy")
def _slice_rule(g, terms, axis, run, ellipses, piece, part, rung, out, work):
    """One rung of the outer rule over v in ``part`` = (v0, v1) of the cut piece ``piece`` = (x_a, span, y0, y1):
    at each x, the y-interval cut at every ellipse's roots, each part by the same G_n."""
    xa, span, y0, y1 = piece
    v0, v1 = part
    out[:run.bins] = 0.0
    cuts = np.empty(2 * ellipses.shape[0] + 2)
    for i in range(_LADDER[rung]):
        v = v0 + (v1 - v0) * _NODES[rung, i]
        s = math.sin(0.5 * math.pi * v)
        x = xa + span * s * s
        weight = (v1 - v0) * _WEIGHTS[rung, i] * 0.5 * math.pi * span * math.sin(math.pi * v)
        cuts[0], cuts[1] = y0, y1
        count = 2
        for k in range(ellipses.shape[0]):
            low, high = _line_roots(g, (ellipses[k, 0], ellipses[k, 1], ellipses[k, 2], ellipses[k, 3]), True, x)
            for root in (low, high):
                if y0 < root < y1:
                    cuts[count] = root
                    count += 1
        cuts[:count].sort()
        for p in range(count - 1):
            height = cuts[p + 1] - cuts[p]
            if height > 0.0:
                for m in range(_LADDER[rung]):
                    _point(g, terms, axis, run, (x, cuts[p] + height * _NODES[rung, m]),
                           weight * height * _WEIGHTS[rung, m], out, work)


@njit(cache=True, error_model="numpy", inline="always")
def _agree(low, high, bins, limits):
    for i in range(bins):
        for c in range(OUTPUTS):
            if abs(low[i, c] - high[i, c]) > limits[c]:
                return False
    return True


@njit(cache=True, error_model="numpy")
def _whole_cell(g, terms, axis, run, box, limits, total, work, rungs):
    """Add the outputs over a cell no kink isochrone crosses to ``total``: the tensor ladder, split in four."""
    low, high = rungs[0], rungs[1]
    boxes = np.empty((_STACK, 4))
    depths = np.empty(_STACK, dtype=np.int64)
    boxes[0, :] = box
    depths[0] = 0
    top, rules, failures = 1, 0, 0
    while top > 0:
        top -= 1
        rules += 1
        x0, x1, y0, y1 = boxes[top, 0], boxes[top, 1], boxes[top, 2], boxes[top, 3]
        _box_rule(g, terms, axis, run, (x0, x1, y0, y1), 0, high, work)
        done = False
        for rung in range(1, _LADDER.size):
            low[:run.bins] = high[:run.bins]
            _box_rule(g, terms, axis, run, (x0, x1, y0, y1), rung, high, work)
            if _agree(low, high, run.bins, limits):
                done = True
                break
        if done or depths[top] >= _MAX_DEPTH or top + 4 > _STACK or rules >= _MAX_RULES:
            failures += 0 if done else 1
            total[:run.bins] += high[:run.bins]
            continue
        depth, xm, ym = depths[top] + 1, 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        for qx0, qx1 in ((x0, xm), (xm, x1)):
            for qy0, qy1 in ((y0, ym), (ym, y1)):
                boxes[top, 0], boxes[top, 1], boxes[top, 2], boxes[top, 3] = qx0, qx1, qy0, qy1
                depths[top] = depth
                top += 1
    return failures


@njit(cache=True, error_model="numpy")
def _cut_cell(g, terms, axis, run, box, ellipses, limits, total, work, rungs):
    """Add the outputs over a cell the ``ellipses`` (kink isochrones, rows cx, cy, a, b) cross to ``total``."""
    x0, x1, y0, y1 = box
    cuts = np.empty(6 * ellipses.shape[0] + 2)
    cuts[0], cuts[1] = x0, x1
    count = 2
    for k in range(ellipses.shape[0]):
        ellipse = (ellipses[k, 0], ellipses[k, 1], ellipses[k, 2], ellipses[k, 3])
        reach = math.sqrt((ellipse[2] * g.ex) ** 2 + (ellipse[3] * g.ey) ** 2)
        for point in (ellipse[0] - reach, ellipse[0] + reach):
            if x0 < point < x1:
                cuts[count] = point
                count += 1
        for level in (y0, y1):
            low, high = _line_roots(g, ellipse, False, level)
            for root in (low, high):
                if x0 < root < x1:
                    cuts[count] = root
                    count += 1
    cuts[:count].sort()
    low, high = rungs[0], rungs[1]
    lows, highs, depths = np.empty(_STACK), np.empty(_STACK), np.empty(_STACK, dtype=np.int64)
    failures = 0
    for p in range(count - 1):
        piece = (cuts[p], cuts[p + 1] - cuts[p], y0, y1)
        if not piece[1] > 0.0:
            continue
        lows[0], highs[0], depths[0] = 0.0, 1.0, 0
        top, rules = 1, 0
        while top > 0:
            top -= 1
            rules += 1
            v0, v1, depth = lows[top], highs[top], depths[top]
            _slice_rule(g, terms, axis, run, ellipses, piece, (v0, v1), 0, high, work)
            done = False
            for rung in range(1, _LADDER.size):
                low[:run.bins] = high[:run.bins]
                _slice_rule(g, terms, axis, run, ellipses, piece, (v0, v1), rung, high, work)
                if _agree(low, high, run.bins, limits):
                    done = True
                    break
            if done or depth >= _MAX_DEPTH or top + 2 > _STACK or rules >= _MAX_RULES:
                failures += 0 if done else 1
                total[:run.bins] += high[:run.bins]
            else:
                top = _halves((lows, highs, depths), top, v0, v1, depth + 1)
    return failures


@njit(cache=True, error_model="numpy", inline="always")
def _halves(stack, top, v0, v1, depth):
    """Push [v0, (v0 + v1)/2] and [(v0 + v1)/2, v1] at ``depth`` on ``stack`` = (lows, highs, depths); the new top."""
    lows, highs, depths = stack
    middle = 0.5 * (v0 + v1)
    lows[top], highs[top], depths[top] = v0, middle, depth
    lows[top + 1], highs[top + 1], depths[top + 1] = middle, v1, depth
    return top + 2


@njit(cache=True, error_model="numpy")
def _limits(g, box, scales, rtol, deepest, limits):
    """Each output's accuracy in this cell: rtol x ∫_cell |w_j| (a fixed G_6 x G_6) x the waveform's scale.

    ``scales`` = (max_n κ_n, max_n |κ_n'|, max_n |[S - u s]|, max_n |[s']|) over τ: y's scale is
    ∫ a max κ; a position's ∫ |∂a/∂θ| max κ + ∫ |a ∂d/∂θ| max |κ'|, at least ∫ a (max κ / t_min +
    max |κ'|) (a column's own scale, so that a derivative vanishing over the cell asks no more than its
    column needs); the time zero's ∫ a max |κ'|, the moment's that times the cell's largest d; the
    pulse's two ∫ a times their own (inf where they are not wanted: they then never split a cell).
    """
    x0, x1, y0, y1 = box
    rung, amp, magnitude = 3, np.empty(RELAY_AMPLITUDES), np.zeros(RELAY_AMPLITUDES)
    for i in range(_LADDER[rung]):
        for m in range(_LADDER[rung]):
            amplitudes(g, x0 + (x1 - x0) * _NODES[rung, i], y0 + (y1 - y0) * _NODES[rung, m], amp)
            weight = (x1 - x0) * (y1 - y0) * _WEIGHTS[rung, i] * _WEIGHTS[rung, m]
            for j in range(RELAY_AMPLITUDES if g.surfaces else 13):
                magnitude[j] += weight * abs(amp[j])
    kernel, slope, scaled, curvature = scales
    area = magnitude[0]
    limits[0] = rtol * area * kernel
    for c in range(1, 7):
        limits[c] = rtol * max(magnitude[c] * kernel + magnitude[c + 6] * slope, area * (kernel / g.first + slope))
    limits[7] = rtol * area * slope
    limits[8] = rtol * area * slope * deepest
    limits[9] = rtol * area * scaled
    limits[10] = rtol * area * curvature
    # a relay wall's normal and moments (zero for the plane): as the positions', the moments' floor times
    # their weight's reach
    for j in range(3):
        limits[11 + j] = rtol * max(magnitude[13 + j] * kernel, area * kernel)
    for j in range(2):
        limits[14 + j] = rtol * max(magnitude[16 + j] * kernel + magnitude[18 + j] * slope,
                                    g.mscale * area * (kernel / g.first + slope))


@njit(cache=True, error_model="numpy", nogil=True)
def waveform_pair_sums(g, cells, terms, axis, scales, rtol, out):
    """Σ_cells f x the :data:`OUTPUTS` integrals of each bin into ``out`` ((N, 16), zeroed by the caller).

    Returns how many cell integrals were kept before meeting ``rtol`` (0 normally).

    Parameters
    ----------
    g : PairGeometry
    cells : float64[C, 5]
        x0, x1, y0, y1 (metres) and the reflectance f of each cell.
    terms : WaveformTerms
        The waveform (not a step function).
    axis : TimeAxis
        The bins.
    scales : tuple of float
        max_n κ_n (metres), max_n |κ_n'| (dimensionless), max_n |[S(u) - u s(u)]| (metres) and
        max_n |[s'(u)]| (1/m) over τ, the last two inf where outputs 9 and 10 are not wanted.
    rtol : float
        Relative accuracy of each cell's integrals (:func:`_limits`).
    out : float64[N, 16]
        Outputs: m⁻¹ (y) and m⁻² (the derivatives) times the kernels' units; output 9 as y, 10 as y per m².
    """
    kinked = terms.starts[terms.kinks]
    work = np.zeros((7, max(RELAY_AMPLITUDES, axis.count + 1)))
    rungs = np.zeros((2, axis.count, OUTPUTS))
    total = np.zeros((axis.count, OUTPUTS))
    limits = np.empty(OUTPUTS)
    failures = 0
    for c in range(cells.shape[0]):
        box = (cells[c, 0], cells[c, 1], cells[c, 2], cells[c, 3])
        x0, x1, y0, y1 = box
        deepest = max(max(_path(g, x0, y0), _path(g, x1, y0)), max(_path(g, x0, y1), _path(g, x1, y1)))
        # |∇d| <= 2 on the plane: no point of the cell is nearer than this
        nearest = max(g.first, _path(g, 0.5 * (x0 + x1), 0.5 * (y0 + y1)) - math.hypot(x1 - x0, y1 - y0))
        run = pixel_bins(nearest, deepest, axis, terms.lead, terms.duration)
        if run.bins == 0:
            continue
        count = 0
        for e in range(run.first, run.first + run.bins + 1):
            for b in kinked:
                if nearest < bin_edge(axis, e) - b < deepest:
                    count += 1
        ellipses = np.empty((count, 4))
        count = 0
        for e in range(run.first, run.first + run.bins + 1):
            for b in kinked:
                tau = bin_edge(axis, e) - b
                if nearest < tau < deepest:
                    ellipses[count, 0], ellipses[count, 1], ellipses[count, 2], ellipses[count, 3] = \
                        isochrone_ellipse(g, tau)
                    count += 1
        _limits(g, box, scales, rtol, deepest, limits)
        total[:run.bins] = 0.0
        if count == 0:
            failures += _whole_cell(g, terms, axis, run, box, limits, total, work, rungs)
        else:
            failures += _cut_cell(g, terms, axis, run, box, ellipses, limits, total, work, rungs)
        for i in range(run.bins):
            for k in range(OUTPUTS):
                out[run.first + i, k] += cells[c, 4] * total[i, k]
    return failures
