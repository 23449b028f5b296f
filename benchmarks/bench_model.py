"""Speed, memory and accuracy of the exact system matrix A, against a brute force and an earlier version.

    python benchmarks/bench_model.py --out out/bench_model [--quick] [--before REV] [--compile]

Measures, on this machine (named in the output, with its load average):

1. A's build in one process, after a warm-up call (the honest measure of the
   model: interpreter start-up is not the model), against NumPy midpoint
   supersampling (benchmarks/supersampled.py: 32 x 32 samples per pixel at
   M = 50, 8 x 8 at M = 256, K = 16) in the same process: the ratio, and
   every entry's error relative to its row's largest against a tight
   assembly. With ``--before REV`` the same child script runs on the
   project as it was at git revision REV (``git archive`` into a folder of
   the temporary directory named by the commit and kept, so that its Numba
   cache, warmed first, serves later runs), so that before and after are
   one run's numbers.
2. ``forward`` at M = 1024, K = 16 end to end (process start to files
   written) and its peak resident memory, now and at REV.
3. Scaling: time, CPU time, non-zeros, time per non-zero and peak memory
   against M (64 ... 1024, K = 16) and against K (1 ... 64, M = 256), each
   in a fresh process, with the share of (pair, pixel) combinations that a
   kernel breakpoint cuts (or a foot is near) and the cost of one: the
   smooth pairs' cost per pair is measured on the same scene with one bin
   that no edge crosses, and the cut pairs' cost is the rest of the time
   over their number.
4. ``forward`` and the brute-force script end to end at M = 50 and 256
   (interleaved runs, best and median).
5. The tolerance setting: build time and achieved error (against the tight
   assembly) from 1e-2 to 1e-8 on the default scene.
6. With ``--compile``: Numba's compile from an empty cache (a fresh
   ``NUMBA_CACHE_DIR``), wall and CPU time and peak memory, of what
   ``scripts/setup.sh``'s warm-up compiles (A's assembly), then of the
   entry points only the tests use (``pair_entries`` by every route), now
   and at REV.

Prints markdown tables and writes ``results.json`` in --out. Timings on a
shared machine are provisional: compare ratios taken in the same run.
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

from analytic.files import save_json  # noqa: E402
from analytic.scenes.common import default_scene  # noqa: E402
from analytic.operator.system import MIN_TOLERANCE, QuadratureWarning, system_matrix  # noqa: E402
from supersampled import supersampled  # noqa: E402
from validation.runs.bench import cpu_model  # noqa: E402

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
    T = 0.1 m, the 10 bins from 2 m that hold the light, impulse, lambertian) with M = pixels and a
    uniform reflectance."""
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
start = 2.0
count = 10

[model]
attenuation = "lambertian"
""")
    return path


def run(command: str, root: Path = ROOT) -> float:
    """Wall seconds of a command, process start to exit (it must succeed), with the project at ``root``."""
    return run_measured(command, root)[0]


def run_measured(command: str, root: Path = ROOT, **environment) -> tuple[float, int]:
    """(wall seconds, peak resident bytes) of a command, process start to exit (it must succeed)."""
    return run_usage(command, root, **environment)[::2]


def run_usage(command, root: Path = ROOT, **environment) -> tuple[float, float, int]:
    """(wall seconds, CPU seconds, peak resident bytes) of a command line or argument list (it must succeed),
    extra variables set."""
    environment = dict(os.environ, PYTHONPATH=f"{root}{os.pathsep}{Path(__file__).resolve().parent}", **environment)
    started = time.perf_counter()
    arguments = shlex.split(command) if isinstance(command, str) else command
    process = subprocess.Popen(arguments, env=environment, cwd=root, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(process.pid, 0)
    seconds = time.perf_counter() - started
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise subprocess.CalledProcessError(process.returncode, command)
    return seconds, usage.ru_utime + usage.ru_stime, usage.ru_maxrss * 1024


def child(code: str, root: Path = ROOT) -> dict:
    """Run a Python snippet in a fresh process with the project at ``root``; it prints one JSON object."""
    environment = dict(os.environ, PYTHONPATH=f"{root}{os.pathsep}{Path(__file__).resolve().parent}")
    done = subprocess.run([sys.executable, "-c", code], check=True, env=environment, capture_output=True,
                          text=True, cwd=root)
    return json.loads(done.stdout.strip().splitlines()[-1])


SCALING = """
import time, json, resource, warnings
from analytic.scenes.scene_file import load_scene
from analytic.operator.system import system_matrix

def resident_kib(field):
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith(field + ":"):
                return int(line.split()[1])

scene = load_scene({scene!r})
system_matrix(scene.replace(pixels=2, reflectance=0.5))
statistics = {{}}
with open("/proc/self/clear_refs", "w") as handle:     # reset the peak (VmHWM) to the current size
    handle.write("5")
before = resident_kib("VmRSS")
wall = time.perf_counter()
cpu = time.process_time()
matrix = system_matrix(scene, statistics=statistics)
wall = time.perf_counter() - wall
cpu = time.process_time() - cpu
peak = resident_kib("VmHWM")
from analytic.scenes.common import Sampling
uncut = scene.replace(sampling=Sampling(bin_width_opl=100.0, start_opl=0.0, count=1))
uncut_statistics = {{}}
uncut_cpu = time.process_time()
system_matrix(uncut, statistics=uncut_statistics)
uncut_cpu = time.process_time() - uncut_cpu
print(json.dumps(dict(seconds=wall, cpu_seconds=cpu, nnz=int(matrix.nnz), rss_before_kib=before, rss_peak_kib=peak,
                      matrix_bytes=int(matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes),
                      uncut_cpu_seconds=uncut_cpu, **statistics,
                      uncut_smooth_pairs=uncut_statistics["smooth_pairs"])))
"""


IN_PROCESS = """
import json, time
from analytic.scenes.common import default_scene
from analytic.operator.system import system_matrix
from supersampled import supersampled

def best(function, repeats):
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return min(times)

system_matrix(default_scene(pixels=2, noise=None))          # compile or load the cached kernels
rows = []
for pixels, factor in ((50, 32), (256, 8)):
    scene = default_scene(pixels=pixels, noise=None)
    sampling = scene.sampling
    exact = best(lambda: system_matrix(scene), {repeats})
    brute = best(lambda: supersampled(scene.size, pixels, scene.source, scene.sensors, sampling.start_opl,
                                      sampling.bin_width_opl, sampling.count, factor, scene.intensity), {repeats})
    rows.append(dict(M=pixels, factor=factor, exact_seconds=exact, brute_seconds=brute, ratio=exact / brute))
print(json.dumps(rows))
"""

WARM = "{python} -c 'from analytic.scenes.common import default_scene; from analytic.operator.matrix_free import forward; " \
       "forward(default_scene(pixels=4, noise=None))'"

# What a fresh clone compiles: A's assembly (the set-up's warm-up), then the routes only the tests call
COMPILE_ASSEMBLY = """
from analytic.scenes.common import default_scene
from analytic.operator.system import system_matrix
system_matrix(default_scene(pixels=4, noise=None))
"""
COMPILE_ROUTES = """
import contextlib
from analytic.scenes.common import default_scene
from analytic.operator.system import METHODS, pair_entries
for method in METHODS:
    for taylor in (True, False):
        with contextlib.suppress(ValueError):      # a route that does not apply to this pixel was still compiled
            pair_entries(default_scene(pixels=4, noise=None), 0, 5, method=method, taylor=taylor)
"""


def checkout(revision: str) -> Path:
    """The project's files at a git revision (``git archive``: no git state changes), in a temporary folder
    named by the commit and kept: its Numba cache beside the sources serves the next run (compiling an
    old revision took up to 30 minutes on a loaded machine)."""
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", f"{revision}^{{commit}}"], check=True,
                            capture_output=True, text=True).stdout.strip()
    folder = Path(tempfile.gettempdir()) / f"bench_model_before_{commit}"
    if (folder / ".complete").exists():
        return folder
    staging = Path(tempfile.mkdtemp(prefix="bench_model_before_"))
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", commit], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(staging)], input=archive, check=True)
    (staging / ".complete").touch()
    if folder.exists():      # an interrupted extraction
        return staging
    staging.rename(folder)
    return folder


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


def in_process(root: Path, repeats: int) -> list:
    """Section 1's timings by the project at ``root``, in one fresh process after its warm-up."""
    return child(IN_PROCESS.format(repeats=repeats), root)


def compile_times(versions: dict) -> list:
    """Section 6: each version's compile from an empty cache, A's assembly first, then the tests' routes."""
    rows, measured = [], []
    for label, root in versions.items():
        with tempfile.TemporaryDirectory(prefix="bench_model_cache_") as cache:
            for step, code in (("assembly (set-up's warm-up)", COMPILE_ASSEMBLY), ("tests' routes", COMPILE_ROUTES)):
                wall, cpu, peak = run_usage([sys.executable, "-c", code], root, NUMBA_CACHE_DIR=cache)
                measured.append({"version": label, "step": step, "seconds": wall, "cpu_seconds": cpu,
                                 "peak_bytes": peak})
                rows.append([label, step, f"{wall:.0f}", f"{cpu:.0f}", f"{peak / 2**30:.2f}"])
    print("Numba's compile from an empty cache (a fresh NUMBA_CACHE_DIR; each step one process, the routes after "
          "the assembly in the same cache):\n")
    table(["version", "what", "wall (s)", "CPU (s)", "peak memory (GiB)"], rows)
    return measured


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench_model")
    parser.add_argument("--quick", action="store_true", help="skip M = 512, 1024 and K = 64; fewer repeats")
    parser.add_argument("--before", metavar="REV", help="also time the project at this git revision")
    parser.add_argument("--compile", action="store_true",
                        help="also time Numba's compile from an empty cache (minutes; GiB of memory at some revisions)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    repeats = 2 if args.quick else 3
    results = {"machine": machine(), "load_average_start": load(), "before": args.before}
    print(f"machine: {results['machine']}; load average at start {results['load_average_start']} "
          f"(shared machine: timings provisional)\n")
    for package in ("analytic", "transient", "validation", "interop"):  # as scripts/setup.sh does
        compileall.compile_dir(ROOT / package, quiet=1)
    system_matrix(default_scene(pixels=2, noise=None))       # compile or load the cached kernels
    work = Path(tempfile.mkdtemp(prefix="bench_model_"))
    python = shlex.quote(sys.executable)
    versions = {"now": ROOT}
    if args.before:
        versions = {f"before ({args.before})": checkout(args.before), "now": ROOT}
        run(WARM.format(python=python), versions[f"before ({args.before})"])   # its kernels compiled once

    # 1. A against the brute force, in one process
    rows, comparison = [], []
    for label, root in versions.items():
        for entry in in_process(root, repeats):
            entry["version"] = label
            comparison.append(entry)
            rows.append([label, str(entry["M"]), f"{entry['factor']}x{entry['factor']}",
                         f"{entry['exact_seconds']:.3f}", f"{entry['brute_seconds']:.3f}", f"{entry['ratio']:.2f}"])
    results["in_process"] = comparison
    print(f"A's build against midpoint supersampling, in one process after a warm-up call (default scene, "
          f"K = 16, tolerance 1e-6; best of {repeats}):\n")
    table(["version", "M", "brute force", "exact A (s)", "brute (s)", "exact / brute"], rows)

    errors = []
    for pixels, factor in ((50, 32), (256, 8)):
        scene = default_scene(pixels=pixels, noise=None)
        reference = tight(scene)
        sampling = scene.sampling
        brute = supersampled(scene.size, pixels, scene.source, scene.sensors, sampling.start_opl,
                             sampling.bin_width_opl, sampling.count, factor, scene.intensity)
        errors.append({"M": pixels, "factor": factor, "exact_error": error_against(system_matrix(scene), reference),
                       "brute_error": error_against(brute, reference)})
    results["errors"] = errors
    print("Their accuracy (max |A - A_tight| / row max, A_tight at tolerance 1e-10):\n")
    table(["M", "exact error", "brute error"],
          [[str(e["M"]), f"{e['exact_error']:.1e}", f"{e['brute_error']:.1e} ({e['factor']}x{e['factor']})"]
           for e in errors])

    # 2. forward at M = 1024, end to end, with its peak memory
    if not args.quick:
        path = scene_file(work, 1024, 4)
        rows, big = [], []
        for label, root in versions.items():
            runs = [run_measured(FORWARD.format(python=python, scene=path, out=work / "f1024"), root)
                    for _ in range(2)]
            seconds, peak = min(r[0] for r in runs), max(r[1] for r in runs)
            big.append({"version": label, "seconds": seconds, "peak_bytes": peak})
            rows.append([label, f"{seconds:.2f}", f"{peak / 2**30:.2f}"])
        results["forward_1024"] = big
        print("`forward` at M = 1024, K = 16 (10 bins of 0.1 m), process start to files written (best of 2) "
              "and peak resident memory:\n")
        table(["version", "seconds", "peak memory (GiB)"], rows)

    # 3. scaling, with the cut pairs' share and cost
    sizes = (64, 128, 256) if args.quick else (64, 128, 256, 512, 1024)
    grids = (1, 2, 4) if args.quick else (1, 2, 4, 8)
    scaling = []
    for pixels, grid in [(m, 4) for m in sizes] + [(256, g) for g in grids if g != 4]:
        entry = child(SCALING.format(scene=str(scene_file(work, pixels, grid))))
        entry.update(M=pixels, K=grid * grid)
        scaling.append(entry)
    results["scaling"] = scaling
    print("Scaling (fresh process each; memory = growth of the peak resident size while A is built, A itself "
          "included; cut = pairs a kernel breakpoint crosses or near a foot; smooth cost per pair from the same "
          "scene with one uncut bin, cut cost = the rest of the CPU time over the cut pairs):\n")
    rows = []
    for entry in sorted(scaling, key=lambda e: (e["K"] != 16, e["K"], e["M"])):
        growth = max(entry["rss_peak_kib"] - entry["rss_before_kib"], 0) * 1024
        cut = entry["pairs"] - entry["smooth_pairs"]
        smooth_cost = entry["uncut_cpu_seconds"] / max(entry["uncut_smooth_pairs"], 1)
        cut_cost = max(entry["cpu_seconds"] - entry["smooth_pairs"] * smooth_cost, 0.0) / max(cut, 1)
        entry.update(cut_pairs=cut, smooth_cost_seconds=smooth_cost, cut_cost_seconds=cut_cost)
        rows.append([str(entry["M"]), str(entry["K"]), f"{entry['seconds']:.2f}", f"{entry['cpu_seconds']:.2f}",
                     f"{entry['nnz']:,}", f"{entry['seconds'] / entry['nnz'] * 1e6:.2f}",
                     f"{growth / 2**20:.0f}", f"{growth / entry['nnz']:.0f}",
                     f"{cut / max(entry['pairs'], 1):.1%}", f"{smooth_cost * 1e6:.2f}", f"{cut_cost * 1e6:.1f}"])
    table(["M", "K", "wall (s)", "CPU (s)", "nnz", "µs per nnz (wall)", "memory (MiB)", "bytes per nnz",
           "cut pairs", "µs per smooth pair (CPU)", "µs per cut pair (CPU)"], rows)

    # 4. end to end against the brute-force script
    rows, ends = [], []
    for pixels, factor in ((50, 32), (256, 8)):
        path = scene_file(work, pixels, 4)
        forward_times, brute_times = [], []
        for _ in range(5):     # interleaved, so that a busy spell hits both alike
            forward_times.append(run(FORWARD.format(python=python, scene=path, out=work / f"f{pixels}")))
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
    print("End to end, process start to files written (5 interleaved runs each; best / median):\n")
    table(["M", "brute force", "forward (s)", "brute script (s)", "forward / brute"], rows)

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

    if args.compile:
        results["compile"] = compile_times(versions)

    results["load_average_end"] = load()
    print(f"load average at end {results['load_average_end']}")
    save_json(out / "results.json", results)


if __name__ == "__main__":
    main()
