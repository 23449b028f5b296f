"""A measured instrument response: the piecewise-linear interpolation of samples, unit peak.

docs/design.md section 8: samples x_0 ... x_{n-1} at t_i = start + i w
(``sample_width`` w in metres of path, or ``sample_width_ps`` in
picoseconds), s(t) their linear interpolation divided by the largest, 0
outside [t_0, t_{n-1}]. S is then a quadratic on each (t_i, t_{i+1}], a
``POLYNOMIAL`` piece of degree 2 with origin t_i:

    S(u) = K_i + s_i x + (s_{i+1} - s_i) x² / (2 w_i),   x = u - t_i,

K_i = Σ_{j<i} (s_j + s_{j+1}) w_j / 2 summed with compensation (so a
kernel across pieces keeps ~ε of the area for any count), and every
sample is a kink, where the model cuts its integrals; a kernel within one
piece cancels K_i exactly. The model's moments route takes three Taylor
terms, exactly. Runs of zeros at either end are dropped (s is the same).
"""

from __future__ import annotations

import numpy as np

from .measured import sample_width_metres
from .pieces import POLYNOMIAL, make_terms
from .waveform import Parameter, Waveform

__all__ = ["build", "plugin_entries", "NAME", "SUMMARY", "PARAMETERS"]

NAME = "sampled"
SUMMARY = "piecewise-linear interpolation of measured ``samples``"
#: Scene keys of ``[illumination]`` this waveform takes (:mod:`analytic.waveforms.builders`; ``file`` is
#: read into ``samples``).
PARAMETERS = (Parameter("samples", "samples", "", "required, or file", plugin="samples"),
              Parameter("file", "file", "", "none (or samples)"),
              Parameter("sample_width", "length", "m", "required, or sample_width_ps", plugin="sample_width"),
              Parameter("sample_width_ps", "positive", "ps", "none (or sample_width)"),
              Parameter("start", "coordinate", "m", "0", plugin="sample_start"))


def plugin_entries(illumination, period: float) -> dict:
    """``samples`` as text, ``sample_width`` in metres (from either key) and ``sample_start``."""
    del period
    # repr: the plugin reads back the very floats, so its pieces are the model's
    return {"samples": ",".join(repr(float(value)) for value in illumination.samples),
            "sample_width": sample_width_metres(illumination.sample_width, illumination.sample_width_ps),
            "sample_start": 0.0 if illumination.start is None else float(illumination.start)}


def build(illumination, period: float) -> Waveform:
    """The sampled response of the scene's ``samples`` (read from ``file`` by the scene file).

    Parameters
    ----------
    illumination : analytic.Illumination
        ``samples`` (checked: finite, >= 0, some > 0), ``sample_width`` or
        ``sample_width_ps``, ``start`` (metres, default 0).
    period : float
        Sampling period, metres (not needed).
    """
    del period
    raw = np.asarray(illumination.samples, dtype=np.float64)
    width = sample_width_metres(illumination.sample_width, illumination.sample_width_ps)
    start = 0.0 if illumination.start is None else float(illumination.start)
    values = raw / raw.max()
    nonzero = np.flatnonzero(values)
    first, last = max(nonzero[0] - 1, 0), min(nonzero[-1] + 1, values.size - 1)
    times = start + width * np.arange(values.size, dtype=np.float64)
    times, values = times[first:last + 1], values[first:last + 1]
    steps = np.diff(times)
    constant, compensation = 0.0, 0.0
    pieces = []
    for i in range(values.size - 1):
        pieces.append((times[i], True, constant, POLYNOMIAL, times[i],
                       [0.0, values[i], 0.5 * (values[i + 1] - values[i]) / steps[i]]))
        # K_{i+1} = K_i + (s_i + s_{i+1}) w_i / 2, Kahan-compensated
        area = 0.5 * (values[i] + values[i + 1]) * steps[i] - compensation
        total = constant + area
        compensation = (total - constant) - area
        constant = total
    pieces.append((times[-1], True, constant, POLYNOMIAL, 0.0, []))
    peak_time = float(times[int(np.argmax(values))])
    parameters = {"samples": tuple(float(v) for v in raw), "start": start}
    if illumination.sample_width is not None:
        parameters["sample_width"] = float(illumination.sample_width)
    else:
        parameters["sample_width_ps"] = float(illumination.sample_width_ps)
    source = f" from {illumination.file}" if illumination.file is not None else ""
    description = (f"sampled instrument response{source}: {raw.size} samples every {width:.6g} m from "
                   f"{start:.6g} m, linear between them, unit peak at {peak_time:.6g} m")
    return Waveform("sampled", make_terms(pieces, duration=max(float(times[-1]), 0.0),
                                          lead=min(float(times[0]), 0.0)),
                    description, peak_time, parameters)
