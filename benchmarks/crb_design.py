"""Design study: how the Cramér-Rao bound of the image moves with bin width, sensor count and pulse.

    python benchmarks/crb_design.py --out docs [--pixels 12] [--hidden-pixels 8]

Two set-ups, each varied one knob at a time from a base case (analytic.crb, Gaussian noise):

- the letter's plane (docs/paper.md): 1 m plane, source 1 m above its centre at 10⁴ W/sr, a square grid of
  sensors of extent 1 m around it, σ = 0.1, image at M = ``--pixels`` (8 by default: at the letter's M = 50
  the 192 samples of 4 x 4 sensors x 12 bins cannot fix 2500 pixels, and every pixel's bound is inf); base
  4 x 4 sensors, T = 0.1 m, impulse;
- a confocal relay-wall scan (docs/nlos.md's default geometry: 1 m hidden square 1 m from a 2 m wall, laser
  and sensor at (-0.5, 0, 0.25)), hidden image at M = ``--hidden-pixels`` (8), base 4 x 4 scan points,
  T = 0.05 m, impulse, σ = 1 % of the base case's largest sample (kept for every variant).

Knobs: T (each window covers all the light, ``covering_sampling``), the sensor (or scan) grid n x n, and the
pulse: impulse, square (width T/5), Butterworth (defaults), gaussian (FWHM T/2) and EMG (FWHM T/2, tail T), each
scaled to the impulse's energy (the source's intensity divided by the pulse's ∫ s dt: the same photons, only
their spread in time differs). Reported per case: the median bound over the pixels
(inf when more than half are unbounded), the pixels the data fix, and the effective rank. Writes
``crb_design.png`` and ``crb_design.json`` to ``--out``; about 1-3 minutes on 2 cores at the default sizes.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from analytic.inversion.bounds import crb
from analytic.operator.system import system_matrix
from analytic.operator.window import covering_sampling
from analytic.scenes.common import Illumination, Noise, default_scene, sensor_grid
from analytic.scenes.relay_wall import Scan, default_relay_wall_scene
from analytic.waveforms import make_waveform

PERIODS = {"plane": (0.025, 0.05, 0.1, 0.2), "relay_wall": (0.02, 0.05, 0.1, 0.2)}
GRIDS = (2, 3, 4, 6)


def pulses(period: float) -> dict:
    return {"impulse": Illumination(waveform="impulse"), "square": Illumination(waveform="square"),
            "butterworth": Illumination(waveform="butterworth"),
            "gaussian": Illumination(waveform="gaussian", fwhm=period / 2),
            "emg": Illumination(waveform="emg", fwhm=period / 2, tail=period)}


def equal_energy(scene, period: float):
    """The scene with its window covering the light at T, and its pulse scaled to the impulse's energy."""
    energy = make_waveform(scene.illumination, period).energy
    return scene.replace(sampling=covering_sampling(scene, period), intensity=scene.intensity / energy)


def plane(pixels: int, *, grid=4, period=0.1, illumination=None):
    scene = default_scene(pixels=pixels, sensors=sensor_grid((grid, grid), 1.0, (0.5, 0.5, 1.0)),
                          illumination=illumination or Illumination(waveform="impulse"))
    return equal_energy(scene, period)


def relay_wall(pixels: int, sigma: float | None, *, grid=4, period=0.05, illumination=None):
    scene = default_relay_wall_scene(pixels=pixels, scan=Scan(type="confocal", grid=(grid, grid)),
                                     illumination=illumination or Illumination(waveform="impulse"),
                                     noise=Noise(kind="gaussian", sigma=sigma if sigma else 1.0))
    return equal_energy(scene, period)


def measure(scene) -> dict:
    started = time.perf_counter()
    bounds = crb(scene, matrix=system_matrix(scene))
    image = bounds.image
    return {"median": float(np.median(image)), "fixed_pixels": int(np.count_nonzero(np.isfinite(image))),
            "pixels": int(image.size), "effective_rank": bounds.effective_rank,
            "numerical_rank": bounds.numerical_rank, "samples": scene.sensor_count * scene.sampling.count,
            "seconds": time.perf_counter() - started}


def study(make, base_period: float) -> dict:
    rows = {"period": [], "grid": [], "pulse": []}
    for period in PERIODS[make.kind]:
        rows["period"].append({"value": period, **measure(make(period=period))})
    for grid in GRIDS:
        rows["grid"].append({"value": grid * grid, **measure(make(grid=grid, period=base_period))})
    for name, illumination in pulses(base_period).items():
        rows["pulse"].append({"value": name, **measure(make(period=base_period, illumination=illumination))})
    return rows


def figure(results: dict, sizes: dict, path: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    from validation.plots import new_figure, save_figure

    fig = new_figure(12.0, 7.0, dpi=100)
    axes = fig.subplots(2, 3)
    labels = {"period": "bin width T (m of path)", "grid": "sensors (scan points)", "pulse": "pulse"}
    for row, (kind, title) in enumerate((("plane", f"letter's plane, M = {sizes['plane']}"),
                                          ("relay_wall", f"confocal relay wall, M = {sizes['relay_wall']}"))):
        for column, knob in enumerate(("period", "grid", "pulse")):
            axis = axes[row, column]
            cases = results[kind][knob]
            x = np.arange(len(cases)) if knob == "pulse" else [c["value"] for c in cases]
            medians = np.array([c["median"] for c in cases])
            finite = np.isfinite(medians)
            axis.semilogy(np.asarray(x)[finite], medians[finite], "o" if knob == "pulse" else "o-", color="C0",
                          label="median bound")
            top = medians[finite].max() * 2 if finite.any() else 1.0
            for xi, case in zip(x, cases):
                axis.annotate(f"{case['fixed_pixels']}/{case['pixels']}", (xi, case["median"] if
                              np.isfinite(case["median"]) else top), fontsize=6, ha="center", va="bottom",
                              color="C3" if not np.isfinite(case["median"]) else "k")
            if (~finite).any():
                axis.semilogy(np.asarray(x)[~finite], np.full((~finite).sum(), top), "v", color="C3",
                              label="inf (most pixels unbounded)")
            if knob == "pulse":
                axis.set_xticks(x, [c["value"] for c in cases], fontsize=7)
            elif knob == "period":
                axis.set_xscale("log")
                axis.set_xticks(x, [f"{value:g}" for value in x], fontsize=7)
                axis.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            axis.set_xlabel(labels[knob], fontsize=8)
            axis.set_ylabel("median CRB (reflectance std)", fontsize=8)
            axis.set_title(title, fontsize=8)
            axis.legend(fontsize=6)
            axis.grid(True, which="both", alpha=0.3)
    fig.suptitle("Cramér-Rao bound on the image: median over pixels (labels: pixels fixed / all)", fontsize=9)
    save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs")
    parser.add_argument("--pixels", type=int, default=8)
    parser.add_argument("--hidden-pixels", type=int, default=8)
    args = parser.parse_args()
    out = Path(args.out)
    started = time.perf_counter()
    warnings.simplefilter("ignore")         # window notices of the varied cases; the numbers are exact

    def make_plane(**options):
        return plane(args.pixels, **options)
    make_plane.kind = "plane"
    base = relay_wall(args.hidden_pixels, None)
    sigma = 0.01 * float(np.max(np.abs(system_matrix(base) @ base.reflectance.ravel())))

    def make_wall(**options):
        return relay_wall(args.hidden_pixels, sigma, **options)
    make_wall.kind = "relay_wall"
    results = {"plane": study(make_plane, 0.1), "relay_wall": study(make_wall, 0.05)}
    sizes = {"plane": args.pixels, "relay_wall": args.hidden_pixels}
    results["sizes"] = {**sizes, "relay_wall_sigma": sigma, "seconds": time.perf_counter() - started}
    (out / "crb_design.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
    figure(results, sizes, out / "crb_design.png")
    for kind in ("plane", "relay_wall"):
        for knob, cases in results[kind].items():
            print(kind, knob, ", ".join(f"{c['value']}: {c['median']:.3g} ({c['fixed_pixels']}/{c['pixels']}, "
                                        f"rank {c['effective_rank']})" for c in cases))
    print(f"{time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
