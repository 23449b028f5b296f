"""``calibrate``: a scene's free parameters and an overall scale fitted to a capture (docs/design.md section 9).

- :mod:`.fit`: Levenberg–Marquardt on the exact Jacobian, the directions the data do not fix;
- :mod:`.verdict`: :func:`calibrate` (data read as ``check`` reads them) and its :class:`Calibration`;
- :mod:`.files`: calibration.json, the fitted scene.toml, report.md and the residual figure.

Names are loaded on first use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "verdict": ["Calibration", "calibrate", "stated_start_opl", "UNDETERMINED"],
    "fit": ["levenberg_marquardt", "FitProblem", "FitOutcome", "Degenerate", "DEGENERATE_RATIO"],
    "files": ["write_calibration", "scene_toml"],
})
