"""The ``diffuse-imaging`` program: its parser, a command's run, and the policy for warnings and output.

A user's mistake (:class:`analytic.errors.UserError`: a scene, image, data
file, flag or resource problem) ends the command with one line on stderr and
exit status 2, before any output file is written; anything else is a bug and
keeps its traceback.

Warnings: this project's own (their classes are defined in ``analytic``,
``transient`` or ``validation``) are one line each,
``diffuse-imaging: warning: ...``; another library's warning is one line
too when it may have changed a number (a ``RuntimeWarning``: NumPy's
overflow, a singular matrix), and is not shown otherwise (deprecations,
drawing notices). Each distinct line is shown once per command. They are held
while the command checks its inputs and shown once it accepts them (or
ends), so that a refused command prints its error line alone.

The command's own output (:func:`console`): a character the terminal's
encoding cannot show is written as a backslash escape (``\\u03c7`` for χ),
never an error. When the reader of stdout goes away (``diffuse-imaging ... |
head -1``) the rest of the output is dropped and the exit status is the
command's own (its files are written); when stdout cannot be written (a full
disk, ``>/dev/full``) the status is 2 with one line on stderr. A command
never ends in a traceback because of its own output.
"""

from __future__ import annotations

import errno
import os
import sys
import warnings
from pathlib import Path

from .common import OneLineParser

__all__ = ["main", "console", "build_parser", "OWN_PACKAGES"]

#: The packages whose warning classes are this project's own.
OWN_PACKAGES = ("analytic", "transient", "validation", "interop")


def build_parser() -> OneLineParser:
    """The ``diffuse-imaging`` parser with every command."""
    from . import bench, calibrate, checks, crb, interop, jacobian, model, plot, reconstruct, render, sweep

    parser = OneLineParser(
        prog="diffuse-imaging",
        description="Diffuse imaging of a Lambertian plane: exact forward model, Monte Carlo "
                    "rendering, cross-check, reconstruction. Lengths in metres, time as optical "
                    "path length in metres (c = 1).")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (model, jacobian, render, plot, checks, reconstruct, sweep, bench, interop, crb, calibrate):
        module.add_commands(commands)
    return parser


def _is_own(category: type) -> bool:
    """Whether a warning class is this project's own."""
    return category.__module__.split(".")[0] in OWN_PACKAGES


class _OneLineWarnings:
    """``warnings.showwarning`` for a command: the policy of the module docstring.

    Parameters
    ----------
    hold : bool
        Keep the lines until :meth:`release` (a command holds them while it checks its inputs, so that a
        refused command's stderr is its one error line: :meth:`drop` forgets them).
    """

    def __init__(self, *, hold: bool = False):
        self.shown = set()
        self.held: list[tuple[str, object]] | None = [] if hold else None

    def __call__(self, message, category, filename, lineno, file=None, line=None):
        own = _is_own(category)
        if not own and not issubclass(category, RuntimeWarning):
            return     # another library's notice that changes no number
        text = " ".join(str(message).split())
        if not own:    # say where it came from: it may have changed a number
            text = f"{text} ({category.__name__} at {Path(filename).name}:{lineno})"
        if text in self.shown:
            return
        self.shown.add(text)
        if self.held is not None:
            self.held.append((text, file))
            return
        self._print(text, file)

    @staticmethod
    def _print(text: str, file) -> None:
        try:
            print(f"diffuse-imaging: warning: {text}", file=sys.stderr if file is None else file)
        except (OSError, ValueError):
            pass       # stderr is gone: a warning is not worth failing the command for

    def release(self) -> None:
        """Print the lines held so far, and every later one at once."""
        held, self.held = self.held or [], None
        for text, file in held:
            self._print(text, file)

    def drop(self) -> None:
        """Forget the lines held (the command was refused: its error is its one line)."""
        if self.held is not None:
            self.held.clear()


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns its exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).
    """
    from analytic.errors import UserError

    args = build_parser().parse_args(argv)
    # warnings are held until the command has accepted its inputs (common.release_warnings, called by
    # common.announce_window) or ends; a refusal drops them, so that its stderr is one line
    shower = warnings.showwarning = _OneLineWarnings(hold=True)
    try:
        status = args.run(args)
    except KeyboardInterrupt:
        shower.release()
        print("diffuse-imaging: interrupted", file=sys.stderr)
        return 130
    except UserError as error:
        shower.drop()
        text = " ".join(str(error).split())
        print(f"diffuse-imaging: error: {text}", file=sys.stderr)
        return 2
    except BaseException:
        shower.release()            # a bug's traceback, after what it warned of
        raise
    shower.release()
    return status


class _GuardedStream:
    """A text stream that forwards to another and keeps its first error instead of raising it.

    The error is an OSError (a closed pipe, a full disk) or a ValueError (a
    closed file). After it nothing more is written. Everything else
    (``isatty``, ``encoding``, ``fileno``) is the wrapped stream's.
    """

    def __init__(self, stream):
        self.stream = stream
        self.error: OSError | ValueError | None = None

    def write(self, text: str) -> int:
        if self.error is None:
            try:
                self.stream.write(text)
            except (OSError, ValueError) as error:
                self.error = error
        return len(text)

    def flush(self) -> None:
        if self.error is None:
            try:
                self.stream.flush()
            except (OSError, ValueError) as error:
                self.error = error

    def __getattr__(self, name):
        return getattr(self.stream, name)


def _escape_unencodable(stream) -> None:
    """Write characters the stream's encoding lacks as backslash escapes instead of failing."""
    reconfigure = getattr(stream, "reconfigure", None)
    if reconfigure is not None:
        try:
            reconfigure(errors="backslashreplace")
        except (OSError, ValueError):
            pass


def _discard_pending(descriptor: int) -> None:
    """Point a failed standard stream at /dev/null, so that the interpreter's last flush of what it
    still holds neither fails nor prints "Exception ignored"."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, descriptor)
        os.close(null)
    except OSError:
        pass


def _run_guarded(run) -> int:
    """Run ``run()`` with guarded standard streams; its status, or 2 when stdout could not be written."""
    # a descriptor closed at start-up (``>&-``) leaves the stream None: what the user closed they do not
    # want to read, so it is discarded and the command still ends with its own status
    if sys.stdout is None:
        sys.stdout = open(os.devnull, "w", encoding="utf-8")
    if sys.stderr is None:
        sys.stderr = open(os.devnull, "w", encoding="utf-8")
    for stream in (sys.stdout, sys.stderr):
        _escape_unencodable(stream)
    stdout, stderr = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = guarded_out, guarded_error = _GuardedStream(stdout), _GuardedStream(stderr)
    try:
        try:
            status = run()
        except SystemExit as exit:       # argparse's --help and its refusals
            status = exit.code if isinstance(exit.code, int) else (0 if exit.code is None else 2)
        guarded_out.flush()
        guarded_error.flush()
    finally:
        sys.stdout, sys.stderr = stdout, stderr
    for guarded, descriptor in ((guarded_out, 1), (guarded_error, 2)):
        if guarded.error is not None:
            _discard_pending(descriptor)
    error = guarded_out.error
    if error is None or getattr(error, "errno", None) == errno.EPIPE:
        # the reader stopped reading (| head): what it did not read was not wanted; the files are written
        return status
    try:
        reason = getattr(error, "strerror", None) or error
        print(f"diffuse-imaging: error: cannot write to standard output ({reason}); what it printed is lost, "
              f"its files are as the command left them (its own exit status: {status}); send stdout elsewhere",
              file=sys.stderr, flush=True)
    except (OSError, ValueError):
        _discard_pending(2)
    return 2


def console() -> int:
    """The console script ``diffuse-imaging``: :func:`main` on the process's arguments, its output
    guarded as the module docstring says; the process then ends at once, its exit handlers run
    (:func:`validation.process_exit.exit_without_teardown`)."""
    from validation.process_exit import exit_without_teardown

    status = _run_guarded(main)
    exit_without_teardown(status)
    return status
