"""A waveform's pieces as compiled code reads them: the compiled evaluators every kernel reads S through.

The pieces and what each family's closed form is are described in
:mod:`analytic.waveforms.pieces`, which builds them (:func:`make_terms`);
the record (:class:`WaveformTerms`), the families' codes and each family's
form, written once for NumPy, Numba and Dr.Jit, are :mod:`.forms`. Here:
the forms compiled (:func:`piece_value`), and what only compiled code needs,
the pieces' derivatives and bounds on them (the moments route's).
"""

from __future__ import annotations

import math
import numpy as np

from .cache import njit
from .forms import ERRORFUNCTIONS, EXPONENTIALS, POLYNOMIAL, ROUNDING, SIGMOIDS, TERM_SIZES, WaveformTerms, piece_forms
from .special import erfcx_scalar, erfcx_taylor

__all__ = ["WaveformTerms", "POLYNOMIAL", "EXPONENTIALS", "ERRORFUNCTIONS", "SIGMOIDS", "TERM_SIZES", "ROUNDING",
           "piece_of", "piece_value", "piece_derivatives", "piece_derivative_bound"]

#: The families' forms (:func:`.forms.piece_forms`) compiled with ``math``'s functions.
_polynomial, _exponentials, _errorfunctions, _sigmoids = (
    njit(cache=True, error_model="numpy", forceinline=True)(form) for form in piece_forms(math.exp, math.cos, math.sin, erfcx_scalar))


# The small ones are inlined: a real call that passes the record (eight arrays) pays a reference count
# on each array, more than the evaluation itself.


@njit(cache=True, error_model="numpy", forceinline=True)
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


@njit(cache=True, error_model="numpy", forceinline=True)
def piece_value(terms, piece, u):
    """(F_i(u), a bound on the size of its terms) for piece i, metres: :func:`.forms.piece_forms` compiled."""
    first = terms.offsets[piece]
    last = terms.offsets[piece + 1]
    x = u - terms.origins[piece]
    family = terms.families[piece]
    if family == POLYNOMIAL:
        return _polynomial(terms.coefficients, first, last, x)
    if family == ERRORFUNCTIONS:
        return _errorfunctions(terms.coefficients, first, last, x)
    if family == SIGMOIDS:
        return _sigmoids(terms.coefficients, first, last, x)
    return _exponentials(terms.coefficients, first, last, x)


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
def _sigmoid_derivatives(coefficients, first, last, x, count, out):
    """out[j] += d^j/dx^j of the SIGMOIDS terms at x, j = 1 ... count - 1 (see piece_derivatives).

    With w = e^y, σ(y + h) = g(h) / (1 + g(h)), g(h) = w e^h = Σ_k w h^k / k!: its Taylor coefficients
    q_k solve q (1 + g) = g, q_k = (g_k - Σ_{i=1}^k g_i q_{k-i}) / (1 + w) (they decay as π^-k, the
    sums' terms as e^π π^-k: no growth of the rounding with k).
    """
    series = np.empty(count)
    for t in range(first, last, 3):
        a = coefficients[t + 1]
        w = math.exp(a * (x - coefficients[t + 2]))
        series[0] = w / (1.0 + w)
        for k in range(1, count):
            total = 0.0
            factorial = 1.0
            for i in range(1, k + 1):
                factorial *= i
                total += w / factorial * series[k - i]
            series[k] = (w / factorial - total) / (1.0 + w)
        scale = coefficients[t]
        factorial = 1.0
        for j in range(1, count):
            factorial *= j
            scale *= a
            out[j] += scale * factorial * series[j]


@njit(cache=True, error_model="numpy")
def piece_derivatives(terms, piece, u, count, out):
    """out[j] = d^j F_i / du^j at u for j = 1 ... count - 1 (out[0] is left alone), metres^(1-j).

    POLYNOMIAL: Σ_m c_m m!/(m-j)! x^(m-j); EXPONENTIALS: each term is
    Re[(b - i c) e^{z x}] with z = a + iω, so its j-th derivative is
    Re[(b - i c) z^j e^{z x}]; ERRORFUNCTIONS: j! times the Taylor
    coefficients of each term, the Cauchy product of those of
    e^{y(β - γy)} (Hermite's recurrence) and of erfcx(p y + s)
    (:func:`analytic.kernels.special.erfcx_taylor`); SIGMOIDS: j! a^j times
    the logistic's Taylor coefficients (:func:`_sigmoid_derivatives`).
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
    if terms.families[piece] == 3:          # SIGMOIDS
        _sigmoid_derivatives(coefficients, first, last, x, count, out)
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
    ERRORFUNCTIONS: Cauchy's estimate (:func:`_error_derivative_bound`);
    SIGMOIDS: Cauchy's estimate on circles of radius π/2 in y = a(x - c),
    where |Im y| <= π/2 keeps |1 + e^y| >= max(1, |e^y|), so |σ| <= min(1,
    e^{Re y}): |b| order! (2|a|/π)^order min(1, e^{max y + π/2}).
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
    if terms.families[piece] == 3:
        factorial = 1.0
        for k in range(2, order + 1):
            factorial *= k
        for t in range(first, last, 3):
            a = coefficients[t + 1]
            highest = max(a * (low - origin - coefficients[t + 2]), a * (high - origin - coefficients[t + 2]))
            bound += (abs(coefficients[t]) * factorial * (2.0 * abs(a) / math.pi) ** order
                      * min(1.0, math.exp(highest + 0.5 * math.pi)))
        return bound
    for t in range(first, last, 4):
        a = coefficients[t]
        envelope = math.exp(a * ((high if a > 0.0 else low) - origin))
        size = abs(coefficients[t + 2]) + abs(coefficients[t + 3])
        bound += envelope * size * math.hypot(a, coefficients[t + 1]) ** order
    return bound
