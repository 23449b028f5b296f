"""``diffuse-imaging render``: the Monte Carlo estimate of a scene's transient, resumable from its folder alone."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from .common import (UsageError, add_quiet, add_window_option, announce_window, apply_window, load_scene_argument,
                     samples_type, seed_type, show_progress)
from .counts import discard_counts, refuse_unreachable_counts, write_render_counts

__all__ = ["add_commands", "command_render"]


def _interrupted_line(folder: str | None) -> str:
    """One line: the render was interrupted, and the exact command that resumes it (its folder as given)."""
    if folder is None:
        return "diffuse-imaging: interrupted; nothing was saved"
    return f"diffuse-imaging: interrupted; resume with: diffuse-imaging render --resume {shlex.quote(folder)}"


def _resumed_scene(args):
    """(scene given, saved render) of ``--resume DIR``: the state's, checked against SCENE, --spp, --seed
    and --variant when they are given again (each that differs is named, on one line, before any work)."""
    from transient.render_state import read_saved_render

    if not Path(args.resume).is_dir():
        raise UsageError(f"--resume {args.resume}: no such folder; give the --out folder of the "
                         f"interrupted render")
    given = None if args.scene is None else apply_window(args, load_scene_argument(args.scene))
    saved = read_saved_render(args.resume, scene=given, spp=args.spp, seed=args.seed, variant=args.variant)
    if given is None and args.window == "auto":
        from analytic.operator.window import auto_sampling

        if auto_sampling(saved.scene) != saved.scene.sampling:
            window = saved.scene.sampling
            raise UsageError(f"--window auto: the render in {args.resume} was started with the window start "
                             f"{window.start_opl:.12g} m, count {window.count}, not the automatic one; leave "
                             f"--window out to resume it")
    return given, saved


def command_render(args) -> int:
    """Render (or resume rendering) into a folder; exit status 0 when done, 130 when interrupted."""
    from validation.plots.worker import FigureWorker

    if args.resume:
        given, saved = _resumed_scene(args)
        scene, variant = saved.scene, saved.variant
    else:
        if args.spp is None:
            raise UsageError("--spp: required for a new render (the number of samples, e.g. --spp 4194304); "
                             "only --resume DIR takes it from the folder")
        given, scene, variant = None, apply_window(args, load_scene_argument(args.scene)), \
            args.variant
    with FigureWorker() as drawer:     # matplotlib's import beside Mitsuba's (validation.plots.worker)
        return _render(args, scene, given, variant, drawer)


def _render(args, scene, given, variant, drawer) -> int:
    from analytic.files import output_folder
    from transient.backend import select_variant
    from transient.render import FIGURE_FILE, render, resume

    select_variant(variant)          # a variant that cannot run here is refused before anything is said
    refuse_unreachable_counts(scene)  # the counts are drawn after the render's files: their limit is checked first
    folder = args.resume if args.resume else args.out
    option = "--resume" if args.resume else "--out"
    progress = show_progress(args)
    try:
        with output_folder(folder, option=option) as out:
            announce_window(args, scene)
            if args.resume:
                result = resume(out, scene=given, spp=args.spp, seed=args.seed, variant=args.variant,
                                progress=progress)
            else:
                discard_counts(out)
                result = render(scene, spp=args.spp, seed=0 if args.seed is None else args.seed, out_dir=out,
                                variant=args.variant, progress=progress)
            _draw(drawer, out / FIGURE_FILE, scene, result)
            write_render_counts(out, scene, result.mean)
    except KeyboardInterrupt as interrupted:
        # a RenderInterrupted names the folder its state was saved in; a resume's folder holds one anyway
        resumable = args.resume or getattr(interrupted, "folder", None) is not None
        print(_interrupted_line(folder if resumable else None), file=sys.stderr)
        return 130
    if not args.quiet:
        _summary(args, result, out)
    return 0


def _draw(drawer, path: Path, scene, result) -> None:
    """The render's figure (as ``forward`` draws the model's), with ±1 standard error as a band."""
    from validation.plots import scene_transient_figure

    from .plot import render_title

    title = render_title(scene.name, samples=result.samples, replicas=result.replicas)
    drawer.draw(scene_transient_figure, scene, result.mean, stderr=result.stderr, label="render", title=title)
    drawer.save(path)


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
        description="Monte Carlo render of a scene's transient into --out DIR (transient.npy/.exr/.h5, "
                    "stderr.npy, replicas.npy, meta.json and the figure transient.png, once every replica is "
                    "done; until then the estimate so far is in DIR/partial/). An interrupted render (Ctrl-C, "
                    "SIGTERM) resumes with --resume DIR alone: the folder holds its scene, seed, samples and "
                    "variant, and any of them given again must match.")
    render.add_argument("scene", nargs="?",
                        help="scene TOML, a plane or a relay-wall capture (default: the built-in scene; with "
                             "--resume: the scene saved there)")
    render.add_argument("--spp", type=samples_type,
                        help="total number of samples (points on the plane or the hidden rectangle; each "
                             "serves every sensor or (laser point, read point) pair), "
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
    add_window_option(render)
    add_quiet(render)
    render.set_defaults(run=command_render)
