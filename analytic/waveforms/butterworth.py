"""The Butterworth pulse: the truncated impulse response of an analogue Butterworth low-pass, unit peak.

The paper's low-pass illumination. The pulse is written as a sum of damped
exponentials, s(t) = Re Σ_i r_i exp(p_i t) over the poles p_i, so that S(u)
is a finite sum of e^{a u} (b cos ωu + c sin ωu) terms (an ``EXPONENTIALS``
piece whose constant is the pulse's area and whose form is the remainder
still to come, so that far in the tail a kernel keeps its relative
accuracy), with its Taylor series near u = 0 where those terms cancel (a
``POLYNOMIAL`` piece). :func:`build` says how it is built so that float64
delivers it to ~1e-14 of the pulse's area, and which scene values it
refuses because float64 cannot.

Notes
-----
The Butterworth pulse of order n and cutoff f_c (ω_c = 2π f_c) is
h(t) = Σ_k r_k e^{p_k t}, scaled to unit peak and truncated at the
duration. With x = ω_c t, its poles are ω_c q_k,
q_k = exp(iπ(2k + n - 1) / (2n)), k = 1..n (closed form, conjugate pairs
exact), and its residues ω_c ρ_k with ρ_k = 1 / Π_{j≠k} (q_k - q_j), each
accurate to ~n ulps (the q_k are at least 2 sin(π/2n) apart). Then

    S(u) = G(ω_c u) / (ω_c g_max),  G(x) = 1 + Re Σ_k (ρ_k / q_k) e^{q_k x},

since Σ_k ρ_k / q_k = -1/B(0) = -1 for the Butterworth polynomial B.
Evaluated so, S has an absolute rounding error of about
ε Σ_k |ρ_k| e^{Re q_k x} in units of the area 1/(ω_c g_max): the terms
cancel, and Σ |ρ_k| grows as ~1.7^n (1.8e4 at n = 20). Near x = 0 the
Taylor series G(x) = Σ_m M_{m-1} x^m / m! is used instead; its
coefficients are exact in closed form: B(s) B(-s) = 1 + (-1)^n s^{2n}
makes the Markov parameters M_j = h^{(j)}(0) the signed coefficients
b_r of B, M_{n-1+r+2nc} = (-1)^r b_r (-(-1)^n)^c for 0 <= r <= n
(0 for n < r < 2n), b_r = Π_{i=1}^r cos((i-1)π/2n) / sin(iπ/2n). The
series' rounding error is ~ε Σ_m |M_{m-1}| x^m / m!; the switch
(``series_limit``) is where the two error bounds cross, x ≈ 0.38 n + 0.2,
so S is accurate to ~ε Σ|ρ_k| e^{Re q_k x₀} of the area everywhere
(measured against an mpmath state-space model: ≤ 2e-15 for n ≤ 10,
≤ 1e-14 for n ≤ 20), and relatively to ~1e-15 below x₀ / 2, to
~ε Σ|ρ_k| e^{Re q_k x₀} / G(x₀) around x₀ (up to 2.5e-12 at n = 20,
where S(x₀) is 1e-3 of the area).

The unit-peak scale g_max is the first local maximum of h (the global
one for an all-pole Butterworth response): a march in steps of 1/16 in
x brackets the first sign change of h' (from the series near 0, from
h' = Σ r_k p_k e^{p_k t} beyond; a sign counts only when larger than its
rounding-error bound), and Brent's method finds the root. When the
truncation comes before it, h rises up to the truncation and the peak
is h(duration). The pulse is followed only until less than 2^-60 of its
area is left (``Waveform.duration``), so no exponential or cosine ever
sees a large argument and any longer duration gives the untruncated
pulse.

Bounds (``MAX_ORDER``, ``CUTOFF_RANGE``, ``CUTOFF_PERIOD_RANGE``,
``MIN_CUTOFF_DURATION``), where float64 cannot deliver:

- order <= 20. Accuracy is not the limit (~ε Σ|ρ| e^{Re q x₀}, 4e-14
  at n = 30) but the series' coefficients M ω_c^{m-1} / (m! g_max),
  which multiply u^m in metres up to m = 2n: measured over the cutoff
  and duration ranges below they span 6e-251..4e245 at n = 20 (1e57 to
  spare at either end), 1e-264..4e257 at n = 21; at n = 24 they
  overflow (cutoff 1e6), at n = 25 they underflow (cutoff 1e-6).
- 1e-6 <= cutoff <= 1e6 cycles/m, for the same reason (ω_c^39 / 40! in
  range).
- 1e-3 <= cutoff T <= 1e3: a longer pulse touches up to ~1e5 bins per
  path (untruncated, n = 20), a shorter one rises within 1e-4 T,
  where path lengths resolved to ε |t| blur it beyond 1e-6 relative over
  windows of 1e6 periods.
- cutoff x duration >= 1e-6: a truncation that early keeps s ~
  (t / duration)^{n-1}, whose Taylor coefficients ~duration^{1-n} (1e228
  at n = 20, cutoff 1e6) approach float64's range.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..values import exact
from .pieces import EXPONENTIALS, POLYNOMIAL, make_terms
from .waveform import Parameter, Waveform

__all__ = ["build", "NAME", "SUMMARY", "PARAMETERS", "MAX_ORDER", "CUTOFF_RANGE", "CUTOFF_PERIOD_RANGE",
           "MIN_CUTOFF_DURATION"]

NAME = "butterworth"
SUMMARY = "truncated impulse response of an analogue Butterworth low-pass"
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`).
PARAMETERS = (Parameter("cutoff", "positive", "cycles/m", "1/(2T)", plugin="cutoff"),
              Parameter("duration", "positive", "m", "3 / cutoff", plugin="duration"),
              Parameter("order", "integer", "", "3", plugin="order"))

#: Highest Butterworth order accepted (criterion in :func:`make_waveform`).
MAX_ORDER = 20
#: Accepted Butterworth cutoffs, cycles per metre of path length.
CUTOFF_RANGE = (1e-6, 1e6)
#: Accepted Butterworth cutoff x sampling period (dimensionless).
CUTOFF_PERIOD_RANGE = (1e-3, 1e3)
#: Smallest accepted Butterworth cutoff x duration (dimensionless).
MIN_CUTOFF_DURATION = 1e-6

# The pulse counts as over once what is left of its energy, and the rounding
# error of its exponential sum, are below this fraction of its area (a
# quarter of an ulp of the area): S is then constant in float64.
_SETTLED = 2.0 ** -60
# Taylor terms are dropped once the rest of the series is below this fraction
# of S at the series' upper end.
_SERIES_TAIL = 2.0 ** -60
# Taylor coefficients of the normalized pulse kept for the search of the
# series' range and of the peak: past x = 10 (beyond any crossover for order
# <= 20), term 170 is below 1e-140 of the largest.
_TAYLOR_TERMS = 170
# Step of the march that brackets the peak, in units of 1/ω_c: well below
# the half-period π of the pulse's ringing, so no sign change of h' is skipped.
_BRACKET_STEP = 1.0 / 16.0


def build(illumination, period: float) -> Waveform:
    """The Butterworth pulse of the scene's order, cutoff and duration, defaults resolved against the period.

    Parameters
    ----------
    illumination : analytic.Illumination
        ``order`` (default 3, the paper's), ``cutoff`` (cycles per metre of
        path length; default 1/(2 period), the sampler's Nyquist frequency)
        and ``duration`` (the truncation, metres; default 3 / cutoff).
    period : float
        Sampling period T, metres.

    Raises
    ------
    SceneError
        An order, cutoff or duration (or a period setting the default
        cutoff) outside the bounds of the module docstring.
    """
    order, cutoff, duration = _butterworth_parameters(illumination, period)
    return _butterworth(order, cutoff, duration)


def _butterworth_parameters(illumination, period: float) -> tuple[int, float, float]:
    """Order, cutoff (cycles/m) and duration (m) with defaults, checked against the bounds."""
    order = illumination.order if illumination.order is not None else 3
    if order > MAX_ORDER:
        raise SceneError("illumination.order", f"must be <= {MAX_ORDER}, got {order}: higher orders "
                         f"need Taylor coefficients near t = 0 outside float64's range")
    low, high = CUTOFF_RANGE
    if illumination.cutoff is None:
        cutoff = 0.5 / period
        if not low <= cutoff <= high:
            raise SceneError("sampling.period", f"{exact(period)} m sets the default Butterworth cutoff "
                             f"1/(2 period) = {exact(cutoff)} cycles/m outside [{low:g}, {high:g}], where "
                             f"the pulse's Taylor coefficients fit float64; use a period in "
                             f"[{0.5 / high:g}, {0.5 / low:g}] m")
    else:
        cutoff = illumination.cutoff
        if not low <= cutoff <= high:
            raise SceneError("illumination.cutoff", f"must be in [{low:g}, {high:g}] cycles/m, got "
                             f"{exact(cutoff)}: outside it the pulse's Taylor coefficients leave float64's range")
        low, high = CUTOFF_PERIOD_RANGE
        if not low <= cutoff * period <= high:
            raise SceneError("illumination.cutoff", f"cutoff x period must be in [{low:g}, {high:g}], got "
                             f"{exact(cutoff * period)}: a pulse over 1/({low:g} cutoff) long touches too many "
                             f"bins per path, one under 1/({high:g} cutoff) is blurred by float64 path "
                             f"lengths")
    if illumination.duration is None:
        duration = 3.0 / cutoff
    else:
        duration = illumination.duration
        if not cutoff * duration >= MIN_CUTOFF_DURATION:
            raise SceneError("illumination.duration", f"must be >= {MIN_CUTOFF_DURATION:g} / cutoff = "
                             f"{exact(MIN_CUTOFF_DURATION / cutoff)} m, got {exact(duration)}: a shorter truncation "
                             f"has Taylor coefficients ~duration^(1-order) outside float64's range")
    return order, cutoff, duration


class _NormalizedButterworth:
    """The Butterworth impulse response g(x) for ω_c = 1 (x = ω_c t), evaluated stably.

    Parameters
    ----------
    order : int
        n, 1..MAX_ORDER.

    Attributes
    ----------
    poles, residues : numpy.ndarray
        q_k and ρ_k, all n of them (complex).
    taylor : numpy.ndarray
        G(x) = Σ_m taylor[m] x^m, taylor[m] = M_{m-1} / m!.
    switch : float
        x₀: the series is used below it, the exponential sum above.
    """

    def __init__(self, order: int):
        n = order
        angles = [math.pi * (2 * k - 1) / (2 * n) for k in range(1, n // 2 + 1)]
        upper = [complex(-math.sin(phi), math.cos(phi)) for phi in angles]
        poles = upper + [q.conjugate() for q in upper] + ([-1.0 + 0.0j] if n % 2 else [])
        self.poles = np.array(poles)
        differences = self.poles[:, None] - self.poles[None, :]
        np.fill_diagonal(differences, 1.0)
        self.residues = 1.0 / np.prod(differences, axis=1)
        self.taylor = self._taylor(n)
        self.switch = self._crossing(n)

    @staticmethod
    def _taylor(n: int) -> np.ndarray:
        gamma = math.pi / (2 * n)
        coefficients = [1.0]
        for i in range(1, n + 1):
            coefficients.append(coefficients[-1] * math.cos((i - 1) * gamma) / math.sin(i * gamma))
        taylor = np.zeros(_TAYLOR_TERMS)
        factorial = 1.0
        for m in range(1, _TAYLOR_TERMS):
            factorial *= m
            j = m - 1 - (n - 1)             # M_{m-1} = M_{n-1+j}
            if j < 0:
                continue
            cycle, r = divmod(j, 2 * n)
            if r <= n:
                taylor[m] = (-1) ** r * coefficients[r] * (-(-1) ** n) ** cycle / factorial
        return taylor

    def envelope(self, x: float) -> float:
        """Σ_k |ρ_k| e^{Re q_k x}: bounds the exponential sum's terms and the pulse's remaining area."""
        return float(np.sum(np.abs(self.residues) * np.exp(self.poles.real * x)))

    def series_magnitude(self, x: float) -> float:
        """Σ_m |taylor[m]| x^m: bounds the series' terms."""
        return float(np.polynomial.polynomial.polyval(x, np.abs(self.taylor)))

    def _crossing(self, n: int) -> float:
        from scipy import optimize

        # the series' error bound grows from 0, the exponential sum's decays: one crossing
        return float(optimize.brentq(lambda x: self.series_magnitude(x) - self.envelope(x),
                                     0.0, 0.6 * n + 3.0, xtol=1e-12))

    def derivative(self, x: np.ndarray, times: int) -> tuple[np.ndarray, np.ndarray]:
        """d^times G / dx^times at x >= 0 (1: g, 2: g'), and a bound on its rounding error."""
        x = np.asarray(x, dtype=np.float64)
        series = self.taylor
        for _ in range(times):
            series = np.polynomial.polynomial.polyder(series)
        weights = self.residues * self.poles ** (times - 1)
        exponential = np.real(np.exp(np.multiply.outer(x, self.poles)) @ weights)
        error_exponential = 16 * np.finfo(float).eps * (1 + x) * (
            np.exp(np.multiply.outer(x, self.poles.real)) @ np.abs(weights))
        polynomial = np.polynomial.polynomial.polyval(x, series)
        error_polynomial = 16 * np.finfo(float).eps * np.polynomial.polynomial.polyval(x, np.abs(series))
        small = x < self.switch
        return (np.where(small, polynomial, exponential),
                np.where(small, error_polynomial, error_exponential))

    def first_peak(self) -> float:
        """x of the first local maximum of g (0 for order 1, where g falls from the start)."""
        from scipy import optimize

        slowest = float(-np.max(self.poles.real))       # sin(π/2n)
        grid = np.arange(0.0, 4.0 / slowest + 8.0, _BRACKET_STEP)
        slope, error = self.derivative(grid, 2)
        sign = np.where(slope > error, 1, np.where(slope < -error, -1, 0))
        falling = np.flatnonzero(sign < 0)
        if falling.size == 0:
            raise RuntimeError("the Butterworth response has no peak within 4 group delays")
        rising = np.flatnonzero(sign[:falling[0]] > 0)
        if rising.size == 0:
            return 0.0
        return float(optimize.brentq(lambda x: float(self.derivative(x, 2)[0]), grid[rising[-1]],
                                     grid[falling[0]], xtol=1e-15, rtol=4 * np.finfo(float).eps))

    def settled(self) -> float:
        """x after which less than _SETTLED of the (unit) area is left."""
        from scipy import optimize

        slowest = float(-np.max(self.poles.real))
        high = (math.log(float(np.sum(np.abs(self.residues)))) - math.log(_SETTLED)) / slowest
        return float(optimize.brentq(lambda x: math.log(self.envelope(x)) - math.log(_SETTLED),
                                     0.0, high * (1 + 1e-12) + 1e-12, xtol=1e-9))

    def series_terms(self, limit: float) -> int:
        """Highest power P such that the Taylor terms above it are below _SERIES_TAIL of G(limit)."""
        magnitudes = np.abs(self.taylor) * limit ** np.arange(self.taylor.size)
        value = abs(float(np.polynomial.polynomial.polyval(limit, self.taylor)))
        tails = np.cumsum(magnitudes[::-1])[::-1]              # tails[m] = Σ_{m' >= m}
        return int(np.flatnonzero(tails > _SERIES_TAIL * value)[-1])


def _butterworth(order: int, cutoff: float, duration: float) -> Waveform:
    pulse = _NormalizedButterworth(order)
    omega = 2.0 * math.pi * cutoff
    scaled_duration = omega * duration
    first_peak = pulse.first_peak()
    peak_x = min(first_peak, scaled_duration)
    peak = float(pulse.derivative(peak_x, 1)[0])
    peak_time = duration if scaled_duration <= first_peak else peak_x / omega
    end = min(duration, pulse.settled() / omega)

    # one term per real pole and per conjugate pair (Im q > 0; its partner adds the conjugate)
    keep = pulse.poles.imag >= 0.0
    pair = np.where(pulse.poles.imag[keep] > 0.0, 2.0, 1.0)
    coefficients = pulse.residues[keep] / pulse.poles[keep] / (omega * peak) * pair
    exponentials = np.column_stack([omega * pulse.poles.real[keep], omega * pulse.poles.imag[keep],
                                    coefficients.real, -coefficients.imag]).ravel()
    constant = 1.0 / (omega * peak)     # the untruncated area: G(∞) = 1

    # S(u) = Σ_m taylor[m] (ω u)^m / (ω g_max), so u^m has the coefficient taylor[m] ω^(m-1) / g_max
    highest = pulse.series_terms(min(pulse.switch, scaled_duration))
    powers = np.arange(highest + 1)
    series = pulse.taylor[:highest + 1] / peak * omega ** (powers - 1.0)
    if scaled_duration > pulse.switch:
        # the series up to the switch, then the area less the remainder still to come (which
        # keeps a tail kernel's relative accuracy), and past the end the remainder left there
        switch = pulse.switch / omega
        remainder = _exponentials_at(exponentials, end)
        pieces = [(0.0, True, 0.0, POLYNOMIAL, 0.0, series),
                  (switch, False, constant, EXPONENTIALS, 0.0, exponentials),
                  (end, True, constant, POLYNOMIAL, 0.0, [remainder])]
    else:   # the truncation comes before the switch: the series covers the whole pulse
        pieces = [(0.0, True, 0.0, POLYNOMIAL, 0.0, series),
                  (end, True, 0.0, POLYNOMIAL, 0.0, [np.polynomial.polynomial.polyval(end, series)])]
    if end < duration:
        ending = f"untruncated (truncation {duration:.6g} m; below 2^-60 of its area after {end:.6g} m)"
    else:
        ending = f"truncated at {duration:.6g} m"
    description = (f"Butterworth low-pass, order {order}, cutoff {cutoff:.6g} cycles/m, {ending}, "
                   f"unit peak at {peak_time:.6g} m")
    return Waveform("butterworth", make_terms(pieces, float(end)), description, float(peak_time),
                    {"cutoff": float(cutoff), "duration": float(duration), "order": int(order)})


def _exponentials_at(coefficients: np.ndarray, u: float) -> float:
    """Σ_j e^{a_j u} (b_j cos ω_j u + c_j sin ω_j u) for ``EXPONENTIALS`` coefficients (a, ω, b, c)."""
    a, w, b, c = np.reshape(coefficients, (-1, 4)).T
    return float(np.sum(np.exp(a * u) * (b * np.cos(w * u) + c * np.sin(w * u))))
