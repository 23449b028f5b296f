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

from .backend import BackendError, select_variant
from .chunks import ChunkPlan, ReplicaAccumulator, ReplicaLayout
from .render import RenderResult, RenderStateError, render, render_loaded

__all__ = ["BackendError", "select_variant", "RenderResult", "RenderStateError", "render", "render_loaded",
           "ReplicaLayout", "ChunkPlan", "ReplicaAccumulator"]
