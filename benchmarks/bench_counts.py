"""Reconstruction from photon counts: PSNR against photons per pixel, and the approximation's error.

The paper's default set-up (source 1 m above a 1 m plane, 4 x 4 sensors
over W = 1 m, T = 0.1 m: in the letter's Section VII units a 15 m scene
sampled at ~750 MHz) at M = 24, its image recovered from counts of a
single-photon detector at 10 ... 10^5 signal photons per pixel (the total
expected signal count over the whole capture divided by M²), without dead
time and with it (first photon per cycle, Coates; 10^4 cycles, so the
brightest levels pile up). The rule is :func:`analytic.inversion.poisson.reconstruct_counts`
(weighted least squares on the rate estimates, λ by the discrepancy
principle); the oracle λ is the bound. At one level, the approximation's
image is held to the exact Poisson (multinomial) MAP at the same λ.

    python benchmarks/bench_counts.py --out out/bench_counts.json
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from analytic.measurement.detector import Detector, draw_counts
from analytic.files import save_json
from analytic.inversion import RankDeficiencyWarning, RegularizationWarning, flat_image_psnr, image_metrics
from analytic.inversion.poisson import compare_to_map, reconstruct_counts
from analytic.scenes.common import default_scene
from analytic.operator.system import system_matrix
from validation.runs.bench import cpu_model

LEVELS = (10.0, 1e2, 1e3, 1e4, 1e5)
CYCLES = 1e4
BACKGROUND = 1e-4       # per bin per cycle: dark and ambient counts


def _detector(level: float, y: np.ndarray, pixels: int, dead_time: str, seed: int) -> Detector:
    """photons such that the capture's expected signal count is ``level`` per pixel."""
    photons = level * pixels**2 / (CYCLES * float(np.sum(np.maximum(y, 0.0))))
    return Detector(photons=photons, background=BACKGROUND, cycles=CYCLES, dead_time=dead_time, seed=seed)


def run(pixels: int = 24, seed: int = 0, map_level: float = 1e3) -> dict:
    scene = default_scene(pixels=pixels, noise=None)
    started = time.perf_counter()
    matrix = system_matrix(scene)
    assembly = time.perf_counter() - started
    truth = scene.reflectance
    y = (matrix @ truth.ravel()).reshape(scene.sensor_count, -1)
    rows = []
    approximation = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RankDeficiencyWarning)      # 192 rows for 576 unknowns, by design
        warnings.simplefilter("ignore", RegularizationWarning)
        for dead_time in ("none", "cycle"):
            for level in LEVELS:
                detector = _detector(level, y, pixels, dead_time, seed)
                counts = draw_counts(y, detector)
                began = time.perf_counter()
                rule = reconstruct_counts(matrix, counts, detector, pixels)
                seconds = time.perf_counter() - began
                oracle = reconstruct_counts(matrix, counts, detector, pixels, rule="oracle", truth=truth)
                row = {"dead_time": dead_time, "photons_per_pixel": level, "photons": detector.photons,
                       "counts": int(counts.sum()), "peak_rate": float(np.max(detector.photons * y)),
                       "psnr": image_metrics(rule.image, truth)["psnr"], "lambda": rule.lam,
                       "oracle_psnr": image_metrics(oracle.image, truth)["psnr"], "seconds": seconds}
                if level == map_level:
                    found = compare_to_map(matrix, counts, detector, pixels, rule)
                    row["map_relative_difference"] = found["relative_difference"]
                    row["map_psnr"] = image_metrics(found["map_image"], truth)["psnr"]
                    approximation = approximation or row
                rows.append(row)
    return {"machine": cpu_model(), "pixels": pixels, "sensors": scene.sensor_count, "bins": scene.sampling.count,
            "cycles": CYCLES, "background": BACKGROUND, "assembly_seconds": assembly,
            "flat_psnr": flat_image_psnr(truth), "rows": rows}


def _table(result: dict) -> str:
    lines = [f"Machine: {result['machine']}; M = {result['pixels']}, {result['sensors']} sensors x "
             f"{result['bins']} bins, {result['cycles']:g} cycles, background {result['background']:g} per bin per "
             f"cycle; flat image {result['flat_psnr']:.2f} dB", "",
             "| dead time | photons / pixel | counts | peak λ per cycle | PSNR (discrepancy) | PSNR (oracle) "
             "| MAP: relative difference | MAP PSNR |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in result["rows"]:
        exact = (f"{row['map_relative_difference']:.2e} | {row['map_psnr']:.2f}" if "map_psnr" in row else " | ")
        lines.append(f"| {row['dead_time']} | {row['photons_per_pixel']:g} | {row['counts']} | {row['peak_rate']:.3g} "
                     f"| {row['psnr']:.2f} | {row['oracle_psnr']:.2f} | {exact} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=24)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="write the figures as JSON here")
    arguments = parser.parse_args()
    result = run(arguments.pixels, arguments.seed)
    print(_table(result))
    if arguments.out is not None:
        save_json(arguments.out, result)


if __name__ == "__main__":
    main()
