"""The ``diffuse-imaging sweep`` command: a parameter sweep on a Dask cluster.

``diffuse-imaging sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N]``

Without ``--scheduler`` a local cluster is started (one worker process per
core, one thread each, dashboard off, loopback only); with it the sweep runs
on that cluster. The results are the same either way. Rerunning the command
on the same ``--out`` skips finished items and resumes unfinished ones.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .common import UsageError, add_quiet, release_warnings, show_progress

__all__ = ["add_commands", "command_sweep"]


def command_sweep(args) -> int:
    """Run the sweep; exit status 0 when done (and every cross-checked item agrees), else 1."""
    from analytic.files import output_folder
    from validation.sweep import check_variant, load_sweep, require_dask, run_sweep

    require_dask()                   # the lean install has no Dask: one line naming the extra, before any work
    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise UsageError(f"--workers: must be in [1, 1024], got {args.workers}")
    sweep = load_sweep(args.sweep)   # SceneError (exit 2) before any output is written
    if args.scheduler is None:
        check_variant(sweep.variant)  # a variant this machine cannot run: one line, before any file or cluster
    release_warnings()               # the sweep is accepted: what it warned of, before its long work
    with output_folder(args.out) as out:
        result = run_sweep(sweep, out, scheduler=args.scheduler, workers=args.workers,
                           progress=show_progress(args))
    cut = [row["name"] for row in result.rows
           if row.get("window_share") is not None and row["window_share"] < 0.999]
    if cut:
        print(f"diffuse-imaging: warning: {len(cut)} of {len(result.rows)} items' windows hold less than "
              f"99.9 % of the light ({', '.join(cut[:3])}{', ...' if len(cut) > 3 else ''}); see the "
              f"window_share column of index.csv", file=sys.stderr)
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
    add_quiet(sweep)
    sweep.set_defaults(run=command_sweep)
