"""What ``check`` is given, in memory or by path, made into the arrays it judges: one reader for the command
line and the Python calls.

``check --data FILE...`` and :func:`validation.check_transient` /
:func:`validation.assert_agrees` take the same things (:func:`read_inputs`):

- a scene: a :class:`~analytic.Scene` or :class:`~analytic.RelayWallScene`,
  or a scene file's path (TOML, or a tal YAML configuration);
- data: one ``(K, N)`` transient (with its standard error) or ``(R, K, N)``
  replicas, as arrays or a list of them; mitransient's films as
  ``np.array(film)`` gives them (one sensor's ``(1, 1, N, C)``, the K
  sensors stacked ``(K, 1, 1, N, C)``, a list of the K single-sensor films,
  and replicas of any of these; a relay wall's ``(H, W, T, C)`` or
  exhaustive ``(H, W, Lh, Lw, T, C)``); and any file or folder
  :func:`~validation.check.read_data` reads (our render's folder brings its
  replicas or its standard error; tal's HDF5 captures), or a list of them
  as replicas;
- a standard error: an array or a file.

Refusals are :class:`~analytic.errors.DataError` or
:class:`~analytic.errors.OptionError` with one line; they name the
caller's own words for the options (:data:`PYTHON_WORDS`: ``stderr=``;
:data:`COMMAND_WORDS`: ``--stderr FILE``).
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass

import numpy as np

from analytic.errors import DataError, OptionError
from analytic.scenes.kinds import for_kind
from validation.judging.arrays import real_array

from .readers import (checked_transient, film_transient, read_data, read_stderr, replicas_beside, scene_of,
                      stderr_beside)

__all__ = ["Words", "PYTHON_WORDS", "COMMAND_WORDS", "Inputs", "scene_of", "read_inputs"]


@dataclass(frozen=True)
class Words:
    """How the caller names each input, for messages."""

    data: str
    stderr: str
    stderr_value: str
    shape_only: str
    expect: str
    radius: str

    def stating(self, name: str) -> str:
        """How the caller states convention ``name``: ``expect="irradiancemeter"``, ``--expect irradiancemeter``."""
        return f'{self.expect}="{name}"' if self.expect == "expect" else f"{self.expect} {name}"


#: A Python call's words (keyword arguments).
PYTHON_WORDS = Words(data="data", stderr="stderr", stderr_value="stderr=<array or file>",
                     shape_only="shape_only=True", expect="expect", radius="radius")

#: The command line's words (its options).
COMMAND_WORDS = Words(data="--data", stderr="--stderr", stderr_value="--stderr FILE", shape_only="--shape-only",
                      expect="--expect", radius="--radius")


@dataclass(frozen=True)
class Inputs:
    """What is judged: ``(K, N)`` data with its ``stderr`` (and its ``dof``), or ``(R, K, N)`` replicas."""

    data: np.ndarray
    stderr: np.ndarray | None
    dof: int | None
    sources: tuple = ()          # the files read, for the report

    @property
    def replicas(self) -> int:
        return 1 if self.data.ndim == 2 else self.data.shape[0]


def _is_path(value) -> bool:
    return isinstance(value, (str, os.PathLike))


def _relay_wall_films(name: str, array: np.ndarray, scene, listed: bool) -> np.ndarray | None:
    """nlos_capture_meter films: one (H, W, T, C) or (H, W, Lh, Lw, T, C) film, or replicas of them stacked."""
    film = 6 if scene.scan.type == "exhaustive" else 4
    if array.ndim == film:
        return film_transient(name, array, scene)
    if array.ndim == film + 1:
        return np.stack([film_transient(f"{name}[{r}]", one, scene) for r, one in enumerate(array)])
    return None


def _plane_films(name: str, array: np.ndarray, scene, listed: bool) -> np.ndarray | None:
    """irradiancemeter films: one sensor's (1, 1, N, C), the K sensors' stacked, or replicas of those."""
    if array.ndim == 4 and scene.sensor_count > 1:      # one sensor's film
        if not listed:
            raise DataError(f"{name}: one sensor's film {array.shape} for the scene's {scene.sensor_count} "
                            f"sensors; give the films of all of them, stacked (K, 1, 1, N, C) or as a list")
        return film_transient(name, array, scene, sensors=1)
    if array.ndim in (4, 5):                # one sensor's film, or the K sensors' stacked
        return film_transient(name, array, scene)
    if array.ndim == 6:                     # replicas of stacked films
        return np.stack([film_transient(f"{name}[{r}]", one, scene) for r, one in enumerate(array)])
    return None


def _no_films(name, array, scene, listed) -> None:
    """A kind mitransient has no film of."""
    return None


#: How mitransient's films of each scene kind come as arrays (None: not a film of the scene).
_FILMS = {"plane": _plane_films, "relay_wall": _relay_wall_films}


def _array_transients(name: str, array: np.ndarray, scene, *, listed: bool = False) -> np.ndarray:
    """An array given as data: ``(K, N)`` or ``(R, K, N)``, films and stacks of films undone; in a list
    (``listed``), one sensor's film ``(1, 1, N, C)`` is its ``(1, N)`` row."""
    if array.ndim <= 3:
        return array
    films = for_kind(_FILMS, scene, "mitransient films", default=_no_films)(name, array, scene, listed)
    if films is not None:
        return films
    raise DataError(f"{name}: an array of shape {array.shape} is no transient of the scene: give (K, N) = "
                    f"({scene.sensor_count}, {scene.sampling.count}), (R, K, N) replicas, or mitransient's films "
                    f"as np.array(film) gives them")


def _one(name: str, item, scene, *, locks, words: Words) -> np.ndarray:
    """One list item: a file (one transient) or an array (a transient, a film, or replicas)."""
    if _is_path(item):
        locks.enter_context(_reading(item, words.data))
        return read_data(item, scene)
    if isinstance(item, (list, tuple)):
        return _listed(name, item, scene, locks=locks, words=words)
    return _array_transients(name, real_array(name, item), scene, listed=True)


def _listed(name: str, items, scene, *, locks, words: Words) -> np.ndarray:
    """A list: one transient (its K sensors' single-sensor films), or replicas (one transient each)."""
    if len(items) == 0:
        raise DataError(f"{name}: an empty list; give a transient or its replicas")
    parts = [_one(f"{name}[{i}]", item, scene, locks=locks, words=words) for i, item in enumerate(items)]
    shape = (scene.sensor_count, scene.sampling.count)
    if len(parts) == 1:
        return parts[0]
    rows = [part.shape[0] if part.ndim == 2 else None for part in parts]
    if scene.sensor_count > 1 and len(parts) == scene.sensor_count and all(
            part.ndim == 2 and part.shape == (1, shape[1]) for part in parts):
        return np.concatenate(parts)            # one film per sensor: one transient
    if all(part.ndim == 2 for part in parts):
        return np.stack([checked_transient(f"{name}[{i}]", part, scene) for i, part in enumerate(parts)])
    raise DataError(f"{name}: a list of {len(parts)} items with {rows} rows: give one transient per item "
                    f"(replicas), or the scene's {scene.sensor_count} single-sensor films of one render")


@contextlib.contextmanager
def _reading(path, label: str):
    """Keep our commands from writing where ``path`` lies while it is read (:func:`reading_folder`)."""
    from analytic.files import reading_folder

    with reading_folder(path, option=label) as held:
        yield held


def _checked_dof(dof) -> int | None:
    if dof is not None and (isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 1):
        raise OptionError(f"dof: the standard error's degrees of freedom must be a whole number >= 1, got {dof!r}")
    return None if dof is None else int(dof)


def _refused_combinations(replicas: int, stderr, shape_only: bool, words: Words) -> None:
    """Refuse the combinations of data, ``stderr`` and ``shape_only`` that mean nothing."""
    if replicas == 2:
        raise DataError(f"{words.data}: two replicas give each bin's error one degree of freedom; give at least 3 "
                        f"(or one transient with its standard error)")
    if replicas > 1 and (stderr is not None or shape_only):
        raise DataError(f"replicas carry their own error: give neither {words.stderr} nor {words.shape_only} with "
                        f"them")
    if stderr is not None and shape_only:
        raise DataError(f"{words.shape_only}: refused together with {words.stderr} (a standard error allows the "
                        f"real test)")
    if replicas == 1 and stderr is None and not shape_only:
        raise DataError(f"one transient without errors: give its standard error ({words.stderr_value}), several "
                        f"independent replicas, or ask for a shape-only judgement ({words.shape_only})")


def read_inputs(scene, data, stderr=None, *, dof: int | None = None, shape_only: bool = False,
                words: Words = PYTHON_WORDS) -> Inputs:
    """The data (one transient or replicas) with its standard error and dof, from arrays or files.

    Parameters
    ----------
    scene : Scene or RelayWallScene
        What the data are of (:func:`scene_of` loads a path).
    data : array_like, path or list
        See the module's docstring. A single path to our render's output
        (its folder, ``transient.npy`` or ``.exr``) brings its own error:
        ``replicas.npy`` beside it (three or more), else ``stderr.npy``
        with the render's degrees of freedom, unless ``stderr`` or
        ``shape_only`` is given.
    stderr : array_like or path, optional
        The standard error of one transient.
    dof : int, optional
        Its degrees of freedom.
    shape_only : bool
        A transient without errors, to be judged by shape.
    words : Words
        The caller's names of the options, for messages.

    Returns
    -------
    Inputs

    Raises
    ------
    DataError
        Anything :func:`~validation.check.read_data` refuses, arrays that
        are not real numbers, shapes other than the scene's, meaningless
        combinations (replicas with ``stderr``, one transient without it).
    OptionError
        A ``dof`` that is not a whole number >= 1.
    """
    dof = _checked_dof(dof)
    sources = []
    with contextlib.ExitStack() as locks:
        if _is_path(data):
            locks.enter_context(_reading(data, words.data))
            values = read_data(data, scene)
            sources.append(str(data))
            if stderr is None and not shape_only:
                replicas = replicas_beside(data, scene, values)
                if replicas is not None:
                    return Inputs(replicas, None, None, tuple(sources))
                beside = stderr_beside(data, scene)
                if beside is not None:
                    stderr, dof = beside[0], beside[1] if dof is None else dof
        elif isinstance(data, (list, tuple)):
            sources += [str(item) for item in data if _is_path(item)]
            values = _listed(words.data, list(data), scene, locks=locks, words=words)
        else:
            values = _array_transients(words.data, real_array(words.data, data), scene)
        if values.ndim == 3 and values.shape[0] == 1:
            values = values[0]
        if values.ndim == 3:
            values = np.stack([checked_transient(f"{words.data}[{r}]", one, scene) for r, one in enumerate(values)])
        else:
            values = checked_transient(words.data, values, scene)
        if _is_path(stderr):
            locks.enter_context(_reading(stderr, words.stderr))
            sources.append(str(stderr))
            error = read_stderr(stderr, scene)
        elif stderr is not None:
            error = checked_transient(words.stderr, _array_transients(words.stderr, real_array(words.stderr, stderr),
                                                                      scene), scene)
            if np.any(error < 0):
                raise DataError(f"{words.stderr}: {int(np.sum(error < 0))} negative standard error(s); give the "
                                f"standard error of each bin (>= 0)")
        else:
            error = None
    _refused_combinations(1 if values.ndim == 2 else values.shape[0], error, shape_only, words)
    return Inputs(values, error, dof if error is not None else None, tuple(sources))
