"""The runs and their reports: the cross-check of a scene and of the suite, the corner, the paper, the benchmarks.

- :mod:`.harness`: one scene's model, render, verdict and reconstructions (:func:`check_scene`);
- :mod:`.suite`: the built-in hard cases that ``validate`` runs;
- :mod:`.corner`: a scene outside the one-bounce model, two rectangles meeting at a corner;
- :mod:`.paper`: the paper's figures and claims (``reproduce``);
- :mod:`.bench`: speed against error, ours and mitransient's;
- :mod:`.report`: ``report.md``, ``metrics.json`` and the figures of ``validate`` and ``run``.

Names are loaded on first use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "harness": ["SceneCheck", "check_scene", "data_driven_rule", "reconstruct_from_noisy_data"],
    "suite": ["hard_cases", "validation_suite"],
    "corner": ["check_corner"],
    "report": ["write_report"],
    "paper": ["reproduce"],
    "bench": ["speed_against_error"],
})
