"""``diffuse-imaging crb``: what a capture can tell, the Cramér-Rao bounds of its image and free parameters."""

from __future__ import annotations

import sys

from .common import (add_quiet, announce_model, load_scene_argument, parameter_option, refuse_unmodellable,
                     release_warnings)

__all__ = ["add_commands", "command_crb"]


def command_crb(args) -> int:
    """Write crb.npy, crb.json and the figures; one line on stderr says what the data fix; exit status 0."""
    import numpy as np

    from analytic.files import output_folder, save_json, save_npy, staged_writes
    from analytic.inversion.bounds import crb
    from analytic.measurement.fisher import measurement_of
    from analytic.operator.system import system_matrix
    from validation.plots import save_figure
    from validation.plots.bounds import bound_image_figure, whitened_spectrum_figure

    scene = load_scene_argument(args.scene)
    cost = refuse_unmodellable(scene)
    measurement_of(scene, args.measurement)             # the inputs, checked before any file
    if args.free:
        parameter_option(scene, args.free, "--free")
    release_warnings()
    with output_folder(args.out) as out:
        announce_model(args, cost, "crb")
        matrix = system_matrix(scene)
        bounds = crb(scene, args.free, matrix=matrix, measurement=args.measurement)
        record = {"scene": scene.name, **bounds.as_dict()}
        what = f"{scene.name}: {bounds.measurement}"
        with staged_writes():
            save_npy(out / "crb.npy", bounds.image)
            save_json(out / "crb.json", record)
            save_figure(bound_image_figure(np.asarray(scene.reflectance, dtype=np.float64), bounds.image,
                                           title=what), out / "crb.png")
            save_figure(whitened_spectrum_figure(bounds.singular_values, title=what), out / "spectrum.png")
    print(f"diffuse-imaging: crb: {bounds.summary()}", file=sys.stderr)
    if not args.quiet:
        for key, entry in bounds.parameters.items():
            print(f"crb: {key} = {entry['value']:.6g} ± {entry['bound']:.3g} (Cramér-Rao, 1 standard deviation)")
        print(f"crb: M = {scene.pixels}, {bounds.measurement} -> {out}")
    return 0


def add_commands(subparsers) -> None:
    """Add ``crb``."""
    command = subparsers.add_parser("crb", help="Cramér-Rao bounds: how well the scene's data fix its image "
                                                "and free parameters")
    command.add_argument("scene", nargs="?", help="scene TOML with [noise] or [detector] (default: the built-in "
                                                  "scene)")
    command.add_argument("--free", nargs="+", default=[], metavar="KEY",
                         help="parameters estimated with the image (keys of docs/design.md section 9, e.g. "
                              "source.position.z): their uncertainty enters the image's bound")
    command.add_argument("--measurement", choices=("auto", "noise", "detector"), default="auto",
                         help="which data: the [detector]'s counts (auto, when the scene has one) or the "
                              "[noise]'s samples")
    command.add_argument("--out", required=True, help="output folder")
    add_quiet(command)
    command.set_defaults(run=command_crb)
