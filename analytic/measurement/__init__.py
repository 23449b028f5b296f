"""What a sensor records of y: additive Gaussian or Poisson noise, and a photon-counting detector's histogram.

- :mod:`.noise`: :func:`add_noise` (the scene's ``[noise]``);
- :mod:`.detector`: the ``[detector]`` table, the expected counts and a draw of them (docs/design.md section 8).

Names are loaded on first use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "noise": ["add_noise"],
    "detector": ["Detector", "expected_counts", "draw_counts", "coates_estimate"],
})
