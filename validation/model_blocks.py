"""The exact system matrix over Dask workers, one task per block of pairs.

Each pair (a sensor, or an NLOS laser-sensor pair) owns its N rows of A and
nothing else, and its entries are computed by the same compiled code
whatever else is computed beside it, so A assembled from blocks of pairs on
any number of workers is A, bit for bit. For grids beyond one machine:
an exhaustive 16^4 NLOS scan is 65,536 pairs.

    from validation.sweep.driver import sweep_client
    with sweep_client(workers=4) as client:
        A = system_matrix_on_dask(scene, client, pairs_per_task=64)
"""

from __future__ import annotations

import scipy.sparse

from analytic.geometry import PointPairs, Rectangle
from analytic.scenes.common import Sampling
from analytic.waveforms import Waveform, make_waveform

__all__ = ["system_matrix_on_dask", "pair_block_matrix"]


def pair_block_matrix(rectangle: Rectangle, pairs: PointPairs, start: int, stop: int, sampling: Sampling,
                      waveform: Waveform, tolerance: float) -> scipy.sparse.csr_array:
    """Rows of pairs start ... stop - 1 of A: one task's work.

    Returns
    -------
    scipy.sparse.csr_array
        ``((stop - start) N, M²)``, the same rows as the whole matrix's.
    """
    from analytic.operator.system import rectangle_matrix

    return rectangle_matrix(rectangle, pairs.block(start, stop), sampling, waveform, tolerance=tolerance)


def system_matrix_on_dask(scene, client, *, pairs_per_task: int = 16,
                          tolerance: float | None = None) -> scipy.sparse.csr_array:
    """A of any scene with a geometry (plane or relay wall), its pairs dealt to Dask workers in blocks.

    Parameters
    ----------
    scene : analytic.scenes.common.Scene or analytic.scenes.relay_wall.RelayWallScene
        Anything with ``geometry()``, ``sampling``, ``illumination`` and ``tolerance``.
    client : distributed.Client
        The cluster (:func:`validation.sweep.driver.sweep_client` makes a local one).
    pairs_per_task : int
        Pairs in one task; each task assembles its block on its worker's threads.
    tolerance : float, optional
        Relative accuracy of every entry (default the scene's).

    Returns
    -------
    scipy.sparse.csr_array
        ``(P N, M²)``, equal to :func:`analytic.operator.system.system_matrix` of the scene.
    """
    if pairs_per_task < 1:
        raise ValueError(f"pairs_per_task must be at least 1, got {pairs_per_task}")
    rectangle, pairs = scene.geometry()
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    tolerance = scene.tolerance if tolerance is None else tolerance
    starts = range(0, len(pairs), pairs_per_task)
    futures = [client.submit(pair_block_matrix, rectangle, pairs, start, min(start + pairs_per_task, len(pairs)),
                             scene.sampling, waveform, tolerance, pure=False) for start in starts]
    blocks = client.gather(futures)
    return scipy.sparse.vstack(blocks, format="csr")
