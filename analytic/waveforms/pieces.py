"""A waveform's cumulative S(u) as pieces, each a closed form that NumPy, Numba and Dr.Jit evaluate alike.

Every waveform s(t) (unit peak, or unit area for the impulse) enters the
model only through its cumulative S(u) = ∫_{-∞}^u s(t) dt and the sampling
kernels it induces,

    κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ).

S is stored as pieces: piece i covers (b_i, b_{i+1}] (the last one up to
+∞; S = 0 for u <= b_0) and there

    S(u) = K_i + F_i(u),

with K_i a constant and F_i a closed form of one *family*:

================== ===========================================================
``POLYNOMIAL``     F(u) = Σ_m c_m (u - o)^m (Horner; no coefficient: F = 0)
``EXPONENTIALS``   F(u) = Σ_j e^{a_j (u - o)} (b_j cos ω_j (u - o) + c_j sin ω_j (u - o))
``ERRORFUNCTIONS`` F(u) = Σ_j b_j e^{y (β_j - γ_j y)} erfcx(p_j y + s_j), y = u - o - c_j
``SIGMOIDS``       F(u) = Σ_j b_j e^y / (1 + e^y), y = a_j (u - o - c_j) <= 0 over the piece
================== ===========================================================

(o is the piece's origin; coefficients are stored flat, four per term for
``EXPONENTIALS``: a_j, ω_j, b_j, c_j; six for ``ERRORFUNCTIONS``: b_j, c_j,
β_j, γ_j >= 0, p_j, s_j, built so that p_j y + s_j >= 0 over the piece,
three for ``SIGMOIDS``: b_j, a_j, c_j; where erfcx(v) = e^{v²} erfc(v) <= 1 (:mod:`analytic.kernels.special`),
and the exponent stays at most a few units above its value at the piece's
ends: no term overflows, and e^{-v²} erfcx(v) keeps erfc's relative
accuracy in a Gaussian's tails). Why a constant and a form, not S
itself: far in a pulse's tail S is its area less a remainder 1e-13 of it,
and a kernel computed as the difference of two such S keeps only their
rounding. Each kernel is computed as

    S(b) - S(a) = (K_j - K_i) + (F_j(b) - F_i(a)),

so that within one piece (K_j = K_i) the constant cancels exactly and the
difference keeps the relative accuracy of the forms themselves: a
Butterworth tail keeps its remainder as F.

``kinks[i]`` says whether s or one of its derivatives jumps at b_i: those
are the waveform's breakpoints, where the model's quadrature cuts its
integrals (a piece boundary that only switches between two closed forms of
one analytic function, as the Butterworth pulse's Taylor series and its
exponential sum, is not a kink). Adding a waveform means building its
pieces (see :mod:`analytic.waveforms.square`); each family's form is written
once (:func:`analytic.kernels.forms.piece_forms`), which NumPy (here), Numba
and the renderer's Dr.Jit evaluate, and the quadrature reads nothing else.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels.forms import (ERRORFUNCTIONS, EXPONENTIALS, POLYNOMIAL, ROUNDING, SIGMOIDS, TERM_SIZES, WaveformTerms,
                             piece_forms)
from ..kernels.formulas import RECIPROCAL_SQRT_PI, erfcx_array

__all__ = ["WaveformTerms", "make_terms", "POLYNOMIAL", "EXPONENTIALS", "ERRORFUNCTIONS", "SIGMOIDS", "TERM_SIZES",
           "cumulative_array", "derivative_array", "kernel_array", "without_tail_kinks", "ROUNDING"]

#: The families' forms (:func:`analytic.kernels.forms.piece_forms`) with NumPy's functions.
_FORMS = piece_forms(np.exp, np.cos, np.sin, erfcx_array)


def _frozen(values, dtype=np.float64) -> np.ndarray:
    array = np.array(values, dtype=dtype)
    array.setflags(write=False)
    return array


def make_terms(pieces, duration: float, lead: float = 0.0) -> WaveformTerms:
    """The record of a list of pieces.

    Parameters
    ----------
    pieces : sequence of (start, kink, constant, family, origin, coefficients)
        In increasing order of start (metres); see :class:`WaveformTerms`.
    duration : float
        Where s ends, metres.
    lead : float
        Where s starts, metres (<= 0; default 0, a causal pulse).

    Returns
    -------
    WaveformTerms
    """
    starts = [float(p[0]) for p in pieces]
    if any(not b > a for a, b in zip(starts, starts[1:])):
        raise ValueError(f"piece starts must increase, got {starts}")
    if not lead <= 0.0 <= duration or not math.isfinite(lead):
        raise ValueError(f"the pulse must start at lead <= 0 (got {lead}) and end at duration >= 0 (got {duration})")
    for piece in pieces:
        if piece[3] not in TERM_SIZES:
            raise ValueError(f"unknown family {piece[3]!r}")
        if len(piece[5]) % TERM_SIZES[piece[3]]:
            raise ValueError(f"family {piece[3]} takes {TERM_SIZES[piece[3]]} coefficients per term")
    sizes = [len(p[5]) for p in pieces]
    polynomial = all(p[3] == POLYNOMIAL for p in pieces)
    degree = max((size - 1 for size in sizes), default=0) if polynomial else -1
    return WaveformTerms(_frozen(starts), _frozen([bool(p[1]) for p in pieces], np.bool_),
                         _frozen([p[2] for p in pieces]), _frozen([p[3] for p in pieces], np.int64),
                         _frozen([p[4] for p in pieces]), _frozen(np.concatenate([[0], np.cumsum(sizes)]), np.int64),
                         _frozen(np.concatenate([np.asarray(p[5], dtype=np.float64) for p in pieces])
                                 if pieces else []),
                         float(duration), float(lead), int(max(degree, 0) if polynomial else -1))


def _piece_indices(terms: WaveformTerms, u: np.ndarray) -> np.ndarray:
    """Piece of each u (-1 where S = 0): the largest i with b_i < u."""
    index = np.searchsorted(terms.starts, u, side="left") - 1
    return np.where(np.isnan(u), -1, index)


def _forms(terms: WaveformTerms, piece: int, x: np.ndarray, derivative: bool) -> np.ndarray:
    """F_i (or dF_i/du) at x = u - o_i: the shared forms for F, their derivatives here (NumPy only)."""
    first, last = int(terms.offsets[piece]), int(terms.offsets[piece + 1])
    family = int(terms.families[piece])
    if not derivative:
        return _FORMS[family](terms.coefficients, first, last, x)[0] + np.zeros_like(x)
    coefficients = terms.coefficients[first:last]
    if family == POLYNOMIAL:
        if coefficients.size <= 1:
            return np.zeros_like(x)
        return np.polynomial.polynomial.polyval(x, np.polynomial.polynomial.polyder(coefficients))
    value = np.zeros_like(x)
    if family == ERRORFUNCTIONS:
        for b, centre, beta, gamma, p, shift in coefficients.reshape(-1, 6):
            y = x - centre
            front = b * np.exp(y * (beta - gamma * y))
            argument = p * y + shift
            # d/dy e^E erfcx(v) = e^E [(E' + 2pv) erfcx(v) - 2p/√π]
            value += front * ((beta - 2.0 * gamma * y + 2.0 * p * argument) * erfcx_array(argument)
                              - 2.0 * p * RECIPROCAL_SQRT_PI)
        return value
    if family == SIGMOIDS:
        for b, a, centre in coefficients.reshape(-1, 3):
            scaled = np.exp(a * (x - centre))      # d/dx b σ(y) = b a σ(1 - σ), σ(1 - σ) = e^y / (1 + e^y)²
            value += b * a * scaled / (1.0 + scaled) ** 2
        return value
    for a, w, b, c in coefficients.reshape(-1, 4):
        b, c = a * b + w * c, a * c - w * b     # d/dx of e^{ax}(b cos wx + c sin wx)
        value += np.exp(a * x) * (b * np.cos(w * x) + c * np.sin(w * x))
    return value


def _evaluate(terms: WaveformTerms, u, derivative: bool) -> np.ndarray:
    u = np.asarray(u, dtype=np.float64)
    flat = u.ravel()
    index = _piece_indices(terms, flat)
    out = np.zeros(flat.shape)
    for piece in np.unique(index[index >= 0]):
        chosen = index == piece
        forms = _forms(terms, int(piece), flat[chosen] - terms.origins[piece], derivative)
        out[chosen] = forms if derivative else terms.constants[piece] + forms
    return out.reshape(u.shape)


def cumulative_array(terms: WaveformTerms, u) -> np.ndarray:
    """S(u) at path lengths u (metres), NumPy."""
    return _evaluate(terms, u, derivative=False)


def derivative_array(terms: WaveformTerms, u) -> np.ndarray:
    """dS/du = s(u) inside the pieces (metres of path length in, dimensionless out), NumPy."""
    return _evaluate(terms, u, derivative=True)


def kernel_array(terms: WaveformTerms, a, b) -> np.ndarray:
    """S(b) - S(a), elementwise, with the constants of one piece cancelled exactly (NumPy)."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    flat_a, flat_b = a.ravel(), b.ravel()
    i, j = _piece_indices(terms, flat_a), _piece_indices(terms, flat_b)
    constants = np.concatenate([terms.constants, [0.0]])     # index -1: S = 0
    constant = constants[j] - constants[i]
    forms = np.zeros(flat_a.shape)
    for index, points, sign in ((j, flat_b, 1.0), (i, flat_a, -1.0)):
        for piece in np.unique(index[index >= 0]):
            chosen = index == piece
            forms[chosen] += sign * _forms(terms, int(piece), points[chosen] - terms.origins[piece], False)
    return (constant + forms).reshape(a.shape)


#: A kink is a truncation point, no breakpoint, where s and its slope times the pulse's span stay below this
#: fraction of s's peak on both sides (a Gaussian's, an EMG's, a sech²'s ends, 2^-60 of the area out):
#: not cutting there moves an integral by about that much, 100 times below the smallest tolerance (1e-10).
TAIL_FLOOR = 1e-12


def without_tail_kinks(terms: WaveformTerms) -> WaveformTerms:
    """``terms`` with the kinks that only truncate a vanishing tail cleared (:data:`TAIL_FLOOR`).

    A smooth pulse is stored truncated where its tail falls below 2^-60 of its area; the jump of s there is
    far below any tolerance, but a quadrature that cuts its integrals at every kink isochrone (one per bin
    edge and kink) spends most of its work there when the bins are fine: the exact derivatives' cell
    integrals took 17 times longer on a relay wall with a Gaussian of FWHM 2 bins
    (analytic/operator/relay_wall_sensitivity.py). s is sampled on each side of each kink, in the kink's
    own neighbouring piece, over a hundredth of its distance to the peak (a pulse that only starts there,
    as a Butterworth's rises from 0, is far above the floor that close).
    """
    if terms.degree == 0 or not np.any(terms.kinks):
        return terms
    span = float(terms.duration - terms.lead)
    grid = np.linspace(terms.lead, terms.duration, 4097)
    density = np.abs(derivative_array(terms, grid))
    peak, crest = float(np.max(density)), float(grid[np.argmax(density)])
    kinks = terms.kinks.copy()
    for i in np.flatnonzero(terms.kinks):
        start = float(terms.starts[i])
        reach = max(abs(crest - start), 1e-9 * span) * np.geomspace(1e-9, 1e-2, 24)
        small = True
        for piece, points in ((i - 1, start - reach), (i, start + reach)):
            if piece < 0 or not small:
                continue
            values = _forms(terms, piece, points - terms.origins[piece], True)
            slopes = np.diff(values) / np.diff(points)
            small = (np.max(np.abs(values)) <= TAIL_FLOOR * peak
                     and np.max(np.abs(slopes)) * span <= TAIL_FLOOR * peak)
        kinks[i] = not small
    return terms._replace(kinks=_frozen(kinks, np.bool_))
