"""``diffuse-imaging jacobian``: ∂y/∂θ of a scene for parameters named by scene-file keys (docs/design.md section 9)."""

from __future__ import annotations

import time
from pathlib import Path

from .common import add_quiet, load_scene_argument, parameter_option, positive_float_type, rows_text, show_progress

__all__ = ["add_commands", "command_jacobian"]


def command_jacobian(args) -> int:
    """Write jacobian.npy ``(K, N, P)`` and meta.json naming the keys, their units and each column's error
    bound; exit status 0."""
    from analytic.files import build_meta, output_folder, save_json, save_npy, staged_writes
    from analytic.operator.derivatives import exact_keys, jacobian

    scene = load_scene_argument(args.scene)
    if args.tolerance is not None:
        scene = scene.replace(tolerance=args.tolerance)
    items = parameter_option(scene, args.parameters, "--parameters")   # a bad key: one line, before any file
    exact = exact_keys(scene, items)
    with output_folder(args.out) as out:
        started = time.perf_counter()
        values, bounds = jacobian(scene, [item.key for item in items], progress=show_progress(args), errors=True)
        seconds = time.perf_counter() - started
        meta = build_meta(scene, kind="model", jacobian={
            "shape": list(values.shape), "axes": ["row (sensor or pair)", "bin", "parameter"],
            "parameters": [{"key": item.key, "unit": item.unit, "route": "exact" if closed else "differences",
                            "column_unit": f"y per {item.unit}" if item.unit != "1" else "y per unit scale",
                            "error": _error(values[..., p], bounds[:, p], closed)}
                           for p, (item, closed) in enumerate(zip(items, exact))],
            "seconds": seconds})
        with staged_writes():
            save_npy(out / "jacobian.npy", values)
            save_json(out / "meta.json", meta)
    if not args.quiet:
        routes = sum(exact)
        print(f"jacobian: {rows_text(scene)} x {scene.sampling.count} bins x {len(items)} parameters "
              f"({routes} exact, {len(items) - routes} by differences) in {seconds:.2f} s -> {Path(args.out)}")
    return 0


def _error(column, bound, closed: bool) -> dict:
    """meta.json's error bound of one key: per row (sensor or pair), in the column's units and relative to the
    row's largest |entry| (null where the column is zero), and what it is (docs/derivatives.md "Error estimates")."""
    import numpy as np

    largest = np.abs(column).max(axis=-1)
    relative = [float(b / top) if top > 0 else None for b, top in zip(bound, largest)]    # None: a zero column
    basis = ("the scene's tolerance of the column's largest entry (what the exact route's integrals are judged to)"
             if closed else "Richardson pair's disagreement or the stencil's second-difference change times the "
                            "step, whichever is larger, plus the model's tolerance over the step")
    return {"bound": [float(b) for b in bound], "relative": relative, "basis": basis}


def add_commands(subparsers) -> None:
    """Add ``jacobian``."""
    command = subparsers.add_parser("jacobian", help="∂y/∂θ for parameters named by scene-file keys")
    command.add_argument("scene", nargs="?", help="scene TOML, a plane or a relay-wall capture (default: the "
                                                  "built-in scene)")
    command.add_argument("--parameters", nargs="+", required=True, metavar="KEY",
                         help="scene-file keys (source.position.x, sensors.positions.3.z, sampling.start, ...; "
                              "docs/design.md section 9)")
    command.add_argument("--out", required=True, help="output folder")
    command.add_argument("--tolerance", type=positive_float_type("--tolerance"),
                         help="relative accuracy of each entry, of its column's largest (default: the scene's)")
    add_quiet(command)
    command.set_defaults(run=command_jacobian)
