"""Bin kernels as Taylor series in path length: one set of moments serves every bin of a pixel (compiled).

Over a range of path lengths [c - h, c + h] that no kink of the waveform
crosses (shifted to a bin edge), every bin kernel κ_n is analytic, so

    κ_n(τ) = Σ_j c_{n,j} (τ - c)^j,   c_{n,j} = κ_n^{(j)}(c) / j!,

and an entry ∫ κ_n(τ) G(τ) dτ (G the pixel's response, or the pixel's
attenuation with τ = d(x)) is Σ_j c_{n,j} m_j with the *moments*
m_j = ∫ (τ - c)^j G(τ) dτ. The moments do not depend on the bin: one
quadrature of a few scalars serves every bin the pixel reaches, and the
kernels are evaluated once per bin edge instead of at every quadrature
node. The impulse needs one moment (κ_n is constant between edges), the
square two (linear), the Butterworth pulse as many as its remainder bound
asks (:func:`kernel_taylor`).

Accuracy: the terms kept are those whose remainder, bounded by the
waveform's own derivative bounds over the range
(:func:`analytic.kernels.pieces.piece_derivative_bound`), is below a
share of the tolerance of the bin's scale; the moments are integrated to
the tolerance relative to M_j = ∫ |τ - c|^j |G|, so an entry's error is
within the tolerance of U_n = Σ_j |c_{n,j}| M_j, which is within a few
times ∫ |κ_n| |G| when the series converges. Where it does not (U_n far
above the entry itself: a kernel that swings over the range), the caller
takes the direct route (:func:`cancels`).
"""

from __future__ import annotations

import math

from .cache import njit
from .pieces import piece_derivative_bound, piece_derivatives, piece_of, piece_value

__all__ = ["MAX_TERMS", "kernel_taylor", "entries_from_moments", "cancels"]

#: Most Taylor terms a kernel may need on one range; beyond, the direct route takes it.
MAX_TERMS = 12
# The truncation may take this share of the tolerance (relative to the bin's scale).
_TRUNCATION = 0.05
# An entry whose U_n exceeds this many times its own value is left to the direct route.
_CANCELLATION = 8.0


@njit(cache=True, error_model="numpy", forceinline=True)
def _edge_value(terms, u):
    """(piece, K, F(u)) at one bin edge u = t_n - c (piece -1, 0, 0 where S = 0)."""
    piece = piece_of(terms, u)
    constant = 0.0
    value = 0.0
    if piece >= 0:
        constant = terms.constants[piece]
        value = piece_value(terms, piece, u)[0]
    return piece, constant, value


@njit(cache=True, error_model="numpy")
def _derivative_bound(terms, u, half, order):
    """A bound on |S^(order)| over [u - half, u + half]: the largest over every piece that range overlaps.

    A switch between two forms of one analytic function may lie inside the range; a kink only at its ends.
    """
    low = u - half
    high = u + half
    bound = 0.0
    for i in range(max(piece_of(terms, low), 0), piece_of(terms, high) + 1):
        start = max(low, terms.starts[i])
        end = min(high, terms.starts[i + 1]) if i + 1 < terms.starts.size else high
        bound = max(bound, piece_derivative_bound(terms, i, start, end, order))
    return bound


@njit(cache=True, error_model="numpy", forceinline=True)
def _constant_forms(terms, piece):
    """Whether a piece's form is a constant (no coefficient, or one polynomial coefficient): S' = 0 there.

    (Written with branches: a value-producing ``or`` of array reads compiles to slow generic code.)
    """
    if piece < 0:
        return True
    if terms.families[piece] != 0:
        return False
    return terms.offsets[piece + 1] - terms.offsets[piece] <= 1


@njit(cache=True, error_model="numpy", forceinline=True)
def kernel_taylor(terms, axis, run, centre, half, rtol, coefficients, lower_edge, upper_edge):
    """Taylor coefficients of the run's kernels at ``centre`` over centre ± half; returns how many terms.

    Parameters
    ----------
    terms : WaveformTerms
    axis : analytic.kernels.bins.TimeAxis
    run : analytic.kernels.bins.BinRun
    centre, half : float
        The range of path length, metres; no kink of any κ_n inside it.
    rtol : float
        The entries' relative tolerance.
    coefficients : float64[:, MAX_TERMS]
        Output: coefficients[i, j] = κ_{first+i}^(j)(centre) / j!, metres^(1-j).
    lower_edge, upper_edge : float64[MAX_TERMS + 1]
        Scratch: S's derivatives at a bin edge.

    Returns
    -------
    int
        J, the terms kept (1 ... MAX_TERMS), or 0 when some kernel needs more.
    """
    if terms.degree >= 0:
        return _polynomial_taylor(terms, axis, run, centre, coefficients, lower_edge, upper_edge)
    needed = 1
    lower_u = axis.start_opl + axis.bin_width_opl * run.first - centre
    lower_piece, lower_constant, lower_value = _edge_value(terms, lower_u)
    for i in range(run.bins):
        upper_u = axis.start_opl + axis.bin_width_opl * (run.first + i + 1) - centre
        upper_piece, upper_constant, upper_value = _edge_value(terms, upper_u)
        coefficients[i, 0] = (upper_constant - lower_constant) + (upper_value - lower_value)
        for j in range(1, MAX_TERMS):       # the run's other kernels may keep more terms than this one
            coefficients[i, j] = 0.0
        terms_here = 1
        if not (_constant_forms(terms, lower_piece) and _constant_forms(terms, upper_piece)
                and _constant_forms(terms, piece_of(terms, lower_u - half))
                and _constant_forms(terms, piece_of(terms, upper_u + half))):
            terms_here = _more_terms(terms, (lower_u, lower_piece), (upper_u, upper_piece), half, rtol, coefficients,
                                     i, lower_edge, upper_edge)
            if terms_here == 0:
                return 0
        needed = max(needed, terms_here)
        for j in range(MAX_TERMS + 1):
            lower_edge[j] = upper_edge[j]
        lower_u, lower_piece, lower_constant, lower_value = upper_u, upper_piece, upper_constant, upper_value
    return needed


@njit(cache=True, error_model="numpy", forceinline=True)
def _polynomial_taylor(terms, axis, run, centre, coefficients, lower_edge, upper_edge):
    """:func:`kernel_taylor` for polynomial pieces of degree D: D + 1 terms, exactly (no remainder)."""
    count = terms.degree + 1
    if count > MAX_TERMS:
        return 0
    lower_u = axis.start_opl + axis.bin_width_opl * run.first - centre
    lower_piece, lower_constant, lower_value = _edge_value(terms, lower_u)
    for j in range(1, count):
        lower_edge[j] = 0.0
    if count > 1 and lower_piece >= 0:
        piece_derivatives(terms, lower_piece, lower_u, count, lower_edge)
    for i in range(run.bins):
        upper_u = axis.start_opl + axis.bin_width_opl * (run.first + i + 1) - centre
        upper_piece, upper_constant, upper_value = _edge_value(terms, upper_u)
        coefficients[i, 0] = (upper_constant - lower_constant) + (upper_value - lower_value)
        if count > 1:
            for j in range(1, count):
                upper_edge[j] = 0.0
            if upper_piece >= 0:
                piece_derivatives(terms, upper_piece, upper_u, count, upper_edge)
            sign = -1.0             # κ = S(t_{n+1} - τ) - S(t_n - τ): each d/dτ flips the sign
            factorial = 1.0
            for j in range(1, count):
                factorial *= j
                coefficients[i, j] = sign * (upper_edge[j] - lower_edge[j]) / factorial
                sign = -sign
                lower_edge[j] = upper_edge[j]
        lower_constant, lower_value = upper_constant, upper_value
    return count


@njit(cache=True, error_model="numpy")
def _more_terms(terms, lower, upper, half, rtol, coefficients, i, lower_edge, upper_edge):
    """Terms 1, 2, ... of bin i's kernel until the remainder is within the tolerance; 0 if more than MAX_TERMS.

    ``lower``, ``upper``: (u, piece) at the bin's two edges (u in metres from the range's centre).
    """
    lower_u, lower_piece = lower
    upper_u, upper_piece = upper
    for j in range(MAX_TERMS + 1):
        lower_edge[j] = 0.0
        upper_edge[j] = 0.0
    if lower_piece >= 0:
        piece_derivatives(terms, lower_piece, lower_u, MAX_TERMS, lower_edge)
    if upper_piece >= 0:
        piece_derivatives(terms, upper_piece, upper_u, MAX_TERMS, upper_edge)
    scale = abs(coefficients[i, 0])
    sign = -1.0             # κ = S(t_{n+1} - τ) - S(t_n - τ): each d/dτ flips the sign
    factorial = 1.0
    power = 1.0
    for j in range(1, MAX_TERMS + 1):
        factorial *= j
        power *= half
        remainder = ((_derivative_bound(terms, upper_u, half, j) + _derivative_bound(terms, lower_u, half, j))
                     * power / factorial)
        if remainder <= _TRUNCATION * rtol * scale:
            return j
        if j < MAX_TERMS:
            coefficients[i, j] = sign * (upper_edge[j] - lower_edge[j]) / factorial
            scale = max(scale, abs(coefficients[i, j]) * power)
        sign = -sign
    return 0


@njit(cache=True, error_model="numpy", forceinline=True)
def entries_from_moments(coefficients, count, bins, moments, out):
    """out[i] += Σ_{j < count} coefficients[i, j] moments[j] for i < bins."""
    for i in range(bins):
        total = 0.0
        for j in range(count - 1, -1, -1):
            total += coefficients[i, j] * moments[j]
        out[i] += total


@njit(cache=True, error_model="numpy", forceinline=True)
def cancels(coefficients, count, bins, moments, magnitudes):
    """Whether some entry Σ c_j m_j is far below U = Σ |c_j| M_j: its Taylor terms cancel (see the module docstring)."""
    for i in range(bins):
        value = 0.0
        bound = 0.0
        for j in range(count):
            value += coefficients[i, j] * moments[j]
            bound += abs(coefficients[i, j]) * magnitudes[j]
        if bound > _CANCELLATION * abs(value):
            return True
    return False
