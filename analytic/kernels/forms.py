"""A waveform's pieces: the record, the families and each family's closed form, written once for every backend.

No Numba here (the renderer and the scene schema import it): :mod:`.pieces`
compiles the forms with ``math``'s functions, :mod:`analytic.waveforms.pieces`
evaluates them with NumPy's, :mod:`transient.common` with Dr.Jit's. What each
family is, and how the pieces make S(u), is described in
:mod:`analytic.waveforms.pieces`.

Each form takes the flat coefficients, the piece's range ``first:last`` in
them and x = u - o_i, and returns (F_i(x), a bound on the size of its terms),
the size scaling the rounding bound of a kernel (compiled code keeps it; the
others drop it). A form's loop runs over Python floats, NumPy scalars or
compiled array reads alike; x may be a float, a NumPy array or a Dr.Jit
array.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["WaveformTerms", "POLYNOMIAL", "EXPONENTIALS", "ERRORFUNCTIONS", "SIGMOIDS", "TERM_SIZES", "ROUNDING",
           "piece_forms"]

#: Families of the pieces' closed forms.
POLYNOMIAL, EXPONENTIALS, ERRORFUNCTIONS, SIGMOIDS = 0, 1, 2, 3
#: Coefficients per term of each family (POLYNOMIAL: one per power).
TERM_SIZES = {POLYNOMIAL: 1, EXPONENTIALS: 4, ERRORFUNCTIONS: 6, SIGMOIDS: 3}

#: Relative rounding allowed per term of a closed form when bounding a kernel's rounding error
#: (a few roundings of each term and of the sums).
ROUNDING = 8.0 * 2.0**-52


class WaveformTerms(NamedTuple):
    """A waveform's pieces as a record that compiled (Numba) code accepts.

    Attributes
    ----------
    starts : float64[P]
        b_i, increasing, metres of path length; piece i covers (b_i, b_{i+1}].
    kinks : bool[P]
        Whether s or a derivative jumps at b_i (a breakpoint of the quadrature).
    constants : float64[P]
        K_i, metres (dimensionless for the impulse).
    families : int64[P]
        ``POLYNOMIAL``, ``EXPONENTIALS``, ``ERRORFUNCTIONS`` or ``SIGMOIDS``.
    origins : float64[P]
        o_i, metres.
    offsets : int64[P + 1]
        Piece i's coefficients are ``coefficients[offsets[i]:offsets[i + 1]]``.
    coefficients : float64[C]
        See :mod:`analytic.waveforms.pieces`.
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
        degree between kinks (:mod:`analytic.kernels.taylor`).
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


def piece_forms(exp, cos, sin, erfcx):
    """Each family's F(x) for an array module's functions.

    Parameters
    ----------
    exp, cos, sin : callable
        ``math``'s (compiled code), NumPy's or Dr.Jit's.
    erfcx : callable
        erfcx(v) = e^{v²} erfc(v) for v >= 0 of the same backend.

    Returns
    -------
    tuple of callable
        ``(polynomial, exponentials, errorfunctions, sigmoids)``, indexed by
        the family codes; each ``form(coefficients, first, last, x) -> (F,
        size)``.

    Notes
    -----
    POLYNOMIAL Σ_m c_m x^m by Horner's rule; EXPONENTIALS Σ_j e^{a_j x}
    (b_j cos ω_j x + c_j sin ω_j x) (a zero frequency: e^{a_j x} b_j);
    ERRORFUNCTIONS Σ_j b_j e^{y(β_j - γ_j y)} erfcx(p_j y + s_j), y = x - c_j;
    SIGMOIDS Σ_j b_j e^{y} / (1 + e^{y}), y = a_j (x - c_j) <= 0 over the
    piece (no overflow; e^y keeps the logistic's relative accuracy in its
    tail). A term's size counts an exponent E's rounding ε|E| as relative.
    """
    def polynomial(coefficients, first, last, x):
        value = 0.0
        size = 0.0
        magnitude = abs(x)
        for m in range(last - 1, first - 1, -1):
            value = value * x + coefficients[m]
            size = size * magnitude + abs(coefficients[m])
        return value, size

    def exponentials(coefficients, first, last, x):
        value = 0.0
        size = 0.0
        for j in range(first, last, 4):
            envelope = exp(coefficients[j] * x)
            frequency = coefficients[j + 1]
            if frequency == 0.0:
                term = envelope * coefficients[j + 2]
                size = size + abs(term)
            else:
                angle = frequency * x
                term = envelope * (coefficients[j + 2] * cos(angle) + coefficients[j + 3] * sin(angle))
                size = size + envelope * (abs(coefficients[j + 2]) + abs(coefficients[j + 3]))
            value = value + term
        return value, size

    def errorfunctions(coefficients, first, last, x):
        value = 0.0
        size = 0.0
        for t in range(first, last, 6):
            y = x - coefficients[t + 1]
            exponent = y * (coefficients[t + 2] - coefficients[t + 3] * y)
            term = coefficients[t] * exp(exponent) * erfcx(coefficients[t + 4] * y + coefficients[t + 5])
            value = value + term
            size = size + abs(term) * (1.0 + abs(exponent))
        return value, size

    def sigmoids(coefficients, first, last, x):
        value = 0.0
        size = 0.0
        for t in range(first, last, 3):
            y = coefficients[t + 1] * (x - coefficients[t + 2])
            scaled = exp(y)
            term = coefficients[t] * scaled / (1.0 + scaled)
            value = value + term
            size = size + abs(term) * (1.0 + abs(y))
        return value, size

    return polynomial, exponentials, errorfunctions, sigmoids
