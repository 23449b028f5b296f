"""From a scene file to a reconstructed image, through the Python API, saying what each step does.

Run it from anywhere: ``python3 examples/tutorial.py [OUT]`` (OUT, default
``out/tutorial``, receives the files). About a minute on 2 cores once
Numba's cache is warm (``scripts/setup.sh`` warms it). The same steps on the
command line are the README's tour; docs/model.md, docs/renderer.md and
docs/check.md say what happens inside each one.

1. load the paper's set-up from ``examples/paper.toml``;
2. find the time window that holds all of its light, exactly;
3. model the transient y = A f (the exact model);
4. render the same transient by Monte Carlo (Mitsuba 3) with its standard error;
5. judge the render against the model (the cross-check), and ``check`` a
   transient that follows another renderer's convention;
6. reconstruct the image from noisy data, with λ chosen from the data;
7. the corner: a scene the one-bounce model does not cover, rendered with 1
   and 3 bounces.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

import analytic
import transient
import validation
from analytic.files import write_transient

EXAMPLES = Path(__file__).resolve().parent

#: Render samples: small, so that the tutorial stays quick (the main job uses 2^22).
SAMPLES = 2**18


def step(title: str) -> float:
    """Print a step's title; return the time it starts."""
    print(f"\n== {title}")
    return time.perf_counter()


def done(started: float) -> None:
    print(f"   ({time.perf_counter() - started:.1f} s)")


def load(out: Path):
    started = step("1. the scene: examples/paper.toml")
    scene = analytic.load_scene(EXAMPLES / "paper.toml")
    print(f"   {scene.name}: a {scene.size:g} m plane at M = {scene.pixels}, {scene.sensor_count} sensors, "
          f"{scene.illumination.waveform} illumination at {scene.intensity:g} W/sr, "
          f"{scene.sampling.count} bins of {scene.sampling.bin_width_opl:g} m from {scene.sampling.start_opl:g} m")
    done(started)
    return scene


def window(scene) -> None:
    started = step("2. the time window")
    first, last = analytic.response_range(scene)
    covering = analytic.covering_sampling(scene, scene.sampling.bin_width_opl)
    print(f"   light reaches the sensors between {first:.4f} m and {last:.4f} m of path (exact)")
    print(f"   the bins that hold all of it at T = {covering.bin_width_opl:g} m: start = "
          f"{covering.start_opl:g}, count = {covering.count}; the scene's window holds "
          f"{100 * analytic.window_share(scene):.2f} % of the light")
    done(started)


def model(scene, out: Path):
    started = step("3. the exact model: y = A f")
    matrix = analytic.system_matrix(scene)
    y = analytic.forward(scene, matrix)
    print(f"   A: {matrix.shape[0]} x {matrix.shape[1]}, {matrix.nnz:,} non-zeros; "
          f"y: {y.shape}, peak {y.max():.4g} W m^-1")
    write_transient(out / "model", y, analytic.build_meta(scene, kind="model"))
    print(f"   wrote {out / 'model'}")
    done(started)
    return matrix, y


def render(scene):
    started = step(f"4. the Monte Carlo render: {SAMPLES:,} samples")
    result = transient.render(scene, spp=SAMPLES, seed=1, progress=False)
    relative = result.stderr.max() / result.mean.max()
    print(f"   {result.replicas} replicas ({result.dof} degrees of freedom), {result.variant}; "
          f"largest standard error {100 * relative:.2f} % of the peak")
    done(started)
    return result


def cross_check(scene, y, result) -> None:
    started = step("5. the cross-check, and check")
    # the replicas give the limits by sign flips, valid whatever the correlation between bins
    agreement = validation.compare_transients(result.mean, result.stderr, y, dof=result.dof,
                                              replicas=result.replica_means)
    verdict = "agrees" if agreement.agrees else "DISAGREES"
    print(f"   render against model: {verdict}, χ²/dof {agreement.chi2_per_dof:.3f} over {agreement.bins} bins, "
          f"max |z| {agreement.max_abs_z:.2f}")
    # A renderer with mitransient's irradiancemeter convention reads 1/4 of the fluence rate:
    # check finds the scale (and would find a time offset) by fitting it.
    quarter = result.replica_means / 4
    checked = validation.check_transient(scene, quarter, model=y)
    print(f"   the same replicas / 4: agrees as given: {checked.agrees}; fitted scale "
          f"{checked.fit.scale:.4f} ± {checked.fit.scale_stderr:.4f}, offset "
          f"{checked.fit.offset_opl:+.1e} ± {checked.fit.offset_stderr:.0e} m; agrees after the fit: "
          f"{checked.agrees_after_fit}")
    # check as a test (a renderer's regression test, docs/testing-your-renderer.md): stated 1/4, it agrees
    stated = validation.assert_agrees(scene, quarter, expect=validation.Convention(0.25, 0.0, "a quarter"),
                                      model=y)
    print(f"   stated as a quarter: agrees; these replicas would flag a scale error of "
          f"{100 * stated.detectable['scale']:.2g} % or a shift of {stated.detectable['shift_opl']:.1e} m "
          f"half the time")
    done(started)


def reconstruct(scene, matrix, y) -> None:
    started = step("6. reconstruction from noisy data")
    noisy = analytic.add_noise(y, scene.noise)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = analytic.reconstruct(matrix, noisy, scene.pixels, rule="discrepancy", sigma=scene.noise.sigma)
    for warning in caught:      # e.g. A's rank: the data fix only part of the image
        print(f"   note: {warning.message}")
    metrics = analytic.image_metrics(result.image, scene.reflectance)
    flat = analytic.flat_image_psnr(scene.reflectance)
    print(f"   σ = {scene.noise.sigma:g}: λ = {result.lam:.3g} by the discrepancy rule, "
          f"PSNR {metrics['psnr']:.2f} dB, SSIM {metrics['ssim']:.3f} (the best flat image: {flat:.2f} dB)")
    done(started)


def corner() -> None:
    started = step("7. the corner: floor and wall, 1 and 3 bounces")
    found = validation.check_corner(spp=SAMPLES)
    print(f"   one bounce agrees with the floor + wall model: {found['one_bounce_agrees']}; "
          f"further bounces carry {100 * found['further_bounce_share']:.1f} % of the light")
    done(started)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    scene = load(out)
    window(scene)
    matrix, y = model(scene, out)
    result = render(scene)
    cross_check(scene, y, result)
    reconstruct(scene, matrix, y)
    corner()
    np.save(out / "render_mean.npy", result.mean)
    print(f"\nDone; files in {out}.")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/tutorial"))
