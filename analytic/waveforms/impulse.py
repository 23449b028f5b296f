"""The Dirac impulse: s(t) = δ(t), unit area, so S(u) = 1 for u > 0 and κ_n(τ) = 1 when t_n <= τ < t_{n+1}."""

from __future__ import annotations

from .pieces import POLYNOMIAL, make_terms
from .waveform import Waveform

__all__ = ["build", "NAME", "SUMMARY", "PARAMETERS"]

NAME = "impulse"
SUMMARY = "Dirac impulse δ(t), unit area"
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`).
PARAMETERS = ()


def build(illumination, period: float) -> Waveform:
    """The impulse (``illumination`` and ``period`` are not needed: it has no parameters).

    Notes
    -----
    One piece (0, +∞) with K = 1 and F = 0: S(u) = [u > 0], so a path of
    length τ falls in the bin with t_n <= τ < t_{n+1}, as
    :func:`analytic.binning.bin_index` bins it.
    """
    del illumination, period
    terms = make_terms([(0.0, True, 1.0, POLYNOMIAL, 0.0, [])], duration=0.0)
    return Waveform("impulse", terms, "Dirac impulse (unit area)")
