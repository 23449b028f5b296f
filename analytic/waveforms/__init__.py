"""Illumination waveforms s(t) and the sampling kernels κ_n they induce.

A waveform has support [lead, duration] with lead <= 0 <= duration (a
causal pulse has lead 0; a Gaussian centred at 0 starts before it). Its cumulative S(u) = ∫_{-∞}^u s(t) dt is known in closed form,
piece by piece (:mod:`analytic.waveforms.pieces`), so the box-prefiltered
sample of light that left the plane at path length τ is

    κ_n(τ) = ∫_{t_n}^{t_{n+1}} s(t - τ) dt = S(t_{n+1} - τ) - S(t_n - τ),

exactly, with t_n = start + n T. Between the waveform's breakpoints (the
pieces' kinks) shifted to the bin edges, every κ_n is smooth in τ; the
quadrature of the system matrix splits its integrals there.

One module per waveform (:mod:`.impulse`, :mod:`.square`,
:mod:`.butterworth`, :mod:`.gaussian`, :mod:`.emg`, :mod:`.sech2`, :mod:`.sampled`),
each declaring ``NAME``, ``SUMMARY``, ``PARAMETERS`` (its scene keys as
:class:`~.waveform.Parameter`: kind, unit, default, plugin property) and
``build(illumination, period) -> Waveform``; the registry
(:mod:`analytic.waveforms.builders`) maps the scene's ``waveform`` name to it,
and the scene's schema, the XML export, the plugins' properties and their docs
derive from it. A new waveform is one such module and its tests.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "builders": ["make_waveform", "register", "WAVEFORMS", "BUILDERS"],
    "waveform": ["Waveform", "Parameter"],
    "pieces": ["WaveformTerms", "make_terms", "cumulative_array", "derivative_array", "kernel_array",
               "POLYNOMIAL", "EXPONENTIALS", "ERRORFUNCTIONS", "SIGMOIDS"],
    "measured": ["read_samples", "check_samples", "MAX_SAMPLES", "METRES_PER_PICOSECOND"],
    "emg": ["TAIL_RATIO_RANGE"],
    "butterworth": ["MAX_ORDER", "CUTOFF_RANGE", "CUTOFF_PERIOD_RANGE", "MIN_CUTOFF_DURATION"],
})
