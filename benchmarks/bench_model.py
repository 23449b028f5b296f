"""Speed, memory and accuracy of the exact system matrix A, against a brute force.

    python benchmarks/bench_model.py --out out/bench_model [--quick]
        [--forward-command "{python} -m validation.cli forward {scene} --out {out} --quiet"]

Measures, on this machine (named in the output, with its load average):

1. ``forward`` end to end, process start to files written (the command
   is a parameter), against the brute-force script (benchmarks/supersampled.py:
   32 x 32 samples per pixel at M = 50, 8 x 8 at M = 256, K = 16) on the
   same scene file, interleaved runs, best and median.
2. Where ``forward``'s time goes: Python start, imports, Numba's first
   dispatch (cache load), A, y = A f, matplotlib's import and the figure
   (which forward runs in a forked process, beside the rest), each in a
   fresh process, and the rest of the command (files, exit).
3. A's build against the same supersampling in one process, with every
   entry's error relative to its row's largest against a tight assembly
   (tolerance MIN_TOLERANCE).
4. Scaling: time, CPU time, non-zeros, time per non-zero and peak memory
   against M (64 ... 1024, K = 16) and against K (1 ... 64, M = 256), each
   in a fresh process.
5. The tolerance setting: build time and achieved error (against the tight
   assembly) from 1e-2 to 1e-8 on the default scene, both as each entry's
   relative error (what the tolerance bounds) and against its row's largest.

The project's modules are compiled first, as scripts/setup.sh does (a
machine with PYTHONDONTWRITEBYTECODE would otherwise recompile them at every
start of ``forward``). Prints markdown tables and writes ``results.json`` in
--out. Timings on a shared machine are provisional: compare ratios taken in
the same run.
"""

from __future__ import annotations

import argparse
import compileall
import json
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from analytic.io import save_json  # noqa: E402
from analytic.scene import default_scene  # noqa: E402
from analytic.system import MIN_TOLERANCE, QuadratureWarning, system_matrix  # noqa: E402
from supersampled import supersampled  # noqa: E402
from validation.bench import cpu_model  # noqa: E402

FORWARD = "{python} -m validation.cli forward {scene} --out {out} --quiet"
BRUTE = ("{python} " + str(Path(__file__).resolve().parent / "supersampled.py")
         + " {scene} --factor {factor} --out {out}")


def machine() -> str:
    return f"{cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def load() -> str:
    try:
        return " ".join(open("/proc/loadavg").read().split()[:3])
    except OSError:
        return "unknown"


def scene_file(folder: Path, pixels: int, grid: int) -> Path:
    """The default scene's geometry (source 1 m above the centre, grid x grid sensors of extent 1 m,
    T = 0.1 m, 40 bins from 0, impulse, lambertian) with M = pixels and a uniform reflectance."""
    path = folder / f"scene_M{pixels}_K{grid * grid}.toml"
    path.write_text(f"""[plane]
size = 1.0
pixels = {pixels}
reflectance = 0.5

[source]
position = [0.5, 0.5, 1.0]

[illumination]
waveform = "impulse"

[sensors]
grid = [{grid}, {grid}]
extent = 1.0
center = [0.5, 0.5, 1.0]

[sampling]
period = 0.1
start = 0.0
count = 40

[model]
attenuation = "lambertian"
""")
    return path


def run(command: str) -> float:
    """Wall seconds of a command, process start to exit (it must succeed)."""
    environment = dict(os.environ, PYTHONPATH=str(ROOT))
    started = time.perf_counter()
    subprocess.run(shlex.split(command), check=True, env=environment, stdout=subprocess.DEVNULL)
    return time.perf_counter() - started


def child(code: str) -> dict:
    """Run a Python snippet in a fresh process; it prints one JSON object."""
    environment = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", code], check=True, env=environment, capture_output=True,
                          text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


BREAKDOWN = """
import time, json
t0 = time.perf_counter()
import numpy, scipy.sparse
t1 = time.perf_counter()
import numba
t2 = time.perf_counter()
from analytic.scene_file import load_scene
from analytic.system import system_matrix
t3 = time.perf_counter()
scene = load_scene({scene!r})
system_matrix(scene.replace(pixels=2, reflectance=0.5))
t4 = time.perf_counter()
matrix = system_matrix(scene)
t5 = time.perf_counter()
y = matrix @ scene.reflectance.ravel()
t6 = time.perf_counter()
from matplotlib.backends import backend_agg
from matplotlib import figure
t7 = time.perf_counter()
import io
from validation.plots import model_figure
model_figure(scene.sampling, y.reshape(scene.sensor_count, -1), title="x").savefig(io.BytesIO(), format="png")
t8 = time.perf_counter()
print(json.dumps(dict(numpy_scipy=t1 - t0, numba=t2 - t1, analytic=t3 - t2, first_dispatch=t4 - t3,
                      matrix=t5 - t4, product=t6 - t5, matplotlib=t7 - t6, figure=t8 - t7)))
"""

#: Runs of each end-to-end command (short, and the most sensitive to a shared machine's load).
END_TO_END_REPEATS = 7

#: Parts of the breakdown that ``forward`` runs in its forked figure process, beside the others.
FORKED_PARTS = ("matplotlib", "figure")

SCALING = """
import time, json, resource, warnings
from analytic.scene_file import load_scene
from analytic.system import system_matrix

def resident_kib(field):
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith(field + ":"):
                return int(line.split()[1])

scene = load_scene({scene!r})
system_matrix(scene.replace(pixels=2, reflectance=0.5))
with open("/proc/self/clear_refs", "w") as handle:     # reset the peak (VmHWM) to the current size
    handle.write("5")
before = resident_kib("VmRSS")
wall = time.perf_counter()
cpu = time.process_time()
matrix = system_matrix(scene)
wall = time.perf_counter() - wall
cpu = time.process_time() - cpu
peak = resident_kib("VmHWM")
print(json.dumps(dict(seconds=wall, cpu_seconds=cpu, nnz=int(matrix.nnz), rss_before_kib=before, rss_peak_kib=peak,
                      matrix_bytes=int(matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes))))
"""


def best(function, repeats):
    times, result = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - started)
    return min(times), result


def error_against(matrix, reference) -> float:
    """max over entries of |A - A_ref| / (its row's largest |A_ref|)."""
    row_max = abs(reference).max(axis=1).toarray().ravel()
    row_max[row_max == 0] = 1.0
    return float((abs(matrix - reference).max(axis=1).toarray().ravel() / row_max).max())


def entry_error_against(matrix, reference) -> float:
    """max over entries of |A - A_ref| / |A_ref| (|A - A_ref| where A_ref is 0), dense: A is small here."""
    difference = abs(matrix.toarray() - reference.toarray())
    scale = abs(reference.toarray())
    return float(np.where(scale > 0, difference / np.where(scale > 0, scale, 1.0), difference).max())


def tight(scene):
    with warnings.catch_warnings():     # a few pieces stop at float64's rounding at this tolerance
        warnings.simplefilter("ignore", QuadratureWarning)
        return system_matrix(scene, tolerance=MIN_TOLERANCE)


def table(header, rows):
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench_model")
    parser.add_argument("--quick", action="store_true", help="skip M = 512, 1024 and K = 64; fewer repeats")
    parser.add_argument("--forward-command", default=FORWARD,
                        help="end-to-end command; {python}, {scene} and {out} are filled in")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    repeats = 2 if args.quick else 3
    results = {"machine": machine(), "load_average_start": load(), "forward_command": args.forward_command}
    print(f"machine: {results['machine']}; load average at start {results['load_average_start']} "
          f"(shared machine: timings provisional)\n")
    for package in ("analytic", "transient", "validation"):  # as scripts/setup.sh does
        compileall.compile_dir(ROOT / package, quiet=1)
    system_matrix(default_scene(pixels=2, noise=None))       # compile or load the cached kernels
    work = Path(tempfile.mkdtemp(prefix="bench_model_"))
    python = shlex.quote(sys.executable)

    # 1. end to end
    rows, ends = [], []
    for pixels, factor in ((50, 32), (256, 8)):
        path = scene_file(work, pixels, 4)
        forward_times, brute_times = [], []
        for _ in range(END_TO_END_REPEATS):     # interleaved, so that a busy spell hits both alike
            forward_times.append(run(args.forward_command.format(python=python, scene=path,
                                                                 out=work / f"f{pixels}")))
            brute_times.append(run(BRUTE.format(python=python, scene=path, factor=factor, out=work / f"b{pixels}")))
        entry = {"M": pixels, "factor": factor, "forward_seconds": forward_times, "brute_seconds": brute_times,
                 "ratio_of_bests": min(forward_times) / min(brute_times),
                 "ratio_of_medians": statistics.median(forward_times) / statistics.median(brute_times)}
        ends.append(entry)
        rows.append([str(pixels), f"{factor}x{factor}",
                     f"{min(forward_times):.2f} / {statistics.median(forward_times):.2f}",
                     f"{min(brute_times):.2f} / {statistics.median(brute_times):.2f}",
                     f"{entry['ratio_of_bests']:.2f} / {entry['ratio_of_medians']:.2f}"])
    results["end_to_end"] = ends
    print(f"End to end, process start to files written ({END_TO_END_REPEATS} interleaved runs each; best / "
          f"median); forward = `{args.forward_command}`:\n")
    table(["M", "brute force", "forward (s)", "brute script (s)", "forward / brute"], rows)

    # 2. where forward's time goes
    scene50 = scene_file(work, 50, 4)
    startup = min(run(f"{python} -c pass") for _ in range(repeats))
    parts = [child(BREAKDOWN.format(scene=str(scene50))) for _ in range(repeats)]
    parts = {"python_start": startup, **{key: min(p[key] for p in parts) for key in parts[0]}}
    total = min(ends[0]["forward_seconds"])
    serial = sum(value for key, value in parts.items() if key not in FORKED_PARTS)
    parts["rest_of_command"] = total - serial
    results["forward_breakdown"] = {**parts, "total": total}
    print("Where forward's time goes (M = 50, K = 16; each part best of fresh processes; the total is the "
          "best run above; matplotlib and the figure run in forward's forked figure process, beside the command's "
          "parts; the rest is the total less the command's parts: writing files, exit, waiting for the "
          "figure):\n")
    table(["part", "seconds", "share of the total"],
          [[key.replace("_", " "), f"{value:.3f}",
            "(forked, beside)" if key in FORKED_PARTS else f"{value / total:.0%}"] for key, value in parts.items()]
          + [["total", f"{total:.3f}", ""]])

    # 3. A against the brute force, in this process
    rows, comparison = [], []
    for pixels, factor in ((50, 32), (256, 8)):
        scene = default_scene(pixels=pixels, noise=None)
        reference = tight(scene)
        exact_seconds, exact = best(lambda scene=scene: system_matrix(scene), repeats)
        sampling = scene.sampling
        brute_seconds, brute = best(
            lambda scene=scene, pixels=pixels, factor=factor, sampling=sampling: supersampled(
                scene.size, pixels, scene.source, scene.sensors, sampling.start_opl, sampling.bin_width_opl,
                sampling.count, factor, scene.intensity), repeats)
        entry = {"M": pixels, "K": scene.sensor_count, "factor": factor, "exact_seconds": exact_seconds,
                 "exact_error": error_against(exact, reference), "brute_seconds": brute_seconds,
                 "brute_error": error_against(brute, reference), "ratio": exact_seconds / brute_seconds,
                 "nnz": int(exact.nnz)}
        comparison.append(entry)
        rows.append([str(pixels), f"{factor}x{factor}", f"{exact_seconds:.3f}", f"{entry['exact_error']:.1e}",
                     f"{brute_seconds:.3f}", f"{entry['brute_error']:.1e}", f"{entry['ratio']:.2f}"])
    results["against_brute_force"] = comparison
    print("A's build against midpoint supersampling (K = 16, tolerance 1e-6; same process, best of "
          f"{repeats}; error = max |A - A_tight| / row max):\n")
    table(["M", "brute force", "exact (s)", "exact error", "brute (s)", "brute error", "exact / brute"], rows)

    # 4. scaling
    sizes = (64, 128, 256) if args.quick else (64, 128, 256, 512, 1024)
    grids = (1, 2, 4) if args.quick else (1, 2, 4, 8)
    scaling = []
    for pixels, grid in [(m, 4) for m in sizes] + [(256, g) for g in grids if g != 4]:
        entry = child(SCALING.format(scene=str(scene_file(work, pixels, grid))))
        entry.update(M=pixels, K=grid * grid)
        scaling.append(entry)
    results["scaling"] = scaling
    print("Scaling (fresh process each; memory = growth of the peak resident size while A is built, "
          "A itself included):\n")
    rows = []
    for entry in sorted(scaling, key=lambda e: (e["K"] != 16, e["K"], e["M"])):
        growth = max(entry["rss_peak_kib"] - entry["rss_before_kib"], 0) * 1024
        rows.append([str(entry["M"]), str(entry["K"]), f"{entry['seconds']:.2f}", f"{entry['cpu_seconds']:.2f}",
                     f"{entry['nnz']:,}", f"{entry['seconds'] / entry['nnz'] * 1e6:.2f}",
                     f"{growth / 2**20:.0f}", f"{growth / entry['nnz']:.0f}",
                     f"{entry['matrix_bytes'] / 2**20:.1f}"])
    table(["M", "K", "wall (s)", "CPU (s)", "nnz", "µs per nnz (wall)", "memory (MiB)", "bytes per nnz",
           "A (MiB)"], rows)

    # 5. tolerance: what it bounds (each entry's relative error) and the error against each row's largest
    scene = default_scene(noise=None)
    reference = tight(scene)
    rows, sweep = [], []
    for tolerance in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
        seconds, matrix = best(lambda tolerance=tolerance: system_matrix(scene, tolerance=tolerance), repeats)
        entry_error = entry_error_against(matrix, reference)
        error = error_against(matrix, reference)
        sweep.append({"tolerance": tolerance, "seconds": seconds, "entry_error": entry_error, "error": error})
        rows.append([f"{tolerance:g}", f"{seconds:.3f}", f"{entry_error:.1e}", f"{tolerance / entry_error:.1f}",
                     f"{error:.1e}"])
    results["tolerance"] = sweep
    print(f"Tolerance (default scene, M = 50, K = 16; reference: tolerance {MIN_TOLERANCE:g}; best of {repeats}; "
          "entry error = max |A - A_tight| / |A_tight|, what the tolerance bounds; row error = max "
          "|A - A_tight| / row max):\n")
    table(["tolerance", "build (s)", "entry error", "tolerance / entry error", "row error"], rows)

    results["load_average_end"] = load()
    print(f"load average at end {results['load_average_end']}")
    save_json(out / "results.json", results)


if __name__ == "__main__":
    main()
