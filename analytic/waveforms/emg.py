"""The exponentially modified Gaussian (EMG): a Gaussian of FWHM ``fwhm`` at 0 convolved with e^{-t/tail} / tail.

A single-photon detector's instrument response is close to this: a
Gaussian timing jitter tens of picoseconds wide with a slower exponential
tail (docs/design.md section 8). Divided by its peak, as every pulse but
the impulse.

Notes
-----
With σ = fwhm / (2√(2 ln 2)), τ = tail, q = 1/(σ√2), w = q u and
r = σ / (τ√2) (so that u / τ = 2 r w), the unit-area EMG has the density
and the cumulative

    f(u) = e^{-w²} erfcx(r - w) / (2τ),                              w <= r
         = (2 e^{r² - 2rw} - e^{-w²} erfcx(w - r)) / (2τ),           w > r
    F(u) = ½ e^{-w²} (erfcx(-w) - erfcx(r - w)),                     u <= 0
    1 - F(u) = ½ e^{-w²} (erfcx(w) + erfcx(r - w)),                  0 < w <= r
             = ½ e^{-w²} erfcx(w) + e^{r² - 2rw} - ½ e^{-w²} erfcx(w - r),   w > r

(the textbook form e^{r² - 2rw} erfc(r - w) overflows or cancels; here
every erfcx argument is >= 0, every exponent <= 0). Each line is one
``ERRORFUNCTIONS`` piece; the switches at 0 and at w = r are not kinks.
Past u = 0 S is the area less the remainder 1 - F still to come, so a
kernel keeps its relative accuracy in the exponential tail; on u <= 0 the
two erfcx cancel by up to a factor ~w / r (relative rounding
~ε w √2 τ / σ: 2e-11 at tail = 1e4 fwhm, within the model's smallest
tolerance; the absolute error stays ~ε of the area everywhere).

Truncation: as the Gaussian (:mod:`analytic.waveforms.gaussian`) on the
left (the EMG's left tail is lighter than its Gaussian's), and on the
right where 1 - F falls to 2^-60. The peak is found by Brent's method on
the log-concave density (flat at the peak, so its value is exact to
rounding).

Bounds: tail / fwhm in [1e-4, 1e4] (``TAIL_RATIO_RANGE``): a shorter
tail is the Gaussian moved by ``tail`` to within 1e-4 of its width
(use ``waveform = "gaussian"``), a longer one would lose more than 1e-10
of the left tail's relative accuracy to the cancellation above.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..values import exact
from .gaussian import FWHM, FWHM_PER_SIGMA, TRUNCATION, require
from .pieces import ERRORFUNCTIONS, POLYNOMIAL, make_terms
from ..kernels.formulas import erfcx_array
from .waveform import Parameter, Waveform

__all__ = ["build", "NAME", "SUMMARY", "PARAMETERS", "TAIL_RATIO_RANGE"]

NAME = "emg"
SUMMARY = "a Gaussian (FWHM ``fwhm``) convolved with an exponential of time constant ``tail`` (a SPAD's response)"
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`).
PARAMETERS = (FWHM, Parameter("tail", "length", "m", "required", plugin="tail"))

#: Accepted tail / fwhm (see the module docstring).
TAIL_RATIO_RANGE = (1e-4, 1e4)

# The pulse is followed until 1 - F falls to this share of the area (as the Butterworth pulse).
_SETTLED = 2.0 ** -60


def build(illumination, period: float) -> Waveform:
    """The EMG of the scene's ``fwhm`` and ``tail`` (metres of path length, both required).

    Parameters
    ----------
    illumination : analytic.Illumination
        ``fwhm``: the Gaussian's full width at half maximum; ``tail``: the
        exponential's time constant τ (e^{-t/τ}); metres.
    period : float
        Sampling period, metres (not needed).

    Raises
    ------
    SceneError
        ``illumination.fwhm`` or ``illumination.tail`` missing, or
        tail / fwhm outside :data:`TAIL_RATIO_RANGE`.
    """
    del period
    fwhm = require(illumination, "fwhm")
    tail = require(illumination, "tail")
    low, high = TAIL_RATIO_RANGE
    if not low <= tail / fwhm <= high:
        raise SceneError("illumination.tail", f"tail / fwhm must be in [{low:g}, {high:g}], got {exact(tail / fwhm)}: "
                         f"a shorter tail is a Gaussian moved by the tail (use waveform = \"gaussian\"), a "
                         f"longer one loses the left tail's accuracy in float64")
    shape = _Shape(fwhm / FWHM_PER_SIGMA, tail)
    peak_time, peak = shape.peak()
    end = shape.settled()
    scale = 1.0 / peak
    q, r = shape.q, shape.r
    switch = r / q                                  # w = r: u = σ² / τ
    lead = -TRUNCATION / q
    half = 0.5 * scale
    left = [half, 0.0, 0.0, q * q, -q, 0.0, -half, 0.0, 0.0, q * q, -q, r]
    rising = [-half, 0.0, 0.0, q * q, q, 0.0, -half, 0.0, 0.0, q * q, -q, r]
    falling = [-half, 0.0, 0.0, q * q, q, 0.0, -scale, 0.5 * switch, -2.0 * r * q, 0.0, 0.0, 0.0,
               half, 0.0, 0.0, q * q, q, -r]
    first = -scale * shape.cumulative_left(lead)    # S(lead) = 0
    area = first + scale
    pieces = [(lead, True, first, ERRORFUNCTIONS, 0.0, left),
              (0.0, False, area, ERRORFUNCTIONS, 0.0, rising)]
    if switch < end:
        pieces.append((switch, False, area, ERRORFUNCTIONS, 0.0, falling))
    pieces.append((end, True, area, POLYNOMIAL, 0.0, [-scale * shape.survival(end)]))
    description = (f"exponentially modified Gaussian, Gaussian FWHM {fwhm:.6g} m, tail {tail:.6g} m, "
                   f"unit peak at {peak_time:.6g} m")
    return Waveform("emg", make_terms(pieces, duration=end, lead=lead), description, peak_time,
                    {"fwhm": fwhm, "tail": tail})


class _Shape:
    """The unit-area EMG of σ and τ in the stable forms of the module docstring (NumPy, metres)."""

    def __init__(self, sigma: float, tail: float):
        self.sigma, self.tail = sigma, tail
        self.q = 1.0 / (sigma * math.sqrt(2.0))
        self.r = sigma / (tail * math.sqrt(2.0))

    def density(self, u):
        """f(u), 1/m."""
        w = self.q * np.asarray(u, dtype=np.float64)
        r = self.r
        gaussian = np.exp(-w * w)
        rising = gaussian * erfcx_array(r - w)
        falling = 2.0 * np.exp(np.minimum(r * r - 2.0 * r * w, 0.0)) - gaussian * erfcx_array(w - r)
        return np.where(w <= r, rising, falling) / (2.0 * self.tail)

    def cumulative_left(self, u: float) -> float:
        """F(u) for u <= 0."""
        w = self.q * u
        return float(0.5 * math.exp(-w * w) * (erfcx_array(-w) - erfcx_array(self.r - w)))

    def survival(self, u: float) -> float:
        """1 - F(u) for u > 0."""
        w = self.q * u
        r = self.r
        gaussian = math.exp(-w * w)
        value = 0.5 * gaussian * float(erfcx_array(w))
        if w <= r:
            return value + 0.5 * gaussian * float(erfcx_array(r - w))
        return value + math.exp(r * r - 2.0 * r * w) - 0.5 * gaussian * float(erfcx_array(w - r))

    def peak(self) -> tuple[float, float]:
        """(the mode, f there): Brent's method on -log f over [-σ, τ + σ] (f is log-concave)."""
        from scipy import optimize

        low, high = -self.sigma, self.tail + self.sigma
        found = optimize.minimize_scalar(lambda u: -math.log(float(self.density(u))), bounds=(low, high),
                                         method="bounded", options={"xatol": 1e-12 * (high - low)})
        return float(found.x), float(self.density(found.x))

    def settled(self) -> float:
        """u > 0 where 1 - F falls to _SETTLED."""
        from scipy import optimize

        high = 10.0 * self.sigma + self.tail * (self.r * self.r + 45.0)    # 1 - F < 2^-62 there
        # (1 - F may underflow to 0 towards ``high`` when the tail is short: floor it for the logarithm)
        return float(optimize.brentq(lambda u: math.log(max(self.survival(u), 1e-300)) - math.log(_SETTLED),
                                     0.0, high, xtol=1e-14 * high))
