"""Unbiasedness and N^-1/2 convergence of the renderer against the exact model.

    python benchmarks/convergence_render.py --out out/convergence [--max-power 32] [--precision-power 34]

For the default scene and the 1 m plane of bench_render.py, renders 2^20,
2^22, ..., 2^max-power samples (independent seeds), judges each against the
analytic 'lambertian' model with validation.compare (DESIGN.md section 6),
and fits log(relative L2 error) against log(samples): an unbiased renderer
gives slope -1/2. A last render of 2^precision-power samples on the plane
checks that float64 accumulation loses nothing at that count (it must still
agree). Writes results.json and convergence.png in --out; prints a table.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_render import plane_scene  # noqa: E402

from analytic.io import save_json  # noqa: E402
from analytic.scene import default_scene  # noqa: E402
from analytic.system import forward  # noqa: E402
from transient.render import render  # noqa: E402
from validation.compare import compare_transients  # noqa: E402


def run(scene, samples, seed):
    started = time.perf_counter()
    result = render(scene, spp=samples, seed=seed, progress=False)
    model = forward(scene)
    agreement = compare_transients(result.mean, result.stderr, model)
    return {"scene": scene.name, "samples": samples, "seed": seed,
            "seconds": time.perf_counter() - started, "relative_l2": agreement.relative_l2,
            "chi2_per_dof": agreement.chi2_per_dof, "max_abs_z": agreement.max_abs_z,
            "z_threshold": agreement.z_threshold, "bins": agreement.bins, "agrees": agreement.agrees}


def fit_slope(rows):
    x = np.log([r["samples"] for r in rows])
    y = np.log([r["relative_l2"] for r in rows])
    design = np.column_stack([x, np.ones_like(x)])
    coefficients, residual, *_ = np.linalg.lstsq(design, y, rcond=None)
    dof = max(len(x) - 2, 1)
    sigma2 = float(residual[0]) / dof if len(residual) else 0.0
    covariance = sigma2 * np.linalg.inv(design.T @ design)
    return float(coefficients[0]), float(np.sqrt(covariance[0, 0]))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/convergence")
    parser.add_argument("--min-power", type=int, default=20)
    parser.add_argument("--max-power", type=int, default=32)
    parser.add_argument("--precision-power", type=int, default=34)
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"series": {}, "slopes": {}}
    print("| scene | samples | seconds | rel. L2 | χ²/dof | max abs z (limit) | verdict |")
    print("|---|---|---|---|---|---|---|")
    for scene in (default_scene(noise=None), plane_scene()):
        rows = []
        for power in range(args.min_power, args.max_power + 1, 2):
            row = run(scene, 2**power, seed=100 + power)
            rows.append(row)
            print(f"| {scene.name} | 2^{power} | {row['seconds']:.1f} | {row['relative_l2']:.3e} | "
                  f"{row['chi2_per_dof']:.3f} | {row['max_abs_z']:.2f} ({row['z_threshold']:.2f}) | "
                  f"{'agree' if row['agrees'] else 'DISAGREE'} |", flush=True)
        slope, error = fit_slope(rows)
        results["series"][scene.name] = rows
        results["slopes"][scene.name] = {"slope": slope, "standard_error": error,
                                         "decades": np.log10(rows[-1]["samples"] / rows[0]["samples"])}
    if args.precision_power:
        row = run(plane_scene(), 2**args.precision_power, seed=7)
        results["precision"] = row
        print(f"| {row['scene']} | 2^{args.precision_power} | {row['seconds']:.1f} | "
              f"{row['relative_l2']:.3e} | {row['chi2_per_dof']:.3f} | {row['max_abs_z']:.2f} "
              f"({row['z_threshold']:.2f}) | {'agree' if row['agrees'] else 'DISAGREE'} |", flush=True)
    print()
    for name, fit in results["slopes"].items():
        print(f"{name}: relative L2 ∝ N^({fit['slope']:.3f} ± {fit['standard_error']:.3f}) "
              f"over {fit['decades']:.1f} decades")
    save_json(out / "results.json", results)
    _plot(out / "convergence.png", results)


def _plot(path, results):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(5, 3.6))
    for name, rows in results["series"].items():
        samples = np.array([r["samples"] for r in rows], float)
        errors = np.array([r["relative_l2"] for r in rows])
        fit = results["slopes"][name]
        axis.loglog(samples, errors, "o", label=f"{name}: slope {fit['slope']:.3f}")
        axis.loglog(samples, errors[0] * (samples / samples[0]) ** -0.5, ":", color="grey")
    axis.set_xlabel("samples N")
    axis.set_ylabel("relative L2 error vs exact model")
    axis.legend(fontsize=8)
    axis.set_title("renderer convergence (dotted: N^-1/2)", fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    main()
