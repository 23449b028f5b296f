"""The hidden image of a 64 x 64 confocal capture: ours by `analytic.reconstruct`, beside tal's bp, fbp and f-k.

    python benchmarks/bench_nlos_size_reconstruct.py --out out/bench-nlos-size-reconstruct

The capture of benchmarks/bench_nlos_size.py (a 1 m square of 64 x 64 pixels 0.9 m in front of the
2 m wall, a 64 x 64 confocal scan, 512 bins of 5 mm from 1.8 m) carrying the built-in letter-like
pattern, with Gaussian noise of σ = 1e-5 (0.2 % of the brightest bin), seed 0. The data are `forward`'s
(the offset route's compiled product, analytic.operator.offsets); ours is the library's own call as
`diffuse-imaging reconstruct` makes it (validation.cli.reconstruct.reconstruction_matrix: A never built,
applied by FFT over the capture's pixel offsets, analytic.operator.offset_operator; then `reconstruct`,
Tikhonov with the Laplacian penalty, the lsqr method its size selects, λ by the discrepancy rule's search
of its default range, each solve stopped by the noise: analytic.inversion.iterative), timed from the
operator's making with the process's peak resident memory. tal's methods and the scoring (each image
after its least-squares affine map onto the truth; tal's also divided by each pixel's known gain) are
benchmarks/bench_nlos_reconstruct.py's.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_model import load, machine  # noqa: E402
import bench_nlos_reconstruct  # noqa: E402
from bench_nlos_reconstruct import affine_fit, gain, pixel_centres, run_tal  # noqa: E402

SIGMA = 1e-5


def main() -> int:
    from analytic import forward
    from analytic.files import save_json
    from analytic.inversion import image_metrics, reconstruct
    from analytic.measurement.noise import add_noise
    from analytic.scenes.common import Noise, Sampling
    from analytic.scenes.reflectance import builtin_reflectance
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from interop.tal import write_relay_wall_capture
    from validation.cli.reconstruct import reconstruction_matrix

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench-nlos-size-reconstruct"))
    parser.add_argument("--tal-python", type=Path, default=bench_nlos_reconstruct.TAL_PYTHON,
                        help="the Python of tal's environment (default: .venv-tal of this checkout)")
    args = parser.parse_args()
    bench_nlos_reconstruct.TAL_PYTHON = args.tal_python
    args.out.mkdir(parents=True, exist_ok=True)
    truth = builtin_reflectance(64)
    scene = RelayWallScene(pixels=64, reflectance=truth, center=(0.0, 0.0, 0.9), scan=Scan(type="confocal",
                           grid=(64, 64)), sampling=Sampling(bin_width_opl=0.005, start_opl=1.8, count=512),
                           noise=Noise(sigma=SIGMA, seed=0), name="nlos-64")
    start_load = load()
    print(f"machine: {machine()}; load average {start_load}")
    y = add_noise(forward(scene), scene.noise)
    import resource

    started = time.perf_counter()
    matrix = reconstruction_matrix(scene, "laplacian", None)
    assembly = time.perf_counter() - started
    result = reconstruct(matrix, y, scene.pixels, rule="discrepancy", sigma=SIGMA, progress=sys.stderr.isatty())
    ours_seconds = time.perf_counter() - started
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20      # KiB -> GiB
    misfit = result.residual_norm**2 / (y.size * SIGMA**2)
    results = {"ours": (result.image, ours_seconds)}
    np.save(args.out / "ours.npy", result.image)
    print(f"ours: {ours_seconds:.1f} s, peak {peak:.2f} GiB, λ = {result.lam:.3g}, ‖A f - y‖² / (m σ²) = "
          f"{misfit:.4g}; {result.stopping}", flush=True)
    weights = gain(scene)
    with tempfile.TemporaryDirectory(dir=args.out) as folder:
        folder = Path(folder)
        capture = write_relay_wall_capture(folder / "capture.h5", y, scene, scene_info={"case": "64 x 64"})
        told = run_tal(capture, pixel_centres(scene), folder)
        best = max((f"fbp {f}" for f in ("2", "3", "4")),
                   key=lambda k: image_metrics(affine_fit(np.load(folder / f"tal {k}.npy"), truth), truth)["psnr"])
        for name, key in (("tal bp", "tal bp"), ("tal fbp", best), ("tal fk", "tal fk")):
            image = np.load(folder / f"tal {key.removeprefix('tal ')}.npy")
            results[name] = (image, told["times"][key])
            results[f"{name} ÷ gain"] = (image / weights, told["times"][key])
    rows = []
    for method, (image, seconds) in results.items():
        metrics = image_metrics(affine_fit(image, truth), truth)
        row = {"method": method, "psnr": metrics["psnr"], "ssim": metrics["ssim"], "seconds": seconds}
        if method == "ours":
            raw = image_metrics(image, truth)
            row.update(psnr_as_is=raw["psnr"], ssim_as_is=raw["ssim"], lam=result.lam, rule=result.rule,
                       peak_gib=peak, misfit=misfit, stopping=result.stopping, warnings=list(result.warnings),
                       operator=type(matrix).__name__, lambdas_solved=len(result.lambdas))
        if method.startswith("tal fbp"):
            row["filter"] = f"wavelength {best.split()[1]} pitches"
        rows.append(row)
    record = {"machine": machine(), "load_average_start": start_load, "load_average_end": load(),
              "operator_seconds": assembly,
              "nonzeros": int(matrix.nnz), "sigma": SIGMA, "lambdas": result.lambdas.tolist(), "rows": rows}
    save_json(args.out / "results.json", record)
    print(f"A ({matrix.shape[0]:,} x {matrix.shape[1]:,}, {matrix.nnz:,} non-zeros) as {type(matrix).__name__} in "
          f"{assembly:.1f} s (within ours); load average at the end {record['load_average_end']}\n")
    print("| method | PSNR (dB) | SSIM | time (s) | note |\n|---|---|---|---|---|")
    for row in rows:
        note = (f"as is {row['psnr_as_is']:.1f} dB; discrepancy λ = {row['lam']:.3g}; peak {row['peak_gib']:.2f} GiB"
                if row["method"] == "ours"
                else row.get("filter", ""))
        print(f"| {row['method']} | {row['psnr']:.1f} | {row['ssim']:.3f} | {row['seconds']:.2f} | {note} |")
    print(json.dumps({"out": str(args.out / "results.json")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
