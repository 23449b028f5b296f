"""The Gaussian pulse: s(t) = exp(-t² / (2σ²)), unit peak, centred at t = 0, σ = fwhm / (2 √(2 ln 2)).

A laser pulse, or a detector's timing jitter, as docs/design.md section 8
defines it. S(u) = σ √(π/2) erfc(-u / (σ√2)): on u <= 0 that form keeps its
relative accuracy (erfc of a non-negative argument, e^{-v²} erfcx(v)); on
u > 0 S is the area less the remainder still to come, σ √(π/2) erfc(u /
(σ√2)), which keeps a kernel's relative accuracy far in the right tail (as
the Butterworth pulse's exponential piece does). Both are ``ERRORFUNCTIONS``
pieces (:mod:`analytic.waveforms.pieces`), switching at 0 (not a kink:
one analytic function).

Truncation: the pulse is followed over |t| <= Z σ √2 with erfc(Z) = 2^-59,
Z = 6.2037 (|t| <= 8.77 σ): the mass left beyond each end is 2^-60 of the
area, a quarter of an ulp of the area and 1/256 of the float64 resolution
of a kernel near the peak; a bin wholly beyond it reads 0 instead of at
most 2^-60 of the area. The cut ends are kinks (s jumps by e^{-Z²} ≈ 2e-17
there), so the model's quadrature cuts at them.
"""

from __future__ import annotations

import math

from ..errors import SceneError
from .pieces import ERRORFUNCTIONS, POLYNOMIAL, make_terms
from .waveform import Parameter, Waveform

__all__ = ["build", "NAME", "SUMMARY", "PARAMETERS", "FWHM", "TRUNCATION", "FWHM_PER_SIGMA", "require"]

NAME = "gaussian"
SUMMARY = "Gaussian of FWHM ``fwhm`` centred at 0"
#: The full width at half maximum, metres of path (gaussian, emg, sech2).
FWHM = Parameter("fwhm", "length", "m", "required", plugin="fwhm")
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`).
PARAMETERS = (FWHM,)

#: FWHM / σ of a Gaussian, 2 √(2 ln 2).
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
#: Z with erfc(Z) = 2^-59: the pulse is followed over |t| <= Z σ √2 (see the module docstring).
TRUNCATION = 6.20367489214687


def require(illumination, name: str) -> float:
    """The illumination's ``name`` (metres), or a SceneError saying the waveform needs it."""
    value = getattr(illumination, name)
    if value is None:
        raise SceneError(f"illumination.{name}", f"required with waveform = {illumination.waveform!r} "
                         f"(metres of path; 1 ps = 2.99792458e-4 m)")
    return float(value)


def build(illumination, period: float) -> Waveform:
    """The Gaussian pulse of the scene's ``fwhm`` (metres of path length, required).

    Parameters
    ----------
    illumination : analytic.Illumination
        ``fwhm``, the full width at half maximum, metres.
    period : float
        Sampling period, metres (not needed: no default depends on it).

    Raises
    ------
    SceneError
        ``illumination.fwhm`` missing.

    Notes
    -----
    With q = 1 / (σ√2) and c = σ √(π/2) (the area is 2c = σ √(2π)):
    piece (-Zσ√2, 0]: S = K_0 + c e^{-q²u²} erfcx(-qu), K_0 = -c erfc(Z)
    (S = 0 at the cut); piece (0, Zσ√2]: S = K_1 - c e^{-q²u²} erfcx(qu),
    K_1 = K_0 + 2c; beyond, S = K_1 - c erfc(Z).
    """
    del period
    fwhm = require(illumination, "fwhm")
    sigma = fwhm / FWHM_PER_SIGMA
    q = 1.0 / (sigma * math.sqrt(2.0))
    c = sigma * math.sqrt(0.5 * math.pi)
    cut = TRUNCATION / q
    lost = c * math.erfc(TRUNCATION)
    pieces = [(-cut, True, -lost, ERRORFUNCTIONS, 0.0, [c, 0.0, 0.0, q * q, -q, 0.0]),
              (0.0, False, 2.0 * c - lost, ERRORFUNCTIONS, 0.0, [-c, 0.0, 0.0, q * q, q, 0.0]),
              (cut, True, 2.0 * c - lost, POLYNOMIAL, 0.0, [-lost])]
    return Waveform("gaussian", make_terms(pieces, duration=cut, lead=-cut),
                    f"Gaussian pulse, unit peak at 0, FWHM {fwhm:.6g} m (sigma {sigma:.6g} m)",
                    parameters={"fwhm": fwhm})
