"""Mitsuba 3 transient renderer of the diffuse-imaging scene.

``backend`` picks the Mitsuba variant and a libLLVM Dr.Jit survives, and
registers the plugins: ``sensor`` (``omni_point``), ``plane``
(``transient_opl``, the single-plane estimator, with ``plane_sampling``: its
sampling techniques and their mixture density) and ``path``
(``transient_opl_path``, diffuse scenes with several bounces) and ``nlos``
(``transient_opl_nlos``, the third bounce through a relay wall), which share
``common`` (S(u), the attenuation, sample streams, jittered points, the
deposit) and ``spherical_rectangle`` (solid-angle sampling);
``mitsuba_scene`` builds every Mitsuba scene dictionary; ``chunks`` cuts a
render into replicas and chunks and folds their sums; ``render`` runs the
chunked, checkpointed Monte Carlo render and ``render_state`` keeps and
checks its saved state.

Importing this package does not import Mitsuba or Dr.Jit: that happens in
:func:`select_variant`, after the libLLVM has been chosen.
"""

import lazy_loader

# Loaded on first use (lazy_loader, as in every package of this project), so that importing one
# module of this package does not import the others.
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "backend": ["BackendError", "select_variant"],
    "chunks": ["ReplicaLayout", "ChunkPlan", "ReplicaAccumulator"],
    "render": ["RenderResult", "render", "render_loaded", "resume", "RenderInterrupted"],
    "render_state": ["RenderStateError", "read_saved_render", "SavedRender"],
    "intensity": ["emitter_intensity"],
})
