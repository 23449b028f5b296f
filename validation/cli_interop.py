"""The ``check`` and ``export`` subcommands of ``diffuse-imaging`` (other tools' renders and scenes).

Wired into the main parser with::

    from validation.cli_interop import add_commands
    add_commands(commands)      # commands = parser.add_subparsers(...)

Each command returns an exit status: ``check`` 0 when the data agree with
the model as given, 1 when not; ``export`` 0. User mistakes raise
:class:`validation.check.DataError` (a bad data file),
:class:`analytic.scene.SceneError` (a bad scene or option),
:class:`analytic.reflectance.ImageError` or :class:`FileNotFoundError`,
which the main CLI turns into one line and exit status 2. Heavy modules
are imported inside the commands so that ``--help`` answers at once.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["add_commands", "command_check", "command_export"]


def _load_scene(path: str | None):
    from analytic.scene import default_scene, load_scene

    return default_scene() if path is None else load_scene(path)


def command_check(args) -> int:
    """Judge transient file(s) against the exact model of the scene; fit scale and offset."""
    import numpy as np

    from validation.check import DataError, check_transient, read_data, read_stderr, write_check_report

    scene = _load_scene(args.scene)
    if args.stderr is not None and len(args.data) > 1:
        raise DataError("--stderr: give it with one --data file; several files are replicas whose "
                        "spread is their error")
    if args.shape_only and (args.stderr is not None or len(args.data) > 1):
        raise DataError("--shape-only: only for one --data file without --stderr")
    arrays = [read_data(path, scene) for path in args.data]
    stderr = read_stderr(args.stderr, scene) if args.stderr is not None else None
    data = arrays[0] if len(arrays) == 1 else np.stack(arrays)
    result = check_transient(scene, data, stderr=stderr, shape_only=args.shape_only)
    out = Path(args.out)
    write_check_report(out, result, scene_name=scene.name, data_paths=args.data)
    if not args.quiet:
        print(result.summary())
        print(f"-> {out / 'report.md'}")
    return 0 if result.agrees else 1


def command_export(args) -> int:
    """Write the scene as a Mitsuba 3 XML file for our plugins or for mitransient."""
    from transient.export import export_scene

    from analytic.scene import SceneError

    scene = _load_scene(args.scene)
    if args.format != "mitransient" and (args.radius is not None or args.spp is not None):
        raise SceneError("--radius/--spp", "apply to --format mitransient only")
    try:
        written = export_scene(scene, args.out, args.format, radius=args.radius, spp=args.spp)
    except SceneError:
        raise
    except ValueError as error:   # a bad --radius or --spp, named in the message
        raise SceneError("export", str(error)) from None
    if not args.quiet:
        print(f"export: {scene.name} for {args.format} -> {written['scene.xml']}")
    return 0


def _positive_float(text: str) -> float:
    import argparse
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be finite and > 0, got {text!r}")
    return value


def add_commands(commands) -> None:
    """Add ``check`` and ``export`` to the ``diffuse-imaging`` subparsers.

    Parameters
    ----------
    commands : argparse._SubParsersAction
        What ``parser.add_subparsers()`` returned.
    """
    from transient.export import FORMATS, RADIUS, SPP

    check = commands.add_parser(
        "check", help="judge a transient from any tool against the exact model",
        description="Judge transient(s) rendered by anything against the exact model of SCENE, then "
                    "fit a global scale and a time offset (the two usual convention errors) and judge "
                    "again. Exit 0 when the data agree as given, 1 when not, 2 on a bad file.")
    check.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    check.add_argument("--data", nargs="+", required=True, metavar="FILE",
                       help="transient file(s): our transient.npy/.exr or their folder, a (K, N) .npy, "
                            "tal's HDF5, mitransient's saved film (K, 1, 1, N, C) or save_frames folder; "
                            "several files are independent replicas")
    check.add_argument("--stderr", metavar="FILE", help="per-bin standard error of a single --data file")
    check.add_argument("--shape-only", action="store_true",
                       help="judge a single file without errors by shape only (relative L2)")
    check.add_argument("--out", required=True, help="output folder (report.md, metrics.json, figures)")
    check.add_argument("--quiet", action="store_true", help="no summary")
    check.set_defaults(run=command_check)

    export = commands.add_parser(
        "export", help="write the scene as a Mitsuba 3 XML file (ours or mitransient's plugins)",
        description="Write SCENE as scene.xml + reflectance.exr (+ README.md) for Mitsuba 3: with this "
                    "package's transient_opl integrator and omni_point sensors (--format mitsuba), or "
                    "with mitransient's transient_path and one irradiancemeter sphere per sensor "
                    "(--format mitransient).")
    export.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    export.add_argument("--format", required=True, choices=FORMATS, help="target plugins")
    export.add_argument("--out", required=True, help="output folder")
    export.add_argument("--radius", type=_positive_float,
                        help=f"mitransient: irradiancemeter sphere radius, metres (default {RADIUS:g})")
    export.add_argument("--spp", type=int,
                        help=f"mitransient: default samples per sensor in the XML (default {SPP})")
    export.add_argument("--quiet", action="store_true", help="no summary")
    export.set_defaults(run=command_export)
