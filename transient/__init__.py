"""Mitsuba 3 transient renderer of the diffuse-imaging scene.

``backend`` picks the Mitsuba variant and a libLLVM Dr.Jit survives, and
registers the plugins: ``sensor`` (``omni_point``), ``plane``
(``transient_opl``, the single-plane estimator) and ``path``
(``transient_opl_path``, diffuse scenes with several bounces), which share
``common`` (S(u), the attenuation, sample streams, jittered points, the
deposit) and ``spherical_rectangle`` (solid-angle sampling);
``mitsuba_scene`` builds every Mitsuba scene dictionary; ``chunks`` cuts a
render into replicas and chunks and folds their sums; ``render`` runs the
chunked, checkpointed Monte Carlo render.

Importing this package does not import Mitsuba or Dr.Jit: that happens in
:func:`select_variant`, after the libLLVM has been chosen.
"""

import importlib

# public name -> submodule that defines it (loaded on first use, so that
# importing one module of this package does not import the others)
_EXPORTS = {"BackendError": "backend", "select_variant": "backend", "ReplicaLayout": "chunks",
            "ChunkPlan": "chunks", "ReplicaAccumulator": "chunks", "RenderResult": "render",
            "RenderStateError": "render", "render": "render", "render_loaded": "render", "resume": "render",
            "read_saved_render": "render", "SavedRender": "render", "RenderInterrupted": "render",
            "export_scene": "export", "emitter_intensity": "intensity"}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'transient' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
