"""Efficiency of our relay-wall renderer against mitransient's transient_nlos_path on the same capture.

    python benchmarks/bench_nlos_render.py --out out/bench_nlos_render [--ours 65536 262144 1048576 4194304]
                                           [--theirs 16384 65536] [--repeats 4] [--strategy mis]
    python benchmarks/bench_nlos_render.py --out out/bench_nlos_strategies --near-wall

The capture: an 8 x 8 single scan of the default relay-wall scene (a 1 m
hidden square of the built-in pattern 1 m in front of a 2 m wall, lit at
the wall's centre), 140 bins of 1 cm, impulse. Both renderers are timed
after a warm-up render (kernels compiled), in this process (ours, at each
``--ours`` sample count) and in one subprocess (mitransient,
``llvm_ad_mono``, the scene as ``export --format mitransient`` writes it,
at each ``--theirs`` count of samples per read point), one after the other
on the same machine. ``--theirs`` with no value skips mitransient (to time
another version of ours back to back: run this script with that
version's folder first on PYTHONPATH).

Error: the RMS over every (pair, bin) of y_render - y_model, divided by the
model's largest bin (its peak), against the exact model, the mean error²
over ``--repeats`` renders of different seeds. Efficiency: 1 / (error² x
seconds), with the wall-clock seconds and, beside them, the process's CPU
seconds (all threads; steadier than wall time on a shared machine).
mitransient's renders also hold a bias (its ray offsets, docs/interop.md),
whose RMS (from :func:`validation.check.offset_model`) is reported beside
them: its variance part alone sets its efficiency and time, and the bias is
the floor no number of samples goes below.

Seconds to an RMS error of 1e-3 of the peak: mitransient's independent
samples have variance ∝ 1/samples, so seconds x variance / 1e-6. Ours are
stratified (error falling faster than 1/sqrt(samples)): interpolated
log-log between the two measured counts whose errors bracket 1e-3, else
extrapolated from the nearest count by the 1/sqrt law (an upper bound).

Per sample: nanoseconds per (sample, pair) for ours (each sample serves
every pair) and per path for mitransient (``spp`` paths per read point),
and the variance per sample, error² x samples (relative to the peak²).

``--near-wall`` instead measures our sampling strategies (area, l's solid
angle alone, MIS) on a single scan of a 0.6 x 0.5 m rectangle at 30, 15, 5,
2 and 0.5 cm from a 1 m wall, lit right below it and read on a 3 x 3 grid:
the mean squared error against the model over 6 seeds of 2^16 samples,
area's over each strategy's (docs/renderer.md quotes it).

Writes results.json in --out and prints the table docs/benchmarks.md quotes.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from analytic.files import save_json
from analytic.relay_wall import Scan, default_relay_wall_scene
from validation.bench import cpu_model

_MITRANSIENT = r"""
import json, sys, time
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_mono")
import mitransient
xml, repeats, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
timings = {}
for spp in (int(s) for s in sys.argv[4:]):
    scene = mi.load_file(xml, spp=spp)
    np.array(mi.render(scene, seed=10**6)[1])                       # compile
    timings[spp] = []
    for seed in range(repeats):
        started, cpu = time.perf_counter(), time.process_time()
        film = np.array(mi.render(scene, seed=seed)[1])
        timings[spp].append((time.perf_counter() - started, time.process_time() - cpu))
        np.save(f"{out}/film_{spp}_{seed}.npy", film)
print(json.dumps(timings))
"""

TARGET = 1e-3


def bench_scene():
    return default_relay_wall_scene(scan=Scan(type="single", grid=(8, 8)), name="bench-nlos")


def ours(scene, samples: int, repeats: int, estimator: dict):
    """Our transient_opl_nlos estimates (units of y) and their (wall, CPU) seconds, after a warm-up render."""
    from transient.backend import select_variant

    select_variant()
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import relay_wall_scene_dict

    loaded = mi.load_dict(relay_wall_scene_dict(scene, **estimator))
    integrator = loaded.integrator()
    layout = ReplicaLayout.for_samples(samples)

    def render(seed):
        sums = integrator.render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout, first=0,
                                                          count=layout.samples)
        return sums.sum(axis=0) / layout.samples * scene.intensity

    render(10**6)
    estimates, seconds = [], []
    for seed in range(repeats):
        started, cpu = time.perf_counter(), time.process_time()
        estimates.append(render(seed))
        seconds.append((time.perf_counter() - started, time.process_time() - cpu))
    return estimates, seconds


def theirs(scene, counts, repeats: int, out: Path):
    """mitransient's estimates of the exported scene and their (wall, CPU) seconds, per spp, after a warm-up."""
    import json

    from transient.backend import choose_libllvm, find_llvm_libraries
    from transient.export import export_scene
    from validation.check import read_data

    export_scene(scene, out / "xml", "mitransient")
    environment = os.environ | {"DRJIT_LIBLLVM_PATH": choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"),
                                                                     find_llvm_libraries())}
    done = subprocess.run([sys.executable, "-c", _MITRANSIENT, str(out / "xml" / "scene.xml"), str(repeats), str(out),
                           *(str(c) for c in counts)], capture_output=True, text=True, env=environment, timeout=3600)
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    timings = json.loads(done.stdout.strip().splitlines()[-1])
    return {int(spp): ([read_data(out / f"film_{spp}_{seed}.npy", scene) for seed in range(repeats)], seconds)
            for spp, seconds in timings.items()}


def summary(name: str, samples: int, evaluations: int, estimates, seconds, model, bias: float = 0.0) -> dict:
    """One row: errors, seconds, efficiencies, cost per evaluation and variance per sample."""
    peak = float(model.max())
    error2 = float(np.mean([np.mean((estimate - model) ** 2) for estimate in estimates])) / peak**2
    wall, cpu = (float(np.mean([s[i] for s in seconds])) for i in (0, 1))
    variance = max(error2 - bias**2, 0.0)
    return {"renderer": name, "samples": samples, "seconds": wall, "cpu_seconds": cpu,
            "rms_error_of_peak": math.sqrt(error2), "bias_rms_of_peak": bias,
            "efficiency": 1.0 / (variance * wall), "efficiency_cpu": 1.0 / (variance * cpu),
            "ns_per_evaluation": 1e9 * wall / evaluations, "cpu_ns_per_evaluation": 1e9 * cpu / evaluations,
            "variance_per_sample": variance * samples}


def seconds_to_target(rows, stratified: bool) -> float:
    """Seconds to an RMS error of TARGET (variance part), by the rule of the module docstring."""
    points = sorted((r["samples"], r["seconds"], math.sqrt(r["variance_per_sample"] / r["samples"])) for r in rows)
    if stratified:
        for (_, t0, e0), (_, t1, e1) in zip(points, points[1:]):
            if e1 <= TARGET <= e0 and e1 < e0:
                fraction = math.log(e0 / TARGET) / math.log(e0 / e1)
                return math.exp(math.log(t0) + fraction * math.log(t1 / t0))
        nearest = min(points, key=lambda p: abs(math.log(p[2] / TARGET)))
        return nearest[1] * (nearest[2] / TARGET) ** 2
    return float(np.mean([t * (e / TARGET) ** 2 for _, t, e in points]))


def near_wall_strategies(samples: int = 2**16, seeds: int = 6) -> list[dict]:
    """Each strategy's variance gain over area sampling on near-wall single scans (module docstring)."""
    from analytic.relay_wall import RelayWallScene
    from analytic.scene import Sampling
    from analytic.system import forward
    from analytic.window import pairs_range

    rows = []
    for distance in (0.3, 0.15, 0.05, 0.02, 0.005):
        scene = RelayWallScene(pixels=4, reflectance=np.linspace(0.2, 1.0, 16).reshape(4, 4),
                               center=(0.05, 0.0, distance), u=(0.6, 0.0, 0.0), v=(0.0, -0.5, 0.0),
                               wall_size=(1.0, 1.0), scan=Scan(type="single", grid=(3, 3), laser_point=(0.1, 0.05, 0.0)))
        low, high = pairs_range(*scene.geometry())
        scene = scene.replace(sampling=Sampling(bin_width_opl=0.02, start_opl=low - 0.02,
                                                count=int((high - low) / 0.02) + 3))
        model = forward(scene)
        error2 = {strategy: float(np.mean([np.mean((estimate - model) ** 2) for estimate in
                                           ours(scene, samples, seeds, {"strategy": strategy})[0]]))
                  for strategy in ("area", "source", "mis")}
        rows.append({"distance": distance, "techniques": len(_plan(scene)),
                     **{f"gain_{strategy}": error2["area"] / error2[strategy] for strategy in error2}})
    return rows


def _plan(scene):
    import mitsuba as mi

    from transient.mitsuba_scene import relay_wall_scene_dict

    return mi.load_dict(relay_wall_scene_dict(scene)).integrator().plan


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--ours", type=int, nargs="+", default=[2**16, 2**18, 2**20, 2**22],
                        help="our samples per render (each serves every pair)")
    parser.add_argument("--theirs", type=int, nargs="*", default=[2**14, 2**16],
                        help="mitransient's samples per read point (none: skip mitransient)")
    parser.add_argument("--repeats", type=int, default=4)
    parser.add_argument("--strategy", default=None, help="our sampling strategy (default: the plugin's)")
    parser.add_argument("--label", default="ours (transient_opl_nlos)")
    parser.add_argument("--near-wall", action="store_true", help="measure our strategies on near-wall scans instead")
    args = parser.parse_args(argv)
    if args.near_wall:
        rows = near_wall_strategies()
        print(f"machine: {cpu_model()}; squared error of area sampling over each strategy's, 6 seeds of 2^16 samples")
        print("| rectangle's distance to the wall (m) | techniques (mis) | l's solid angle | MIS |")
        print("|---|---|---|---|")
        for row in rows:
            print(f"| {row['distance']} | {row['techniques']} | {row['gain_source']:.3g} | {row['gain_mis']:.3g} |")
        args.out.mkdir(parents=True, exist_ok=True)
        save_json(args.out / "results.json", {"machine": cpu_model(), "near_wall": rows})
        return 0
    from analytic.system import forward
    from validation.check import offset_model

    scene = bench_scene()
    model = forward(scene)
    pairs = scene.sensor_count
    estimator = {} if args.strategy is None else {"strategy": args.strategy}
    load = os.getloadavg()[0]
    rows = [summary(args.label, n, n * pairs, *ours(scene, n, args.repeats, estimator), model) for n in args.ours]
    theirs_rows = []
    if args.theirs:
        args.out.mkdir(parents=True, exist_ok=True)
        bias = float(np.sqrt(np.mean((offset_model(scene) - model) ** 2)) / model.max())
        theirs_rows = [summary("mitransient (transient_nlos_path)", spp, spp * pairs, estimates, seconds, model, bias)
                       for spp, (estimates, seconds) in theirs(scene, args.theirs, args.repeats, args.out).items()]
    results = {"machine": cpu_model(), "load_average_at_start": load, "load_average_at_end": os.getloadavg()[0],
               "scene": "8 x 8 single scan, 140 bins of 1 cm, 32 x 32 hidden image", "repeats": args.repeats,
               "ours": rows, "theirs": theirs_rows, "ours_seconds_to_1e-3": seconds_to_target(rows, True)}
    print(f"machine: {cpu_model()}; load average {load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")
    print(f"capture: {results['scene']}; error = RMS of (render - model) over pairs and bins / the model's peak")
    print("| renderer | samples | seconds (CPU) | RMS error / peak | bias RMS / peak | efficiency 1/(error² s) "
          "(CPU s) | ns per evaluation (CPU) | variance per sample |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows + theirs_rows:
        unit = "every pair" if row in rows else "per point"
        print(f"| {row['renderer']} | {row['samples']} ({unit}) | {row['seconds']:.3g} ({row['cpu_seconds']:.3g}) | "
              f"{row['rms_error_of_peak']:.3e} | {row['bias_rms_of_peak']:.1e} | {row['efficiency']:.3e} "
              f"({row['efficiency_cpu']:.3e}) | {row['ns_per_evaluation']:.3g} ({row['cpu_ns_per_evaluation']:.3g}) | "
              f"{row['variance_per_sample']:.3e} |")
    print(f"seconds to 1e-3: ours {results['ours_seconds_to_1e-3']:.3g}")
    if theirs_rows:
        results["theirs_seconds_to_1e-3"] = seconds_to_target(theirs_rows, False)
        reference = {key: float(np.mean([r[key] for r in theirs_rows])) for key in ("efficiency", "efficiency_cpu")}
        results["efficiency_ratios"] = [{"samples": r["samples"], "wall": r["efficiency"] / reference["efficiency"],
                                         "cpu": r["efficiency_cpu"] / reference["efficiency_cpu"]} for r in rows]
        print(f"seconds to 1e-3: mitransient {results['theirs_seconds_to_1e-3']:.3g} (its variance alone)")
        for ratio in results["efficiency_ratios"]:
            print(f"efficiency ratio at {ratio['samples']} of our samples (over mitransient's mean, variance alone): "
                  f"{ratio['wall']:.3g} wall, {ratio['cpu']:.3g} CPU")
    args.out.mkdir(parents=True, exist_ok=True)
    save_json(args.out / "results.json", results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
