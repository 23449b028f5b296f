"""Efficiency of our relay-wall renderer against mitransient's transient_nlos_path on the same capture.

    python benchmarks/bench_nlos_render.py --out out/bench_nlos_render [--ours 65536] [--theirs 16384]
                                           [--repeats 4]

The capture: an 8 x 8 single scan of the default relay-wall scene (a 1 m
hidden square of the built-in pattern 1 m in front of a 2 m wall, lit at
the wall's centre), 140 bins of 1 cm, impulse. Both renderers are timed
after a warm-up render (kernels compiled), in this process (ours) and in
one subprocess (mitransient, ``llvm_ad_mono``, the scene as ``export
--format mitransient`` writes it), one after the other on the same machine.

Error: the RMS over every (pair, bin) of y_render - y_model, divided by the
model's largest bin (its peak), against the exact model. Efficiency:
1 / (error² x seconds), from the mean error² over ``--repeats`` renders of
different seeds. The time to an RMS error of 1e-3 of the peak is
seconds x (error / 1e-3)² for an unbiased renderer; mitransient's renders
also hold a bias (its ray offsets, docs/interop.md), whose RMS (from
:func:`validation.check.offset_model`) is reported beside them: its
variance part alone sets its efficiency and time, and the bias is the
floor no number of samples goes below.

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
xml, spp, repeats, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
scene = mi.load_file(xml, spp=spp)
np.array(mi.render(scene, seed=10**6)[1])                       # compile
seconds = []
for seed in range(repeats):
    started = time.perf_counter()
    film = np.array(mi.render(scene, seed=seed)[1])
    seconds.append(time.perf_counter() - started)
    np.save(f"{out}/film_{seed}.npy", film)
print(json.dumps(seconds))
"""

TARGET = 1e-3


def bench_scene():
    return default_relay_wall_scene(scan=Scan(type="single", grid=(8, 8)), name="bench-nlos")


def ours(scene, samples: int, repeats: int) -> tuple[list[np.ndarray], list[float]]:
    """Our transient_opl_nlos estimates (units of y) and their seconds, after a warm-up render."""
    from transient.backend import select_variant

    select_variant()
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import relay_wall_scene_dict

    loaded = mi.load_dict(relay_wall_scene_dict(scene))
    integrator = loaded.integrator()
    layout = ReplicaLayout.for_samples(samples)

    def render(seed):
        sums = integrator.render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout, first=0,
                                                          count=layout.samples)
        return sums.sum(axis=0) / layout.samples * scene.intensity

    render(10**6)
    estimates, seconds = [], []
    for seed in range(repeats):
        started = time.perf_counter()
        estimates.append(render(seed))
        seconds.append(time.perf_counter() - started)
    return estimates, seconds


def theirs(scene, spp: int, repeats: int, out: Path) -> tuple[list[np.ndarray], list[float]]:
    """mitransient's estimates of the exported scene and their seconds, after a warm-up render."""
    import json

    from transient.backend import choose_libllvm, find_llvm_libraries
    from transient.export import export_scene
    from validation.check import read_data

    export_scene(scene, out / "xml", "mitransient")
    environment = os.environ | {"DRJIT_LIBLLVM_PATH": choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"),
                                                                     find_llvm_libraries())}
    done = subprocess.run([sys.executable, "-c", _MITRANSIENT, str(out / "xml" / "scene.xml"), str(spp),
                           str(repeats), str(out)], capture_output=True, text=True, env=environment, timeout=3600)
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    seconds = json.loads(done.stdout.strip().splitlines()[-1])
    return [read_data(out / f"film_{seed}.npy", scene) for seed in range(repeats)], seconds


def summary(name: str, estimates, seconds, model, bias: float = 0.0) -> dict:
    peak = float(model.max())
    squared = [float(np.mean((estimate - model) ** 2)) / peak**2 for estimate in estimates]
    error2, time_ = float(np.mean(squared)), float(np.mean(seconds))
    variance = max(error2 - bias**2, 0.0)
    return {"renderer": name, "seconds": time_, "rms_error_of_peak": math.sqrt(error2), "bias_rms_of_peak": bias,
            "efficiency": 1.0 / (error2 * time_), "efficiency_variance_only": 1.0 / (variance * time_),
            "seconds_to_1e-3": (time_ * variance / TARGET**2) if bias < TARGET else math.inf}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--ours", type=int, default=2**16, help="our samples per render (each serves every pair)")
    parser.add_argument("--theirs", type=int, default=2**14, help="mitransient's samples per read point")
    parser.add_argument("--repeats", type=int, default=4)
    args = parser.parse_args(argv)
    from analytic.system import forward
    from validation.check import offset_model

    scene = bench_scene()
    model = forward(scene)
    bias = float(np.sqrt(np.mean((offset_model(scene) - model) ** 2)) / model.max())
    load = os.getloadavg()[0]
    ours_result = summary("ours (transient_opl_nlos)", *ours(scene, args.ours, args.repeats), model)
    args.out.mkdir(parents=True, exist_ok=True)
    theirs_result = summary("mitransient (transient_nlos_path)", *theirs(scene, args.theirs, args.repeats, args.out),
                            model, bias)
    ratio = ours_result["efficiency"] / theirs_result["efficiency_variance_only"]
    results = {"machine": cpu_model(), "load_average_at_start": load, "load_average_at_end": os.getloadavg()[0],
               "scene": "8 x 8 single scan, 140 bins of 1 cm, 32 x 32 hidden image", "ours_samples": args.ours,
               "theirs_spp": args.theirs, "repeats": args.repeats, "ours": ours_result, "theirs": theirs_result,
               "efficiency_ratio": ratio}
    save_json(args.out / "results.json", results)
    print(f"machine: {cpu_model()}; load average {load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")
    print(f"capture: {results['scene']}; error = RMS of (render - model) over pairs and bins / the model's peak")
    print(f"| renderer | samples | seconds | RMS error / peak | bias RMS / peak | efficiency 1/(error² s) | "
          f"seconds to 1e-3 |")
    print("|---|---|---|---|---|---|---|")
    for result, samples in ((ours_result, f"{args.ours} (every pair)"), (theirs_result, f"{args.theirs} per point")):
        print(f"| {result['renderer']} | {samples} | {result['seconds']:.3g} | {result['rms_error_of_peak']:.3e} | "
              f"{result['bias_rms_of_peak']:.1e} | {result['efficiency_variance_only']:.3e} | "
              f"{result['seconds_to_1e-3']:.3g} |")
    print(f"efficiency ratio (ours / mitransient's variance alone): {ratio:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
