"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): command-line values: flags at and
beyond their limits, each refused in one line or answered right.
"""

from __future__ import annotations

import dataclasses
import math

from probe.cli_reference import GREY_LEVELS, png_bytes, reference
from probe.cli_probe import GOOD, case_table, case_test, check_command, forward, noisy_data


CASES, case = case_table()


@case("flags", "render --spp 0x1000", "exit 0; 4096 samples")
def _(probe):
    if probe.cli("render", probe.scene(), "--spp", "0x1000", "--out", probe.out, "--quiet").answered():
        probe.check(probe.meta().get("samples") == 4096, f"samples {probe.meta().get('samples')}")


@case("flags", "render --spp 1e3", "exit 0; 1024 samples (1000 rounded up to 32 replicas)")
def _(probe):
    if probe.cli("render", probe.scene(), "--spp", "1e3", "--out", probe.out, "--quiet").answered():
        probe.check(probe.meta().get("samples") == 1024, f"samples {probe.meta().get('samples')}")


@case("flags", "render --spp 2^44 + 1", "exit 2, one line naming --spp")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", str(2**44 + 1), "--out", probe.out).refused("--spp")


@case("flags", "render --variant cuda_ad_rgb (not offered)", "exit 2, one line naming the variant")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", "64", "--variant", "cuda_ad_rgb", "--out", probe.out) \
        .refused("variant")


@case("flags", "render --resume of a folder that never rendered", "exit 2, one line naming the folder")
def _(probe):
    probe.out.mkdir()
    (probe.out / "notes.txt").write_text("mine")
    probe.cli("render", "--resume", probe.out, "--quiet").refused(str(probe.out))


@case("flags", "render --resume with a different --seed", "exit 2, one line naming --seed; the render as it was")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", "4096", "--seed", "3", "--out", probe.out, "--quiet")
    if probe.answered():
        probe.cli("render", "--resume", probe.out, "--seed", "4", "--quiet").refused("--seed")


@case("flags", "render intensity law: I = 1e-300 and 1e30 against 1, same seed",
      "exit 0 each; y / I and stderr / I equal to 1e-14")
def _(probe):
    runs = {}
    for intensity in (1.0, 1e-300, 1e30):
        probe.out = probe.tmp / f"out{intensity:g}"
        scene = probe.scene(dataclasses.replace(GOOD, intensity=intensity), f"i{intensity:g}.toml")
        if probe.cli("render", scene, "--spp", "4096", "--seed", "5", "--out", probe.out, "--quiet",
                     outside_changes=True).answered(warnings=True):
            runs[intensity] = (probe.y() / intensity, probe.y("stderr.npy") / intensity)
    if 1.0 in runs:
        for intensity, (y, se) in runs.items():
            probe.close(y, runs[1.0][0], rtol=1e-14, what=f"y / I at {intensity:g}")
            probe.close(se, runs[1.0][1], rtol=1e-12, what=f"stderr / I at {intensity:g}")


@case("flags", "render paper attenuation, 2^16 samples", "exit 0; y within 5 stderr + 1e-3 of the eq. 1 reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, attenuation="paper")
    if probe.cli("render", probe.scene(geometry), "--spp", "65536", "--out", probe.out, "--quiet").answered():
        y, se = probe.y(), probe.y("stderr.npy")
        expected, bound = reference(geometry)
        probe.close(y, expected, atol=5 * se + bound, what="render against eq. 1")


@case("flags", "render --resume after render_state.npz was cut to 100 bytes",
      "exit 2, one line naming render_state.npz; the folder as it was")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", "4096", "--out", probe.out, "--quiet")
    state = probe.out / "render_state.npz"
    state.write_bytes(state.read_bytes()[:100])
    probe.cli("render", "--resume", probe.out, "--quiet").refused("render_state.npz")


@case("flags", "check of a render folder whose replicas.npy is empty",
      "exit 2, one line naming replicas.npy, no --out")
def _(probe):
    scene = probe.scene()
    rendered = probe.tmp / "rendered"
    probe.cli("render", scene, "--spp", "4096", "--out", rendered, "--quiet", outside_changes=True)
    (rendered / "replicas.npy").write_bytes(b"")
    check_command(probe, rendered, None, scene=scene).refused("replicas.npy")


@case("flags", "forward --tolerance 1e-300", "exit 2, one line naming --tolerance")
def _(probe):
    forward(probe, probe.scene(), "--tolerance", "1e-300").refused("tolerance")


@case("flags", "export --format MITSUBA (capitals)", "exit 2, one line naming --format")
def _(probe):
    probe.cli("export", probe.scene(), "--format", "MITSUBA", "--out", probe.out).refused("--format")


@case("flags", "export --format mitransient --spp 0", "exit 2, one line naming --spp")
def _(probe):
    probe.cli("export", probe.scene(), "--format", "mitransient", "--spp", "0", "--out", probe.out).refused("--spp")


@case("flags", "check --expect irradiancemeter --radius 5 (above the sensor)", "exit 2, one line naming --radius")
def _(probe):
    files = [probe.npy(f"r{seed}.npy", noisy_data(seed=seed)[0]) for seed in range(3)]
    check_command(probe, files, None, "--expect", "irradiancemeter", "--radius", "5").refused("radius")


@case("flags", "reconstruct --regularizer TV (capitals)", "exit 2, one line naming --regularizer")
def _(probe):
    probe.cli("reconstruct", probe.scene(), "--data", probe.npy("y.npy", noisy_data()[0]), "--regularizer", "TV",
              "--out", probe.out).refused("--regularizer")


@case("flags", "diffuse-imaging --version", "exit 0 with a version, or exit 2 in one line")
def _(probe):
    probe.cli("--version")
    if probe.status != 0:
        probe.refused()


@case("flags", "forward --quiet --quiet", "exit 0")
def _(probe):
    forward(probe, probe.scene(), "--quiet")
    probe.answered()


@case("flags", "run on a noisy 2 x 2-sensor scene, --spp 4096", "exit 0; the cross-check agrees; finite PSNRs")
def _(probe):
    text = dataclasses.replace(GOOD, intensity=1e4, reflectance=GREY_LEVELS / 255.0).toml(image="i.png") \
        .replace("positions = [[0.2, 0.7, 1.0]]", "grid = [2, 2]\ncenter = [0.5, 0.5, 1.0]") + "[noise]\nsigma = 0.1\n"
    probe.file("i.png", png_bytes(GREY_LEVELS[..., None], 8, 0))
    probe.cli("run", probe.scene(text), "--spp", "4096", "--out", probe.out, "--quiet")
    if probe.answered(warnings=True):
        metrics = probe.metrics()
        probe.check(metrics.get("agreement", {}).get("agrees") is True, f"agreement {metrics.get('agreement')}")
        reconstruction = metrics.get("reconstruction", {})
        for side in ("model", "render"):
            psnr = (reconstruction.get(side) or {}).get("psnr")
            probe.check(isinstance(psnr, float) and math.isfinite(psnr), f"{side} psnr {psnr}")


def sweep_refusal(name: str, text: str, *words: str):
    @case("flags", f"sweep: {name}", f"exit 2, one line naming {', '.join(words)}, before any worker starts")
    def _(probe):
        probe.scene(name="base.toml")
        head = 'scene = "base.toml"\nsamples = 4096\n'
        if "samples" in words:
            head = head.replace("4096", "0")
        if "missing.toml" in words:
            head = head.replace("base.toml", "missing.toml")
        sweep = probe.file("sweep.toml", head + text)
        probe.cli("sweep", sweep, "--out", probe.out, "--workers", "1", "--quiet").refused(*words)


sweep_refusal("a grid key with a typo", '[grid]\n"plane.sizee" = [1.0, 2.0]\n', "grid.plane.sizee")
sweep_refusal("a negative size in the grid", '[grid]\n"plane.size" = [1.0, -1.0]\n', "grid.plane.size")
sweep_refusal("an empty grid list", '[grid]\n"plane.size" = []\n', "grid.plane.size")
sweep_refusal("samples = 0", '[grid]\n"plane.size" = [1.0]\n', "samples")
sweep_refusal("its scene missing", '[grid]\n"plane.size" = [1.0]\n', "missing.toml")


test_case = case_test(CASES)
