"""Estimated against measured time and peak memory of assembling A for large relay-wall scans.

    python benchmarks/bench_assembly_memory.py [confocal] [exhaustive]

The geometry of examples/nlos.toml (a 1 m hidden square 1 m in front of a
2 m wall, laser and sensor at (-0.5, 0, 0.25), 240 bins of 1 cm from
1.99 m) with a uniform hidden square of reflectance 0.5:

- ``confocal``: a 64 x 64 confocal scan of 16 x 16 pixels (4,096 pairs);
- ``exhaustive``: a 16 x 16 laser grid x 16 x 16 read grid of 2 x 2 pixels
  (65,536 pairs).

For each, :func:`analytic.operator.cost.model_cost` (the estimate every
command checks and states before a long model), then
:func:`analytic.system_matrix` under tracemalloc (which sees every NumPy
array; the kernels' own scratch is not in it): wall seconds, tracemalloc's
peak, A's bytes and the process's peak resident memory. Prints one line per
scan (docs/benchmarks.md, "Big scans").
"""

from __future__ import annotations

import resource
import sys
import time
import tracemalloc
from pathlib import Path

from analytic.operator.cost import model_cost
from analytic.operator.system import system_matrix
from analytic.scenes.relay_wall import Scan
from analytic.scenes.scene_file import load_scene

_SCANS = {"confocal": (16, Scan(type="confocal", grid=(64, 64))),
          "exhaustive": (2, Scan(type="exhaustive", grid=(16, 16)))}


def measure(name: str) -> str:
    """One scan's line: estimated and measured time and memory."""
    pixels, scan = _SCANS[name]
    example = Path(__file__).resolve().parents[1] / "examples" / "nlos.toml"
    scene = load_scene(example).replace(pixels=pixels, reflectance=0.5, scan=scan, noise=None)
    cost = model_cost(scene)
    tracemalloc.start()
    started = time.perf_counter()
    matrix = system_matrix(scene)
    seconds = time.perf_counter() - started
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    size = matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return (f"{name}: {scene.sensor_count:,} pairs, {matrix.nnz:,} entries | estimated {cost.seconds:.1f} s, "
            f"{cost.memory / 2**30:.3f} GiB | measured {seconds:.1f} s, peak {peak / 2**30:.3f} GiB, "
            f"A {size / 2**30:.3f} GiB (peak / A {peak / size:.2f}), max RSS {rss / 2**30:.3f} GiB")


if __name__ == "__main__":
    for scan_name in sys.argv[1:] or list(_SCANS):
        print(measure(scan_name), flush=True)
