"""Convergence, calibration and tails of the renderer against the exact model, hard geometry included.

    python benchmarks/convergence_render.py --out out/convergence [--min-power 16] [--max-power 26]

For the 1 m plane of the bench, the default scene, a source 1e-3 m above
the plane, a sensor 1e-3 m above it, and the suite's ``low`` case (both),
each with the stratified sampler (what ``render`` uses) and with
independent points (the unstratified rate), renders 2^min ... 2^max
samples with several seeds and reports:

- the RMS over seeds of the relative L2 error and the fitted slope of
  log(error) against log(samples) with its standard error (an unbiased
  unstratified estimator gives -1/2; stratification gives down to -3/4
  where the integrand has edges);
- calibration: RMS error over the RMS of the predicted error
  sqrt(Σ se²) / ||y|| (1 when the replicas' standard errors are honest);
- tails: the excess kurtosis of the standardised replica means pooled
  over the judged bins (about 0 for normal replica means; a heavy-tailed
  estimator gives large values) and the largest |z| of the replica means.

Writes results.json and convergence.png in --out; prints a table.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from analytic.files import save_json
from analytic.scenes.common import Sampling, Scene, default_scene
from analytic.operator.system import QuadratureWarning
from analytic.operator.matrix_free import forward
from transient.backend import select_variant
from transient.chunks import ChunkPlan, ReplicaLayout
from validation.runs.bench import plane_scene
from analytic.operator.window import response_range
from validation.runs.suite import hard_cases


def low_scene(which: str) -> Scene:
    """The bench's 1 m plane with the source (or the sensor) 1e-3 m above it."""
    source, sensor = (0.5, 0.5, 1.0), (0.8, 0.3, 1.0)
    if which == "source":
        source = (0.3, 0.4, 1e-3)
    else:
        sensor = (0.7, 0.6, 1e-3)
    scene = Scene(name=f"low {which}", size=1.0, pixels=10, reflectance=hard_cases(pixels=10)["low"].reflectance,
                  source=source, sensors=[sensor])
    low, high = response_range(scene)
    count = 40
    period = (high - low) / (count - 4)
    return scene.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - 2 * period, count=count))


def replica_means(loaded, layout: ReplicaLayout, seed: int) -> tuple[np.ndarray, float]:
    """``(R, K, N)`` replica means of one render, and its wall time in seconds."""
    integrator = loaded.integrator()
    shape = (len(loaded.sensors()), integrator.bins)
    sums = np.zeros((layout.replicas,) + shape)
    started = time.perf_counter()
    for chunk in ChunkPlan(layout, 2**22):
        part = integrator.render_chunk(loaded, seed=seed, layout=layout, first=chunk.first, count=chunk.count)
        rows = chunk.replicas(layout)
        sums[rows.start:rows.stop] += part
    return sums / layout.size, time.perf_counter() - started


def measure(scene: Scene, sampler: str, powers, seeds: int) -> dict:
    from transient.mitsuba_scene import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadratureWarning)
        model = forward(scene)
    norm = float(np.linalg.norm(model))
    loaded = load_scene(scene, sampler=sampler)
    replica_means(loaded, ReplicaLayout.for_samples(2**12), 0)      # compile
    rows = []
    for power in powers:
        errors, predicted, seconds, standardised, largest = [], [], [], [], 0.0
        for s in range(seeds):
            means, elapsed = replica_means(loaded, ReplicaLayout.for_samples(2**power), 100 * power + s)
            replicas = means.shape[0]
            mean = means.mean(axis=0)
            spread = means.std(axis=0, ddof=1)
            judged = spread > 0
            se = spread / np.sqrt(replicas)
            judged &= se < 0.1 * np.abs(mean)
            errors.append(np.linalg.norm(mean - model) / norm)
            predicted.append(np.linalg.norm(se) / norm)
            seconds.append(elapsed)
            if judged.any():
                u = (means[:, judged] - mean[judged]) / spread[judged]
                standardised.append(u.ravel())
                z = (means[:, judged] - model[judged]) / spread[judged]
                largest = max(largest, float(np.max(np.abs(z))))
        pooled = np.concatenate(standardised) if standardised else np.zeros(1)
        rows.append({"samples": 2**power, "rms_error": float(np.sqrt(np.mean(np.square(errors)))),
                     "rms_predicted": float(np.sqrt(np.mean(np.square(predicted)))),
                     "seconds": float(np.mean(seconds)),
                     "replica_excess_kurtosis": float(np.mean(pooled**4) - 3.0),
                     "replica_max_abs_z": largest})
    x = np.log([r["samples"] for r in rows])
    y = np.log([r["rms_error"] for r in rows])
    slope, intercept = np.polyfit(x, y, 1)
    design = np.column_stack([x, np.ones_like(x)])
    sigma2 = float(np.sum((y - design @ [slope, intercept]) ** 2)) / max(len(x) - 2, 1)
    slope_error = float(np.sqrt(sigma2 * np.linalg.inv(design.T @ design)[0, 0]))
    return {"scene": scene.name, "sampler": sampler, "rows": rows, "slope": float(slope),
            "slope_error": slope_error, "decades": float(np.log10(rows[-1]["samples"] / rows[0]["samples"]))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/convergence")
    parser.add_argument("--min-power", type=int, default=16)
    parser.add_argument("--max-power", type=int, default=26)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--scenes", default="plane,default,low source,low sensor,low",
                        help="comma-separated: plane, default, low source, low sensor, low")
    parser.add_argument("--samplers", default="stratified,independent")
    args = parser.parse_args(argv)
    select_variant()
    builders = {"plane": plane_scene, "default": lambda: default_scene(noise=None),
                "low source": lambda: low_scene("source"), "low sensor": lambda: low_scene("sensor"),
                "low": lambda: hard_cases(pixels=10)["low"]}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    powers = range(args.min_power, args.max_power + 1, 2)
    results = []
    print("| scene | sampler | slope (± se) over decades | error at 2^max | calibration | excess kurtosis | max abs z |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        for sampler in args.samplers.split(","):
            result = measure(builders[name](), sampler, powers, args.seeds)
            results.append(result)
            last = result["rows"][-1]
            kurtosis = max(r["replica_excess_kurtosis"] for r in result["rows"])
            print(f"| {name} | {sampler} | {result['slope']:.3f} ± {result['slope_error']:.3f} over "
                  f"{result['decades']:.1f} | {last['rms_error']:.2e} | "
                  f"{last['rms_error'] / last['rms_predicted']:.2f} | {kurtosis:.2f} | "
                  f"{max(r['replica_max_abs_z'] for r in result['rows']):.1f} |", flush=True)
            save_json(out / "results.json", {"powers": list(powers), "seeds": args.seeds, "results": results})
    _plot(out / "convergence.png", results)
    return 0


def _plot(path, results):
    from validation.plots import new_figure, save_figure

    figure = new_figure(6, 4)
    axis = figure.add_subplot()
    for result in results:
        samples = np.array([r["samples"] for r in result["rows"]], float)
        errors = np.array([r["rms_error"] for r in result["rows"]])
        style = "o-" if result["sampler"] == "stratified" else "s:"
        axis.loglog(samples, errors, style, label=f"{result['scene']}, {result['sampler']}: {result['slope']:.2f}")
    axis.set_xlabel("samples N")
    axis.set_ylabel("RMS relative L2 error vs exact model")
    axis.legend(fontsize=6)
    axis.set_title("renderer convergence (slopes of log error against log N)", fontsize=9)
    save_figure(figure, path)


if __name__ == "__main__":
    sys.exit(main())
