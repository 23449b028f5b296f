"""The operator: the system matrix A of a scene, what it costs, the window it sees, and its conditioning.

- :mod:`.system`: A assembled (sparse, exact to the scene's tolerance), y = A f;
- :mod:`.blocks`: the compiled kernels run block by block on a pool of threads;
- :mod:`.cost`: what assembling A will cost, and the refusal of an impractical illumination;
- :mod:`.window`: which path lengths reach the sensors, and the share of the light a window holds;
- :mod:`.response`: continuous impulse responses g_k(t) from the contour (coarea) form;
- :mod:`.conditioning`: A's singular values against the array's extent and the period;
- :mod:`.derivatives`: derivatives of y with respect to the scene's parameters (exact or by differences);
- :mod:`.sensitivity`, :mod:`.waveform_sensitivity`: the exact route's interior and bin-edge terms for a
  plane scene (the impulse; every other waveform); :mod:`.relay_wall_legs`: a relay wall's end legs;
  :mod:`.relay_wall_sensitivity`: a relay wall's other geometric keys, in the rectangle's frame;
- :mod:`.offsets`, :mod:`.offset_operator`: captures whose pairs are translates by whole pixels, each
  distinct offset computed once; A applied by FFT over them without A (for reconstructions at size);
- :mod:`.parameters`: the scene's numbers named by scene-file keys (docs/design.md section 9).

The compiled kernels these drive are :mod:`analytic.kernels`. Names are
loaded on first use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "system": ["system_matrix", "rectangle_matrix", "count_entries", "pair_entries", "QuadratureWarning"],
    "matrix_free": ["forward", "forward_route"],
    "offset_operator": ["OffsetOperator", "capture_operator"],
    "response": ["impulse_response", "binned_contour_model"],
    "window": ["response_range", "covering_sampling", "window_share", "WindowWarning"],
    "conditioning": ["singular_values", "conditioning_summary"],
    "derivatives": ["jacobian", "derivative"],
    "sensitivity": ["EdgeOnArrivalWarning"],
    "parameters": ["Parameter", "parameter", "parameters", "value_of", "with_values", "parameter_keys"],
})
