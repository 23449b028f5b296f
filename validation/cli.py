"""The ``diffuse-imaging`` command.

Heavy modules (Numba kernels, Mitsuba) are imported inside each command so
that ``--help`` and argument errors answer at once. A bad scene or value
ends the command with exit status 2 and one line naming the key and the
problem, before any output file is written.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

__all__ = ["main"]


class UsageError(Exception):
    """A user error reported as one line with exit status 2."""


def _load(scene_path: str | None):
    from analytic.scene import default_scene, load_scene

    return default_scene() if scene_path is None else load_scene(scene_path)


def _scene_meta(scene, waveform) -> dict:
    return {
        "scene": scene.name,
        "start_opl": scene.sampling.start_opl,
        "period_opl": scene.sampling.bin_width_opl,
        "attenuation": scene.attenuation,
        "illumination": waveform.name,
        "illumination_detail": waveform.description,
        "source": scene.source.tolist(),
        "sensor_positions": scene.sensors.tolist(),
        "plane_size": scene.size,
        "pixels": scene.pixels,
    }


def command_forward(args) -> int:
    """Model the noiseless transient (and a noisy one when the scene asks)."""
    from analytic.io import write_transient
    from analytic.noise import add_noise
    from analytic.system import system_matrix
    from analytic.waveforms import make_waveform

    scene = _load(args.scene)
    if args.tolerance is not None:
        scene = scene.replace(tolerance=args.tolerance)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    started = time.perf_counter()
    matrix = system_matrix(scene, progress=not args.quiet)
    assembly = time.perf_counter() - started
    y = (matrix @ scene.reflectance.ravel()).reshape(scene.sensor_count, scene.sampling.count)
    noisy = add_noise(y, scene.noise) if scene.noise is not None else None
    meta = _scene_meta(scene, waveform) | {
        "kind": "model",
        "samples": 0,
        "seed": scene.noise.seed if scene.noise is not None else 0,
        "tolerance": scene.tolerance,
        "nonzeros": int(matrix.nnz),
        "assembly_seconds": assembly,
    }
    if scene.noise is not None:
        meta["noise"] = {"kind": scene.noise.kind, "sigma": scene.noise.sigma,
                         "photons": scene.noise.photons, "seed": scene.noise.seed}
    out = Path(args.out)
    write_transient(out, y, meta, noisy=noisy)
    from validation.plots import plot_transients

    curves = {"model": y} if noisy is None else {"model": y, "model + noise": noisy}
    plot_transients(out / "transient.png", scene.sampling.edges, curves,
                    title=f"{scene.name}: {waveform.name}, {scene.attenuation}")
    if not args.quiet:
        print(f"forward: {scene.sensor_count} sensors x {scene.sampling.count} bins, "
              f"A {matrix.shape[0]} x {matrix.shape[1]} with {matrix.nnz:,} non-zeros "
              f"assembled in {assembly:.2f} s -> {out}")
    return 0


def command_render(args) -> int:
    """Monte Carlo render of the same transient with its standard error."""
    from transient.render import render

    scene = _load(args.scene)
    out = Path(args.resume if args.resume else args.out)
    if args.spp is None or args.spp < 1:
        raise UsageError("--spp: give a positive sample count")
    result = render(scene, spp=args.spp, seed=args.seed, out_dir=out, variant=args.variant,
                    resume=bool(args.resume), progress=not args.quiet)
    if not args.quiet:
        print(f"render: {result.samples:,} samples in {result.seconds:.1f} s "
              f"({result.samples / max(result.seconds, 1e-9):,.0f} samples/s, {result.variant}) -> {out}")
    return 0


def command_validate(args) -> int:
    """Cross-check renders against the model on the given scenes (default: the built-in suite)."""
    from validation.corner import check_corner
    from validation.harness import check_scene
    from validation.report import write_report
    from validation.suite import validation_suite

    if args.scene:
        from analytic.scene import load_scene
        suite = [(load_scene(path), args.spp or 2**22) for path in args.scene]
    else:
        suite = [(scene, args.spp or spp) for scene, spp in validation_suite()]
    checks = []
    iterator = suite
    if not args.quiet:
        from tqdm import tqdm
        iterator = tqdm(suite, desc="validate", unit="scene")
    for scene, spp in iterator:
        # Reconstruction needs an array of sensors; a hard case's one or two cannot image.
        checks.append(check_scene(scene, spp=spp, seed=args.seed, convergence=not args.fast,
                                  reconstruction=scene.pixels <= 64 and scene.sensor_count >= 4))
    corner = None if args.scene else check_corner(spp=args.spp or 2**22, seed=args.seed)
    metrics = write_report(Path(args.out), checks, corner)
    failed = [check for check in checks if not check.agreement.agrees]
    if corner is not None and not corner["one_bounce_agrees"]:
        print("diffuse-imaging: corner: the one-bounce render disagrees with the one-bounce model",
              file=sys.stderr)
    for check in failed:
        worst = ", ".join(f"sensor {k} bin {n} (z = {z:+.1f})" for k, n, z in check.agreement.worst[:5])
        print(f"diffuse-imaging: {check.name} DISAGREES: {worst}", file=sys.stderr)
    if not args.quiet:
        print(f"validate: {len(checks) - len(failed)} of {len(checks)} scenes agree"
              + ("" if corner is None else f"; corner: further bounces carry "
                 f"{100 * corner['further_bounce_share']:.1f} % of the light")
              + f" -> {Path(args.out) / 'report.md'}")
    return 0 if metrics["all_agree"] else 1


def command_run(args) -> int:
    """The whole pipeline on one scene: model, render, cross-check, reconstruct from both, report."""
    from analytic.io import write_transient
    from analytic.waveforms import make_waveform
    from validation.harness import check_scene
    from validation.report import write_report

    scene = _load(args.scene)
    if scene.noise is not None:
        scene = scene.replace(noise=None)   # the cross-check compares noiseless model and render
    out = Path(args.out)
    check = check_scene(scene, spp=args.spp, seed=args.seed, progress=not args.quiet)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    meta = _scene_meta(scene, waveform)
    write_transient(out / "model", check.model, meta | {"kind": "model", "samples": 0, "seed": 0})
    write_transient(out / "render", check.render, meta | {"kind": "render", "samples": args.spp,
                                                          "seed": args.seed}, stderr=check.stderr)
    write_report(out, [check])
    if not args.quiet:
        print(check.agreement.summary())
        recon = check.metrics.get("reconstruction", {})
        if "model" in recon:
            print(f"reconstruction PSNR: {recon['model']['psnr']:.1f} dB from model data, "
                  f"{recon['render']['psnr']:.1f} dB from rendered data (same λ) -> {out / 'report.md'}")
    return 0 if check.agreement.agrees else 1


def command_bench(args) -> int:
    """Speed against error: model over tolerance, renderer and mitransient over samples."""
    from validation.bench import speed_against_error

    result = speed_against_error(args.out)
    if not args.quiet:
        print(result["markdown"])
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="diffuse-imaging",
        description="Diffuse imaging of a Lambertian plane: exact forward model, Monte Carlo "
                    "rendering, cross-check. Lengths in metres, time as path length (c = 1).")
    commands = parser.add_subparsers(dest="command", required=True)

    forward = commands.add_parser("forward", help="model the noiseless transient y = A f")
    forward.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    forward.add_argument("--out", required=True, help="output folder")
    forward.add_argument("--tolerance", type=float, help="relative accuracy of A (default 1e-6)")
    forward.add_argument("--quiet", action="store_true", help="no progress or summary")
    forward.set_defaults(run=command_forward)

    render = commands.add_parser("render", help="Monte Carlo render of the transient")
    render.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    render.add_argument("--spp", type=int, help="total number of samples")
    render.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    group = render.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", help="output folder")
    group.add_argument("--resume", metavar="DIR", help="continue an interrupted render in DIR")
    render.add_argument("--variant", help="Mitsuba variant (default: llvm, CPU)")
    render.add_argument("--quiet", action="store_true", help="no progress or summary")
    render.set_defaults(run=command_render)

    validate = commands.add_parser("validate", help="cross-check renders against the model")
    validate.add_argument("scene", nargs="*", help="scene TOML files (default: the built-in suite)")
    validate.add_argument("--out", required=True, help="output folder (report.md, metrics.json, plots)")
    validate.add_argument("--spp", type=int, help="samples per render (default: the suite's)")
    validate.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    validate.add_argument("--fast", action="store_true", help="skip the convergence studies")
    validate.add_argument("--quiet", action="store_true", help="no progress or summary")
    validate.set_defaults(run=command_validate)

    run = commands.add_parser("run", help="model, render, cross-check, reconstruct, report: one scene")
    run.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    run.add_argument("--out", required=True, help="output folder")
    run.add_argument("--spp", type=int, default=2**22, help="render samples (default 2^22)")
    run.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    run.add_argument("--quiet", action="store_true", help="no progress or summary")
    run.set_defaults(run=command_run)

    bench = commands.add_parser("bench", help="speed against error of model, renderer, mitransient")
    bench.add_argument("--out", required=True, help="output folder")
    bench.add_argument("--quiet", action="store_true", help="no summary")
    bench.set_defaults(run=command_bench)
    from validation.cli_reconstruct import add_commands as add_reconstruction_commands
    from validation.cli_sweep import add_commands as add_sweep_commands

    add_reconstruction_commands(commands)   # reconstruct, reproduce
    add_sweep_commands(commands)            # sweep
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except KeyboardInterrupt:
        print("diffuse-imaging: interrupted", file=sys.stderr)
        return 130
    except Exception as error:  # one line for the user's mistakes, a traceback for ours
        if _is_user_error(error):
            print(f"diffuse-imaging: error: {error}", file=sys.stderr)
            return 2
        raise


def _is_user_error(error: Exception) -> bool:
    from analytic.reflectance import ImageError
    from analytic.scene import SceneError

    if isinstance(error, (SceneError, ImageError, UsageError, FileNotFoundError)):
        return True
    try:
        from transient.backend import BackendError
    except ImportError:
        return False
    return isinstance(error, BackendError)


if __name__ == "__main__":
    sys.exit(main())
