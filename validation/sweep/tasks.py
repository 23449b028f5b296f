"""What a Dask worker runs: one chunk of an item's render, or an item's model.

Each worker process keeps a few loaded Mitsuba scenes (:class:`WorkerCache`);
nothing of the driver's Mitsuba state travels with a task.
"""

from __future__ import annotations

import time
from collections import OrderedDict

import numpy as np

from analytic.scenes.common import Scene

__all__ = ["render_chunk", "model_transient", "WorkerCache"]


class WorkerCache:
    """A worker process's loaded scenes, keyed by (fingerprint, variant), and its thread setting.

    Loading compiles nothing but builds the scene; keeping a few means
    interleaved items do not reload, but not all of a long sweep's.
    """

    limit = 4

    def __init__(self):
        self.loaded: OrderedDict = OrderedDict()
        self.threads_set = False

    def get(self, scene: Scene, fingerprint: str, variant: str | None):
        """(active variant, Mitsuba scene, integrator) for a scene, loading it if needed."""
        from transient.backend import select_variant

        active = select_variant(variant)
        if not self.threads_set:
            import drjit as dr

            # Dr.Jit's thread count fixes the order of a chunk's float64 atomic
            # additions; tying it to the Dask worker's thread count makes a
            # chunk's sums a function of the chunk alone, and one worker per
            # core with one thread each keeps the machine busy without
            # oversubscription.
            try:
                from distributed import get_worker
                threads = get_worker().state.nthreads
            except (ImportError, ValueError, AttributeError):
                threads = None
            if threads:
                dr.set_thread_count(int(threads))
            self.threads_set = True
        key = (fingerprint, active)
        if key in self.loaded:
            self.loaded.move_to_end(key)
            return self.loaded[key]
        from transient.mitsuba_scene import load_scene

        loaded = load_scene(scene)
        entry = (active, loaded, loaded.integrator())
        self.loaded[key] = entry
        while len(self.loaded) > self.limit:
            self.loaded.popitem(last=False)
        return entry


#: This process's cache (one per worker process).
_CACHE = WorkerCache()


def render_chunk(scene: Scene, fingerprint: str, seed: int, layout, chunk,
                 variant: str | None = None) -> tuple[np.ndarray, float, str]:
    """Render one chunk of an item's samples (a Dask task).

    Parameters
    ----------
    scene : Scene
        The item's scene.
    fingerprint : str
        :func:`transient.render_state.scene_fingerprint` of ``scene``: the key of
        the worker's cache of loaded Mitsuba scenes.
    seed : int
        Render seed; sample g depends on (seed, g) only.
    layout : transient.chunks.ReplicaLayout
        The render's replicas.
    chunk : transient.chunks.Chunk
        The global samples [first, first + count) to draw.
    variant : str, optional
        Mitsuba variant (default: the worker's CPU default).

    Returns
    -------
    sums : numpy.ndarray
        ``(replicas the chunk touches, K, N)`` float64 Σc per replica (units of y).
    seconds : float
        Wall time of the render call on the worker, seconds.
    variant : str
        The Mitsuba variant used.
    """
    active, loaded, integrator = _CACHE.get(scene, fingerprint, variant)
    started = time.perf_counter()
    sums = integrator.render_chunk(loaded, seed=int(seed), layout=layout, first=int(chunk.first),
                                   count=int(chunk.count))
    return np.asarray(sums, dtype=np.float64), time.perf_counter() - started, active


def model_transient(scene: Scene) -> tuple[np.ndarray, float]:
    """The exact model's noiseless y of a scene (a Dask task); returns (y, seconds)."""
    from analytic.operator.matrix_free import forward

    started = time.perf_counter()
    y = forward(scene)
    return np.asarray(y, dtype=np.float64), time.perf_counter() - started


def _identity(value):
    return value


