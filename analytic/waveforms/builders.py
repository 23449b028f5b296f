"""The scene's ``[illumination] waveform`` name -> the module that builds its :class:`~analytic.waveforms.Waveform`."""

from __future__ import annotations

from . import butterworth, emg, gaussian, impulse, sampled, square
from .waveform import Waveform

__all__ = ["make_waveform", "BUILDERS"]

#: The scene's ``[illumination] waveform`` -> the module that builds it.
BUILDERS = {"impulse": impulse, "square": square, "butterworth": butterworth, "gaussian": gaussian, "emg": emg,
            "sampled": sampled}


def make_waveform(illumination, period: float) -> Waveform:
    """The waveform of an illumination, with defaults resolved against the period.

    Parameters
    ----------
    illumination : analytic.Illumination
        The scene's ``[illumination]`` table.
    period : float
        Sampling period T, metres; sets the defaults (square width T/5,
        Butterworth cutoff 1/(2T) cycles per metre, duration 3/cutoff,
        order 3). The Gaussian, EMG and sampled pulses have no default.

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
