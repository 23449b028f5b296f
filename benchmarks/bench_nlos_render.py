"""Efficiency of our relay-wall renderer against mitransient's transient_nlos_path on the same capture.

    python benchmarks/bench_nlos_render.py --out out/bench_nlos_render [--ours 65536 262144 1048576 4194304]
                                           [--theirs 16384 65536] [--repeats 4] [--strategy mis]
                                           [--variant cuda_ad_mono] [--model out/bench_nlos_render/model.npz]
    python benchmarks/bench_nlos_render.py --out out/bench_nlos_quick --quick
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

``--variant`` (default: :func:`transient.backend.select_variant`'s,
``llvm_ad_mono``) is the Mitsuba variant of both renderers: ours runs in
it and mitransient's subprocess sets it, so ``--variant cuda_ad_mono``
compares the two on one GPU. The exact model (and mitransient's bias) is
computed once and saved as ``model.npz`` in ``--out``; ``--model`` reads
such a file instead (checked against the capture), for a machine where
Numba's first compilation would cost minutes. Without the OpenEXR module
the exported texture is written by Mitsuba's own EXR writer.

``--quick`` is a smoke test, not a measurement: 2^12 and 2^14 of our
samples, 2^8 of mitransient's per read point, 2 repeats (each unless
given), in well under a minute on 2 CPU cores.

Error: the RMS over every (pair, bin) of y_render - y_model, divided by the
model's largest bin (its peak), against the exact model, the mean error²
over ``--repeats`` renders of different seeds. Efficiency: 1 / (error² x
seconds), with the wall-clock seconds and, beside them, the process's CPU
seconds (all threads; steadier than wall time on a shared machine).
mitransient's renders also hold a bias (its ray offsets, docs/interop.md),
whose RMS (from :func:`interop.mitransient.offset_model`) is reported beside
them: its variance part alone sets its efficiency and time, and the bias is
the floor no number of samples goes below.

Seconds to an RMS error of 1e-3 of the peak: mitransient's independent
samples have variance ∝ 1/samples, so seconds x variance / 1e-6. Ours are
stratified (error falling faster than 1/sqrt(samples)): interpolated
log-log between the two measured counts whose errors bracket 1e-3, else
extrapolated from the nearest count by the 1/sqrt law (an upper bound).
Both by wall-clock and by CPU seconds (a shared machine's load stretches
the wall-clock of a multi-threaded render most).

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
from analytic.scenes.relay_wall import Scan, default_relay_wall_scene
from validation.runs.bench import cpu_model

_MITRANSIENT = r"""
import json, sys, time
import numpy as np, mitsuba as mi
mi.set_variant(sys.argv[1])
import mitransient
xml, repeats, out = sys.argv[2], int(sys.argv[3]), sys.argv[4]
timings = {}
for spp in (int(s) for s in sys.argv[5:]):
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

#: ``--quick``'s counts (a smoke test of every step, not a measurement).
QUICK = {"ours": [2**12, 2**14], "theirs": [2**8], "repeats": 2}
#: The full run's defaults (docs/benchmarks.md's table).
FULL = {"ours": [2**16, 2**18, 2**20, 2**22], "theirs": [2**14, 2**16], "repeats": 4}


def bench_scene():
    return default_relay_wall_scene(scan=Scan(type="single", grid=(8, 8)), name="bench-nlos")


def ours(scene, samples: int, repeats: int, estimator: dict, variant: str | None = None):
    """Our transient_opl_nlos estimates (units of y) and their (wall, CPU) seconds, after a warm-up render."""
    from transient.backend import select_variant

    select_variant(variant)
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


def theirs(scene, counts, repeats: int, out: Path, variant: str):
    """mitransient's estimates of the exported scene and their (wall, CPU) seconds, per spp, after a warm-up."""
    import json

    from transient.backend import choose_libllvm, find_llvm_libraries
    from validation.check import read_data

    export_for_mitransient(scene, out / "xml")
    environment = dict(os.environ)
    if variant.startswith("llvm_"):
        environment["DRJIT_LIBLLVM_PATH"] = choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"),
                                                           find_llvm_libraries())
    done = subprocess.run([sys.executable, "-c", _MITRANSIENT, variant, str(out / "xml" / "scene.xml"), str(repeats),
                           str(out), *(str(c) for c in counts)], capture_output=True, text=True, env=environment,
                          timeout=3600)
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    timings = json.loads(done.stdout.strip().splitlines()[-1])
    return {int(spp): ([read_data(out / f"film_{spp}_{seed}.npy", scene) for seed in range(repeats)], seconds)
            for spp, seconds in timings.items()}


def export_for_mitransient(scene, folder: Path) -> None:
    """``export --format mitransient`` into ``folder``; without the OpenEXR module (as on the GPU machines),
    the texture is written by Mitsuba's own EXR writer instead and read back."""
    from unittest import mock

    import analytic.files
    from interop.mitransient.export import export_scene

    try:
        import OpenEXR  # noqa: F401
    except ImportError:
        with mock.patch.object(analytic.files, "save_exr", _save_exr_with_mitsuba):
            export_scene(scene, folder, "mitransient")
        return
    export_scene(scene, folder, "mitransient")


def _save_exr_with_mitsuba(path, image, attributes=None) -> Path:
    """A one-channel float32 EXR by ``mi.Bitmap.write`` (the benchmark's fallback for a missing OpenEXR)."""
    import mitsuba as mi

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pixels = np.ascontiguousarray(image, dtype=np.float32)
    mi.Bitmap(pixels[..., None], mi.Bitmap.PixelFormat.Y).write(str(path))
    back = np.array(mi.Bitmap(str(path)), dtype=np.float32).reshape(pixels.shape)
    if not np.array_equal(back, pixels):
        raise RuntimeError(f"{path}: the EXR Mitsuba wrote reads back different")
    return path


def exact_model(scene, path: Path | None, out: Path, bias: bool):
    """(The exact model (P, N), mitransient's bias RMS / peak or None): from ``path`` (``--model``), else computed;
    saved to ``out/model.npz`` either way."""
    if path is not None:
        with np.load(path) as saved:
            model, name = saved["model"], str(saved["scene"])
            offset = saved["offset"] if "offset" in saved.files else None
        if model.shape != (scene.sensor_count, scene.sampling.count) or name != scene.name:
            raise SystemExit(f"{path}: not the model of this capture ({scene.name}, {scene.sensor_count} pairs x "
                             f"{scene.sampling.count} bins)")
    else:
        from analytic.operator.matrix_free import forward

        model, offset = forward(scene), None
    if bias and offset is None:
        from interop.mitransient import offset_model

        offset = offset_model(scene)
    out.mkdir(parents=True, exist_ok=True)
    arrays = {"model": model, "scene": np.array(scene.name)} | ({} if offset is None else {"offset": offset})
    np.savez(out / "model.npz", **arrays)
    return model, (None if offset is None else float(np.sqrt(np.mean((offset - model) ** 2)) / model.max()))


def device(variant: str) -> str:
    """The machine: the CPU, and for a CUDA variant the GPU (nvidia-smi's name, if it answers)."""
    if not variant.startswith("cuda_"):
        return cpu_model()
    try:
        done = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                              text=True, timeout=30)
        gpu = done.stdout.strip().splitlines()[0]
    except (OSError, IndexError, subprocess.SubprocessError):
        gpu = "a CUDA GPU"
    return f"{gpu} (host {cpu_model()})"


def summary(name: str, samples: int, evaluations: int, estimates, seconds, model, bias: float | None = None) -> dict:
    """One row: errors, seconds, efficiencies, cost per evaluation and variance per sample.

    ``bias``: the renderer's known bias RMS / peak (mitransient's), None for ours (unbiased: not
    measured, taken as 0). An error at or below the bias leaves no variance to measure: inf efficiency.
    """
    peak = float(model.max())
    error2 = float(np.mean([np.mean((estimate - model) ** 2) for estimate in estimates])) / peak**2
    wall, cpu = (float(np.mean([s[i] for s in seconds])) for i in (0, 1))
    variance = max(error2 - (bias or 0.0)**2, 0.0)
    efficiency = (lambda time: 1.0 / (variance * time) if variance > 0 else math.inf)
    return {"renderer": name, "samples": samples, "seconds": wall, "cpu_seconds": cpu,
            "rms_error_of_peak": math.sqrt(error2), "bias_rms_of_peak": bias,
            "efficiency": efficiency(wall), "efficiency_cpu": efficiency(cpu),
            "ns_per_evaluation": 1e9 * wall / evaluations, "cpu_ns_per_evaluation": 1e9 * cpu / evaluations,
            "variance_per_sample": variance * samples}


def seconds_to_target(rows, stratified: bool, clock: str = "seconds") -> float:
    """Seconds to an RMS error of TARGET (variance part), by the rule of the module docstring, on ``clock``
    (``seconds``: wall; ``cpu_seconds``: the process's CPU)."""
    points = sorted((r["samples"], r[clock], math.sqrt(r["variance_per_sample"] / r["samples"])) for r in rows)
    if stratified:
        for (_, t0, e0), (_, t1, e1) in zip(points, points[1:]):
            if e1 <= TARGET <= e0 and e1 < e0:
                fraction = math.log(e0 / TARGET) / math.log(e0 / e1)
                return math.exp(math.log(t0) + fraction * math.log(t1 / t0))
        nearest = min(points, key=lambda p: abs(math.log(p[2] / TARGET)))
        return nearest[1] * (nearest[2] / TARGET) ** 2
    return float(np.mean([t * (e / TARGET) ** 2 for _, t, e in points]))


def near_wall_strategies(variant: str | None = None, samples: int = 2**16, seeds: int = 6) -> list[dict]:
    """Each strategy's variance gain over area sampling on near-wall single scans (module docstring)."""
    from analytic.scenes.relay_wall import RelayWallScene
    from analytic.scenes.common import Sampling
    from analytic.operator.matrix_free import forward
    from analytic.operator.window import pairs_range

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
                                           ours(scene, samples, seeds, {"strategy": strategy}, variant)[0]]))
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
    parser.add_argument("--ours", type=int, nargs="+", default=None,
                        help="our samples per render (each serves every pair); default 2^16 2^18 2^20 2^22")
    parser.add_argument("--theirs", type=int, nargs="*", default=None,
                        help="mitransient's samples per read point (none: skip mitransient); default 2^14 2^16")
    parser.add_argument("--repeats", type=int, default=None, help="renders of different seeds per count (default 4)")
    parser.add_argument("--strategy", default=None, help="our sampling strategy (default: the plugin's)")
    parser.add_argument("--variant", default=None,
                        help="Mitsuba variant of both renderers, e.g. cuda_ad_mono (default: llvm_ad_mono)")
    parser.add_argument("--model", type=Path, default=None,
                        help="the exact model from an earlier run's model.npz (default: computed here)")
    parser.add_argument("--quick", action="store_true", help="a smoke test with small counts (not a measurement)")
    parser.add_argument("--label", default="ours (transient_opl_nlos)")
    parser.add_argument("--near-wall", action="store_true", help="measure our strategies on near-wall scans instead")
    args = parser.parse_args(argv)
    if args.near_wall:
        ignored = [flag for flag, given in (("--quick", args.quick), ("--model", args.model), ("--ours", args.ours),
                                            ("--theirs", args.theirs), ("--repeats", args.repeats),
                                            ("--strategy", args.strategy)) if given]
        if ignored:
            parser.error(f"--near-wall measures its own fixed cases; leave out {', '.join(ignored)}")
    for key, value in (QUICK if args.quick else FULL).items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    from transient.backend import BackendError, select_variant

    try:
        variant = select_variant(args.variant)       # before anything imports Dr.Jit
    except BackendError as error:
        raise SystemExit(f"bench_nlos_render: {error}") from None
    if args.near_wall:
        rows = near_wall_strategies(variant)
        print(f"machine: {device(variant)}; squared error of area sampling over each strategy's, 6 seeds of 2^16 "
              f"samples")
        print("| rectangle's distance to the wall (m) | techniques (mis) | l's solid angle | MIS |")
        print("|---|---|---|---|")
        for row in rows:
            print(f"| {row['distance']} | {row['techniques']} | {row['gain_source']:.3g} | {row['gain_mis']:.3g} |")
        args.out.mkdir(parents=True, exist_ok=True)
        save_json(args.out / "results.json", {"machine": device(variant), "variant": variant, "near_wall": rows})
        return 0
    scene = bench_scene()
    model, bias = exact_model(scene, args.model, args.out, bool(args.theirs))
    pairs = scene.sensor_count
    estimator = {} if args.strategy is None else {"strategy": args.strategy}
    load = os.getloadavg()[0]
    rows = [summary(args.label, n, n * pairs, *ours(scene, n, args.repeats, estimator, variant), model)
            for n in args.ours]
    theirs_rows = []
    if args.theirs:
        theirs_rows = [summary("mitransient (transient_nlos_path)", spp, spp * pairs, estimates, seconds, model, bias)
                       for spp, (estimates, seconds) in theirs(scene, args.theirs, args.repeats, args.out,
                                                               variant).items()]
    results = {"machine": device(variant), "variant": variant, "quick": args.quick, "load_average_at_start": load, "load_average_at_end": os.getloadavg()[0],
               "scene": "8 x 8 single scan, 140 bins of 1 cm, 32 x 32 hidden image", "repeats": args.repeats,
               "ours": rows, "theirs": theirs_rows, "ours_seconds_to_1e-3": seconds_to_target(rows, True),
               "ours_cpu_seconds_to_1e-3": seconds_to_target(rows, True, "cpu_seconds")}
    print(f"machine: {results['machine']}; variant {variant}; load average {load:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end{'; --quick: a smoke test, not a measurement' if args.quick else ''}")
    print(f"capture: {results['scene']}; error = RMS of (render - model) over pairs and bins / the model's peak")
    print("| renderer | samples | seconds (CPU) | RMS error / peak | bias RMS / peak | efficiency 1/(error² s) "
          "(CPU s) | ns per evaluation (CPU) | variance per sample |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows + theirs_rows:
        unit = "every pair" if row in rows else "per point"
        print(f"| {row['renderer']} | {row['samples']} ({unit}) | {row['seconds']:.3g} ({row['cpu_seconds']:.3g}) | "
              f"{row['rms_error_of_peak']:.3e} | "
              f"{'- (unbiased)' if row['bias_rms_of_peak'] is None else format(row['bias_rms_of_peak'], '.1e')} | "
              f"{row['efficiency']:.3e} "
              f"({row['efficiency_cpu']:.3e}) | {row['ns_per_evaluation']:.3g} ({row['cpu_ns_per_evaluation']:.3g}) | "
              f"{row['variance_per_sample']:.3e} |")
    print(f"seconds to 1e-3: ours {results['ours_seconds_to_1e-3']:.3g} "
          f"({results['ours_cpu_seconds_to_1e-3']:.3g} CPU)")
    if theirs_rows:
        results["theirs_seconds_to_1e-3"] = seconds_to_target(theirs_rows, False)
        results["theirs_cpu_seconds_to_1e-3"] = seconds_to_target(theirs_rows, False, "cpu_seconds")
        reference = {key: float(np.mean([r[key] for r in theirs_rows])) for key in ("efficiency", "efficiency_cpu")}
        results["efficiency_ratios"] = [{"samples": r["samples"], "wall": r["efficiency"] / reference["efficiency"],
                                         "cpu": r["efficiency_cpu"] / reference["efficiency_cpu"]} for r in rows]
        print(f"seconds to 1e-3: mitransient {results['theirs_seconds_to_1e-3']:.3g} "
              f"({results['theirs_cpu_seconds_to_1e-3']:.3g} CPU; its variance alone): ours "
              f"{results['theirs_seconds_to_1e-3'] / results['ours_seconds_to_1e-3']:.3g} x sooner "
              f"({results['theirs_cpu_seconds_to_1e-3'] / results['ours_cpu_seconds_to_1e-3']:.3g} x in CPU seconds)")
        for ratio in results["efficiency_ratios"]:
            print(f"efficiency ratio at {ratio['samples']} of our samples (over mitransient's mean, variance alone): "
                  f"{ratio['wall']:.3g} wall, {ratio['cpu']:.3g} CPU")
    args.out.mkdir(parents=True, exist_ok=True)
    save_json(args.out / "results.json", results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
