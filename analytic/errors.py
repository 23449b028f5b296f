"""Whose mistake is it? The exception classes that end a command with one line and exit status 2.

Every class here is a :class:`UserError`: a problem the user can fix, which
the command line reports as ``diffuse-imaging: error: <message>`` and exit
status 2, before any output file is written. Anything else that escapes a
command is a bug of ours and keeps its traceback.

| class | the user's ... |
| --- | --- |
| :class:`SceneError` | scene or sweep file: a key and what is wrong with its value |
| :class:`ImageError` | reflectance image (unreadable, wrong size, colour, out of [0, 1]) |
| :class:`DataError` | transient data file given to ``reconstruct`` or ``check`` |
| :class:`OptionError` | option of a command or argument of a Python call (a false-alarm rate, a convention's name) |
| :class:`ResourceError` | request this machine cannot serve: memory, disk, time, output folder, GPU |

The command line's ``UsageError`` for flags (:mod:`validation.cli`) is an
:class:`OptionError`; the renderer's ``BackendError`` (no usable LLVM,
no GPU) is a :class:`ResourceError`.
"""

from __future__ import annotations

__all__ = ["UserError", "SceneError", "ImageError", "DataError", "OptionError", "ResourceError"]


class UserError(Exception):
    """A problem the user can fix; its message is one line saying what, where and how."""


class SceneError(UserError, ValueError):
    """A bad scene (or sweep) value; ``key`` names the offending TOML key.

    Parameters
    ----------
    key : str
        Dotted TOML key, e.g. ``"sampling.period"``, or a file's path.
    problem : str
        What is wrong, in a few words.
    """

    def __init__(self, key: str, problem: str):
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}")


class ImageError(UserError, ValueError):
    """A reflectance image that cannot be used (unreadable, wrong size, ...)."""


class DataError(UserError, ValueError):
    """A transient data file that cannot be used (unreadable, wrong shape or time axis, NaN, ...)."""


class OptionError(UserError, ValueError):
    """An option or argument out of its range or of the wrong kind (``false_alarm=2``, ``expect="typo"``)."""


class ResourceError(UserError, RuntimeError):
    """A request beyond what this machine can do now (memory, disk, time, folder, device)."""
