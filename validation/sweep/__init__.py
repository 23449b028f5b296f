"""Parameter sweeps: many scenes, rendered (and optionally cross-checked) on a Dask cluster.

A sweep file names a base scene and a grid of scene keys to vary; every
combination of the grid's values is one *item*, a scene built by overriding
the base scene's TOML tables and validated by
:func:`analytic.scenes.scene_file.scene_from_dict`, exactly as a scene file would be.

Each item's render is split into fixed chunks of the sample range,
``[first, first + count)``. Sample i's random numbers depend only on
(seed, i) (:func:`transient.common.sample_stream`), so the chunks are independent,
deterministic tasks: any worker may compute any chunk, a chunk lost with its
worker is simply computed again, and the driver adds the chunks' float64
moments in chunk order. Each worker runs Dr.Jit with as many threads as the
Dask worker has (one, for the local cluster; run a remote cluster's workers
with ``--nthreads 1`` too): the order of a chunk's float64 atomic additions
then depends on nothing but the chunk, so the merged result for a given
seed and chunking is the same bit for bit on 1 or on 8 workers, and equal
to a sequential :func:`transient.render.render` with Dr.Jit on one thread.

Every item's folder holds the ``render`` layout (``transient.npy``/``.exr``,
``stderr.npy``, ``meta.json``), and with cross-checking ``model/`` (the
model's transient) and ``agreement.json``; ``sweep_state.npz`` keeps the
finished chunks' moments, so an interrupted sweep resumes where it stopped,
and ``item.json``, written last, marks the item finished. ``index.json`` and
``index.csv`` list every item. Every file is written atomically.

The package: :mod:`.config` reads and validates sweep files, :mod:`.tasks`
is what workers run, :mod:`.checkpoint` keeps each unfinished item's chunks,
:mod:`.index` writes ``index.json``/``.csv`` and finished items' files, and
:mod:`.driver` runs a sweep on a Dask cluster. Names are loaded on first use
(``lazy_loader``, as in every package of this project), so that reading a
sweep file does not import Dask.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "config": ["Sweep", "SweepItem", "load_sweep", "sweep_from_dict", "DEFAULT_SWEEP_CHUNK"],
    "tasks": ["render_chunk", "model_transient"],
    "driver": ["SweepResult", "run_sweep", "sweep_client", "check_variant", "require_dask"],
    "checkpoint": ["STATE_FILE", "ITEM_FILE"],
})
