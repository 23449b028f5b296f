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
        "start_opl": scene.sampling.start,
        "period_opl": scene.sampling.period,
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
    waveform = make_waveform(scene.illumination, scene.sampling.period)
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
