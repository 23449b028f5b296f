"""The exact relay-wall model at the size of real NLOS captures: before and after the offset route, in one run.

    python benchmarks/bench_nlos_size.py --out out/bench_nlos_size [--before-64]
    python benchmarks/bench_nlos_size.py --out out/bench_nlos_size --strips 57117e2 [--repeat 2]

The captures (issue 43): a 1 m x 1 m hidden square 0.9 m in front of a 2 m x 2 m relay wall (laser and
sensor at (-0.5, 0, 0.25)), impulse illumination, tolerance 1e-6, bins of 5 mm from 1.8 m:

1. A's build (:func:`analytic.system_matrix`), in a fresh process after a warm-up call, for the plane
   (a 32 x 32 sensor array 1 m above a 1 m plane, the letter's scene: no two pairs are translates, so
   the general route) and a 32 x 32 confocal scan, both over 64 x 64 pixels and 512 bins, by the
   general route ("before": :data:`analytic.operator.offsets.MIN_SAVING` set to 0) and by the route the
   model takes ("after": the offset route for the relay wall): seconds, µs per (pair, pixel) and per
   non-zero of A.
2. ``diffuse-imaging forward`` end to end (a fresh process, kernels warm, every file written): the
   32 x 32 and 64 x 64 scans of 64 x 64 pixels with 512 bins, and a 256 x 256 scan of 32 x 32 pixels with
   1024 bins (whose A, ~750 million entries, would not fit in half this machine's memory): wall seconds and
   the command's peak resident memory; the 32 x 32 scan also by the general route (before), and with
   ``--before-64`` the 64 x 64 scan too (several minutes).

``--strips REV`` runs only A's build by the general route (the relay wall's offset route switched off),
for the plane and the relay wall, by the project at git revision REV (before: ``git archive`` into a
temporary folder, :func:`bench_model.checkout`) and by this one (after), alternating, ``--repeat`` times:
wall and CPU seconds of the build, µs per (pair, pixel) and per non-zero, the load average around each
(issue 43: the impulse's pixels that several 5 mm bins cut, once the general strip route's).

Prints markdown tables and the load average (the machine is shared: timings are provisional) and writes
``results.json`` in --out.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from analytic.files import save_json  # noqa: E402
from bench_model import checkout, load, machine, table  # noqa: E402

SCENE = """name = "nlos-size"
[relay_wall]
size = [2.0, 2.0]
[hidden]
center = [0.0, 0.0, 0.9]
u = [1.0, 0.0, 0.0]
v = [0.0, -1.0, 0.0]
pixels = {pixels}
reflectance = 0.5
[laser]
position = [-0.5, 0.0, 0.25]
[sensor]
position = [-0.5, 0.0, 0.25]
[scan]
type = "confocal"
grid = [{grid}, {grid}]
[sampling]
period = 0.005
start = 1.8
count = {bins}
"""

#: Section 1's child: A's build after a warm-up, by the general route when asked.
BUILD = """
import json, time
import numpy as np
from analytic.operator import offsets
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Sampling, Scene, sensor_grid
from analytic.operator.system import system_matrix
if {general}:
    offsets.MIN_SAVING = 0.0
sampling = Sampling(bin_width_opl=0.005, start_opl=1.8, count=512)
if {plane}:
    scene = Scene(size=1.0, pixels=64, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=sensor_grid((32, 32), 1.0, (0.5, 0.5, 1.0)), sampling=Sampling(bin_width_opl=0.005,
                  start_opl=1.95, count=512))
else:
    scene = RelayWallScene(pixels=64, reflectance=0.5, center=(0.0, 0.0, 0.9), scan=Scan(type="confocal",
                           grid=(32, 32)), sampling=sampling)
system_matrix(scene.replace(pixels=2, reflectance=0.5))
load = " ".join(open("/proc/loadavg").read().split()[:3])
wall, cpu = time.perf_counter(), time.process_time()
matrix = system_matrix(scene)
print(json.dumps(dict(seconds=time.perf_counter() - wall, cpu=time.process_time() - cpu, nnz=int(matrix.nnz),
                      pairs=int(scene.sensor_count), load=[load, " ".join(open("/proc/loadavg").read().split()[:3])])))
"""

#: Section 2's command line by the general route (the offset route switched off).
GENERAL = ("import sys, analytic.operator.offsets as offsets; offsets.MIN_SAVING = 0.0; "
           "from validation.cli.program import main; sys.exit(main(sys.argv[1:]))")


def _environment() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT))


def build(plane: bool, general: bool, root: Path = ROOT) -> dict:
    code = BUILD.format(plane=plane, general=general)
    done = subprocess.run([sys.executable, "-c", code], check=True, env=dict(os.environ, PYTHONPATH=str(root)),
                          capture_output=True, text=True, cwd=root)
    return json.loads(done.stdout.strip().splitlines()[-1])


def strips(revision: str, repeat: int, results: dict) -> None:
    """A's build by the general route, before (the project at ``revision``) and after (this one), alternating."""
    before = checkout(revision)
    rows = []
    for _ in range(repeat):
        for scene, plane in (("plane, 32 x 32 sensors", True), ("relay wall, 32 x 32 confocal", False)):
            for label, root in ((f"before ({revision})", before), ("after", ROOT)):
                entry = dict(build(plane, True, root), scene=scene, code=label)
                results["builds"].append(entry)
                work = entry["pairs"] * 64**2
                rows.append([scene, label, f"{entry['seconds']:.2f}", f"{entry['cpu']:.2f}", f"{entry['nnz']:,}",
                             f"{1e6 * entry['seconds'] / work:.3f}", f"{1e6 * entry['cpu'] / work:.3f}",
                             f"{1e6 * entry['seconds'] / entry['nnz']:.3f}", f"{1e6 * entry['cpu'] / entry['nnz']:.3f}",
                             " / ".join(entry["load"])])
    print("A's build by the general route, 64 x 64 pixels, 512 bins of 5 mm, a fresh process after a warm-up call "
          "(wall and CPU: 2 threads):\n")
    table(["scene", "code", "wall (s)", "CPU (s)", "non-zeros", "µs per (pair, pixel)", "CPU µs per (pair, pixel)",
           "µs per non-zero", "CPU µs per non-zero", "load average before / after"], rows)


def forward(folder: Path, grid: int, pixels: int, bins: int, general: bool) -> dict:
    """``forward`` of the capture in a fresh process: wall seconds, the child's peak resident memory."""
    scene = folder / f"scan{grid}_M{pixels}_N{bins}.toml"
    scene.write_text(SCENE.format(grid=grid, pixels=pixels, bins=bins))
    out = folder / f"out{grid}{'-general' if general else ''}"
    start = ["-c", GENERAL] if general else ["-m", "validation.cli"]
    wall = time.perf_counter()
    with open(folder / "stdout.txt", "w") as stdout, open(folder / "stderr.txt", "w") as stderr:
        child = subprocess.Popen([sys.executable, *start, "forward", str(scene), "--out", str(out)],
                                 env=_environment(), stdout=stdout, stderr=stderr, cwd=ROOT)
        _, status, usage = os.wait4(child.pid, 0)          # this child's own peak resident memory
        child.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - wall
    if child.returncode != 0:
        raise SystemExit(f"forward of {scene} failed: {(folder / 'stderr.txt').read_text()}")
    meta = json.loads((out / "meta.json").read_text())
    return dict(grid=grid, pixels=pixels, bins=bins, general=general, seconds=seconds,
                peak_gib=usage.ru_maxrss / 2**20, summary=(folder / "stdout.txt").read_text().strip(),
                estimate=(folder / "stderr.txt").read_text().strip(), nonzeros=meta.get("nonzeros"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/bench_nlos_size")
    parser.add_argument("--before-64", action="store_true", help="the 64 x 64 scan by the general route too")
    parser.add_argument("--strips", metavar="REV", help="only A's general-route build, at REV and here")
    parser.add_argument("--repeat", type=int, default=1, help="--strips: rounds of before and after")
    args = parser.parse_args()
    (out := Path(args.out)).mkdir(parents=True, exist_ok=True)
    results = {"machine": machine(), "load_average_start": load(), "builds": [], "forwards": []}
    print(f"machine: {results['machine']}; load average at start {results['load_average_start']} "
          f"(shared machine: timings provisional)\n")
    if args.strips:
        strips(args.strips, args.repeat, results)
        results["load_average_end"] = load()
        save_json(out / "strips.json", results)
        print(f"load average at the end {results['load_average_end']}; -> {out / 'strips.json'}")
        return
    subprocess.run([sys.executable, "-m", "validation.cli", "forward", "examples/nlos.toml", "--out",
                    str(out / "warm"), "--quiet"], env=_environment(), check=True, cwd=ROOT)   # kernels loaded
    rows = []
    for label, plane, general in (("plane, 32 x 32 sensors", True, True),
                                  ("relay wall, 32 x 32 confocal, general route (before)", False, True),
                                  ("relay wall, 32 x 32 confocal, offset route (after)", False, False)):
        entry = build(plane, general)
        entry["label"] = label
        results["builds"].append(entry)
        work = entry["pairs"] * 64**2
        rows.append([label, f"{entry['seconds']:.2f}", f"{entry['nnz']:,}", f"{1e6 * entry['seconds'] / work:.3f}",
                     f"{1e6 * entry['seconds'] / entry['nnz']:.3f}"])
    print("A's build, 64 x 64 pixels, 512 bins of 5 mm, a fresh process after a warm-up call:\n")
    table(["scene", "A build (s)", "non-zeros", "µs per (pair, pixel)", "µs per non-zero"], rows)
    cases = [(32, 64, 512, True), (32, 64, 512, False), (64, 64, 512, False), (256, 32, 1024, False)]
    if args.before_64:
        cases.insert(2, (64, 64, 512, True))
    rows = []
    for grid, pixels, bins, general in cases:
        entry = forward(out, grid, pixels, bins, general)
        results["forwards"].append(entry)
        peak = f"{entry['peak_gib']:.2f}"
        rows.append([f"{grid} x {grid} scan, {pixels} x {pixels} pixels, {bins} bins",
                     "general (before)" if general else "offsets (after)", f"{entry['seconds']:.1f}", peak,
                     f"{entry['nonzeros']:,}"])
    results["load_average_end"] = load()
    print(f"`diffuse-imaging forward` end to end (fresh process, kernels warm, every file written); load average "
          f"at the end {results['load_average_end']}:\n")
    table(["capture", "route", "wall (s)", "peak memory (GiB)", "A's non-zeros"], rows)
    save_json(out / "results.json", results)
    print(f"-> {out / 'results.json'}")


if __name__ == "__main__":
    main()
