"""Speed, memory and accuracy of the analytic system matrix.

    python benchmarks/bench_model.py --out out/bench_model [--quick]

Measures (warm: Numba kernels compiled and cached before timing):
- the default scene's A (M = 50, K = 16) at tolerance 1e-6, and M = 256;
- memory: bytes of A against nnz, and the process's peak resident memory;
- build time against achieved accuracy over the tolerance setting, beside a
  brute-force supersampled grid (S x S point samples per pixel) — achieved
  error is max |A - A_ref| / (row max), A_ref the tolerance-1e-7 assembly
  (itself checked against an independent QUADPACK reference in the tests).
Prints markdown tables and writes ``results.json`` in --out.
"""

from __future__ import annotations

import argparse
import platform
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from analytic.io import save_json  # noqa: E402
from analytic.binning import bin_index  # noqa: E402
from analytic.scene import default_scene  # noqa: E402
from analytic.system import QuadratureWarning, system_matrix  # noqa: E402


def machine() -> str:
    model = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import os
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def timed(function, repeats=3):
    best = np.inf
    result = None
    for _ in range(repeats):
        started = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - started)
    return best, result


def matrix_bytes(matrix) -> int:
    return matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes


def supersampled(scene, factor: int):
    """Brute force: factor² point samples per pixel, binned with the shared binning (impulse)."""
    size, pixels = scene.size, scene.pixels
    delta = size / pixels
    count = scene.sampling.count
    offsets = (np.arange(factor) + 0.5) / factor
    cells = np.arange(pixels)
    x = ((cells[:, None] + offsets[None, :]) * delta).ravel()             # column-major within pixels
    y = (size - (cells[:, None] + offsets[None, :]) * delta).ravel()       # row r from the top
    xx, yy = np.meshgrid(x, y)
    pixel = (np.arange(pixels * factor) // factor)
    index = (pixel[:, None] * pixels + pixel[None, :]).ravel()
    weight_area = (delta / factor) ** 2
    blocks = []
    source = scene.source
    for k, sensor in enumerate(scene.sensors):
        ds = np.sqrt((xx - source[0]) ** 2 + (yy - source[1]) ** 2 + source[2] ** 2)
        dk = np.sqrt((xx - sensor[0]) ** 2 + (yy - sensor[1]) ** 2 + sensor[2] ** 2)
        a = source[2] * sensor[2] / (np.pi * ds**3 * dk**3) * weight_area
        n, inside = bin_index(ds + dk, scene.sampling.start_opl, scene.sampling.bin_width_opl, count)
        rows = (k * count + n[inside]).astype(np.int64).ravel()
        blocks.append(scipy.sparse.coo_array((a[inside].ravel(), (rows, index[inside.ravel()])),
                                             shape=(scene.sensor_count * count, pixels * pixels)))
    return sum(block.tocsr() for block in blocks)


def relative_error(matrix, reference) -> float:
    row_max = reference.max(axis=1).toarray().ravel()
    row_max[row_max == 0] = 1.0
    difference = abs(matrix - reference).max(axis=1).toarray().ravel()
    return float((difference / row_max).max())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench_model")
    parser.add_argument("--quick", action="store_true", help="skip M = 256")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine()}
    scene = default_scene(noise=None)
    system_matrix(scene.replace(pixels=4, reflectance=0.5))   # compile / load the cached kernels

    seconds, matrix = timed(lambda: system_matrix(scene))
    dense = scene.sensor_count * scene.sampling.count * scene.pixels**2 * 8
    results["default"] = {"M": 50, "K": 16, "seconds": seconds, "nnz": int(matrix.nnz),
                          "bytes": matrix_bytes(matrix), "dense_bytes": dense}
    print(f"machine: {results['machine']}\n")
    print("| scene | M | K | build (s) | nnz | A (MiB) | dense would be (MiB) |")
    print("|---|---|---|---|---|---|---|")
    print(f"| default | 50 | 16 | {seconds:.2f} | {matrix.nnz:,} | {matrix_bytes(matrix) / 2**20:.2f} | "
          f"{dense / 2**20:.0f} |")
    if not args.quick:
        big = default_scene(pixels=256, noise=None)
        seconds, matrix = timed(lambda: system_matrix(big), repeats=1)
        dense = big.sensor_count * big.sampling.count * big.pixels**2 * 8
        results["M256"] = {"M": 256, "K": 16, "seconds": seconds, "nnz": int(matrix.nnz),
                           "bytes": matrix_bytes(matrix), "dense_bytes": dense}
        print(f"| default | 256 | 16 | {seconds:.2f} | {matrix.nnz:,} | {matrix_bytes(matrix) / 2**20:.2f} | "
              f"{dense / 2**20:.0f} |")
        del matrix
    results["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory of this process: {results['peak_rss_mib']:.0f} MiB\n")

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadratureWarning)
        reference = system_matrix(scene, tolerance=1e-7)
    rows = []
    for tolerance in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6):
        seconds, matrix = timed(lambda: system_matrix(scene, tolerance=tolerance))
        rows.append({"method": "isochrone quadrature", "setting": f"tolerance {tolerance:g}",
                     "seconds": seconds, "error": relative_error(matrix, reference)})
    for factor in (2, 4, 8, 16, 32):
        seconds, matrix = timed(lambda: supersampled(scene, factor), repeats=1)
        rows.append({"method": "supersampled grid", "setting": f"{factor}x{factor} per pixel",
                     "seconds": seconds, "error": relative_error(matrix, reference)})
    results["accuracy"] = rows
    print("| method | setting | build (s) | max error / row max |")
    print("|---|---|---|---|")
    for row in rows:
        print(f"| {row['method']} | {row['setting']} | {row['seconds']:.3f} | {row['error']:.1e} |")
    save_json(out / "results.json", results)


if __name__ == "__main__":
    main()
