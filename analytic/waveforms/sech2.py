"""The sech² pulse: s(t) = sech²(t / τ), unit peak, centred at t = 0, τ = fwhm / (2 arccosh √2).

A mode-locked laser's pulse (the soliton shape). sech²(t/τ) = 1/2 at
|t| = τ arccosh √2, so fwhm = 2 arccosh(√2) τ ≈ 1.7627 τ; the area is 2τ.
Its cumulative is a logistic, S(u) = τ (1 + tanh(u/τ)) = 2τ σ(2u/τ) with
σ(y) = e^y / (1 + e^y), a ``SIGMOIDS`` piece
(:mod:`analytic.waveforms.pieces`): on u <= 0 as 2τ σ(2u/τ), which keeps
its relative accuracy in the left tail; on u > 0 as the area less the
remainder still to come, 2τ - 2τ σ(-2u/τ), which keeps a kernel's relative
accuracy in the right tail (as the Gaussian's two pieces do). The switch at
0 is not a kink: one analytic function.

Truncation: the pulse is followed over |t| <= 30 ln(2) τ (20.8 τ), where
σ(-60 ln 2) = 2^-60 / (1 + 2^-60): the mass left beyond each end is 2^-60
of the area, as for the Gaussian; the cut ends are kinks (s jumps by 2^-58
there), so the model's quadrature cuts at them.
"""

from __future__ import annotations

import math

from .gaussian import FWHM, require
from .pieces import POLYNOMIAL, SIGMOIDS, make_terms
from .waveform import Waveform

__all__ = ["build", "NAME", "SUMMARY", "PARAMETERS", "FWHM_PER_TAU", "TRUNCATION"]

NAME = "sech2"
SUMMARY = "sech² laser pulse of FWHM ``fwhm`` centred at 0"
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`).
PARAMETERS = (FWHM,)

#: FWHM / τ of sech²(t/τ), 2 arccosh √2 = 2 ln(1 + √2).
FWHM_PER_TAU = 2.0 * math.acosh(math.sqrt(2.0))
#: The pulse is followed over |t| <= TRUNCATION τ (see the module docstring).
TRUNCATION = 30.0 * math.log(2.0)


def build(illumination, period: float) -> Waveform:
    """The sech² pulse of the scene's ``fwhm`` (metres of path length, required; a SceneError without it).

    The period (metres) is not needed: no default depends on it.

    Notes
    -----
    With a = 2/τ and A = 2τ (the area): piece (-cut, 0]: S = K_0 + A σ(a u),
    K_0 = -A σ(-a cut) (S = 0 at the cut); piece (0, cut]: S = K_1 - A σ(-a u),
    K_1 = K_0 + A; beyond, S = K_1 - A σ(-a cut).
    """
    del period
    fwhm = require(illumination, "fwhm")
    tau = fwhm / FWHM_PER_TAU
    area = 2.0 * tau
    rate = 2.0 / tau
    cut = TRUNCATION * tau
    tail = math.exp(-rate * cut)
    lost = area * tail / (1.0 + tail)
    pieces = [(-cut, True, -lost, SIGMOIDS, 0.0, [area, rate, 0.0]),
              (0.0, False, area - lost, SIGMOIDS, 0.0, [-area, -rate, 0.0]),
              (cut, True, area - lost, POLYNOMIAL, 0.0, [-lost])]
    return Waveform(NAME, make_terms(pieces, duration=cut, lead=-cut),
                    f"sech² pulse, unit peak at 0, FWHM {fwhm:.6g} m (tau {tau:.6g} m)",
                    parameters={"fwhm": fwhm})
