"""``diffuse-imaging render``: the Monte Carlo estimate of a scene's transient, resumable from its folder alone."""

from __future__ import annotations

import shlex
import sys

from .common import UsageError, add_quiet, load_scene_argument, samples_type, seed_type, show_progress

__all__ = ["add_commands", "command_render"]


def _interrupted_line(interrupted) -> str:
    """One line: how far an interrupted render got, and the exact command that resumes it."""
    got = (f"interrupted after {interrupted.done:,} of {interrupted.planned:,} samples "
           f"({interrupted.completed} of {interrupted.replicas} replicas complete)")
    if interrupted.folder is None:
        return f"diffuse-imaging: {got}; nothing was saved"
    return (f"diffuse-imaging: {got}; resume with: diffuse-imaging render --resume "
            f"{shlex.quote(str(interrupted.folder))}")


def command_render(args) -> int:
    """Render (or resume rendering) into a folder; exit status 0 when done, 130 when interrupted."""
    from analytic.files import output_folder
    from analytic.window import warn_if_cut, window_share
    from transient.render import RenderInterrupted, render, resume
    from transient.render_state import read_saved_render

    from pathlib import Path

    if args.resume:
        if not Path(args.resume).is_dir():
            raise UsageError(f"--resume {args.resume}: no such folder; give the --out folder of the "
                             f"interrupted render")
        given = None if args.scene is None else load_scene_argument(args.scene)
        scene = read_saved_render(args.resume, scene=given).scene
    else:
        if args.spp is None:
            raise UsageError("--spp: required for a new render (the number of samples, e.g. --spp 4194304); "
                             "only --resume DIR takes it from the folder")
        scene = load_scene_argument(args.scene)
    warn_if_cut(scene, window_share(scene))
    folder = args.resume if args.resume else args.out
    option = "--resume" if args.resume else "--out"
    progress = show_progress(args)
    try:
        with output_folder(folder, option=option) as out:
            if args.resume:
                result = resume(out, scene=given, spp=args.spp, seed=args.seed, variant=args.variant,
                                progress=progress)
            else:
                result = render(scene, spp=args.spp, seed=0 if args.seed is None else args.seed, out_dir=out,
                                variant=args.variant, progress=progress)
    except RenderInterrupted as interrupted:
        print(_interrupted_line(interrupted), file=sys.stderr)
        return 130
    if not args.quiet:
        _summary(args, result, out)
    return 0


def _summary(args, result, out) -> None:
    """The render's size and speed; samples/s counts only the samples this run drew."""
    if result.drawn == 0:
        print(f"render: {out} already holds all {result.samples:,} samples ({result.variant})")
        return
    requested = args.spp
    if requested is not None and result.samples != requested:
        print(f"render: --spp {requested:,} rounded up to {result.samples:,} "
              f"({result.replicas} replicas of {result.samples // result.replicas:,} samples)")
    resumed = f" ({result.drawn:,} in this run)" if result.drawn != result.samples else ""
    print(f"render: {result.samples:,} samples{resumed} in {result.seconds:.1f} s "
          f"({result.drawn / max(result.seconds, 1e-9):,.0f} samples/s, {result.variant}) -> {out}")


def add_commands(subparsers) -> None:
    """Add ``render``."""
    render = subparsers.add_parser(
        "render", help="Monte Carlo render of the transient",
        description="Monte Carlo render of a scene's transient into --out DIR; an interrupted render "
                    "(Ctrl-C, SIGTERM) resumes with --resume DIR alone: the folder holds its scene, "
                    "seed, samples and variant, and any of them given again must match.")
    render.add_argument("scene", nargs="?",
                        help="scene TOML (default: the built-in scene; with --resume: the scene saved there)")
    render.add_argument("--spp", type=samples_type,
                        help="total number of samples (points on the plane; each serves every sensor), "
                             "rounded up to a whole number per replica (32 replicas); required with --out, "
                             "the state's with --resume")
    render.add_argument("--seed", type=seed_type,
                        help="random seed in [0, 2^32) (default 0; the state's with --resume)")
    group = render.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", help="output folder")
    group.add_argument("--resume", metavar="DIR", help="continue an interrupted render in DIR")
    render.add_argument("--variant",
                        help="Mitsuba variant: a mono llvm_* (CPU) or cuda_* (GPU) variant of the installed "
                             "Mitsuba; its pip wheels have llvm_ad_mono (the default) and cuda_ad_mono")
    add_quiet(render)
    render.set_defaults(run=command_render)
