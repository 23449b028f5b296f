"""``diffuse-imaging validate`` and ``run``: the model against the renderer, and the main job."""

from __future__ import annotations

import sys
from pathlib import Path

from .common import add_quiet, check_samples_type, load_scene_argument, seed_type, show_progress
from .reconstruct import add_lambda_options

__all__ = ["add_commands", "command_validate", "command_run"]

DEFAULT_SAMPLES = 2**22


def command_validate(args) -> int:
    """Cross-check renders against the model on the given scenes (default: the built-in suite).

    Exit status 0 when every scene agrees, 1 when any disagrees (named on stderr).
    """
    from analytic.io import output_folder, staged_writes
    from analytic.scene_file import load_scene
    from validation.corner import check_corner
    from validation.harness import check_scene
    from validation.report import write_report
    from validation.suite import validation_suite

    if args.scene:
        suite = [(load_scene(path), args.spp or DEFAULT_SAMPLES) for path in args.scene]
    else:
        suite = [(scene, args.spp or spp) for scene, spp in validation_suite()]
    with output_folder(args.out) as out:
        checks = []
        iterator = suite
        if show_progress(args):
            from tqdm import tqdm
            iterator = tqdm(suite, desc="validate", unit="scene", leave=False)
        for scene, spp in iterator:
            # Reconstruction needs an array of sensors; a hard case's one or two cannot image.
            checks.append(check_scene(scene, spp=spp, seed=args.seed, convergence=not args.fast,
                                      reconstruction=scene.pixels <= 64 and scene.sensor_count >= 4))
        # the corner's three bounces against mitransient, an independent renderer, when it is installed
        import importlib.util

        independent = 2**20 if importlib.util.find_spec("mitransient") is not None else None
        corner = None if args.scene else check_corner(spp=args.spp or DEFAULT_SAMPLES, seed=args.seed,
                                                      mitransient_samples=independent)
        with staged_writes():
            metrics = write_report(out, checks, corner)
    failed = [check for check in checks if not check.agreement.agrees]
    if corner is not None and not corner["one_bounce_agrees"]:
        print("diffuse-imaging: corner: the one-bounce render disagrees with the one-bounce model",
              file=sys.stderr)
    if corner is not None and corner["mitransient"].get("agrees") is False:
        print("diffuse-imaging: corner: our three-bounce render disagrees with mitransient's", file=sys.stderr)
    for check in failed:
        worst = ", ".join(f"sensor {k} bin {n} (z = {z:+.1f})" for k, n, z in check.agreement.worst[:5])
        print(f"diffuse-imaging: {check.name} DISAGREES: {worst}", file=sys.stderr)
    if not args.quiet:
        print(f"validate: {len(checks) - len(failed)} of {len(checks)} scenes agree"
              + ("" if corner is None else f"; corner: further bounces carry "
                 f"{100 * corner['further_bounce_share']:.1f} % of the light"
                 + {True: ", its three bounces agree with mitransient's",
                    False: ", its three bounces DISAGREE with mitransient's"}.get(
                     corner["mitransient"].get("agrees"), ""))
              + f" -> {Path(args.out) / 'report.md'}")
    return 0 if metrics["all_agree"] else 1


def command_run(args) -> int:
    """The whole pipeline on one scene: model, render, cross-check, reconstruct from both, report.

    Exit status 0 when the render agrees with the model, 1 when not.
    """
    from analytic.io import build_meta, output_folder, staged_writes, write_transient
    from validation.harness import check_scene
    from validation.report import write_report

    from validation.harness import data_driven_rule

    from .reconstruct import lambda_grid_of

    scene = load_scene_argument(args.scene)
    data_driven_rule(scene, args.rule)            # a rule the scene cannot serve is refused before any work
    grid = lambda_grid_of(args)
    with output_folder(args.out) as out:
        check = check_scene(scene, spp=args.spp, seed=args.seed, progress=show_progress(args), rule=args.rule,
                            lambdas=grid)
        share = check.metrics["window_share"]
        with staged_writes():
            write_transient(out / "model", check.model, build_meta(scene, kind="model", window_share=share))
            write_transient(out / "render", check.render,
                            build_meta(scene, kind="render", samples=args.spp, seed=args.seed,
                                       window_share=share), stderr=check.stderr)
            write_report(out, [check], headline=True)
    if not args.quiet:
        print(check.agreement.summary())
        recon = check.metrics.get("reconstruction", {})
        if "model" in recon:
            print(f"reconstruction PSNR: {recon['model']['psnr']:.1f} dB from model data, "
                  f"{recon['render']['psnr']:.1f} dB from rendered data -> {Path(args.out) / 'report.md'}")
    return 0 if check.agreement.agrees else 1


def add_commands(subparsers) -> None:
    """Add ``validate`` and ``run``."""
    validate = subparsers.add_parser("validate", help="cross-check renders against the model")
    validate.add_argument("scene", nargs="*", help="scene TOML files (default: the built-in suite)")
    validate.add_argument("--out", required=True, help="output folder (report.md, metrics.json, plots)")
    validate.add_argument("--spp", type=check_samples_type,
                          help=f"samples per render, at least 4,096 (default: the suite's, "
                               f"{DEFAULT_SAMPLES:,} for a file)")
    validate.add_argument("--seed", type=seed_type, default=0, help="random seed in [0, 2^32) (default 0)")
    validate.add_argument("--fast", action="store_true", help="skip the convergence studies")
    add_quiet(validate)
    validate.set_defaults(run=command_validate)

    run = subparsers.add_parser("run", help="model, render, cross-check, reconstruct, report: one scene")
    run.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    run.add_argument("--out", required=True, help="output folder")
    run.add_argument("--spp", type=check_samples_type, default=DEFAULT_SAMPLES,
                     help=f"render samples, at least 4,096 (default {DEFAULT_SAMPLES:,})")
    run.add_argument("--seed", type=seed_type, default=0, help="random seed in [0, 2^32) (default 0)")
    add_lambda_options(run, default="auto")
    add_quiet(run)
    run.set_defaults(run=command_run)
