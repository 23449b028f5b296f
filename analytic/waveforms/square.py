"""The square pulse: s(t) = 1 on [0, width], so S(u) = min(max(u, 0), width), exact for every width."""

from __future__ import annotations

from ..errors import SceneError
from .pieces import POLYNOMIAL, make_terms
from .waveform import Parameter, Waveform

__all__ = ["build", "plugin_entries", "NAME", "SUMMARY", "PARAMETERS"]

NAME = "square"
SUMMARY = "unit-amplitude box of width ``width``"
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`).
PARAMETERS = (Parameter("width", "positive", "m", "T / 5", plugin="pulse_width"),)


def plugin_entries(illumination, period: float) -> dict:
    """``pulse_width`` resolved (its default follows the period, which the plugin reads as the bin width)."""
    return {"pulse_width": float(build(illumination, period).duration)}


def build(illumination, period: float) -> Waveform:
    """The square pulse of the scene's ``width`` (default period / 5), metres of path length.

    Raises
    ------
    SceneError
        A period so small that the default width period / 5 underflows to 0.

    Notes
    -----
    Two pieces: (0, width] with F(u) = u, and (width, +∞) with K = width:
    a kernel across the end is width - u, within the first piece b - a.
    """
    width = illumination.width if illumination.width is not None else period / 5.0
    if not width > 0.0:
        raise SceneError("sampling.period", f"{period!r} m is so small that the default square "
                         f"width period / 5 underflows to 0; set illumination.width")
    terms = make_terms([(0.0, True, 0.0, POLYNOMIAL, 0.0, [0.0, 1.0]),
                        (width, True, width, POLYNOMIAL, 0.0, [])], duration=width)
    return Waveform("square", terms, f"square pulse, unit amplitude, width {width:.6g} m",
                    parameters={"width": float(width)})
