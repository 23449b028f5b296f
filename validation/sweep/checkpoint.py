"""An unfinished item's checkpoint: the moments of its finished chunks, kept atomically.

``sweep_state.npz`` in an item's folder holds the finished chunks'
float64 moments, so an interrupted sweep resumes where it stopped;
``item.json``, written last, marks the item finished.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analytic.errors import SceneError
from analytic.io import atomic_write
from transient.render import chunk_ranges

from .config import Sweep, SweepItem

__all__ = ["ItemState", "save_state", "load_state", "merge_chunks", "state_identity", "mismatch",
           "STATE_FILE", "ITEM_FILE", "CHECKPOINT_SECONDS"]

#: Per-item checkpoint of finished chunks' moments.
STATE_FILE = "sweep_state.npz"
#: Written last in an item's folder: the item is finished.
ITEM_FILE = "item.json"
#: Seconds between checkpoints of unfinished items: an interruption loses at
#: most this much work, and small chunks do not spend their time in fsync.
CHECKPOINT_SECONDS = 2.0


@dataclass(eq=False)
class ItemState:
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
    window_share: float | None = None
    started: float = field(default_factory=time.perf_counter)
    dirty: bool = False

    @property
    def complete(self) -> bool:
        return bool(self.done.all())


def state_identity(sweep: Sweep, fingerprint: str) -> dict:
    return {"seed": sweep.seed, "samples": sweep.samples, "chunk_size": sweep.chunk_size,
            "fingerprint": fingerprint}


def save_state(state: ItemState, sweep: Sweep) -> None:
    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, sums=state.sums, sums_of_squares=state.squares, done=state.done,
                     seconds=state.seconds, seed=np.int64(sweep.seed), samples=np.int64(sweep.samples),
                     chunk_size=np.int64(sweep.chunk_size), fingerprint=np.array(state.fingerprint),
                     variant=np.array(state.variant))
    atomic_write(state.folder / STATE_FILE, write)
    state.dirty = False


def mismatch(path: Path, what: str) -> SceneError:
    return SceneError(str(path), f"belongs to a sweep with another {what}; use a new --out folder")


def load_state(item: SweepItem, folder: Path, sweep: Sweep, fingerprint: str) -> ItemState:
    ranges = chunk_ranges(sweep.samples, sweep.chunk_size)
    shape = (item.scene.sensor_count, item.scene.sampling.count)
    state = ItemState(item=item, folder=folder, fingerprint=fingerprint, ranges=ranges,
                       sums=np.zeros((len(ranges),) + shape), squares=np.zeros((len(ranges),) + shape),
                       done=np.zeros(len(ranges), dtype=bool), seconds=np.zeros(len(ranges)))
    path = folder / STATE_FILE
    if not path.is_file():
        return state
    with np.load(path, allow_pickle=False) as saved:
        if str(saved["fingerprint"]) != fingerprint:
            raise mismatch(path, "scene")
        for name in ("seed", "samples", "chunk_size"):
            if int(saved[name]) != getattr(sweep, "chunk_size" if name == "chunk_size" else name):
                raise mismatch(path, name)
        if saved["sums"].shape != state.sums.shape:
            raise mismatch(path, "shape")
        state.sums[...] = saved["sums"]
        state.squares[...] = saved["sums_of_squares"]
        state.done[...] = saved["done"]
        state.seconds[...] = saved["seconds"]
        state.variant = str(saved["variant"])
    return state


def merge_chunks(state: ItemState) -> tuple[np.ndarray, np.ndarray]:
    """Σ over chunks in chunk order, from zero, as :func:`transient.render.render` adds them."""
    sums = np.zeros(state.sums.shape[1:])
    squares = np.zeros(state.squares.shape[1:])
    for chunk_sums, chunk_squares in zip(state.sums, state.squares):
        sums = sums + chunk_sums
        squares = squares + chunk_squares
    return sums, squares


