"""Illumination waveforms s(t) and the sampling kernels κ_n they induce.

A waveform is causal with support [0, duration] (duration 0 for the Dirac
impulse). Its cumulative S(u) = ∫_{-∞}^u s(t) dt is known in closed form,
piece by piece (:mod:`analytic.waveforms.pieces`), so the box-prefiltered
sample of light that left the plane at path length τ is

    κ_n(τ) = ∫_{t_n}^{t_{n+1}} s(t - τ) dt = S(t_{n+1} - τ) - S(t_n - τ),

exactly, with t_n = start + n T. Between the waveform's breakpoints (the
pieces' kinks) shifted to the bin edges, every κ_n is smooth in τ; the
quadrature of the system matrix splits its integrals there.

One module per waveform (:mod:`.impulse`, :mod:`.square`,
:mod:`.butterworth`), each with ``PARAMETERS`` (its scene keys) and
``build(illumination, period) -> Waveform``; :data:`BUILDERS` maps the
scene's ``waveform`` name to it. A new waveform is one such module and
its tests.
"""

from __future__ import annotations

from . import butterworth, impulse, square
from .butterworth import CUTOFF_PERIOD_RANGE, CUTOFF_RANGE, MAX_ORDER, MIN_CUTOFF_DURATION
from .pieces import (EXPONENTIALS, POLYNOMIAL, WaveformTerms, cumulative_scalar, kernel_scalar, make_terms,
                     piece_of, piece_value)
from .waveform import Waveform

__all__ = ["Waveform", "WaveformTerms", "make_waveform", "make_terms", "cumulative_scalar", "kernel_scalar",
           "piece_of", "piece_value", "POLYNOMIAL", "EXPONENTIALS", "BUILDERS", "MAX_ORDER", "CUTOFF_RANGE",
           "CUTOFF_PERIOD_RANGE", "MIN_CUTOFF_DURATION"]

#: The scene's ``[illumination] waveform`` -> the module that builds it.
BUILDERS = {"impulse": impulse, "square": square, "butterworth": butterworth}


def make_waveform(illumination, period: float) -> Waveform:
    """The waveform of an illumination, with defaults resolved against the period.

    Parameters
    ----------
    illumination : analytic.Illumination
        The scene's ``[illumination]`` table.
    period : float
        Sampling period T, metres; sets the defaults (square width T/5,
        Butterworth cutoff 1/(2T) cycles per metre, duration 3/cutoff,
        order 3).

    Returns
    -------
    Waveform

    Raises
    ------
    SceneError
        A parameter its waveform cannot deliver in float64 (each module
        names its bounds).
    """
    return BUILDERS[illumination.waveform].build(illumination, period)
