"""Speed and memory of the exact third-bounce model of a capture through a relay wall (docs/design.md section 7).

    python benchmarks/bench_nlos.py --out out/bench_nlos [--quick]

Two captures of a 1 m x 1 m hidden plane of 64 x 64 pixels, 1 m in front of
a 2 m x 2 m relay wall (tal's default wall; laser and sensor at
(-0.5, 0, 0.25)), 512 bins of 1 cm of path from 1.9 m (they hold every
path of both scans: the light spans 2.0 to 4.6 m), impulse illumination,
tolerance 1e-6:

- a 16 x 16 single scan (one lit point, the wall's centre; 256 pairs);
- a 32 x 32 confocal scan (1,024 pairs, l = s).

Each runs in a fresh process after a small warm-up call (the kernels are
compiled or loaded first; interpreter start-up is not the model): A's
build (:func:`analytic.system_matrix`) and the forward product y = A f of
the built-in pattern, wall and CPU seconds, A's non-zeros and bytes, and
the peak resident memory above the process's size before the build. As a
baseline in the same run, the plane scene with the same counts (a 16 x 16
or 32 x 32 sensor array 1 m above a 1 m plane of 64 x 64 pixels, 512 bins
of 1 cm that hold its light): the ratio says what the relay wall's two
cosines and its pairs cost against the letter's scene. ``--quick`` builds
32 x 32-pixel planes instead.

Prints markdown tables and writes ``results.json`` in --out. The machine
is named; timings on a shared machine are provisional.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from analytic.files import save_json  # noqa: E402
from bench_model import load, machine, table  # noqa: E402   (the model benchmark's machine line and tables)

#: Bins of the captures: 1 cm of path (tal-like), 512 of them from 1.9 m.
BIN_WIDTH_OPL, START_OPL, BINS = 0.01, 1.9, 512

CHILD = """
import json, time
import numpy as np
from analytic.scenes.reflectance import builtin_reflectance
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Sampling, Scene, sensor_grid
from analytic.operator.system import system_matrix
from analytic.operator.window import window_share

def resident_kib(field):
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith(field + ":"):
                return int(line.split()[1])

case, pixels, grid = {case!r}, {pixels}, {grid}
sampling = Sampling(bin_width_opl={width}, start_opl={start}, count={bins})
image = builtin_reflectance(pixels)
if case == "plane":
    scene = Scene(size=1.0, pixels=pixels, reflectance=image, source=(0.5, 0.5, 1.0),
                  sensors=sensor_grid((grid, grid), 1.0, (0.5, 0.5, 1.0)), sampling=sampling)
else:
    scan = Scan(type=case, grid=(grid, grid))
    scene = RelayWallScene(pixels=pixels, reflectance=image, scan=scan, sampling=sampling)
system_matrix(scene.replace(pixels=2, reflectance=0.5))          # compile or load the kernels
share = window_share(scene)
with open("/proc/self/clear_refs", "w") as handle:                  # the peak (VmHWM) reset to the current size
    handle.write("5")
before = resident_kib("VmRSS")
wall, cpu = time.perf_counter(), time.process_time()
matrix = system_matrix(scene)
build, build_cpu = time.perf_counter() - wall, time.process_time() - cpu
wall = time.perf_counter()
y = matrix @ scene.reflectance.ravel()
product = time.perf_counter() - wall
peak = resident_kib("VmHWM")
print(json.dumps(dict(case=case, pixels=pixels, grid=grid, rows=int(scene.sensor_count), bins=int(sampling.count),
                      window_share=share, build_seconds=build, build_cpu_seconds=build_cpu,
                      forward_seconds=product, nnz=int(matrix.nnz),
                      matrix_bytes=int(matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes),
                      rss_before_kib=before, rss_peak_kib=peak, y_sum=float(np.sum(y)))))
"""


def measure(case: str, pixels: int, grid: int) -> dict:
    """One case in a fresh process (the project at ROOT); its JSON record."""
    code = CHILD.format(case=case, pixels=pixels, grid=grid, width=BIN_WIDTH_OPL, start=START_OPL, bins=BINS)
    environment = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", code], check=True, env=environment, capture_output=True,
                          text=True, cwd=ROOT)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench_nlos")
    parser.add_argument("--quick", action="store_true", help="32 x 32-pixel hidden planes (a smoke run)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pixels = 32 if args.quick else 64
    results = {"machine": machine(), "load_average_start": load(), "pixels": pixels,
               "bins": {"bin_width_opl": BIN_WIDTH_OPL, "start_opl": START_OPL, "count": BINS}, "cases": []}
    print(f"machine: {results['machine']}; load average at start {results['load_average_start']} "
          f"(shared machine: timings provisional)\n")
    rows = []
    for label, case, grid in (("single scan 16 x 16", "single", 16), ("confocal scan 32 x 32", "confocal", 32)):
        nlos = measure(case, pixels, grid)
        plane = measure("plane", pixels, grid)
        nlos["label"], nlos["baseline"] = label, plane
        results["cases"].append(nlos)
        work = nlos["rows"] * pixels**2
        for name, entry in ((label, nlos), (f"plane, {grid} x {grid} sensors (baseline)", plane)):
            rows.append([name, f"{entry['rows']:,} x {pixels} x {pixels}", f"{entry['window_share']:.4f}",
                         f"{entry['build_seconds']:.2f}", f"{entry['build_cpu_seconds']:.2f}",
                         f"{1e6 * entry['build_seconds'] / work:.2f}", f"{entry['forward_seconds'] * 1e3:.1f}",
                         f"{entry['nnz']:,}", f"{entry['matrix_bytes'] / 2**20:.0f}",
                         f"{(entry['rss_peak_kib'] - entry['rss_before_kib']) / 1024:.0f}",
                         f"{entry['build_seconds'] / plane['build_seconds']:.2f}"])
    print(f"A's build and y = A f, {BINS} bins of {BIN_WIDTH_OPL:g} m from {START_OPL:g} m, impulse, tolerance "
          f"1e-6, each in a fresh process after a warm-up call ({pixels} x {pixels} hidden pixels):\n")
    table(["capture", "pairs x pixels", "window share", "A build (s)", "CPU (s)", "µs per (pair, pixel)",
           "y = A f (ms)", "non-zeros", "A (MiB)", "peak memory above start (MiB)", "build / plane's"], rows)
    save_json(out / "results.json", results)
    print(f"-> {out / 'results.json'}")


if __name__ == "__main__":
    main()
