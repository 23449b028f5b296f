"""``diffuse-imaging render``: the Monte Carlo estimate of a scene's transient, resumable."""

from __future__ import annotations

from .common import UsageError, add_quiet, load_scene_argument, samples_type, seed_type, show_progress

__all__ = ["add_commands", "command_render"]


def command_render(args) -> int:
    """Render (or resume rendering) into ``--out``; exit status 0 when done."""
    from analytic.io import output_folder
    from analytic.window import warn_if_cut, window_share
    from transient.render import render

    from pathlib import Path

    scene = load_scene_argument(args.scene)
    if args.resume and not Path(args.resume).is_dir():
        raise UsageError(f"--resume {args.resume}: no such folder; give the --out folder of the "
                         f"interrupted render")
    warn_if_cut(scene, window_share(scene))
    folder = args.resume if args.resume else args.out
    option = "--resume" if args.resume else "--out"
    with output_folder(folder, option=option) as out:
        result = render(scene, spp=args.spp, seed=args.seed, out_dir=out, variant=args.variant,
                        resume=bool(args.resume), progress=show_progress(args))
    if not args.quiet:
        if args.spp is not None and result.samples != args.spp:
            print(f"render: --spp {args.spp:,} rounded up to {result.samples:,} "
                  f"({result.replicas} replicas of {result.samples // result.replicas:,} samples)")
        print(f"render: {result.samples:,} samples in {result.seconds:.1f} s "
              f"({result.samples / max(result.seconds, 1e-9):,.0f} samples/s, {result.variant}) -> {out}")
    return 0


def add_commands(subparsers) -> None:
    """Add ``render``."""
    render = subparsers.add_parser("render", help="Monte Carlo render of the transient")
    render.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    render.add_argument("--spp", type=samples_type, required=True,
                        help="total number of samples (points on the plane; each serves every sensor), "
                             "rounded up to a whole number per replica (32 replicas)")
    render.add_argument("--seed", type=seed_type, default=0, help="random seed in [0, 2^32) (default 0)")
    group = render.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", help="output folder")
    group.add_argument("--resume", metavar="DIR", help="continue an interrupted render in DIR")
    render.add_argument("--variant", help="Mitsuba variant: llvm_ad_mono or llvm_mono (CPU, the default), "
                                          "cuda_ad_mono or cuda_mono (GPU)")
    add_quiet(render)
    render.set_defaults(run=command_render)
