"""``diffuse-imaging forward``: the exact model's transient of a scene (a plane, or a capture through a relay wall)."""

from __future__ import annotations

import time
from pathlib import Path

from .common import (add_quiet, add_window_option, announce_model, announce_window, apply_window,
                     load_scene_argument, positive_float_type, rows_text, show_progress)
from .counts import draw_scene_counts, refuse_unreachable_counts, write_counts

__all__ = ["add_commands", "command_forward", "model_title"]


def model_title(scene, meta: dict) -> str:
    """The model figure's title: the scene, its pulse, and its attenuation (a plane) or its scan (a capture)."""
    if meta["geometry"] == "relay_wall":
        return (f"{scene.name}: {scene.scan.type} scan through a relay wall, {meta['illumination']} "
                f"illumination (model)")
    return f"{scene.name}: {meta['illumination']} illumination, {scene.attenuation} attenuation"


def command_forward(args) -> int:
    """Model the noiseless transient (and a noisy one when the scene asks); exit status 0."""
    from validation.plots.worker import FigureWorker

    scene = load_scene_argument(args.scene)
    with FigureWorker() as drawer:      # matplotlib's import beside the model's (validation.plots.worker)
        return _forward(args, scene, drawer)


def _forward(args, scene, drawer) -> int:
    from analytic.files import build_meta, output_folder, staged_writes, write_transient
    from analytic.measurement.noise import add_noise
    from analytic.operator.cost import refuse_impractical_illumination
    from analytic.operator.matrix_free import forward, forward_route
    from validation.plots import scene_transient_figure

    scene = apply_window(args, scene)
    if args.tolerance is not None:
        scene = scene.replace(tolerance=args.tolerance)
    cost = refuse_impractical_illumination(scene)   # a response the model cannot cover in reasonable time;
    route, cost = forward_route(scene, cost=cost)   # an A beyond memory is not refused: y is made without it
    refuse_unreachable_counts(scene, margin=1.0)    # before the window's warning
    with output_folder(args.out) as out:
        announce_model(args, cost, "forward" + _ROUTE_TEXT[route])   # first: the window's share may take a model
        share = announce_window(args, scene)
        started = time.perf_counter()
        statistics: dict = {}
        y = forward(scene, progress=show_progress(args), statistics=statistics)
        assembly = time.perf_counter() - started
        noisy = add_noise(y, scene.noise) if scene.noise is not None else None
        counts = draw_scene_counts(scene, y)         # before any file: a refused draw leaves the folder as it was
        meta = build_meta(scene, kind="model",
                          seed=scene.noise.seed if scene.noise is not None else None,
                          window_share=share, nonzeros=int(statistics["nonzeros"]), assembly_seconds=assembly)
        drawer.draw(scene_transient_figure, scene, y, noisy=noisy, title=model_title(scene, meta))
        with staged_writes():
            write_transient(out, y, meta, scene=scene, noisy=noisy)
            drawer.save(out / "transient.png")
            write_counts(out, scene, counts)
    if not args.quiet:
        rows, columns = scene.sensor_count * scene.sampling.count, scene.pixels ** 2
        how = {"matrix": "assembled and applied",
               "offsets": "summed from its distinct pixel offsets (A not held)",
               "blocks": f"assembled {statistics.get('block_pairs', 0):,} pairs at a time (A not held)"}
        print(f"forward: {rows_text(scene)} x {scene.sampling.count} bins, "
              f"A {rows} x {columns} with {statistics['nonzeros']:,} non-zeros "
              f"{how[statistics['route']]} in {assembly:.2f} s -> {Path(args.out)}")
    return 0


#: What the estimate's line adds for each route of analytic.operator.matrix_free.forward.
_ROUTE_TEXT = {"matrix": "", "offsets": "", "blocks": " (A would not fit in memory: y = A f a block of pairs at a time)"}


def add_commands(subparsers) -> None:
    """Add ``forward``."""
    forward = subparsers.add_parser("forward", help="model the noiseless transient y = A f")
    forward.add_argument("scene", nargs="?", help="scene TOML, a plane or a relay-wall capture (default: the "
                                                  "built-in scene)")
    forward.add_argument("--out", required=True, help="output folder")
    forward.add_argument("--tolerance", type=positive_float_type("--tolerance"),
                         help="relative accuracy of every entry of A (default: the scene's, 1e-6)")
    add_window_option(forward)
    add_quiet(forward)
    forward.set_defaults(run=command_forward)
