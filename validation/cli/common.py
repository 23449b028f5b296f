"""What every command shares: one-line errors, argument types, scene loading, progress bars.

A user's mistake ends a command with ``diffuse-imaging: error: <what, where,
how to fix>`` on one line and exit status 2, before any output file is
written; anything else that escapes is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import warnings

from analytic.errors import OptionError

__all__ = ["UsageError", "OneLineParser", "seed_type", "samples_type", "positive_float_type",
           "load_scene_argument", "show_progress", "MAX_SAMPLES", "add_quiet",
           "check_samples_type", "add_window_option", "apply_window", "announce_window", "release_warnings",
           "rows_text", "refuse_unmodellable", "announce_model", "ANNOUNCED_SECONDS"]

#: A model estimated to take longer than this is announced (its time and memory) before it starts.
ANNOUNCED_SECONDS = 2.0

#: Most samples a render may be asked for: 2^44, about two days at 1e8 samples/s.
MAX_SAMPLES = 2**44


class UsageError(OptionError):
    """A bad command-line flag or combination of flags."""


class OneLineParser(argparse.ArgumentParser):
    """argparse, with its errors on one line (what and how to fix) and exit status 2."""

    def error(self, message: str):
        hint = f"; see {self.prog} --help"
        # "argument --x: --x: bad": our option types name their option themselves
        message = re.sub(r"^argument (\S+): \1: ", r"\1: ", message)
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
    from validation.judging.compare import MIN_CHECK_SAMPLES

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


def parameter_option(scene, keys, option: str) -> list:
    """``keys`` read as the scene's parameters (:func:`analytic.operator.parameters.parameters`) for ``option``.

    A bad key ends the command with the option's name in its one line (``--free: 'x' is no parameter ...``)
    instead of the Python API's ``parameter:``.
    """
    from analytic.operator.parameters import parameters

    try:
        return parameters(scene, [keys] if isinstance(keys, str) else list(keys))
    except OptionError as error:
        raise UsageError(f"{option}: {re.sub(r'^parameters?: ', '', str(error))}") from None


def release_warnings() -> None:
    """A command has accepted its inputs: print the warnings held while it checked them (program.main holds
    them, so that a refused command's stderr is its one error line)."""
    release = getattr(warnings.showwarning, "release", None)
    if release is not None:
        release()


def load_scene_argument(path: str | None):
    """The scene a command was given: a TOML file (a plane or a relay-wall capture), or the built-in
    default scene (a plane scene)."""
    from analytic.scenes.common import default_scene
    from analytic.scenes.scene_file import load_scene

    return default_scene() if path is None else load_scene(path)


def rows_text(scene) -> str:
    """A transient's rows in words: "16 sensors", or "64 pairs (confocal scan)" of a relay-wall capture."""
    return scene.describe()


def refuse_unmodellable(scene, *, matrix: bool = True):
    """The scene's model estimate (:class:`analytic.operator.cost.ModelCost`), or a refusal in one line: an
    illumination that makes A impractical, or (``matrix``: a command that needs A itself) an A whose assembly
    would not fit in memory. Without ``matrix`` the estimate is that of y = A f by the route
    :func:`analytic.operator.matrix_free.forward` takes, which needs no A."""
    from analytic.operator.cost import refuse_impractical_illumination, refuse_unaffordable
    from analytic.operator.matrix_free import forward_route

    cost = refuse_impractical_illumination(scene)
    if not matrix:
        return forward_route(scene, cost=cost)[1]
    refuse_unaffordable(cost)
    return cost


def announce_model(args, cost, what: str) -> None:
    """One line on stderr before a model estimated to take more than :data:`ANNOUNCED_SECONDS` (not with
    ``--quiet``): ``diffuse-imaging: <what>: about T s and M GiB (estimate)``. Called once the command's inputs
    are accepted, so that a refused command's stderr is its one error line."""
    from analytic.operator.cost import estimate_text

    if not getattr(args, "quiet", False) and cost.seconds > ANNOUNCED_SECONDS:
        print(f"diffuse-imaging: {what}: {estimate_text(cost)} (estimate)", file=sys.stderr, flush=True)


def show_progress(args) -> bool:
    """Progress bars only on a terminal, and not with ``--quiet``."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def add_quiet(parser) -> None:
    """The ``--quiet`` flag every command has."""
    parser.add_argument("--quiet", action="store_true", help="no progress bars or summary")


def add_window_option(parser) -> None:
    """``--window scene|auto``: the scene's own bins, or the bins that cover its light at its period."""
    parser.add_argument("--window", choices=("scene", "auto"), default="scene",
                        help="scene: the scene's [sampling] start and count (default); auto: replace them by "
                             "the bins that hold every path length and the pulse at the scene's period "
                             "(stated on stderr, recorded in meta.json's start_opl and bins)")


def apply_window(args, scene):
    """The scene with the window ``--window`` asks for: ``scene`` itself for ``scene``, for ``auto`` its copy
    with :func:`analytic.operator.window.auto_sampling` (a SceneError when no window of its period covers the light,
    a UsageError with the estimate when the pulse is too long for the model over those bins:
    :func:`analytic.operator.cost.impractical_illumination`).

    Nothing is printed: :func:`announce_window` states it once the command's inputs are all accepted.
    """
    if getattr(args, "window", "scene") != "auto":
        return scene
    from analytic.operator.cost import impractical_illumination
    from analytic.operator.window import auto_sampling

    chosen = scene.replace(sampling=auto_sampling(scene))
    problem = impractical_illumination(chosen)
    if problem is not None:
        sampling = chosen.sampling
        raise UsageError(f"--window auto: the {sampling.count:,} bins of {sampling.bin_width_opl:g} m that hold "
                         f"all the light are more than this pulse can be modelled over: {problem}; or set "
                         f"[sampling] start and count to the bins you need")
    return chosen


def announce_window(args, scene, share: float | None = None) -> float:
    """State the window ``--window auto`` chose (one line on stderr), then warn in one line when the window
    cuts the light, or else when it is mostly empty; returns its share of the light.

    Called once a command's inputs are all accepted and before its work, so that a refused command's
    stderr is its one error line.

    Parameters
    ----------
    args : argparse.Namespace
        The command's arguments (``window``, when it has the option).
    scene : analytic.Scene
        The scene with the window the command uses (:func:`apply_window`).
    share : float, optional
        The window's share of the light (:func:`analytic.operator.window.window_share`), computed unless given.
    """
    from analytic.operator.window import response_range, warn_if_cut, warn_if_mostly_empty, window_share

    release_warnings()          # the inputs are accepted: the scene's own warnings first
    if getattr(args, "window", "scene") == "auto":
        sampling = scene.sampling
        low, high = response_range(scene)
        print(f"diffuse-imaging: window: start {sampling.start_opl:.12g} m, count {sampling.count} (bins of "
              f"{sampling.bin_width_opl:g} m holding every path length, {low:.6g} to {high:.6g} m, and the "
              f"pulse)", file=sys.stderr)
    share = window_share(scene) if share is None else share
    warn_if_cut(scene, share)
    warn_if_mostly_empty(scene, share)
    return share
