"""The hidden plane's image from a confocal NLOS capture: our Tikhonov-Laplacian beside tal's methods.

One capture geometry, tal's plane example as a confocal scan
(``examples/tal/plane-confocal.yaml``: a 2 m hidden square 1 m in front of
the 2 m relay wall, 32 x 32 confocal points, 1 cm bins, M = 32; of the
example's 394 bins, which hold all the light, the first 152, which hold
99.6 % of it: :data:`BINS`, so that our dense SVD fits in 3.6 GiB), two hidden
images (the built-in letter-like pattern and a chart of fine bars and
checks), each noiseless and with the scene's Gaussian noise. The capture is
the exact model's y = A f (plus noise), written as tal's HDF5 and
reconstructed by:

- ours: Tikhonov with the Laplacian penalty, λ by a data-driven rule
  (the discrepancy principle with the scene's σ for noisy data, GCV for
  noiseless data), in reflectance units;
- tal 0.20 (``.venv-tal``, a subprocess): backprojection (``tal.reconstruct.bp``),
  filtered backprojection (``tal.reconstruct.fbp``, the best of three filter
  wavelengths) evaluated at the hidden pixels' centres (``volume_xyz``, the
  pose is known), and f-k migration (``tal.reconstruct.fk``, which needs bins
  from t = 0: the capture is padded with empty bins in front) interpolated
  there (trilinear, at the depth slice of the plane refined to the brightest
  within ±3 bins).

tal's images are in arbitrary units, so every method is scored after the
least-squares affine map a r + b onto the true image (an oracle
calibration, generous to all); ours is scored as it comes, too. tal's
three images are also scored divided by each hidden pixel's known gain,
the weight its reflectance has in the capture:
g(x) = Σ_(l, s) laser leg(l) · cos θ_l^x cos θ_x^l cos θ_s^x cos θ_x^s / (|x - l|² |x - s|²)
(``gain``; the model's integrand at the pixel's centre, summed over the
scan's pairs whose path lies in the window), which bp, fbp and f-k leave
in their images ("÷ gain"). PSNR and
SSIM are :func:`analytic.inversion.image_metrics` (data range 1). Times are
each method's own (tal's inside its process, without Python's start-up and
imports; ours without A's assembly, reported apart).

    python benchmarks/bench_nlos_reconstruct.py --out out/bench-nlos-reconstruct
    python benchmarks/bench_nlos_reconstruct.py --quick --out out/bench-nlos-quick   # 16 x 16, M = 16
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TAL_PYTHON = ROOT / ".venv-tal" / "bin" / "python"
SCENE = ROOT / "examples" / "tal" / "plane-confocal.yaml"
#: The capture's first bins that are reconstructed: [1.99, 3.51) m, 99.6 % of the light (the figures in the
#: README and docs/tal.md are of these; the example's own window, 394 bins, holds it all).
BINS = 152
METHODS = ("ours", "tal bp", "tal fbp", "tal fk")
#: tal's images divided by each hidden pixel's gain (see ``gain``).
GAINED = tuple(f"{method} ÷ gain" for method in METHODS[1:])

#: Runs tal's reconstructions on one capture (argv: capture.h5, pixel centres .npy, output folder).
_TAL_SCRIPT = r"""
import json, sys, time
import numpy as np
import tal
from tal.enums import VolumeFormat
from scipy.interpolate import RegularGridInterpolator

data = tal.io.read_capture(sys.argv[1])
centres = np.load(sys.argv[2])                              # (M, M, 3), the hidden pixels' centres
out = sys.argv[3]
times, extra = {}, {}

def timed(name, f):
    start = time.perf_counter()
    value = f()
    times[name] = time.perf_counter() - start
    return value

bp = timed("tal bp", lambda: tal.reconstruct.bp.solve(data, volume_xyz=centres, volume_format=VolumeFormat.X_Y_3,
                                                       progress=False))
np.save(f"{out}/tal bp.npy", np.abs(np.asarray(bp)))
pitch = float(np.linalg.norm(data.sensor_grid_xyz[1, 0] - data.sensor_grid_xyz[0, 0]))
best = None
for factor in (2.0, 3.0, 4.0):                             # filter wavelengths, in scan pitches
    wl = factor * pitch
    image = timed(f"fbp {factor:g}", lambda: tal.reconstruct.fbp.solve(
        data, wl_mean=wl, wl_sigma=wl / np.sqrt(2), volume_xyz=centres, volume_format=VolumeFormat.X_Y_3,
        progress=False))
    np.save(f"{out}/tal fbp {factor:g}.npy", np.abs(np.asarray(image)))
# f-k: bins from t = 0 (tal's fk ignores t_start), confocal
lead = int(round(data.t_start / data.delta_t))
assert abs(lead * data.delta_t - data.t_start) < 1e-9 * max(1.0, data.t_start), "t_start is not whole bins"
data.H = np.concatenate([np.zeros((lead,) + data.H.shape[1:]), data.H], axis=0)
data.t_start = 0.0
volume = timed("tal fk", lambda: tal.reconstruct.fk.solve(data))            # (T, Sx, Sy)
grid = data.sensor_grid_xyz
axes = (data.delta_t * np.arange(volume.shape[0]), grid[:, 0, 0], grid[0, :, 1])
look = RegularGridInterpolator(axes, volume, bounds_error=False, fill_value=0.0)
depth = 2 * centres[..., 2]                                # confocal: the time of depth z is 2 z
xy = np.stack([centres[..., 0], centres[..., 1]], axis=-1)
slices = {k: look(np.concatenate([(depth + k * data.delta_t)[..., None], xy], axis=-1)) for k in range(-3, 4)}
shift = max(slices, key=lambda k: float(np.sum(slices[k] ** 2)))
np.save(f"{out}/tal fk.npy", slices[shift])
extra["fk_shift_bins"] = shift
extra["pitch"] = pitch
print(json.dumps({"times": times, **extra}))
"""


def fine_detail(pixels: int) -> np.ndarray:
    """A chart of fine detail in [0, 1]: bars of 1, 2 and 3 pixels both ways, a 1-pixel checkerboard, a dot."""
    image = np.full((pixels, pixels), 0.2)
    half = pixels // 2
    rows, cols = np.indices((half, half))
    image[:half, :half] = np.where((cols // 1) % 2 == 0, 1.0, 0.2)             # vertical 1-pixel bars
    image[:half, half:] = np.where((rows // 2) % 2 == 0, 1.0, 0.2)             # horizontal 2-pixel bars
    image[half:, :half] = np.where((rows + cols) % 2 == 0, 1.0, 0.2)           # 1-pixel checkerboard
    image[half:, half:] = np.where((cols // 3) % 2 == 0, 0.9, 0.3)             # 3-pixel bars, less contrast
    image[half + half // 2, half + half // 2] = 1.0
    return image


def affine_fit(image: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The least-squares a image + b closest to the truth (the oracle calibration of arbitrary units)."""
    design = np.column_stack([image.ravel(), np.ones(image.size)])
    coefficients, *_ = np.linalg.lstsq(design, truth.ravel(), rcond=None)
    return (design @ coefficients).reshape(truth.shape)


def pixel_centres(scene) -> np.ndarray:
    """``(M, M, 3)`` centre of image[r, c] (docs/design.md section 7), metres."""
    rectangle = scene.rectangle()
    m = scene.pixels
    fraction_u = (np.arange(m) + 0.5) / m
    fraction_v = 1.0 - (np.arange(m) + 0.5) / m
    return (rectangle.corner + fraction_v[:, None, None] * rectangle.v + fraction_u[None, :, None] * rectangle.u)


def gain(scene) -> np.ndarray:
    """``(M, M)`` the weight of each hidden pixel's reflectance in the capture, at its centre.

    Σ over the scan's pairs (l, s) of the laser leg I cos θ_l^las / |o_l - l|² (ρ_w / π)² times
    cos θ_l^x cos θ_x^l cos θ_s^x cos θ_x^s / (|x - l|² |x - s|²): the model's integrand without the
    time kernel, κ's 1/π and the pixel's area (the same for every pixel), over the pairs whose path from
    the pixel's centre falls in the window (the rest never reach the capture). bp, fbp and f-k leave it in.
    """
    centres = pixel_centres(scene)[:, :, None, :]                       # (M, M, 1, 3)
    lit, read = scene.pair_points
    normal = scene.rectangle().normal
    factors, path = [], 0.0
    for ends in (lit, read):
        toward = ends[None, None] - centres                              # x -> wall point
        distance = np.linalg.norm(toward, axis=-1)
        cosines = np.clip(toward @ normal / distance, 0, None) * np.clip(-toward[..., 2] / distance, 0, None)
        factors.append(cosines / distance**2)
        path = path + distance
    if scene.scan.account_first_and_last_bounces:
        path = path + np.linalg.norm(scene.laser_position - lit, axis=1) + np.linalg.norm(read - scene.sensor_position,
                                                                                           axis=1)
    sampling = scene.sampling
    seen = (path >= sampling.start_opl) & (path < sampling.start_opl + sampling.count * sampling.bin_width_opl)
    return (scene.laser_leg(lit) * factors[0] * factors[1] * seen).sum(axis=-1)


def ours(matrix, y, scene, sigma: float | None):
    from analytic.inversion import RankDeficiencyWarning, reconstruct

    started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RankDeficiencyWarning)
        # the dense SVD (3.6 GiB here) serves every λ of the sweep at once; LSQR would solve each
        result = reconstruct(matrix, y, scene.pixels, rule="discrepancy" if sigma else "gcv", sigma=sigma,
                             method="svd", memory_limit=6 * 2**30)
    return result.image, time.perf_counter() - started, result.rule, result.lam


def run_tal(capture: Path, centres: np.ndarray, folder: Path) -> dict:
    np.save(folder / "centres.npy", centres)
    done = subprocess.run([str(TAL_PYTHON), "-c", _TAL_SCRIPT, str(capture), str(folder / "centres.npy"), str(folder)],
                          capture_output=True, text=True, timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(f"tal failed: {done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    from analytic import load_scene, system_matrix
    from analytic.files import save_json
    from interop.tal import write_relay_wall_capture
    from analytic.inversion import image_metrics
    from analytic.measurement.noise import add_noise
    from analytic.scenes.reflectance import builtin_reflectance
    from analytic.scenes.relay_wall import Scan
    from analytic.scenes.common import Sampling
    from validation.runs.bench import cpu_model

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench-nlos-reconstruct"))
    parser.add_argument("--figure", type=Path, default=None, help="also save the figure here (docs/)")
    parser.add_argument("--quick", action="store_true",
                        help="a 16 x 16 confocal scan and M = 16 (the same geometry; minutes, not half an hour)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    scene = load_scene(SCENE)
    scene = scene.replace(sampling=Sampling(bin_width_opl=scene.sampling.bin_width_opl,
                                            start_opl=scene.sampling.start_opl, count=BINS))
    if args.quick:
        scene = scene.replace(scan=Scan(type="confocal", grid=(16, 16)), pixels=16, reflectance=1.0)
    weights = gain(scene)
    started = time.perf_counter()
    matrix = system_matrix(scene)
    assembly = time.perf_counter() - started
    images = {"letters": builtin_reflectance(scene.pixels), "fine detail": fine_detail(scene.pixels)}
    rows, shown = [], {}
    for image_name, truth in images.items():
        clean = (matrix @ truth.ravel()).reshape(scene.sensor_count, scene.sampling.count)
        for noisy in (False, True):
            case = f"{image_name}, {'noise' if noisy else 'noiseless'}"
            sigma = scene.noise.sigma if noisy else None
            y = add_noise(clean, scene.noise) if noisy else clean
            image, seconds, rule, lam = ours(matrix, y, scene, sigma)
            results = {"ours": (image, seconds)}
            with tempfile.TemporaryDirectory(dir=args.out) as folder:
                folder = Path(folder)
                capture = write_relay_wall_capture(folder / "capture.h5", y, scene, scene_info={"case": case})
                told = run_tal(capture, pixel_centres(scene), folder)
                best = max((f"fbp {f}" for f in ("2", "3", "4")),
                           key=lambda k: image_metrics(affine_fit(np.load(folder / f"tal {k}.npy"), truth),
                                                       truth)["psnr"])
                results["tal bp"] = (np.load(folder / "tal bp.npy"), told["times"]["tal bp"])
                results["tal fbp"] = (np.load(folder / f"tal {best}.npy"), told["times"][best])
                results["tal fk"] = (np.load(folder / "tal fk.npy"), told["times"]["tal fk"])
                for method, name in zip(METHODS[1:], GAINED):
                    results[name] = (results[method][0] / weights, results[method][1])
            for method, (estimate, seconds) in results.items():
                fitted = affine_fit(estimate, truth)
                metrics = image_metrics(fitted, truth)
                row = {"case": case, "method": method, "psnr": metrics["psnr"], "ssim": metrics["ssim"],
                       "seconds": seconds}
                if method == "ours":
                    raw = image_metrics(estimate, truth)
                    row.update(psnr_as_is=raw["psnr"], ssim_as_is=raw["ssim"], rule=rule, lam=lam)
                if method.startswith("tal fbp"):
                    row["filter"] = f"wl_mean = {best.split()[1]} scan pitches"
                if method.startswith("tal fk"):
                    row["fk_shift_bins"] = told["fk_shift_bins"]
                rows.append(row)
                shown[(case, method)] = fitted
            shown[(case, "truth")] = truth
    record = {"machine": cpu_model(), "scene": str(SCENE.relative_to(ROOT)), "quick": args.quick,
              "scan": list(scene.scan.grid), "pixels": scene.pixels,
              "pairs": scene.sensor_count, "bins": scene.sampling.count, "sigma": scene.noise.sigma,
              "assembly_seconds": assembly, "nonzeros": int(matrix.nnz), "rows": rows}
    save_json(args.out / "bench_nlos_reconstruct.json", record)
    print(f"machine: {record['machine']}; A ({matrix.shape[0]:,} x {matrix.shape[1]:,}, {matrix.nnz:,} non-zeros) "
          f"assembled in {assembly:.1f} s")
    print("| case | method | PSNR (dB) | SSIM | time (s) | note |")
    print("| --- | --- | --- | --- | --- | --- |")
    for row in rows:
        note = (f"as is: {row['psnr_as_is']:.1f} dB / {row['ssim_as_is']:.3f}; {row['rule']} λ = {row['lam']:.3g}"
                if row["method"] == "ours" else row.get("filter", "") or
                (f"depth slice {row['fk_shift_bins']:+d} bins" if "fk_shift_bins" in row else ""))
        print(f"| {row['case']} | {row['method']} | {row['psnr']:.1f} | {row['ssim']:.3f} | {row['seconds']:.2f} | "
              f"{note} |")
    figure(shown, list(dict.fromkeys(row["case"] for row in rows)), args.out / "nlos_tal_reconstructions.png",
           args.figure, scene)
    return 0


def figure(shown: dict, cases: list[str], path: Path, also: Path | None, scene) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = ("truth",) + METHODS + GAINED
    fig, axes = plt.subplots(len(cases), len(columns), figsize=(2.1 * len(columns), 2.2 * len(cases)))
    for i, case in enumerate(cases):
        for j, method in enumerate(columns):
            axis = axes[i, j]
            axis.imshow(np.clip(shown[(case, method)], 0, 1), cmap="gray", vmin=0, vmax=1)
            axis.set_xticks([])
            axis.set_yticks([])
            if i == 0:
                axis.set_title(method, fontsize=10)
            if j == 0:
                axis.set_ylabel(case, fontsize=9)
    width, height = scene.scan.grid
    fig.suptitle(f"hidden plane (M = {scene.pixels}) from a {width} x {height} confocal capture, each image its "
                 f"best affine map to [0, 1]; right: tal's images divided by each pixel's known gain\n"
                 f"Σ laser leg · cos θ_l^x cos θ_x^l cos θ_s^x cos θ_x^s / (|x - l|² |x - s|²) over the scan's"
                 f" pairs whose path lies in the window (the 1/r⁴ fall-off and cosines that bp, fbp and f-k leave "
                 f"in)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    if also is not None:
        fig.savefig(also, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
