"""An unfinished item's checkpoint: the per-replica sums of its finished chunks, kept atomically.

An item's render is R replicas cut into fixed chunks
(:class:`transient.chunks.ChunkPlan`); ``sweep_state.npz`` in the item's
folder holds every finished chunk's per-replica sums, so an interrupted
sweep resumes where it stopped; ``item.json``, written last, marks the item
finished. The chunks are folded in sample order at the end, as
:func:`transient.render.render` folds them, so the result does not depend
on which worker finished first.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analytic.errors import ResourceError
from analytic.files import atomic_write
from transient.chunks import ChunkPlan, ReplicaAccumulator, ReplicaLayout

from .config import Sweep, SweepItem

__all__ = ["ItemState", "save_state", "load_state", "state_identity", "mismatch", "layout_of",
           "STATE_FILE", "ITEM_FILE", "CHECKPOINT_SECONDS"]

#: Per-item checkpoint of finished chunks' moments.
STATE_FILE = "sweep_state.npz"
#: Written last in an item's folder: the item is finished.
ITEM_FILE = "item.json"
#: Seconds between checkpoints of unfinished items: an interruption loses at
#: most this much work, and small chunks do not spend their time in fsync.
CHECKPOINT_SECONDS = 2.0


def layout_of(sweep: Sweep) -> ReplicaLayout:
    """The replicas of every item's render (the same sample count for all)."""
    return ReplicaLayout.for_samples(sweep.samples)


@dataclass(eq=False)
class ItemState:
    """The driver's running totals of one item (mutable, driver only).

    Attributes
    ----------
    plan : ChunkPlan
        The item's chunks.
    chunk_sums : dict
        Chunk index -> its per-replica sums ``(replicas it touches, K, N)``.
    seconds : dict
        Chunk index -> render seconds on its worker.
    """

    item: SweepItem
    folder: Path
    fingerprint: str
    plan: ChunkPlan
    chunk_sums: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)
    variant: str = ""
    model: np.ndarray | None = None
    model_seconds: float = 0.0
    window_share: float | None = None
    started: float = field(default_factory=time.perf_counter)
    dirty: bool = False

    @property
    def complete(self) -> bool:
        return len(self.chunk_sums) == len(self.plan)

    @property
    def samples_done(self) -> int:
        return sum(self.plan[index].count for index in self.chunk_sums)

    def estimate(self) -> ReplicaAccumulator:
        """The chunks folded in sample order (all of them must be done)."""
        shape = (self.item.scene.sensor_count, self.item.scene.sampling.count)
        accumulator = ReplicaAccumulator(self.plan.layout, shape)
        for chunk in self.plan:
            accumulator.add(chunk, self.chunk_sums[chunk.index])
        return accumulator


def state_identity(sweep: Sweep, fingerprint: str) -> dict:
    """What a checkpoint or a finished item must match to be reused."""
    layout = layout_of(sweep)
    return {"seed": sweep.seed, "requested_samples": sweep.samples, "chunk_size": sweep.chunk_size,
            "replicas": layout.replicas, "fingerprint": fingerprint}


def save_state(state: ItemState, sweep: Sweep) -> None:
    """Write the finished chunks' sums, atomically."""
    identity = state_identity(sweep, state.fingerprint)
    done = np.array(sorted(state.chunk_sums), dtype=np.int64)

    def write(temporary):
        with open(temporary, "wb") as stream:
            np.savez(stream, done=done, seconds=np.array([state.seconds[i] for i in done]),
                     variant=np.array(state.variant), fingerprint=np.array(state.fingerprint),
                     **{key: np.int64(value) for key, value in identity.items() if key != "fingerprint"},
                     **{f"sums_{i}": state.chunk_sums[i] for i in done})
    atomic_write(state.folder / STATE_FILE, write)
    state.dirty = False


def mismatch(path: Path, what: str) -> ResourceError:
    """An output folder that belongs to another sweep."""
    return ResourceError(f"{path}: belongs to a sweep with another {what}; use a new --out folder")


def load_state(item: SweepItem, folder: Path, sweep: Sweep, fingerprint: str) -> ItemState:
    """The item's checkpointed chunks (none when it has no checkpoint yet).

    Raises
    ------
    ResourceError
        When the checkpoint belongs to another sweep or cannot be read.
    """
    plan = ChunkPlan(layout_of(sweep), sweep.chunk_size)
    state = ItemState(item=item, folder=folder, fingerprint=fingerprint, plan=plan)
    path = folder / STATE_FILE
    if not path.is_file():
        return state
    shape = (item.scene.sensor_count, item.scene.sampling.count)
    try:
        with np.load(path, allow_pickle=False) as saved:
            if str(saved["fingerprint"]) != fingerprint:
                raise mismatch(path, "scene")
            for key, value in state_identity(sweep, fingerprint).items():
                if key != "fingerprint" and int(saved[key]) != value:
                    raise mismatch(path, key.replace("_", " "))
            state.variant = str(saved["variant"])
            for index, seconds in zip(saved["done"].tolist(), saved["seconds"].tolist()):
                sums = np.array(saved[f"sums_{index}"], dtype=np.float64)
                expected = (len(plan[index].replicas(plan.layout)),) + shape
                if sums.shape != expected or not np.all(np.isfinite(sums)):
                    raise mismatch(path, "shape (or its sums are not finite)")
                state.chunk_sums[index], state.seconds[index] = sums, seconds
    except ResourceError:
        raise
    except Exception as error:  # a truncated or foreign file: numpy and zipfile raise many types
        raise ResourceError(f"{path}: cannot read this sweep checkpoint ({type(error).__name__}: "
                            f"{error}); delete it to render the item again") from None
    return state
