"""``diffuse-imaging check`` and ``export``: other tools' renders judged, our scenes for other tools."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
from pathlib import Path

from .common import (UsageError, add_quiet, announce_window, load_scene_argument, parameter_option, positive_float_type,
                     refuse_unmodellable)
from .counts import add_counts_options, check_counts_options, command_check_counts

__all__ = ["add_commands", "command_check", "command_export"]


def _stated(args):
    """What --expect / --expect-scale / --expect-offset state: a convention's name, a Convention, or None."""
    from validation.check import Convention

    if args.expect is not None and (args.expect_scale is not None or args.expect_offset is not None):
        raise UsageError("--expect: give a named convention or --expect-scale/--expect-offset, not both")
    if args.expect_scale is not None or args.expect_offset is not None:
        scale = 1.0 if args.expect_scale is None else args.expect_scale
        offset = 0.0 if args.expect_offset is None else args.expect_offset
        return Convention(scale=scale, offset_opl=offset, name="the stated scale and offset")
    return args.expect


def command_check(args) -> int:
    """Judge transient file(s) against the exact model of the scene; fit scale and offset.

    Exit status 0 when the data agree with the model as given, or with the
    convention stated by ``--expect``/``--expect-scale``/``--expect-offset``
    when one is; 1 when not. The work is :func:`validation.check.verdict.judge`,
    the function under ``validation.check_transient`` and
    ``validation.assert_agrees``, with the command line's words in its messages.
    """
    from analytic.files import output_folder
    from validation.check import write_check_report
    from validation.check.inputs import COMMAND_WORDS
    from validation.check.verdict import judge

    scene = load_scene_argument(args.scene)
    evaluate = _derivative_column(args, scene)
    if args.counts:
        return command_check_counts(args, scene)
    check_counts_options(args, scene)       # --fit / --false-alarm without --counts are refused
    if args.stderr is not None and len(args.data) > 1:
        raise UsageError("--stderr: give it with one --data file; several files are replicas whose "
                         "spread is their error")
    if args.shape_only and (args.stderr is not None or len(args.data) > 1):
        raise UsageError("--shape-only: only for one --data file without --stderr")
    refuse_unmodellable(scene, matrix=False)    # before the data are read: the model is what takes long
    data = args.data[0] if len(args.data) == 1 else list(args.data)
    result = judge(scene, data, stderr=args.stderr, shape_only=args.shape_only, expect=_stated(args),
                   radius=args.radius, words=COMMAND_WORDS, evaluate=evaluate)
    with output_folder(args.out) as out:
        announce_window(args, scene)
        name = scene.name if evaluate is None else f"{scene.name}, judged as dy/d{evaluate.key}"
        write_check_report(out, result, scene_name=name, data_paths=args.data, scene=scene)
    if not args.quiet:
        if evaluate is not None:
            print(f"check: --data judged as dy/d{evaluate.key} against its exact column")
        print(result.summary())
        print(f"-> {Path(args.out) / 'report.md'}")
    return 0 if result.verdict else 1


def _derivative_column(args, scene):
    """``--derivative KEY``: the exact column ∂y/∂KEY the data are judged against (None without it)."""
    from validation.check import DerivativeColumn

    if args.derivative is None:
        return None
    if args.counts or args.shape_only:
        raise UsageError(f"--derivative: judges a derivative with its standard errors (replicas or --stderr); "
                         f"not with {'--counts' if args.counts else '--shape-only'}")
    return DerivativeColumn(parameter_option(scene, args.derivative, "--derivative")[0].key)


def command_export(args) -> int:
    """Write the scene as a Mitsuba 3 XML file for our plugins or for mitransient; exit status 0."""
    from analytic.errors import UserError
    from analytic.files import output_folder
    from interop.mitransient.export import check_export_options, export_scene

    scene = load_scene_argument(args.scene)
    if args.format != "mitransient" and (args.radius is not None or args.spp is not None):
        raise UsageError("--radius/--spp: apply to --format mitransient only")
    try:
        check_export_options(scene, args.format, radius=args.radius, spp=args.spp)   # before the folder is made
    except UserError:
        raise
    except ValueError as error:
        raise UsageError(f"--{error}") from None
    if args.spp is not None and not 1 <= args.spp <= 2**31:
        raise UsageError(f"--spp: must be in [1, 2^31], got {args.spp}")
    from analytic.errors import SceneError

    _refuse_replacing_inputs(args.scene, args.out)
    with output_folder(args.out) as out:
        try:
            written = export_scene(scene, out, args.format, radius=args.radius, spp=args.spp)
        except SceneError:
            raise
        except ValueError as error:   # a bad --radius, named in the message
            raise UsageError(f"--{error}") from None
    if not args.quiet:
        print(f"export: {scene.name} for {args.format} -> {written['scene.xml']}")
    return 0


#: The files ``export`` writes in --out.
EXPORT_NAMES = ("scene.xml", "reflectance.exr", "README.md")


def _refuse_replacing_inputs(scene_path: str | None, out: str) -> None:
    """UsageError when a file export would write in ``out`` is the scene file or the image it reads.

    (--out in the scene's own folder, whose image is ``reflectance.exr``: the export would replace the
    user's image by its float32 copy.)
    """
    import tomllib

    if scene_path is None:
        return
    scene_path = Path(scene_path)
    inputs = [scene_path]
    with contextlib.suppress(OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):   # load_scene read it
        tables = tomllib.loads(scene_path.read_text(encoding="utf-8-sig"))
        inputs += [scene_path.parent / table["reflectance"] for table in tables.values()
                   if isinstance(table, dict) and isinstance(table.get("reflectance"), str)]
    for name in EXPORT_NAMES:
        target = Path(out) / name
        for source in inputs:
            with contextlib.suppress(OSError):
                if target.exists() and os.path.samefile(target, source):
                    raise UsageError(f"--out {out}: export would replace the scene's own {source.name} with "
                                     f"its {name}; choose another --out")


def _finite_float(option: str):
    """An argparse type for a finite float, naming ``option`` in its error."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option}: expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{option}: must be finite, got {text}")
        return value
    return parse


def add_commands(commands) -> None:
    """Add ``check`` and ``export``."""
    from interop.mitransient.export import FORMATS, RADIUS, SPP, SPP_RELAY_WALL

    check = commands.add_parser(
        "check", help="judge a transient from any tool against the exact model",
        description="Judge transient(s) rendered by anything against the exact model of SCENE, then "
                    "fit a global scale and a time offset (the two usual convention errors) and judge "
                    "again. Exit 0 when the data agree as given (or with the convention --expect states), "
                    "1 when not, 2 on a bad file.")
    check.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    check.add_argument("--data", nargs="+", required=True, metavar="FILE",
                       help="transient file(s): our transient.npy/.exr/.h5 or their folder, a (K, N) .npy, "
                            "tal's HDF5, mitransient's saved film (K, 1, 1, N, C) or save_frames folder; "
                            "several files are independent replicas")
    check.add_argument("--stderr", metavar="FILE",
                       help="per-bin standard error of a single --data file (default for our render's "
                            "output: its replicas.npy, else its stderr.npy with the replicas' degrees of "
                            "freedom)")
    check.add_argument("--shape-only", action="store_true",
                       help="judge a single file without errors by shape only (relative L2)")
    check.add_argument("--expect", choices=("irradiancemeter", "transient_nlos_path"),
                       help="judge against a stated convention, exit 0 when it holds: irradiancemeter = "
                            "mitransient's irradiancemeter spheres (--format mitransient export): the model "
                            "scaled by exactly 1/4 (a Lambertian plane needs no finite-sphere correction) "
                            "and its start_opl moved by 2r/3 + 8.94e-5 m (rays start on the sphere, plus "
                            "Mitsuba's float32 RayEpsilon); transient_nlos_path = mitransient's NLOS "
                            "integrator on a relay-wall scene (--format mitransient export): the model plus "
                            "what its float32 ray offsets add, emulated without a fitted parameter "
                            "(docs/interop.md)")
    check.add_argument("--radius", type=positive_float_type("--radius"),
                       help=f"--expect irradiancemeter: the spheres' radius, metres (default {RADIUS:g}, "
                            f"the export's)")
    check.add_argument("--expect-scale", type=positive_float_type("--expect-scale"), metavar="S",
                       help="judge against S x the model (data / model; default 1 with --expect-offset)")
    check.add_argument("--expect-offset", type=_finite_float("--expect-offset"), metavar="M",
                       help="judge against the model with its start_opl moved by +M metres (positive when "
                            "the data read path lengths short; default 0 with --expect-scale)")
    check.add_argument("--derivative", metavar="KEY",
                       help="judge --data as the derivative dy/dKEY (a differentiable renderer's, with replicas "
                            "or --stderr) against the exact column, KEY a scene-file key of docs/design.md "
                            "section 9 (sensors.positions.0.z, sampling.start, ...)")
    add_counts_options(check)
    check.add_argument("--out", required=True, help="output folder (report.md, metrics.json, figures)")
    add_quiet(check)
    check.set_defaults(run=command_check)

    export = commands.add_parser(
        "export", help="write the scene as a Mitsuba 3 XML file (ours or mitransient's plugins)",
        description="Write SCENE as scene.xml + reflectance.exr (+ README.md) for Mitsuba 3: with this "
                    "package's transient_opl integrator and omni_point sensors (--format mitsuba), or "
                    "with mitransient's transient_path and one irradiancemeter sphere per sensor "
                    "(--format mitransient). A relay-wall (NLOS) scene: our transient_opl_nlos, or "
                    "mitransient's transient_nlos_path with an nlos_capture_meter and a projector laser "
                    "(single and confocal scans).")
    export.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    export.add_argument("--format", required=True, choices=FORMATS, help="target plugins")
    export.add_argument("--out", required=True, help="output folder")
    export.add_argument("--radius", type=positive_float_type("--radius"),
                        help=f"mitransient: irradiancemeter sphere radius, metres (default {RADIUS:g})")
    export.add_argument("--spp", type=int,
                        help=f"mitransient: default samples per sensor in the XML (default {SPP}; a relay-wall "
                             f"capture's per film pixel, default {SPP_RELAY_WALL})")
    add_quiet(export)
    export.set_defaults(run=command_export)
