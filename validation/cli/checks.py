"""``diffuse-imaging validate`` and ``run``: the model against the renderer, and the main job."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from .common import (UsageError, add_quiet, add_window_option, announce_window, apply_window, check_samples_type,
                     load_scene_argument, refuse_unmodellable, release_warnings, seed_type, show_progress)
from .counts import RENDER_STREAM, draw_scene_counts, refuse_unreachable_counts, write_counts
from .reconstruct import add_lambda_options, error_text, information_text

__all__ = ["add_commands", "command_validate", "command_run", "show_reconstruction_warnings"]

DEFAULT_SAMPLES = 2**22


def _named(error, label: str):
    """The same user error, its one line now starting with ``label`` (which scene it is about)."""
    error.args = (f"{label}: {error.args[0] if error.args else error}", *error.args[1:])
    return error


def _suite_samples(requested: int | None) -> list:
    """The built-in suite with each scene's samples: its own, or ``--spp`` when every scene can use it.

    Raises
    ------
    UsageError
        When ``--spp`` is below what some suite scene needs for any of its
        bins to be judged (:data:`validation.runs.suite.MINIMUM_SAMPLES`), naming
        those scenes, before any work.
    """
    from validation.runs.suite import MINIMUM_SAMPLES, validation_suite

    suite = validation_suite()
    if requested is None:
        return suite
    short = [(scene.name, MINIMUM_SAMPLES[scene.name]) for scene, _ in suite
             if requested < MINIMUM_SAMPLES.get(scene.name, 0)]
    if short:
        needed = max(minimum for _, minimum in short)
        names = [f"{name} (needs {minimum:,})" for name, minimum in short]
        names = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
        raise UsageError(f"--spp {requested}: too few samples for the suite's scene{'s' * (len(short) > 1)} "
                         f"{names}: their light is spread over so many bins that no bin's standard error "
                         f"would be under 0.1 of its value, so nothing could be judged; give --spp {needed} "
                         f"or more, or leave --spp out (the suite's own counts)")
    return [(scene, requested) for scene, _ in suite]


def command_validate(args) -> int:
    """Cross-check renders against the model on the given scenes (default: the built-in suite).

    Exit status 0 when every scene agrees, 1 when any disagrees (named on stderr).
    A user error met while checking a scene (one that cannot be judged at
    ``--spp``, say) names that scene. Each scene's figures are in a folder
    named by :func:`validation.runs.report.scene_folder_names`.
    """
    from analytic.errors import UserError
    from analytic.files import output_folder, staged_writes
    from analytic.operator.window import window_share
    from validation.runs.corner import check_corner
    from validation.runs.harness import check_scene, refuse_dark
    from validation.runs.report import write_report

    if args.scene:
        suite = [(load_scene_argument(path), args.spp or DEFAULT_SAMPLES) for path in args.scene]
        labels = [f"scene {scene.name!r} ({path})" for (scene, _), path in zip(suite, args.scene)]
    else:
        suite = _suite_samples(args.spp)
        labels = [f"suite scene {scene.name!r}" for scene, _ in suite]
    shares = []
    for (scene, spp), label in zip(suite, labels):    # a scene with no light is refused before any render
        shares.append(window_share(scene))
        try:
            refuse_unmodellable(scene)
            refuse_dark(scene, shares[-1])
        except UserError as error:
            raise _named(error, f"{label} at {spp:,} samples") from None
    release_warnings()                                 # every scene accepted: what they warned of, before the work
    with output_folder(args.out) as out:
        checks = []
        iterator = list(zip(suite, labels, shares))
        if show_progress(args):
            from tqdm import tqdm
            iterator = tqdm(iterator, desc="validate", unit="scene", leave=False)
        for (scene, spp), label, share in iterator:
            try:
                # Reconstruction needs an array of sensors; a hard case's one or two cannot image.
                checks.append(check_scene(scene, spp=spp, seed=args.seed, convergence=not args.fast,
                                          reconstruction=scene.pixels <= 64 and scene.sensor_count >= 4,
                                          share=share))
            except UserError as error:
                raise _named(error, f"{label} at {spp:,} samples") from None
        # the corner's three bounces against mitransient, an independent renderer, when it is installed
        import importlib.util

        independent = 2**20 if importlib.util.find_spec("mitransient") is not None else None
        corner = None
        if not args.scene:
            try:
                corner = check_corner(spp=args.spp or DEFAULT_SAMPLES, seed=args.seed,
                                      mitransient_samples=independent)
            except UserError as error:
                raise _named(error, "the corner") from None
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

    Exit status 0 when the render agrees with the model, 1 when not. Its
    figures lie beside report.md in ``--out`` (one scene: no folder of its
    own; :mod:`validation.runs.report`).
    """
    from analytic.operator.window import window_share
    from validation.runs.harness import data_driven_rule, imaging_problem, refuse_dark
    from validation.plots.worker import FigureWorker

    from .reconstruct import lambda_grid_of

    scene = load_scene_argument(args.scene)
    with FigureWorker() as drawer:                # matplotlib's import and half the drawing beside the work
        scene = apply_window(args, scene)
        data_driven_rule(scene, args.rule)        # a rule the scene cannot serve is refused before any work
        unimageable = imaging_problem(scene)
        if unimageable is not None and (args.rule != "auto" or args.lambda_range or args.lambda_count):
            raise UsageError(f"--lambda: run does not reconstruct this scene ({unimageable}); leave out "
                             f"--lambda, --lambda-range and --lambda-count")
        grid = lambda_grid_of(args)
        refuse_unmodellable(scene)                # a response the model cannot cover in reasonable time, or
                                                  # an A beyond memory
        refuse_unreachable_counts(scene)          # before the model and render, not after them
        share = window_share(scene)
        refuse_dark(scene, share)                 # nothing to judge: one line, not a warning and then an error
        check = _run(args, scene, share, grid, drawer)
    if not args.quiet:
        print(check.summary())
        recon = check.metrics.get("reconstruction", {})
        if "skipped" in recon:
            print(f"no reconstruction: {recon['skipped']}")
        if "model" in recon:
            print(f"reconstruction: {information_text(recon['information'])}PSNR {recon['model']['psnr']:.1f} dB "
                  f"from model data, {recon['render']['psnr']:.1f} dB from rendered data -> "
                  f"{Path(args.out) / 'report.md'}")
            if recon.get("error"):
                print(f"reconstruction error at the model data's λ: {error_text(recon['error'])}")
            elif recon.get("error_note"):
                print(f"reconstruction error at the model data's λ: {recon['error_note']}")
    return 0 if check.agreement.agrees else 1


def _run(args, scene, share: float, grid, drawer):
    """``run``'s work once its inputs are accepted: the check, then its files, all or none."""
    from analytic.files import build_meta, output_folder, staged_writes, write_transient
    from validation.runs.harness import check_scene
    from validation.runs.report import write_report

    with output_folder(args.out) as out:
        announce_window(args, scene, share)       # check_scene's own warning of a cut window is the same line
        check = check_scene(scene, spp=args.spp, seed=args.seed, progress=show_progress(args), rule=args.rule,
                            lambdas=grid, share=share)
        show_reconstruction_warnings(check.reconstructions)
        share = check.metrics["window_share"]
        # independent draws: the render's from a stream of its own
        counts = {part: draw_scene_counts(scene, y, stream=stream)
                  for part, y, stream in (("model", check.model, 0), ("render", check.render, RENDER_STREAM))}
        with staged_writes():
            write_transient(out / "model", check.model, build_meta(scene, kind="model", window_share=share),
                            scene=scene)
            write_transient(out / "render", check.render,
                            build_meta(scene, kind="render", samples=args.spp, seed=args.seed,
                                       window_share=share, replicas=check.replicas, dof=check.replicas - 1),
                            scene=scene, stderr=check.stderr)
            for part, drawn in counts.items():
                write_counts(out / part, scene, drawn, label=part)
            write_report(out, [check], headline=True, drawer=drawer)
    return check


def show_reconstruction_warnings(reconstructions: dict) -> None:
    """Each warning of ``run``'s reconstructions again, naming the data it came from, for the one-line policy.

    ``reconstructions`` is :func:`validation.runs.harness.reconstruct_from_noisy_data`'s
    result; its ``warnings`` (about A and σ: shown once, "from the scene")
    and its ``model`` and ``render`` entries' ``warnings`` are lists of
    ``{"category": name, "message": text}`` with the category's
    name in :mod:`analytic.inversion` (``RankDeficiencyWarning``,
    ``RegularizationWarning``); another name is shown as a RuntimeWarning.
    """
    from analytic import inversion

    shown = [("the scene", entry) for entry in reconstructions.get("warnings", ())]     # A's and σ's: once
    shown += [(data, entry) for key, data in (("model", "the model's data"), ("render", "the render's data"))
              for entry in reconstructions.get(key, {}).get("warnings", ())]
    for data, entry in shown:
        category = getattr(inversion, str(entry.get("category")), None)
        if not (isinstance(category, type) and issubclass(category, Warning)):
            category = RuntimeWarning
        warnings.warn(f"reconstruction from {data}: {entry['message']}", category, stacklevel=2)


def add_commands(subparsers) -> None:
    """Add ``validate`` and ``run``."""
    validate = subparsers.add_parser("validate", help="cross-check renders against the model")
    validate.add_argument("scene", nargs="*", help="scene TOML files, planes or relay-wall captures (default: "
                                                   "the built-in suite, relay-wall cases included)")
    validate.add_argument("--out", required=True, help="output folder (report.md, metrics.json, plots)")
    validate.add_argument("--spp", type=check_samples_type,
                          help=f"samples per render, at least 4,096, and 65,536 for the built-in suite, "
                               f"whose finest-binned scenes judge nothing below it (default: the suite's, "
                               f"{DEFAULT_SAMPLES:,} for a file)")
    validate.add_argument("--seed", type=seed_type, default=0, help="random seed in [0, 2^32) (default 0)")
    validate.add_argument("--fast", action="store_true", help="skip the convergence studies")
    add_quiet(validate)
    validate.set_defaults(run=command_validate)

    run = subparsers.add_parser("run", help="model, render, cross-check, reconstruct, report: one scene")
    run.add_argument("scene", nargs="?", help="scene TOML, a plane or a relay-wall capture (default: the "
                                              "built-in scene)")
    run.add_argument("--out", required=True, help="output folder")
    run.add_argument("--spp", type=check_samples_type, default=DEFAULT_SAMPLES,
                     help=f"render samples, at least 4,096 (default {DEFAULT_SAMPLES:,})")
    run.add_argument("--seed", type=seed_type, default=0, help="random seed in [0, 2^32) (default 0)")
    add_lambda_options(run, default="auto")
    add_window_option(run)
    add_quiet(run)
    run.set_defaults(run=command_run)
