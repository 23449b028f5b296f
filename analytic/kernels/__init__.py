"""The model's compiled kernels (Numba): closed, so that editing plain Python never recompiles them.

Every module here imports only the others, NumPy, Numba and ``math``, and
takes records (NamedTuples Numba passes by value) rather than long
argument lists. :mod:`.cache` keys their on-disk cache by these sources
alone and says when a compile is slow. Importing this package imports
no module until it is used (``lazy_loader``, as every package of this
project): :mod:`.formulas` is imported by the renderer without Numba. The
Python side (:mod:`analytic.operator.system`, :mod:`analytic.operator.window`,
:mod:`analytic.operator.response`) imports the modules it drives.

- :mod:`.formulas`: formulas written once for NumPy, Numba and Dr.Jit (the
  attenuation, erfcx's ranges), with no import of their own;
- :mod:`.pieces`, :mod:`.special`: a waveform's S(u) piece by piece, erfcx;
- :mod:`.attenuation`, :mod:`.isochrone`, :mod:`.conics`: a_k, the
  isochrones (ellipses) of a pair in a rectangle's frame, their conics;
- :mod:`.bins`: bins and their time kernels κ_n;
- :mod:`.quadrature`: the adaptive Gauss ladders, their rules and integrands;
- :mod:`.arcs`: an isochrone's arcs in a pixel and their integrals, the (τ, φ) tensor rule;
- :mod:`.taylor`, :mod:`.moments`: kernels as Taylor polynomials, a pixel's moments;
- :mod:`.strips`: a cut pixel as slabs between isochrones;
- :mod:`.cuts`: for the impulse, those slabs from the parts below each isochrone;
- :mod:`.routes`: one (pair, pixel)'s entries of A by each quadrature route;
- :mod:`.assembly`: A's entries counted and filled, block by block, straight into CSR;
- :mod:`.offsets`: a translation-invariant capture's A, or y = A f, from one run per pixel offset;
- :mod:`.sensitivity`: the cell integrals of exact derivatives (amplitudes and their coarea at bin edges);
- :mod:`.sensitivity_waveform`: the same derivatives under any other waveform (cells cut at its kinks' isochrones).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submodules=[
    "cache", "formulas", "pieces", "special", "attenuation", "isochrone", "conics", "bins", "quadrature", "arcs", "taylor",
    "moments", "strips", "cuts", "routes", "assembly", "offsets", "sensitivity",
    "sensitivity_waveform"])
