"""What every command shares: one-line errors, argument types, scene loading, progress bars.

A user's mistake ends a command with ``diffuse-imaging: error: <what, where,
how to fix>`` on one line and exit status 2, before any output file is
written; anything else that escapes is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import math
import sys

from analytic.errors import UserError

__all__ = ["UsageError", "OneLineParser", "seed_type", "samples_type", "positive_float_type",
           "load_scene_argument", "show_progress", "MAX_SAMPLES", "add_quiet",
           "check_samples_type"]

#: Most samples a render may be asked for: 2^44, about two days at 1e8 samples/s.
MAX_SAMPLES = 2**44


class UsageError(UserError, ValueError):
    """A bad command-line flag or combination of flags."""


class OneLineParser(argparse.ArgumentParser):
    """argparse, with its errors on one line (what and how to fix) and exit status 2."""

    def error(self, message: str):
        hint = f"; see {self.prog} --help"
        self.exit(2, f"{self.prog}: error: {message}{hint}\n")


def _whole(text: str, option: str) -> int:
    try:
        value = float(text) if any(c in text for c in ".eE") else int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{option}: expected a whole number, got {text!r}") from None
    if isinstance(value, float):
        if not (math.isfinite(value) and value.is_integer()):
            raise argparse.ArgumentTypeError(f"{option}: expected a whole number, got {text!r}")
        value = int(value)
    return value


def seed_type(text: str) -> int:
    """``--seed``: a whole number in [0, 2^32)."""
    value = _whole(text, "--seed")
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"--seed: must be in [0, 2^32), got {text}")
    return value


def check_samples_type(text: str) -> int:
    """``--spp`` of a command that cross-checks: at least MIN_CHECK_SAMPLES, so that bins can be judged."""
    from validation.compare import MIN_CHECK_SAMPLES

    value = samples_type(text)
    if value < MIN_CHECK_SAMPLES:
        raise argparse.ArgumentTypeError(f"--spp: the cross-check needs at least {MIN_CHECK_SAMPLES} samples "
                                         f"(128 per replica) to judge its bins, got {text}")
    return value


def samples_type(text: str) -> int:
    """``--spp``: a whole number of samples in [2, MAX_SAMPLES] (2 for a standard error)."""
    value = _whole(text, "--spp")
    if not 2 <= value <= MAX_SAMPLES:
        raise argparse.ArgumentTypeError(f"--spp: must be in [2, 2^44] (at least 2 for a standard "
                                         f"error; 2^44 is about two days of rendering), got {text}")
    return value


def positive_float_type(option: str):
    """An argparse type for a finite float > 0, naming ``option`` in its error."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option}: expected a number, got {text!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"{option}: must be finite and > 0, got {text}")
        return value
    return parse


def load_scene_argument(path: str | None):
    """The scene a command was given: a TOML file, or the built-in default scene."""
    from analytic.scene import default_scene
    from analytic.scene_file import load_scene

    return default_scene() if path is None else load_scene(path)


def show_progress(args) -> bool:
    """Progress bars only on a terminal, and not with ``--quiet``."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def add_quiet(parser) -> None:
    """The ``--quiet`` flag every command has."""
    parser.add_argument("--quiet", action="store_true", help="no progress bars or summary")
