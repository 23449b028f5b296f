"""Parameter sweeps: many scenes, rendered (and optionally cross-checked) on a Dask cluster.

A sweep file names a base scene and a grid of scene keys to vary; every
combination of the grid's values is one *item*, a scene built by overriding
the base scene's TOML tables and validated by
:func:`analytic.scene.scene_from_dict`, exactly as a scene file would be.

Each item's render is split into fixed chunks of the sample range,
``[first, first + count)``. Sample i's random numbers depend only on
(seed, i) (:mod:`transient.integrator`), so the chunks are independent,
deterministic tasks: any worker may compute any chunk, a chunk lost with its
worker is simply computed again, and the driver adds the chunks' float64
moments in chunk order. Each worker runs Dr.Jit with as many threads as the
Dask worker has (one, for the local cluster; run a remote cluster's workers
with ``--nthreads 1`` too): the order of a chunk's float64 atomic additions
then depends on nothing but the chunk, so the merged result for a given
seed and chunking is the same bit for bit on 1 or on 8 workers, and equal
to a sequential :func:`transient.render.render` with Dr.Jit on one thread.

Every item's folder holds the ``render`` layout (``transient.npy``/``.exr``,
``stderr.npy``, ``meta.json``), and with cross-checking ``model/`` (the
model's transient) and ``agreement.json``; ``sweep_state.npz`` keeps the
finished chunks' moments, so an interrupted sweep resumes where it stopped,
and ``item.json``, written last, marks the item finished. ``index.json`` and
``index.csv`` list every item. Every file is written atomically.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import itertools
import json
import logging
import os
import re
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analytic.io import atomic_write, save_json, write_transient
from analytic.scene import Scene, SceneError, read_toml, scene_from_dict
from transient.render import chunk_ranges, sigterm_as_interrupt

__all__ = ["Sweep", "SweepItem", "SweepResult", "load_sweep", "sweep_from_dict", "default_scene_table",
           "chunk_ranges", "render_chunk", "model_transient", "run_sweep", "sweep_client",
           "STATE_FILE", "ITEM_FILE", "DEFAULT_SWEEP_CHUNK"]

#: Per-item checkpoint of finished chunks' moments.
STATE_FILE = "sweep_state.npz"
#: Written last in an item's folder: the item is finished.
ITEM_FILE = "item.json"
#: Samples per task: about 0.1-1 s of work on one core for the built-in
#: scene, long enough that Dask's few milliseconds per task do not matter,
#: short enough that a lost worker loses little and many workers share one item.
DEFAULT_SWEEP_CHUNK = 2**20

_SWEEP_KEYS = ("scene", "samples", "seed", "chunk", "cross_check", "variant", "grid")
_IMAGE_SUFFIXES = (".png", ".exr")
# Seconds between checkpoints of unfinished items: an interruption loses at
# most this much work, and small chunks do not spend their time in fsync.
_CHECKPOINT_SECONDS = 2.0


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


@dataclass(frozen=True)
class SweepResult:
    """What :func:`run_sweep` did.

    Attributes
    ----------
    out_dir : Path
        The sweep's output folder.
    rows : tuple of dict
        One index row per item (as in ``index.json``).
    computed_chunks : tuple of (str, int)
        (item name, chunk index) of every chunk computed by this call, in
        the order they arrived; chunks restored from checkpoints are absent.
    skipped_items : tuple of str
        Items already finished before this call.
    seconds : float
        Wall time of this call, seconds.
    workers : int
        Workers of the cluster when the sweep started.
    """

    out_dir: Path
    rows: tuple
    computed_chunks: tuple
    skipped_items: tuple
    seconds: float
    workers: int

    @property
    def all_agree(self) -> bool | None:
        """True/False when cross-checked (every item agrees or not); None otherwise."""
        verdicts = [row.get("agrees") for row in self.rows]
        if any(v is None for v in verdicts):
            return None
        return all(verdicts)


# -- the sweep file ---------------------------------------------------------

def default_scene_table() -> dict:
    """The built-in scene (:func:`analytic.scene.default_scene`) as TOML tables.

    The reflectance is the built-in pattern as an array, regenerated at the
    item's ``plane.pixels`` when a sweep varies the resolution (as
    ``default_scene(pixels=...)`` does).
    """
    from analytic.reflectance import builtin_reflectance

    return {
        "name": "default",
        "plane": {"size": 1.0, "pixels": 50, "reflectance": builtin_reflectance(50)},
        "source": {"position": [0.5, 0.5, 1.0]},
        "illumination": {"waveform": "impulse"},
        "sensors": {"grid": [4, 4], "extent": 1.0, "center": [0.5, 0.5, 1.0]},
        "sampling": {"period": 0.1, "start": 0.0, "count": 40},
        "model": {"attenuation": "lambertian"},
        "noise": {"kind": "gaussian", "sigma": 0.1, "seed": 0},
    }


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
    samples = _whole("samples", data["samples"], 2)
    seed = _whole("seed", data.get("seed", 0), 0, 2**32 - 1)
    chunk_size = _whole("chunk", data.get("chunk", DEFAULT_SWEEP_CHUNK), 1, 2**31)
    cross_check = data.get("cross_check", False)
    if not isinstance(cross_check, bool):
        raise SceneError("cross_check", f"expected true or false, got {cross_check!r}")
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

    items = []
    keys = list(grid)
    for index, combination in enumerate(itertools.product(*(grid[k] for k in keys))):
        parameters = dict(zip(keys, combination))
        table = _override(base_table, parameters, default)
        name = _folder_name(index, parameters)
        try:
            scene = scene_from_dict(table, scene_dir, name=name)
        except SceneError as error:
            key = f"grid.{error.key}" if error.key in grid else error.key
            raise SceneError(key, f"{error.problem} (item {name})") from None
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
        from analytic.reflectance import builtin_reflectance

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


# -- worker side ----------------------------------------------------------------

# fingerprint -> (variant, mitsuba scene, integrator). Loading compiles
# nothing but builds the scene; keep a few so interleaved items do not
# reload, but not all of a long sweep's.
_LOADED: OrderedDict = OrderedDict()
_LOADED_LIMIT = 4
_THREADS_SET = False


def _loaded(scene: Scene, fingerprint: str, variant: str | None):
    global _THREADS_SET
    from transient.backend import select_variant

    # Every worker process chooses its own libLLVM and variant: nothing of
    # the driver's Mitsuba state travels with a task.
    active = select_variant(variant)
    if not _THREADS_SET:
        import drjit as dr

        # Dr.Jit's thread count fixes the order of a chunk's float64 atomic
        # additions; tying it to the Dask worker's thread count makes a
        # chunk's sums a function of the chunk alone, and one worker per
        # core with one thread each keeps the machine busy without
        # oversubscription.
        try:
            from distributed import get_worker
            threads = get_worker().state.nthreads
        except (ImportError, ValueError, AttributeError):
            threads = None
        if threads:
            dr.set_thread_count(int(threads))
        _THREADS_SET = True
    key = (fingerprint, active)
    if key in _LOADED:
        _LOADED.move_to_end(key)
        return _LOADED[key]
    from transient.mitsuba_scene import load_scene

    loaded = load_scene(scene)
    entry = (active, loaded, loaded.integrator())
    _LOADED[key] = entry
    while len(_LOADED) > _LOADED_LIMIT:
        _LOADED.popitem(last=False)
    return entry


def render_chunk(scene: Scene, fingerprint: str, seed: int, first: int, count: int,
                 variant: str | None = None) -> tuple[np.ndarray, np.ndarray, float, str]:
    """Render samples ``[first, first + count)`` of a scene (a Dask task).

    Parameters
    ----------
    scene : Scene
        The item's scene.
    fingerprint : str
        :func:`transient.render.scene_fingerprint` of ``scene``: the key of
        the worker's cache of loaded Mitsuba scenes.
    seed : int
        Render seed; sample i depends on (seed, i) only.
    first, count : int
        The chunk: global index of its first sample, and its sample count.
    variant : str, optional
        Mitsuba variant (default: the worker's CPU default).

    Returns
    -------
    sums, sums_of_squares : numpy.ndarray
        ``(K, N)`` float64 Σc and Σc² over the chunk's samples (units of y).
    seconds : float
        Wall time of the render call on the worker, seconds.
    variant : str
        The Mitsuba variant used.
    """
    active, loaded, integrator = _loaded(scene, fingerprint, variant)
    started = time.perf_counter()
    sums, squares = integrator.render_transient(loaded, seed=int(seed), first_sample=int(first),
                                                sample_count=int(count))
    return (np.asarray(sums, dtype=np.float64), np.asarray(squares, dtype=np.float64),
            time.perf_counter() - started, active)


def model_transient(scene: Scene) -> tuple[np.ndarray, float]:
    """The exact model's noiseless y of a scene (a Dask task); returns (y, seconds)."""
    from analytic.system import forward

    started = time.perf_counter()
    y = forward(scene)
    return np.asarray(y, dtype=np.float64), time.perf_counter() - started


def _identity(value):
    return value


# -- driver side ----------------------------------------------------------------

@contextlib.contextmanager
def sweep_client(scheduler: str | None = None, workers: int | None = None) -> Iterator:
    """A ``distributed.Client``: to the cluster at ``scheduler``, or to a new local one.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``). The cluster's
        workers must have this package installed; run them with
        ``--nthreads 1`` and one worker per core.
    workers : int, optional
        Local cluster only: worker processes (default: one per core), one
        thread each, dashboard off, listening on loopback only.
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        if workers is not None:
            raise ValueError("workers: only for a local cluster (the scheduler's cluster has its own)")
        with Client(scheduler) as client:
            yield client
        return
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers: must be >= 1, got {workers}")
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1", silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


@dataclass(eq=False)
class _ItemState:
    """The driver's running totals of one item (mutable, driver only)."""

    item: SweepItem
    folder: Path
    fingerprint: str
    ranges: list
    sums: np.ndarray
    squares: np.ndarray
    done: np.ndarray
    seconds: np.ndarray
    variant: str = ""
    model: np.ndarray | None = None
    model_seconds: float = 0.0
    started: float = field(default_factory=time.perf_counter)
    dirty: bool = False

    @property
    def complete(self) -> bool:
        return bool(self.done.all())


def _state_identity(sweep: Sweep, fingerprint: str) -> dict:
    return {"seed": sweep.seed, "samples": sweep.samples, "chunk_size": sweep.chunk_size,
            "fingerprint": fingerprint}


def _save_state(state: _ItemState, sweep: Sweep) -> None:
    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, sums=state.sums, sums_of_squares=state.squares, done=state.done,
                     seconds=state.seconds, seed=np.int64(sweep.seed), samples=np.int64(sweep.samples),
                     chunk_size=np.int64(sweep.chunk_size), fingerprint=np.array(state.fingerprint),
                     variant=np.array(state.variant))
    atomic_write(state.folder / STATE_FILE, write)
    state.dirty = False


def _mismatch(path: Path, what: str) -> SceneError:
    return SceneError(str(path), f"belongs to a sweep with another {what}; use a new --out folder")


def _load_state(item: SweepItem, folder: Path, sweep: Sweep, fingerprint: str) -> _ItemState:
    ranges = chunk_ranges(sweep.samples, sweep.chunk_size)
    shape = (item.scene.sensor_count, item.scene.sampling.count)
    state = _ItemState(item=item, folder=folder, fingerprint=fingerprint, ranges=ranges,
                       sums=np.zeros((len(ranges),) + shape), squares=np.zeros((len(ranges),) + shape),
                       done=np.zeros(len(ranges), dtype=bool), seconds=np.zeros(len(ranges)))
    path = folder / STATE_FILE
    if not path.is_file():
        return state
    with np.load(path, allow_pickle=False) as saved:
        if str(saved["fingerprint"]) != fingerprint:
            raise _mismatch(path, "scene")
        for name in ("seed", "samples", "chunk_size"):
            if int(saved[name]) != getattr(sweep, "chunk_size" if name == "chunk_size" else name):
                raise _mismatch(path, name)
        if saved["sums"].shape != state.sums.shape:
            raise _mismatch(path, "shape")
        state.sums[...] = saved["sums"]
        state.squares[...] = saved["sums_of_squares"]
        state.done[...] = saved["done"]
        state.seconds[...] = saved["seconds"]
        state.variant = str(saved["variant"])
    return state


def _finished_row(item: SweepItem, folder: Path, sweep: Sweep, fingerprint: str) -> dict | None:
    """The item's index row if ``item.json`` says it is finished with these settings."""
    path = folder / ITEM_FILE
    if not path.is_file():
        return None
    row = json.loads(path.read_text())
    identity = _state_identity(sweep, fingerprint)
    if any(row.get(key) != value for key, value in identity.items()):
        raise _mismatch(path, "scene, seed, sample count or chunking")
    if sweep.cross_check and row.get("agrees") is None:
        return None   # rendered, not yet cross-checked: the checkpoint has every chunk
    return row


def _merge(state: _ItemState) -> tuple[np.ndarray, np.ndarray]:
    """Σ over chunks in chunk order, from zero, as :func:`transient.render.render` adds them."""
    sums = np.zeros(state.sums.shape[1:])
    squares = np.zeros(state.squares.shape[1:])
    for chunk_sums, chunk_squares in zip(state.sums, state.squares):
        sums = sums + chunk_sums
        squares = squares + chunk_squares
    return sums, squares


def _finish_item(state: _ItemState, sweep: Sweep, out_dir: Path) -> dict:
    """Merge, write the item's files and its ``item.json``; return its index row."""
    from analytic.waveforms import make_waveform
    from transient.render import standard_error
    from validation.compare import compare_transients

    scene, item = state.item.scene, state.item
    sums, squares = _merge(state)
    samples = sweep.samples
    mean, stderr = sums / samples, standard_error(sums, squares, samples)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    meta = {"start_opl": float(scene.sampling.start_opl), "period_opl": float(scene.sampling.bin_width_opl),
            "samples": int(samples), "seed": sweep.seed, "attenuation": "lambertian",
            "illumination": waveform.description, "waveform": waveform.name, "variant": state.variant,
            "kind": "render", "requested_samples": int(samples), "scene_fingerprint": state.fingerprint,
            "chunk_size": sweep.chunk_size, "chunks": len(state.ranges),
            "parameters": item.parameters}
    write_transient(state.folder, mean, meta, stderr=stderr)
    compute = float(state.seconds.sum())
    row = {"name": item.name, "index": item.index, "path": str(state.folder.relative_to(out_dir)),
           "parameters": item.parameters, "samples": int(samples), "seed": sweep.seed,
           "chunk_size": sweep.chunk_size, "chunks": len(state.ranges), "fingerprint": state.fingerprint,
           "render_seconds": compute, "samples_per_second": samples / compute if compute > 0 else None,
           "finished_after_seconds": time.perf_counter() - state.started, "variant": state.variant,
           "agrees": None}
    if state.model is not None:
        model_meta = {"start_opl": float(scene.sampling.start_opl), "period_opl": float(scene.sampling.bin_width_opl),
                      "samples": 0, "seed": 0, "attenuation": scene.attenuation,
                      "illumination": waveform.description, "waveform": waveform.name, "kind": "model",
                      "tolerance": scene.tolerance, "parameters": item.parameters}
        write_transient(state.folder / "model", state.model, model_meta)
        agreement = compare_transients(mean, stderr, state.model).as_dict()
        save_json(state.folder / "agreement.json", agreement)
        row.update(agrees=agreement["agrees"], chi2_per_dof=agreement["chi2_per_dof"],
                   max_abs_z=agreement["max_abs_z"], z_threshold=agreement["z_threshold"],
                   bins=agreement["bins"], relative_l2=agreement["relative_l2"],
                   model_seconds=state.model_seconds)
    save_json(state.folder / ITEM_FILE, row)
    return row


_CSV_FIELDS = ("index", "name", "path", "samples", "seed", "chunk_size", "chunks", "render_seconds",
               "samples_per_second", "finished_after_seconds", "agrees", "chi2_per_dof", "max_abs_z",
               "z_threshold", "bins", "relative_l2", "model_seconds", "variant")


def _write_index(out_dir: Path, sweep: Sweep, rows: dict) -> None:
    ordered = []
    for item in sweep.items:
        row = rows.get(item.name)
        ordered.append(dict(row, status="done") if row is not None else
                       {"index": item.index, "name": item.name, "path": item.name,
                        "parameters": item.parameters, "status": "pending"})
    save_json(out_dir / "index.json", {"base": sweep.base, "grid": sweep.grid, "samples": sweep.samples,
                                       "seed": sweep.seed, "chunk_size": sweep.chunk_size,
                                       "cross_check": sweep.cross_check, "items": ordered})
    keys = list(sweep.grid)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["status", *_CSV_FIELDS, *keys])
    for row in ordered:
        values = [row.get(name, "") for name in _CSV_FIELDS]
        parameters = [json.dumps(row["parameters"][key]) if isinstance(row["parameters"][key], list)
                      else row["parameters"][key] for key in keys]
        writer.writerow([row["status"], *["" if v is None else v for v in values], *parameters])
    text = buffer.getvalue()

    def write(temporary):
        with open(temporary, "w", newline="") as stream:
            stream.write(text)
    atomic_write(out_dir / "index.csv", write)


def _prepare(sweep: Sweep, out_dir: Path) -> tuple[dict, dict, list]:
    """Finished items' rows, unfinished items' checkpointed states, and the names skipped."""
    from transient.render import scene_fingerprint

    rows, states, skipped = {}, {}, []
    for item in sweep.items:
        folder = out_dir / item.name
        fingerprint = scene_fingerprint(item.scene)
        row = _finished_row(item, folder, sweep, fingerprint)
        if row is not None:
            rows[item.name] = row
            skipped.append(item.name)
            continue
        states[item.name] = _load_state(item, folder, sweep, fingerprint)
    return rows, states, skipped


def run_sweep(sweep: Sweep, out_dir: str | Path, *, client=None, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, retries: int = 3,
              on_chunk: Callable[[str, int], None] | None = None) -> SweepResult:
    """Render (and cross-check) every item of a sweep on a Dask cluster, resumably.

    Parameters
    ----------
    sweep : Sweep
        The validated sweep.
    out_dir : str or Path
        Output folder: one sub-folder per item, ``index.json``, ``index.csv``.
        Items finished there already are skipped; unfinished ones resume
        from their checkpointed chunks.
    client : distributed.Client, optional
        Use this client (``scheduler`` and ``workers`` must then be None).
    scheduler : str, optional
        Address of a running Dask scheduler; default: start a local cluster.
    workers : int, optional
        Local cluster size (default: one worker per core).
    progress : bool
        tqdm bars over items and samples (on stderr).
    retries : int
        Times Dask re-runs a chunk whose task raised; a chunk whose worker
        died is re-run anyway (Dask's ``allowed-failures``, 3 by default).
    on_chunk : callable, optional
        ``on_chunk(item_name, chunk_index)`` after every chunk computed by
        this call has been added to its item; it may raise
        KeyboardInterrupt to stop the sweep as Ctrl-C would.

    Returns
    -------
    SweepResult

    Raises
    ------
    KeyboardInterrupt
        After the finished chunks of every unfinished item are checkpointed
        and the cluster's outstanding tasks cancelled.
    SceneError
        When ``out_dir`` holds an item of another sweep (other scene, seed,
        sample count or chunking).
    """
    out_dir = Path(out_dir)
    if client is not None and (scheduler is not None or workers is not None):
        raise ValueError("give either client or scheduler/workers, not both")
    # Prepared before any cluster starts: another sweep's folder is refused at once.
    prepared = _prepare(sweep, out_dir)
    if client is None:
        with sweep_client(scheduler, workers) as own:
            return _run(sweep, out_dir, own, prepared, progress=progress, retries=retries,
                        on_chunk=on_chunk)
    return _run(sweep, out_dir, client, prepared, progress=progress, retries=retries, on_chunk=on_chunk)


def _run(sweep: Sweep, out_dir: Path, client, prepared, *, progress, retries, on_chunk) -> SweepResult:
    """run_sweep's work on a connected client, from :func:`_prepare`'s result."""
    from distributed import as_completed

    started = time.perf_counter()
    rows, states, skipped = prepared
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_index(out_dir, sweep, rows)
    worker_count = len(client.nthreads())

    tasks = {}   # future -> (item name, chunk index or None for the model)
    for state in states.values():
        item = state.item
        # Earlier items first, so a long sweep finishes items one after another.
        priority = -item.index
        scene_future = client.submit(_identity, item.scene, pure=False, priority=priority)
        for chunk, (first, count) in enumerate(state.ranges):
            if not state.done[chunk]:
                future = client.submit(render_chunk, scene_future, state.fingerprint, sweep.seed, first, count,
                                       sweep.variant, pure=False, retries=retries, priority=priority)
                tasks[future] = (item.name, chunk)
        if sweep.cross_check:
            tasks[client.submit(model_transient, scene_future, pure=False, retries=retries,
                                priority=priority)] = (item.name, None)
        del scene_future   # the chunk tasks hold it; released when they finish

    total_samples = sweep.samples * len(sweep.items)
    done_samples = sum(sweep.samples for _ in rows) + sum(
        int(sum(count for (first, count), d in zip(s.ranges, s.done) if d)) for s in states.values())
    bars = []
    if progress:
        from tqdm import tqdm
        bars = [tqdm(total=len(sweep.items), initial=len(rows), unit="item", desc="sweep", position=0),
                tqdm(total=total_samples, initial=done_samples, unit="sample", unit_scale=True,
                     desc="samples", position=1, leave=False)]
    computed = []
    last_checkpoint = time.perf_counter()

    def finish_if_ready(state: _ItemState):
        if state.complete and (not sweep.cross_check or state.model is not None):
            if state.dirty:
                _save_state(state, sweep)
            rows[state.item.name] = _finish_item(state, sweep, out_dir)
            del states[state.item.name]
            _write_index(out_dir, sweep, rows)
            if bars:
                bars[0].update(1)

    def collect():
        nonlocal last_checkpoint
        for state in list(states.values()):
            finish_if_ready(state)   # every chunk checkpointed already, nothing to submit
        for future in as_completed(list(tasks)):
            name, chunk = tasks.pop(future)
            state = states[name]
            if chunk is None:
                state.model, state.model_seconds = future.result()
            else:
                sums, squares, seconds, variant = future.result()
                state.sums[chunk], state.squares[chunk] = sums, squares
                state.seconds[chunk], state.variant = seconds, variant
                state.done[chunk] = True
                state.dirty = True
                computed.append((name, chunk))
                if bars:
                    bars[1].update(state.ranges[chunk][1])
            future.release()
            finish_if_ready(state)
            now = time.perf_counter()
            if now - last_checkpoint >= _CHECKPOINT_SECONDS:
                for other in states.values():
                    if other.dirty:
                        _save_state(other, sweep)
                last_checkpoint = now
            if on_chunk is not None and chunk is not None:
                on_chunk(name, chunk)

    try:
        with sigterm_as_interrupt():
            collect()
    except BaseException:
        client.cancel(list(tasks))
        for state in states.values():
            if state.dirty:
                _save_state(state, sweep)
        raise
    finally:
        for bar in bars:
            bar.close()
    ordered = tuple(rows[item.name] for item in sweep.items)
    return SweepResult(out_dir=out_dir, rows=ordered, computed_chunks=tuple(computed),
                       skipped_items=tuple(skipped), seconds=time.perf_counter() - started,
                       workers=worker_count)
