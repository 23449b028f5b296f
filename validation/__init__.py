"""The cross-check of renderers against the exact model, and the application around it.

A user writes, for example::

    import analytic, transient, validation
    result = transient.render(scene, spp=2**22, seed=1)
    agreement = validation.compare_transients(result.mean, result.stderr, analytic.forward(scene))
    validation.assert_transients_agree(result.mean, result.stderr, analytic.forward(scene))

Names are loaded on first use (the command line starts fast); ``__all__``
lists the public API. The command line is :mod:`validation.cli`.
"""

from __future__ import annotations

import importlib

# public name -> submodule that defines it
_EXPORTS = {
    "Agreement": "compare", "compare_transients": "compare", "assert_transients_agree": "compare",
    "SceneCheck": "harness", "check_scene": "harness", "data_driven_rule": "harness",
    "reconstruct_from_noisy_data": "harness",
    "hard_cases": "suite", "validation_suite": "suite",
    "check_corner": "corner",
    "write_report": "report",
    "reproduce": "paper",
    "load_sweep": "sweep", "run_sweep": "sweep",
    "speed_against_error": "bench",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'validation' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
