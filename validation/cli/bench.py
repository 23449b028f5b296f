"""``diffuse-imaging bench``: speed against error of the model, the renderer and mitransient."""

from __future__ import annotations

from .common import add_quiet, release_warnings

__all__ = ["add_commands", "command_bench"]


def command_bench(args) -> int:
    """Run the speed-against-error comparison; exit status 0."""
    from analytic.files import output_folder
    from validation.runs.bench import speed_against_error

    release_warnings()
    with output_folder(args.out) as out:
        result = speed_against_error(out, variant=args.variant)
    if not args.quiet:
        print(result["markdown"])
    return 0


def add_commands(subparsers) -> None:
    """Add ``bench``."""
    bench = subparsers.add_parser("bench", help="speed against error of model, renderer, mitransient")
    bench.add_argument("--out", required=True, help="output folder")
    bench.add_argument("--variant", help="Mitsuba variant of both renderers: llvm_ad_mono (CPU, the default) "
                                         "or cuda_ad_mono (GPU)")
    add_quiet(bench)
    bench.set_defaults(run=command_bench)
