"""The ``diffuse-imaging sweep`` command: a parameter sweep on a Dask cluster.

``diffuse-imaging sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N]``

Without ``--scheduler`` a local cluster is started (one worker process per
core, one thread each, dashboard off, loopback only); with it the sweep runs
on that cluster. The results are the same either way. Rerunning the command
on the same ``--out`` skips finished items and resumes unfinished ones.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_commands", "command_sweep"]


def command_sweep(args) -> int:
    """Run the sweep; exit status 0 when done (and every cross-checked item agrees), else 1."""
    from validation.sweep import load_sweep, run_sweep

    sweep = load_sweep(args.sweep)   # SceneError (exit 2) before any output is written
    if args.workers is not None and args.workers < 1:
        from analytic.scene import SceneError
        raise SceneError("--workers", f"must be >= 1, got {args.workers}")
    result = run_sweep(sweep, Path(args.out), scheduler=args.scheduler, workers=args.workers,
                       progress=not args.quiet)
    if not args.quiet:
        rendered = len(sweep.items) - len(result.skipped_items)
        verdict = ""
        if sweep.cross_check:
            agreeing = sum(1 for row in result.rows if row.get("agrees"))
            verdict = f"; {agreeing} of {len(result.rows)} agree with the model"
        print(f"sweep: {len(sweep.items)} items ({rendered} rendered now, {len(result.skipped_items)} "
              f"already done), {sweep.samples:,} samples each, on {result.workers} workers in "
              f"{result.seconds:.1f} s{verdict} -> {Path(args.out) / 'index.json'}")
    return 1 if result.all_agree is False else 0


def add_commands(subparsers) -> None:
    """Add the ``sweep`` sub-command to the ``diffuse-imaging`` parser's sub-parsers."""
    sweep = subparsers.add_parser(
        "sweep", help="render (and cross-check) a grid of scenes on a Dask cluster",
        description="Render every combination of a sweep file's grid, splitting each render into "
                    "sample chunks across Dask workers; resumable.")
    sweep.add_argument("sweep", help="sweep TOML file")
    sweep.add_argument("--out", required=True, help="output folder (one sub-folder per item, index.json/.csv)")
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="address of a running Dask scheduler (default: start a local cluster)")
    where.add_argument("--workers", type=int, metavar="N",
                       help="local cluster workers (default: one per core)")
    sweep.add_argument("--quiet", action="store_true", help="no progress or summary")
    sweep.set_defaults(run=command_sweep)


if __name__ == "__main__":   # pragma: no cover - convenience for running without the main CLI
    import sys

    parser = argparse.ArgumentParser(prog="diffuse-imaging")
    add_commands(parser.add_subparsers(dest="command", required=True))
    arguments = parser.parse_args()
    sys.exit(arguments.run(arguments))
