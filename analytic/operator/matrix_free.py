"""y = A f for any capture, holding A only where it fits: the route :func:`forward` takes and what it costs.

Three routes, chosen before any work (:func:`forward_route`):

- ``offsets``: the capture's pairs are translates of a few by whole pixels
  (:mod:`analytic.operator.offsets`): the distinct offsets' entries are assembled once and y is summed
  from them, never A (memory: y and the offsets' runs);
- ``matrix``: A is assembled (:func:`analytic.operator.system.system_matrix`) and applied, when its
  estimated assembly fits in the memory limit;
- ``blocks``: A would not fit: y is computed a block of pairs at a time, each block's rows of A
  assembled, applied and dropped (pairs are independent, so the rows are exactly A's; memory: y and
  one block of at most a quarter of the limit), with a progress bar over the pairs.

Each block is a fraction of a second of compiled work, so Ctrl-C stops any route within about a second.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from ..errors import OptionError
from ..resources import available_memory
from ..scenes.scene_file import scene_of
from ..waveforms import make_waveform
from .cost import ModelCost, model_cost, may_be_impractical, refuse_impractical_illumination
from .general_routes import progress_bar
from .offsets import offset_forward, offset_plan, virtual_entries

__all__ = ["forward", "forward_route", "ROUTES", "BLOCK_SHARE"]

ROUTES = ("offsets", "matrix", "blocks")
#: The share of the memory limit one block of pairs' rows of A may take on the ``blocks`` route.
BLOCK_SHARE = 0.25


def _limit(memory_limit: int | None) -> int:
    return available_memory() // 2 if memory_limit is None else int(memory_limit)


def forward_route(scene, *, memory_limit: int | None = None, cost: ModelCost | None = None) -> tuple[str, ModelCost]:
    """The route :func:`forward` takes for ``scene`` and its estimated cost (time, peak memory).

    Parameters
    ----------
    scene : Scene or RelayWallScene
    memory_limit : int, optional
        Bytes the model may use; default half the memory available now.
    cost : ModelCost, optional
        :func:`analytic.operator.cost.model_cost` of the scene (A's assembly), if already computed.

    Returns
    -------
    (str, ModelCost)
        One of :data:`ROUTES`, and the estimate of that route: the offsets' share of the work and the
        product, or A's assembly, or the assembly a block at a time with y and one block in memory.
    """
    cost = model_cost(scene, memory_limit=memory_limit) if cost is None else cost
    y_bytes = 8.0 * scene.sensor_count * scene.sampling.count
    if cost.offset_share is not None:
        return "offsets", dataclasses.replace(cost, memory=y_bytes + cost.virtual_memory)
    limit = _limit(memory_limit)
    if cost.memory <= limit:
        return "matrix", cost
    return "blocks", dataclasses.replace(cost, memory=y_bytes + min(cost.memory, BLOCK_SHARE * limit))


def forward(scene, matrix=None, *, progress: bool = False, memory_limit: int | None = None,
            statistics: dict | None = None) -> np.ndarray:
    """The model's noiseless samples y_k[n] = (A f)[k N + n], by the route :func:`forward_route` names.

    Parameters
    ----------
    scene : Scene, RelayWallScene, str or Path
        The scene (its reflectance image is f), or its file (TOML, or a tal YAML configuration).
    matrix : sparse matrix, optional
        A, if already assembled for this scene (``(K N, M^2)``): y = A f, nothing else.
    progress : bool
        Progress bars on stderr.
    memory_limit : int, optional
        Bytes the model may use; default half the memory available now.
    statistics : dict, optional
        Filled with ``route`` (one of :data:`ROUTES`, or ``"given"``) and ``nonzeros`` (A's entries,
        counted whether or not A was held).

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64, the units of A times the reflectance.
    """
    from .system import QuadratureWarning, _assemble, _problem, check_tolerance, system_matrix

    scene = scene_of(scene)
    f = np.asarray(scene.reflectance, dtype=np.float64).ravel()
    statistics = {} if statistics is None else statistics
    if matrix is not None:
        shape = (scene.sensor_count * scene.sampling.count, f.size)
        if getattr(matrix, "shape", None) != shape:
            raise OptionError(f"matrix: shape {getattr(matrix, 'shape', type(matrix).__name__)} is not this scene's "
                              f"A, {shape} (sensors x bins, pixels); give the matrix system_matrix made for it, or none")
        statistics.update(route="given", nonzeros=int(matrix.nnz if hasattr(matrix, "nnz") else np.count_nonzero(matrix)))
        return np.asarray(matrix @ f, dtype=np.float64).reshape(scene.sensor_count, scene.sampling.count)
    tolerance = check_tolerance(scene.tolerance)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    if may_be_impractical(waveform, scene.sampling):
        refuse_impractical_illumination(scene)
    rectangle, pairs = scene.geometry()
    problem = _problem(rectangle, pairs, scene.sampling, waveform)
    limit = _limit(memory_limit)
    plan = offset_plan(problem)
    if plan is not None:
        runs = virtual_entries(plan, lambda virtual: _assemble(virtual, tolerance, limit, progress, None))
        bar = progress_bar(progress, len(pairs), "y = A f by pixel offsets", "pair")
        try:
            y, nonzeros = offset_forward(plan, runs, f, bar=bar)
        finally:
            if bar is not None:
                bar.close()
        statistics.update(route="offsets", nonzeros=nonzeros)
        return y
    route = "matrix"
    if memory_limit is not None or len(pairs) * scene.pixels ** 2 > 2**20:     # below, A is small
        route, cost = forward_route(scene, memory_limit=memory_limit)
    if route == "matrix":
        matrix = system_matrix(scene, memory_limit=memory_limit, progress=progress)
        statistics.update(route="matrix", nonzeros=int(matrix.nnz))
        return np.asarray(matrix @ f, dtype=np.float64).reshape(scene.sensor_count, scene.sampling.count)
    y, nonzeros, size, failures = _blocks(problem, f, tolerance, BLOCK_SHARE * limit, cost, progress)
    if sum(failures):
        warnings.warn(f"{sum(failures)} quadrature pieces stopped refining before reaching tolerance "
                      f"{tolerance:g}", QuadratureWarning, stacklevel=2)
    statistics.update(route="blocks", nonzeros=nonzeros, block_pairs=size)
    return y


def _blocks(problem, f: np.ndarray, tolerance: float, limit: float, cost: ModelCost, progress: bool):
    """(y, A's non-zeros, the last block's pairs, the pieces that stopped refining) a block of pairs at a time,
    each block's rows of A within ``limit`` bytes: sized from the estimate, halved while its exact count of
    entries (made before anything of that size is allocated) does not fit."""
    from ..errors import ResourceError
    from .system import _assemble

    count, bins = len(problem.pairs), problem.axis.count
    size = max(1, min(count, int(count * limit / max(cost.memory, 1.0))))
    y = np.empty((count, bins))
    failures, nonzeros, start = [], 0, 0
    bar = progress_bar(progress, count, "y = A f a block of pairs at a time", "pair")
    try:
        while start < count:
            stop = min(start + size, count)
            block = problem._replace(pairs=problem.pairs[start:stop], scales=problem.scales[start:stop])
            try:
                rows = _assemble(block, tolerance, int(limit), False, None, failures)
            except ResourceError:
                if size == 1:
                    raise
                size = max(1, size // 2)
                continue
            y[start:stop] = (rows @ f).reshape(stop - start, bins)
            nonzeros += int(rows.nnz)
            del rows
            if bar is not None:
                bar.update(stop - start)
            start = stop
    finally:
        if bar is not None:
            bar.close()
    return y, nonzeros, size, failures
