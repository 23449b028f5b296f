"""The source's intensity across Mitsuba's float32 boundary (no Mitsuba import: the exporter uses it too)."""

from __future__ import annotations

import numpy as np

__all__ = ["emitter_intensity"]


def emitter_intensity(intensity: float) -> float:
    """The point emitter's intensity for a float64 source intensity: the nearest normal float32.

    Mitsuba keeps an emitter's intensity in float32, which flushes
    I < 1.2e-38 W/sr to zero (or a subnormal). The emitter then holds this
    stand-in, and the integrator's ``source_intensity`` (float64) is the
    intensity rendered; :class:`transient.plane.TransientPlaneIntegrator` checks the emitter
    against this function.

    Parameters
    ----------
    intensity : float
        I, W/sr, > 0.

    Returns
    -------
    float
        float32(I) clamped to the normal float32 range [1.18e-38, 3.4e38].
    """
    limits = np.finfo(np.float32)
    return float(np.float32(min(max(float(intensity), float(limits.tiny)), float(limits.max))))
