"""The exact Jacobian's cost against ``forward`` and against central differences, with the error of each.

    python benchmarks/bench_jacobian.py [SCENE ...] [--repeats 5] [--baseline REF] [--gaussian FWHM]

For each plane scene (default: examples/paper.toml, K = 16, M = 50, and
examples/image.toml, K = 16, M = 32) and its 3K + 4 parameters
``source.position.{x,y,z}``, ``sensors.positions.{k}.{x,y,z}`` and
``sampling.start``: the best of ``--repeats`` wall times of ``forward`` and
of ``jacobian`` (each end to end from the scene object, kernels warm: one
untimed call of each first; and the best CPU time of all threads, the work
done whatever the load), and of one ``route="differences"`` Jacobian
(the default step, 4 models at tolerance 1e-10 per key); then the error of
each, per (sensor, key) column relative to its largest entry, against
Richardson differences with a fine step (2e-5 of the scene's extent, good
to ~2e-6: tests/analytic/test_jacobian_exact.py) on the source's three keys,
sensor 5's three and ``sampling.start``. ``--gaussian FWHM`` replaces each scene's illumination by a
Gaussian pulse of that FWHM (metres; the exact route of the other waveforms). Prints a Markdown table and the
machine's load (the machine may be shared). ``--baseline REF`` (a git
revision, e.g. ``main``) times the same two calls of that revision's
``analytic`` (``git archive`` into a temporary folder, in a subprocess, kernels
warmed there first) right after this code's, in the same run, and prints both
ratios side by side: a change's effect on the cost, whatever the load.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from analytic.operator.derivatives import jacobian
from analytic.operator.matrix_free import forward
from analytic.scenes.common import Illumination
from analytic.scenes.scene_file import scene_of


def _best(call, repeats):
    """The best wall time and the best CPU time (all threads: the work, whatever the machine's load)."""
    call()
    walls, cpus = [], []
    for _ in range(repeats):
        started, cpu = time.perf_counter(), time.process_time()
        call()
        walls.append(time.perf_counter() - started)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus)


def _keys(scene):
    """The 3K + 4 position and time-zero keys."""
    return ([f"source.position.{a}" for a in "xyz"]
            + [f"sensors.positions.{k}.{a}" for k in range(scene.sensor_count) for a in "xyz"] + ["sampling.start"])


def _scene(path, gaussian=None):
    scene = scene_of(path)
    return scene if gaussian is None else scene.replace(illumination=Illumination(waveform="gaussian", fwhm=gaussian))


def _timings(path, repeats, gaussian=None):
    """(forward wall, forward CPU, jacobian wall, jacobian CPU), seconds, best of ``repeats``."""
    scene = _scene(path, gaussian)
    keys = _keys(scene)
    return (*_best(lambda: forward(scene), repeats), *_best(lambda: jacobian(scene, keys), repeats))


def _baseline_timings(revision, paths, repeats, gaussian=None):
    """:func:`_timings` of each scene with ``revision``'s ``analytic`` (a subprocess on a ``git archive`` copy)."""
    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory(prefix="bench-jacobian-") as folder:
        archive = subprocess.run(["git", "archive", revision, "analytic"], cwd=root, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
        environment = dict(os.environ, PYTHONPATH=folder)
        result = subprocess.run([sys.executable, __file__, *paths, "--repeats", str(repeats), "--timings-only",
                                 *([] if gaussian is None else ["--gaussian", str(gaussian)])],
                                env=environment, check=True, capture_output=True, text=True)
    return json.loads(result.stdout)


def _column_error(computed, reference):
    scale = np.abs(reference).max(axis=1)
    gap = np.abs(computed - reference).max(axis=1)
    return float(np.max(np.where(scale > 0, gap / np.where(scale > 0, scale, 1.0), gap)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["examples/paper.toml", "examples/image.toml"])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--baseline", metavar="REF", help="also time this git revision's analytic (e.g. main)")
    parser.add_argument("--timings-only", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--gaussian", type=float, default=None, metavar="FWHM",
                        help="a Gaussian pulse of this FWHM (metres) instead of the scenes' illumination")
    args = parser.parse_args(argv)
    if args.timings_only:       # the baseline's subprocess: the timings as JSON, nothing else
        print(json.dumps({path: _timings(path, args.repeats, args.gaussian) for path in args.scenes}))
        return 0
    print(f"machine: {platform.node()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f} "
          f"(1 min average, at the start)")
    print("| scene | K, M, N | keys | forward s (CPU s) | jacobian s (CPU s) | ratio (CPU) | differences s | "
          "error exact | error differences |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in args.scenes:
        scene = _scene(path, args.gaussian)
        count = scene.sensor_count
        keys = _keys(scene)
        seconds_forward, cpu_forward, seconds_exact, cpu_exact = _timings(path, args.repeats, args.gaussian)
        exact = jacobian(scene, keys)
        started = time.perf_counter()
        differences = jacobian(scene, keys, route="differences")
        seconds_differences = time.perf_counter() - started
        sensor = min(5, count - 1)
        chosen = [0, 1, 2, 3 + 3 * sensor, 4 + 3 * sensor, 5 + 3 * sensor, len(keys) - 1]
        reference = jacobian(scene, [keys[i] for i in chosen], route="differences", step=2e-5)
        rows = [slice(None)] * 3 + [slice(sensor, sensor + 1)] * 3 + [slice(None)]
        error_exact = max(_column_error(exact[row, :, i], reference[row, :, j])
                          for j, (i, row) in enumerate(zip(chosen, rows)))
        error_differences = max(_column_error(differences[row, :, i], reference[row, :, j])
                                for j, (i, row) in enumerate(zip(chosen, rows)))
        name = path if args.gaussian is None else f"{path}, Gaussian {args.gaussian:g} m"
        print(f"| {name} | {count}, {scene.pixels}, {scene.sampling.count} | {len(keys)} | "
              f"{seconds_forward:.4f} ({cpu_forward:.4f}) | {seconds_exact:.4f} ({cpu_exact:.4f}) | "
              f"{seconds_exact / seconds_forward:.1f} ({cpu_exact / cpu_forward:.1f}) | "
              f"{seconds_differences:.1f} | {error_exact:.1e} | {error_differences:.1e} |")
    if args.baseline:
        current = {path: _timings(path, args.repeats, args.gaussian) for path in args.scenes}
        baseline = _baseline_timings(args.baseline, args.scenes, args.repeats, args.gaussian)
        print(f"\nthis code and {args.baseline}, timed one after the other (load {os.getloadavg()[0]:.2f}):\n")
        print("| scene | code | forward s (CPU s) | jacobian s (CPU s) | ratio (CPU) |")
        print("|---|---|---|---|---|")
        for path in args.scenes:
            for name, (wall_f, cpu_f, wall_j, cpu_j) in (("this", current[path]), (args.baseline, baseline[path])):
                print(f"| {path} | {name} | {wall_f:.4f} ({cpu_f:.4f}) | {wall_j:.4f} ({cpu_j:.4f}) | "
                      f"{wall_j / wall_f:.1f} ({cpu_j / cpu_f:.1f}) |")
    print(f"load at the end: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
