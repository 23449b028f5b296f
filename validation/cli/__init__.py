"""The ``diffuse-imaging`` command line.

One module per group of commands: :mod:`.model` (forward), :mod:`.render`,
:mod:`.checks` (validate, run), :mod:`.reconstruct` (reconstruct,
reproduce), :mod:`.sweep`, :mod:`.bench`, :mod:`.interop` (check, export).
Heavy modules (Numba kernels, Mitsuba, Dask, matplotlib) are imported
inside each command, so ``--help`` and argument errors answer at once.

A user's mistake (:class:`analytic.errors.UserError`: a scene, image, data
file, flag or resource problem) ends the command with one line on stderr and
exit status 2, before any output file is written; warnings are one line
each; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import sys
import warnings

from .common import OneLineParser, UsageError

__all__ = ["main", "console", "build_parser", "UsageError"]


def build_parser() -> OneLineParser:
    """The ``diffuse-imaging`` parser with every command."""
    from . import bench, checks, interop, model, reconstruct, render, sweep

    parser = OneLineParser(
        prog="diffuse-imaging",
        description="Diffuse imaging of a Lambertian plane: exact forward model, Monte Carlo "
                    "rendering, cross-check, reconstruction. Lengths in metres, time as optical "
                    "path length in metres (c = 1).")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (model, render, checks, reconstruct, sweep, bench, interop):
        module.add_commands(commands)
    return parser


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    text = " ".join(str(message).split())
    print(f"diffuse-imaging: warning: {text}", file=sys.stderr if file is None else file)


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns its exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).
    """
    from analytic.errors import UserError

    args = build_parser().parse_args(argv)
    warnings.showwarning = _one_line_warning
    try:
        return args.run(args)
    except KeyboardInterrupt:
        print("diffuse-imaging: interrupted", file=sys.stderr)
        return 130
    except UserError as error:
        text = " ".join(str(error).split())
        print(f"diffuse-imaging: error: {text}", file=sys.stderr)
        return 2


def console() -> int:
    """The console script ``diffuse-imaging``: :func:`main` on the process's arguments."""
    return main()
