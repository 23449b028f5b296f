"""Mitsuba 3 transient renderer of the diffuse-imaging scene.

``backend`` picks the Mitsuba variant and a libLLVM Dr.Jit survives;
``sensor`` (the ``omni_point`` plugin) and ``integrator`` (the
``transient_opl`` plugin) are Mitsuba plugins; ``mitsuba_scene`` turns an
``analytic.scene.Scene`` into a Mitsuba scene; ``render`` runs the chunked,
checkpointed Monte Carlo render.

Importing this package does not import Mitsuba or Dr.Jit: that happens in
:func:`select_variant`, after the libLLVM has been chosen.
"""

from .backend import BackendError, select_variant
from .render import RenderResult, render

__all__ = ["BackendError", "select_variant", "RenderResult", "render"]
