"""The hidden image of a 64 x 64 confocal capture: ours by LSQR on the sparse A, beside tal's bp, fbp and f-k.

    python benchmarks/bench_nlos_size_reconstruct.py --out out/bench-nlos-size-reconstruct

The capture of benchmarks/bench_nlos_size.py (a 1 m square of 64 x 64 pixels 0.9 m in front of the
2 m wall, a 64 x 64 confocal scan, 512 bins of 5 mm from 1.8 m) carrying the built-in letter-like
pattern, with Gaussian noise of σ = 1e-5 (0.2 % of the brightest bin), seed 0. A is built by the
offset route (analytic.operator.offsets; sparse, 102 million non-zeros, nothing dense) and ours is
Tikhonov with the Laplacian penalty, min ‖A f − y‖² + λ ‖D f‖², by SciPy's LSQR on the stacked sparse
system (atol = btol = 1e-6, at most ``--iterations`` per λ: the library's ``method="lsqr"`` asks 1e-10 and
up to 10,000 iterations, hours at this size on two cores), λ by the discrepancy principle among
``--lambdas`` values from 1e-4 to 1e-6 of ‖A‖₂², each solve warm-started by the last. tal's methods and the scoring (each image
after its least-squares affine map onto the truth; tal's also divided by each pixel's known gain) are
benchmarks/bench_nlos_reconstruct.py's.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_model import load, machine  # noqa: E402
import bench_nlos_reconstruct  # noqa: E402
from bench_nlos_reconstruct import affine_fit, gain, pixel_centres, run_tal  # noqa: E402

SIGMA = 1e-5


def main() -> int:
    from analytic import forward, system_matrix
    from analytic.files import save_json
    from analytic.inversion import image_metrics
    from analytic.inversion.laplacian import neumann_laplacian
    from analytic.measurement.noise import add_noise
    from analytic.scenes.common import Noise, Sampling
    from analytic.scenes.reflectance import builtin_reflectance
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from interop.tal import write_relay_wall_capture

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench-nlos-size-reconstruct"))
    parser.add_argument("--lambdas", type=int, default=3, help="λ values the discrepancy rule tries")
    parser.add_argument("--iterations", type=int, default=100, help="LSQR iterations per λ at most")
    parser.add_argument("--tal-python", type=Path, default=bench_nlos_reconstruct.TAL_PYTHON,
                        help="the Python of tal's environment (default: .venv-tal of this checkout)")
    args = parser.parse_args()
    bench_nlos_reconstruct.TAL_PYTHON = args.tal_python
    args.out.mkdir(parents=True, exist_ok=True)
    truth = builtin_reflectance(64)
    scene = RelayWallScene(pixels=64, reflectance=truth, center=(0.0, 0.0, 0.9), scan=Scan(type="confocal",
                           grid=(64, 64)), sampling=Sampling(bin_width_opl=0.005, start_opl=1.8, count=512),
                           noise=Noise(sigma=SIGMA, seed=0), name="nlos-64")
    print(f"machine: {machine()}; load average {load()}")
    started = time.perf_counter()
    matrix = system_matrix(scene)
    assembly = time.perf_counter() - started
    y = add_noise(forward(scene, matrix), scene.noise)
    # ‖A‖₂² by a few power iterations: the grid spans λ from 1e-6 to 1e-4 of it
    v = np.ones(matrix.shape[1])
    for _ in range(8):
        v = matrix.T @ (matrix @ v)
        top = float(np.linalg.norm(v))
        v /= top
    lambdas = top * np.geomspace(1e-4, 1e-6, args.lambdas)
    penalty = neumann_laplacian(scene.pixels)
    rhs = np.concatenate([y.ravel(), np.zeros(scene.pixels**2)])
    target = y.size * SIGMA**2                   # the discrepancy principle: ‖A f - y‖² = m σ²
    started = time.perf_counter()
    best, start = None, None
    for lam in lambdas:                          # descending, each solve warm-started by the last
        stacked = scipy.sparse.vstack([matrix, math.sqrt(lam) * penalty]).tocsr()
        start = scipy.sparse.linalg.lsqr(stacked, rhs, atol=1e-6, btol=1e-6, iter_lim=args.iterations,
                                         x0=start)[0]
        misfit = float(np.sum((matrix @ start - y.ravel()) ** 2))
        if best is None or abs(math.log(misfit / target)) < abs(math.log(best[1] / target)):
            best = (lam, misfit, start.copy())
    ours_seconds = time.perf_counter() - started
    lam, misfit, image = best
    result = SimpleNamespace(image=image.reshape(scene.pixels, scene.pixels), lam=lam, rule="discrepancy")
    results = {"ours": (result.image, ours_seconds)}
    np.save(args.out / "ours.npy", result.image)
    print(f"ours: {ours_seconds:.1f} s, λ = {lam:.3g}, ‖A f - y‖² / (m σ²) = {misfit / target:.3g}", flush=True)
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
            row.update(psnr_as_is=raw["psnr"], ssim_as_is=raw["ssim"], lam=result.lam, rule=result.rule)
        if method.startswith("tal fbp"):
            row["filter"] = f"wavelength {best.split()[1]} pitches"
        rows.append(row)
    record = {"machine": machine(), "load_average_end": load(), "assembly_seconds": assembly,
              "nonzeros": int(matrix.nnz), "sigma": SIGMA, "lambdas": lambdas.tolist(), "rows": rows}
    save_json(args.out / "results.json", record)
    print(f"A ({matrix.shape[0]:,} x {matrix.shape[1]:,}, {matrix.nnz:,} non-zeros) built in {assembly:.1f} s; "
          f"load average at the end {record['load_average_end']}\n")
    print("| method | PSNR (dB) | SSIM | time (s) | note |\n|---|---|---|---|---|")
    for row in rows:
        note = (f"as is {row['psnr_as_is']:.1f} dB; discrepancy λ = {row['lam']:.3g}" if row["method"] == "ours"
                else row.get("filter", ""))
        print(f"| {row['method']} | {row['psnr']:.1f} | {row['ssim']:.3f} | {row['seconds']:.2f} | {note} |")
    print(json.dumps({"out": str(args.out / "results.json")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
