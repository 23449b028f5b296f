"""Sweep files: a base scene and a grid of scene keys -> validated items.

Every combination of the grid's values is one item, a scene built by
overriding the base scene's TOML tables and validated by
:func:`analytic.scenes.scene_file.scene_from_dict`, exactly as a scene file would be.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from analytic.errors import SceneError
from analytic.scenes.common import Scene
from analytic.scenes.scene_file import read_toml, scene_from_dict, scene_to_tables
from analytic.waveforms import make_waveform
from validation.judging.compare import MIN_CHECK_SAMPLES

__all__ = ["Sweep", "SweepItem", "load_sweep", "sweep_from_dict", "default_scene_table",
           "DEFAULT_SWEEP_CHUNK", "MAX_SWEEP_SAMPLES", "MAX_ITEMS"]

#: Samples per task: about 0.1-1 s of work on one core for the built-in
#: scene, long enough that Dask's few milliseconds per task do not matter,
#: short enough that a lost worker loses little and many workers share one item.
DEFAULT_SWEEP_CHUNK = 2**20
#: Most samples per item (2^40: days on a cluster, the float64 sums still exact to 1e-4).
MAX_SWEEP_SAMPLES = 2**40
#: Most items per sweep.
MAX_ITEMS = 100_000

#: The scene kinds a sweep runs (its harness judges and reconstructs a plane's sensors), and how others are named.
SWEPT_KINDS = ("plane",)
_KIND_WORDS = {"relay_wall": "relay-wall (NLOS) capture"}
_SWEEP_KEYS = ("scene", "samples", "seed", "chunk", "cross_check", "variant", "grid")
_IMAGE_SUFFIXES = (".png", ".exr")


@dataclass(frozen=True, kw_only=True, eq=False)
class SweepItem:
    """One grid point: its parameters, its scene and its output folder name.

    Parameters
    ----------
    index : int
        Position in the sweep (grid order: the last key varies fastest).
    name : str
        Filesystem-safe folder name, unique within the sweep.
    parameters : dict
        Dotted scene key -> value of this item (JSON-ready; an image is its path).
    scene : Scene
        The validated scene.
    """

    index: int
    name: str
    parameters: dict
    scene: Scene


@dataclass(frozen=True, kw_only=True, eq=False)
class Sweep:
    """A validated sweep file.

    Parameters
    ----------
    items : tuple of SweepItem
        Every combination of the grid's values.
    samples : int
        Samples per item render (points on the plane), >= 2.
    seed : int
        Render seed of every item, 0 <= seed < 2^32.
    chunk_size : int
        Samples per task.
    cross_check : bool
        Also model every item and judge the render against the model.
    variant : str or None
        Mitsuba variant the workers use (None: their default, CPU).
    grid : dict
        Dotted scene key -> list of values, as given (images resolved to paths).
    base : str
        The base scene: its path, or ``"default"``.
    """

    items: tuple
    samples: int
    seed: int
    chunk_size: int
    cross_check: bool
    variant: str | None
    grid: dict
    base: str


def default_scene_table() -> dict:
    """The built-in scene (:func:`analytic.scenes.common.default_scene`) as TOML tables.

    The reflectance is the built-in pattern as an array, regenerated at the
    item's ``plane.pixels`` when a sweep varies the resolution (as
    ``default_scene(pixels=...)`` does).
    """
    from analytic.scenes.common import DEFAULT_ARRAY, default_scene

    tables = scene_to_tables(default_scene())
    # as a grid, so that a sweep can vary its extent or its centre
    tables["sensors"] = {"grid": list(DEFAULT_ARRAY["grid"]), "extent": DEFAULT_ARRAY["extent"],
                         "center": list(DEFAULT_ARRAY["center"])}
    return tables


def _whole(key: str, value: Any, minimum: int, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(key, f"expected a whole number, got {value!r}")
    if value < minimum or (maximum is not None and value > maximum):
        bound = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        raise SceneError(key, f"must be {bound}, got {value}")
    return value


def _grid_values(key: str, values: Any, sweep_dir: Path) -> list:
    """The list of values of one grid key; image folders and paths resolved against ``sweep_dir``."""
    if key == "plane.reflectance" and isinstance(values, dict):
        if set(values) != {"folder"} or not isinstance(values["folder"], str):
            raise SceneError(f"grid.{key}", "expected a list of values or { folder = \"path\" }")
        folder = sweep_dir / values["folder"]
        if not folder.is_dir():
            raise SceneError(f"grid.{key}", f"no folder {folder}")
        images = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
        if not images:
            raise SceneError(f"grid.{key}", f"no .png or .exr image in {folder}")
        return [str(p.resolve()) for p in images]
    if not isinstance(values, list) or not values:
        raise SceneError(f"grid.{key}", f"expected a non-empty list of values, got {values!r}")
    if key == "plane.reflectance":
        # Image paths are relative to the sweep file, not to the base scene.
        return [str((sweep_dir / v).resolve()) if isinstance(v, str) else v for v in values]
    return list(values)


def _label(value: Any) -> str:
    if isinstance(value, str) and ("/" in value or os.sep in value):
        return Path(value).stem
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list):
        return "x".join(_label(v) for v in value)
    return str(value)


def _folder_name(index: int, parameters: dict) -> str:
    """``007_sampling.period-0.05_illumination.waveform-impulse``: readable, safe, unique."""
    text = "_".join(f"{key}-{_label(value)}" for key, value in parameters.items())
    text = re.sub(r"[^A-Za-z0-9.+-]+", "_", text).strip("._") or "item"
    if len(text) > 100:   # most filesystems allow 255 bytes; keep room and stay unique
        text = text[:90] + "-" + hashlib.sha256(text.encode()).hexdigest()[:8]
    return f"{index:03d}_{text}"


def sweep_from_dict(data: dict, base_dir: str | Path = ".") -> Sweep:
    """Build a sweep from its parsed TOML.

    Parameters
    ----------
    data : dict
        Keys ``scene`` (path relative to ``base_dir``, or ``"default"``),
        ``samples``, ``seed`` (default 0), ``chunk`` (default 2^20),
        ``cross_check`` (default false), ``variant`` (optional) and the table
        ``grid`` of dotted scene keys -> lists of values.
    base_dir : str or Path
        Folder of the sweep file: relative paths are resolved against it.

    Returns
    -------
    Sweep

    Raises
    ------
    SceneError
        An unknown or bad key of the sweep file (``grid.<key>`` for the grid),
        or an item whose scene is invalid (the scene key, and the item).
    """
    base_dir = Path(base_dir)
    for key in data:
        if key not in _SWEEP_KEYS:
            raise SceneError(key, f"unknown sweep key (known: {', '.join(sorted(_SWEEP_KEYS))})")
    if "scene" not in data:
        raise SceneError("scene", 'required: a scene file relative to the sweep file, or "default"')
    base = data["scene"]
    if not isinstance(base, str):
        raise SceneError("scene", f"expected a path or \"default\", got {base!r}")
    if base == "default":
        base_table, scene_dir, default = default_scene_table(), base_dir, True
    else:
        path = base_dir / base
        try:
            base_table = read_toml(path, "scene")
        except SceneError as error:       # name the sweep file's key, not the scene file
            raise SceneError("scene", f"{path}: {error.problem}") from None
        base_table.setdefault("name", path.stem)
        scene_dir, default = path.parent, False
    if "samples" not in data:
        raise SceneError("samples", "required: samples per item (>= 2)")
    samples = _whole("samples", data["samples"], 2, MAX_SWEEP_SAMPLES)
    seed = _whole("seed", data.get("seed", 0), 0, 2**32 - 1)
    chunk_size = _whole("chunk", data.get("chunk", DEFAULT_SWEEP_CHUNK), 1, 2**31)
    cross_check = data.get("cross_check", False)
    if not isinstance(cross_check, bool):
        raise SceneError("cross_check", f"expected true or false, got {cross_check!r}")
    if cross_check and samples < MIN_CHECK_SAMPLES:
        raise SceneError("samples", f"the cross-check needs at least {MIN_CHECK_SAMPLES} samples per item "
                                    f"(128 per replica) to judge its bins, got {samples}")
    variant = data.get("variant")
    if variant is not None and not (isinstance(variant, str) and variant.startswith(("llvm_", "cuda_"))
                                    and variant.endswith("_mono")):
        raise SceneError("variant", f"expected a mono llvm_* or cuda_* Mitsuba variant, got {variant!r}")
    grid_table = data.get("grid", {})
    if not isinstance(grid_table, dict):
        raise SceneError("grid", "expected a table of \"table.key\" = [values]")
    grid = {}
    for key, values in grid_table.items():
        # TOML turns an unquoted sampling.bin_width_opl into a nested table: accept both spellings.
        flat = _flatten(key, values)
        for dotted, value in flat.items():
            if dotted.count(".") != 1 or dotted == "name":
                raise SceneError(f"grid.{dotted}", "expected a dotted scene key such as \"sampling.period\"")
            grid[dotted] = _grid_values(dotted, value, base_dir)

    count = math.prod(len(values) for values in grid.values())
    if count > MAX_ITEMS:
        raise SceneError("grid", f"{count:,} items (the product of the value lists' lengths), more than a sweep "
                                 f"holds ({MAX_ITEMS:,}); split it into several sweeps")
    items = []
    keys = list(grid)
    for index, combination in enumerate(itertools.product(*(grid[k] for k in keys))):
        parameters = dict(zip(keys, combination))
        table = _override(base_table, parameters, default)
        name = _folder_name(index, parameters)
        try:
            scene = scene_from_dict(table, scene_dir, name=name)
            if scene.kind in SWEPT_KINDS:
                # a waveform's own keys are checked when it is built (e.g. a gaussian's fwhm), not by the scene
                make_waveform(scene.illumination, scene.sampling.bin_width_opl)
        except SceneError as error:
            key = f"grid.{error.key}" if error.key in grid else error.key
            raise SceneError(key, f"{error.problem} (item {name})") from None
        if scene.kind not in SWEPT_KINDS:
            raise SceneError(scene.kind, f"a {_KIND_WORDS.get(scene.kind, scene.kind + ' scene')} cannot be swept "
                                         f"yet; sweep plane scenes")
        items.append(SweepItem(index=index, name=name, parameters=parameters, scene=scene))
    return Sweep(items=tuple(items), samples=samples, seed=seed, chunk_size=chunk_size,
                 cross_check=cross_check, variant=variant, grid=grid, base=base)


def _flatten(key: str, value: Any) -> dict:
    # An unquoted ``sampling.bin_width_opl = [...]`` is a nested TOML table; a quoted
    # ``"sampling.period" = [...]`` a flat key. Both mean the same.
    if "." not in key and isinstance(value, dict):
        return {f"{key}.{inner}": v for inner, v in value.items()}
    return {key: value}


def _override(base: dict, parameters: dict, default: bool) -> dict:
    table = {name: dict(value) if isinstance(value, dict) else value for name, value in base.items()}
    for dotted, value in parameters.items():
        section, key = dotted.split(".")
        if not isinstance(table.get(section, {}), dict):
            raise SceneError(section, "expected a table")
        table.setdefault(section, {})[key] = value
    if default and "plane.reflectance" not in parameters and "plane.pixels" in parameters:
        from analytic.scenes.reflectance import builtin_reflectance

        pixels = parameters["plane.pixels"]
        if isinstance(pixels, int) and not isinstance(pixels, bool) and pixels >= 1:
            table["plane"]["reflectance"] = builtin_reflectance(pixels)
    return table


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file (see :func:`sweep_from_dict`).

    Raises
    ------
    SceneError
        Unreadable file, bad TOML, unknown key or bad value.
    """
    path = Path(path)
    return sweep_from_dict(read_toml(path, "sweep"), path.parent)


