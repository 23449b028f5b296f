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
================== ===========================================================

(o is the piece's origin; coefficients are stored flat, four per term for
``EXPONENTIALS``: a_j, ω_j, b_j, c_j; six for ``ERRORFUNCTIONS``: b_j, c_j,
β_j, γ_j >= 0, p_j, s_j, built so that p_j y + s_j >= 0 over the piece,
where erfcx(v) = e^{v²} erfc(v) <= 1 (:mod:`analytic.waveforms.special`),
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
pieces (see :mod:`analytic.waveforms.square`); the quadrature, the NumPy
and Numba evaluators here and the renderer's Dr.Jit one read nothing else.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..kernel_cache import njit
from .special import RECIPROCAL_SQRT_PI, erfcx_array, erfcx_scalar, erfcx_taylor

__all__ = ["WaveformTerms", "make_terms", "POLYNOMIAL", "EXPONENTIALS", "ERRORFUNCTIONS", "TERM_SIZES",
           "piece_of", "piece_value",
           "piece_derivatives", "piece_derivative_bound",
           "cumulative_scalar", "kernel_scalar", "cumulative_array", "derivative_array", "kernel_array",
           "ROUNDING"]

#: Families of the pieces' closed forms.
POLYNOMIAL, EXPONENTIALS, ERRORFUNCTIONS = 0, 1, 2
#: Coefficients per term of each family (POLYNOMIAL: one per power).
TERM_SIZES = {POLYNOMIAL: 1, EXPONENTIALS: 4, ERRORFUNCTIONS: 6}

#: Relative rounding allowed per term of a closed form when bounding a kernel's rounding error
#: (a few roundings of each term and of the sums).
ROUNDING = 8.0 * 2.0**-52


class WaveformTerms(NamedTuple):
    """A waveform's pieces as a record that compiled (Numba) code accepts; see the module docstring.

    Attributes
    ----------
    starts : float64[P]
        b_i, increasing, metres of path length; piece i covers (b_i, b_{i+1}].
    kinks : bool[P]
        Whether s or a derivative jumps at b_i (a breakpoint of the quadrature).
    constants : float64[P]
        K_i, metres (dimensionless for the impulse).
    families : int64[P]
        ``POLYNOMIAL``, ``EXPONENTIALS`` or ``ERRORFUNCTIONS``.
    origins : float64[P]
        o_i, metres.
    offsets : int64[P + 1]
        Piece i's coefficients are ``coefficients[offsets[i]:offsets[i + 1]]``.
    coefficients : float64[C]
        See the module docstring.
    duration : float
        Where s ends, metres: S is constant beyond it (to 2^-60 of the area).
    lead : float
        Where s starts, metres (<= 0): S is 0 before it (to 2^-60 of the area);
        0 for a causal pulse, negative for one centred at 0 (a Gaussian).
        Light leaving the plane at path length τ reaches the sensors over
        [τ + lead, τ + duration]: the bins visited.
    degree : int
        The highest degree of the pieces' forms when they are all
        polynomials (0: S is constant between kinks, as for the impulse;
        1: linear, as for the square), -1 when some piece is not a
        polynomial. A kernel is then exactly its Taylor polynomial of that
        degree between kinks (:mod:`analytic.taylor`).
    """

    starts: np.ndarray
    kinks: np.ndarray
    constants: np.ndarray
    families: np.ndarray
    origins: np.ndarray
    offsets: np.ndarray
    coefficients: np.ndarray
    duration: float
    lead: float
    degree: int


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


# -- compiled evaluators -------------------------------------------------------------
# The small ones are inlined: a real call that passes the record (eight arrays) pays a reference count
# on each array, more than the evaluation itself.


@njit(cache=True, error_model="numpy", inline="always")
def piece_of(terms, u):
    """Index of the piece holding u, or -1 where S = 0 (u <= b_0, or u NaN)."""
    starts = terms.starts
    if not u > starts[0]:
        return -1
    low, high = 0, starts.size - 1          # starts[low] < u; the answer is in [low, high]
    while low < high:
        middle = (low + high + 1) // 2
        if starts[middle] < u:
            low = middle
        else:
            high = middle - 1
    return low


@njit(cache=True, error_model="numpy")
def _error_terms(coefficients, first, last, x):
    """(Σ_j b_j e^{y(β_j - γ_j y)} erfcx(p_j y + s_j), a bound on its rounding's scale) at x = u - o.

    The scale counts each exponent's size: e^E carries E's rounding ε|E| as a relative error.
    """
    value = 0.0
    size = 0.0
    for t in range(first, last, 6):
        y = x - coefficients[t + 1]
        exponent = y * (coefficients[t + 2] - coefficients[t + 3] * y)
        term = coefficients[t] * math.exp(exponent) * erfcx_scalar(coefficients[t + 4] * y + coefficients[t + 5])
        value += term
        size += abs(term) * (1.0 + abs(exponent))
    return value, size


@njit(cache=True, error_model="numpy", inline="always")
def piece_value(terms, piece, u):
    """(F_i(u), a bound on the size of its terms) for piece i, metres."""
    first = terms.offsets[piece]
    last = terms.offsets[piece + 1]
    x = u - terms.origins[piece]
    coefficients = terms.coefficients
    value = 0.0
    size = 0.0
    if terms.families[piece] == 0:          # POLYNOMIAL, by Horner's rule (as NumPy's polyval)
        magnitude = abs(x)
        for m in range(last - 1, first - 1, -1):
            value = value * x + coefficients[m]
            size = size * magnitude + abs(coefficients[m])
        return value, size
    if terms.families[piece] == 2:          # ERRORFUNCTIONS
        return _error_terms(coefficients, first, last, x)
    for j in range(first, last, 4):         # EXPONENTIALS
        envelope = math.exp(coefficients[j] * x)
        frequency = coefficients[j + 1]
        if frequency == 0.0:
            term = envelope * coefficients[j + 2]
            size += abs(term)
        else:
            angle = frequency * x
            term = envelope * (coefficients[j + 2] * math.cos(angle) + coefficients[j + 3] * math.sin(angle))
            size += envelope * (abs(coefficients[j + 2]) + abs(coefficients[j + 3]))
        value += term
    return value, size


@njit(cache=True, error_model="numpy")
def _error_derivatives(coefficients, first, last, x, count, out):
    """out[j] += d^j/dx^j of the ERRORFUNCTIONS terms at x, j = 1 ... count - 1 (see piece_derivatives)."""
    exponential = np.empty(count)
    scaled = np.empty(count)
    for t in range(first, last, 6):
        b = coefficients[t]
        y = x - coefficients[t + 1]
        beta = coefficients[t + 2]
        gamma = coefficients[t + 3]
        p = coefficients[t + 4]
        # e^{(y + h)(β - γ(y + h))} = e^{y(β - γy)} e^{a h - γ h²}, a = β - 2γy: Taylor coefficients
        # e_0 = 1, e_1 = a, (k + 1) e_{k+1} = a e_k - 2γ e_{k-1} (Hermite's recurrence, stable upward)
        slope = beta - 2.0 * gamma * y
        exponential[0] = 1.0
        if count > 1:
            exponential[1] = slope
        for k in range(1, count - 1):
            exponential[k + 1] = (slope * exponential[k] - 2.0 * gamma * exponential[k - 1]) / (k + 1)
        erfcx_taylor(p * y + coefficients[t + 5], count, scaled)
        power = 1.0
        for k in range(count):
            scaled[k] *= power
            power *= p
        front = b * math.exp(y * (beta - gamma * y))
        factorial = 1.0
        for j in range(1, count):
            factorial *= j
            total = 0.0
            for i in range(j + 1):
                total += exponential[i] * scaled[j - i]
            out[j] += front * total * factorial


@njit(cache=True, error_model="numpy")
def piece_derivatives(terms, piece, u, count, out):
    """out[j] = d^j F_i / du^j at u for j = 1 ... count - 1 (out[0] is left alone), metres^(1-j).

    POLYNOMIAL: Σ_m c_m m!/(m-j)! x^(m-j); EXPONENTIALS: each term is
    Re[(b - i c) e^{z x}] with z = a + iω, so its j-th derivative is
    Re[(b - i c) z^j e^{z x}]; ERRORFUNCTIONS: j! times the Taylor
    coefficients of each term, the Cauchy product of those of
    e^{y(β - γy)} (Hermite's recurrence) and of erfcx(p y + s)
    (:func:`analytic.waveforms.special.erfcx_taylor`).
    """
    first = terms.offsets[piece]
    last = terms.offsets[piece + 1]
    x = u - terms.origins[piece]
    coefficients = terms.coefficients
    for j in range(1, count):
        out[j] = 0.0
    if terms.families[piece] == 0:          # POLYNOMIAL
        for j in range(1, count):
            value = 0.0
            for m in range(last - 1 - first, j - 1, -1):     # Horner on the j-th derivative's coefficients
                factor = 1.0
                for q in range(m - j + 1, m + 1):
                    factor *= q
                value = value * x + coefficients[first + m] * factor
            out[j] = value
        return
    if terms.families[piece] == 2:          # ERRORFUNCTIONS
        _error_derivatives(coefficients, first, last, x, count, out)
        return
    for t in range(first, last, 4):          # EXPONENTIALS
        z = complex(coefficients[t], coefficients[t + 1])
        term = complex(coefficients[t + 2], -coefficients[t + 3]) * np.exp(z * x)
        for j in range(1, count):
            term *= z
            out[j] += term.real


@njit(cache=True, error_model="numpy")
def _error_terms_bound(coefficients, first, last, low, high, radius):
    """max |F(z)| over the complex points within ``radius`` of [low, high] (x = u - o), ERRORFUNCTIONS.

    For z = y + iη, Re[z(β - γz)] = βy - γ(y² - η²) <= max over y of (βy - γy²) + γ radius², and
    |erfcx(v)| <= 1 where Re v >= 0 (|w(z)| <= 1 in the upper half-plane), <= 1 + 2 e^{(Re v)²} where
    Re v < 0 (erfcx(v) = 2e^{v²} - erfcx(-v)).
    """
    total = 0.0
    for t in range(first, last, 6):
        centre = coefficients[t + 1]
        beta = coefficients[t + 2]
        gamma = coefficients[t + 3]
        p = coefficients[t + 4]
        y_low = low - centre - radius
        y_high = high - centre + radius
        if gamma > 0.0:
            vertex = min(max(beta / (2.0 * gamma), y_low), y_high)
            exponent = vertex * (beta - gamma * vertex) + gamma * radius * radius
        else:
            exponent = max(beta * y_low, beta * y_high)
        smallest = min(p * y_low, p * y_high) + coefficients[t + 5]
        factor = 1.0
        if smallest < 0.0:
            factor = 1.0 + 2.0 * math.exp(smallest * smallest)
        total += abs(coefficients[t]) * math.exp(exponent) * factor
    return total


@njit(cache=True, error_model="numpy")
def _error_derivative_bound(coefficients, first, last, low, high, order):
    """A bound on |d^order F / dx^order| over [low, high] for ERRORFUNCTIONS terms, by Cauchy's estimate.

    |F^(n)(x)| <= n! max_{|z - x| = ρ} |F(z)| / ρ^n for every ρ > 0; the radii tried are where a
    Gaussian factor e^{-γy²} at distance d from its centre (n / (2γd), √(n / 2γ)), an exponential e^{βy}
    (n / |β|), or the erfcx argument's margin above 0 ((p y + s) / |p|) make one term's bound least,
    and the piece's length; the least bound is returned.
    """
    factorial = 1.0
    for k in range(2, order + 1):
        factorial *= k
    best = math.inf
    for t in range(first - 6, last, 6):
        for choice in range(4):
            radius = 0.0
            if t < first:           # the piece's length, once
                if choice > 0:
                    continue
                radius = high - low
            else:
                centre = coefficients[t + 1]
                beta = coefficients[t + 2]
                gamma = coefficients[t + 3]
                p = coefficients[t + 4]
                y_low = low - centre
                y_high = high - centre
                if choice == 0 and gamma > 0.0:
                    vertex = beta / (2.0 * gamma)
                    distance = max(y_low - vertex, vertex - y_high, 0.0)
                    if distance > 0.0:
                        radius = order / (2.0 * gamma * distance)
                elif choice == 1 and gamma > 0.0:
                    radius = math.sqrt(order / (2.0 * gamma))
                elif choice == 2 and beta != 0.0:
                    radius = order / abs(beta)
                elif choice == 3 and p != 0.0:
                    radius = (min(p * y_low, p * y_high) + coefficients[t + 5]) / abs(p)
            if not radius > 0.0:
                continue
            bound = factorial * _error_terms_bound(coefficients, first, last, low, high, radius) / radius ** order
            best = min(best, bound)
    return best


@njit(cache=True, error_model="numpy")
def piece_derivative_bound(terms, piece, low, high, order):
    """A bound on |d^order F_i / du^order| over u in [low, high], metres^(1-order).

    POLYNOMIAL: Σ_m |c_m| m!/(m-order)! max|x|^(m-order); EXPONENTIALS:
    Σ e^{a x} (|b| + |c|) |a + iω|^order at the end where e^{a x} is largest;
    ERRORFUNCTIONS: Cauchy's estimate (:func:`_error_derivative_bound`).
    """
    first = terms.offsets[piece]
    last = terms.offsets[piece + 1]
    origin = terms.origins[piece]
    coefficients = terms.coefficients
    bound = 0.0
    if terms.families[piece] == 0:
        reach = max(abs(low - origin), abs(high - origin))
        for m in range(order, last - first):
            factor = 1.0
            for q in range(m - order + 1, m + 1):
                factor *= q
            bound += abs(coefficients[first + m]) * factor * reach ** (m - order)
        return bound
    if terms.families[piece] == 2:
        return _error_derivative_bound(coefficients, first, last, low - origin, high - origin, order)
    for t in range(first, last, 4):
        a = coefficients[t]
        envelope = math.exp(a * ((high if a > 0.0 else low) - origin))
        size = abs(coefficients[t + 2]) + abs(coefficients[t + 3])
        bound += envelope * size * math.hypot(a, coefficients[t + 1]) ** order
    return bound


@njit(cache=True, error_model="numpy")
def cumulative_scalar(terms, u):
    """S(u) at one path length u (metres), compiled."""
    piece = piece_of(terms, u)
    if piece < 0:
        return 0.0
    return terms.constants[piece] + piece_value(terms, piece, u)[0]


@njit(cache=True, error_model="numpy")
def kernel_scalar(terms, a, b):
    """(S(b) - S(a), a bound on its rounding error) for a <= b, metres, compiled.

    (K_j - K_i) + (F_j(b) - F_i(a)): within one piece the constants cancel
    exactly (see the module docstring).
    """
    i = piece_of(terms, a)
    j = piece_of(terms, b)
    constant = 0.0
    value_a = 0.0
    size_a = 0.0
    value_b = 0.0
    size_b = 0.0
    if i >= 0:
        value_a, size_a = piece_value(terms, i, a)
        constant -= terms.constants[i]
    if j >= 0:
        value_b, size_b = piece_value(terms, j, b)
        constant += terms.constants[j]
    return constant + (value_b - value_a), ROUNDING * (abs(constant) + size_a + size_b)


# -- NumPy evaluators ----------------------------------------------------------------


def _piece_indices(terms: WaveformTerms, u: np.ndarray) -> np.ndarray:
    """Piece of each u (-1 where S = 0): the largest i with b_i < u."""
    index = np.searchsorted(terms.starts, u, side="left") - 1
    return np.where(np.isnan(u), -1, index)


def _forms(terms: WaveformTerms, piece: int, x: np.ndarray, derivative: bool) -> np.ndarray:
    """F_i (or dF_i/du) at x = u - o_i."""
    coefficients = terms.coefficients[terms.offsets[piece]:terms.offsets[piece + 1]]
    if terms.families[piece] == POLYNOMIAL:
        if coefficients.size == 0:
            return np.zeros_like(x)
        if derivative:
            coefficients = np.polynomial.polynomial.polyder(coefficients) if coefficients.size > 1 else [0.0]
        return np.polynomial.polynomial.polyval(x, coefficients)
    value = np.zeros_like(x)
    if terms.families[piece] == ERRORFUNCTIONS:
        for b, centre, beta, gamma, p, shift in coefficients.reshape(-1, 6):
            y = x - centre
            front = b * np.exp(y * (beta - gamma * y))
            argument = p * y + shift
            scaled = erfcx_array(argument)
            if derivative:      # d/dy e^E erfcx(v) = e^E [(E' + 2pv) erfcx(v) - 2p/√π]
                value += front * ((beta - 2.0 * gamma * y + 2.0 * p * argument) * scaled
                                  - 2.0 * p * RECIPROCAL_SQRT_PI)
            else:
                value += front * scaled
        return value
    for a, w, b, c in coefficients.reshape(-1, 4):
        if derivative:      # d/dx of e^{ax}(b cos wx + c sin wx)
            b, c = a * b + w * c, a * c - w * b
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
