"""Replicas and chunks: how a render's samples are cut, and how their sums become an estimate and its error.

A render of S samples is R independent **replicas** of n samples each
(S = R n): each replica is a complete stratified point set of its own
(see :mod:`transient.plane`), randomised independently of the others, so
the R replica means are independent and identically distributed. The
estimate is their mean; its standard error comes from their spread, with
R - 1 degrees of freedom (docs/design.md sections 4 and 6).

The samples are numbered globally, replica r holding [r n, (r + 1) n), and
drawn in **chunks** (one kernel launch each) of consecutive global indices;
a chunk may end inside a replica or span several. Sample g's random numbers
depend on (seed, g) only, so any chunking gives the same sums (to the
rounding of float64 additions).

The chunk-level API, for a renderer loop or a distributed sweep::

    layout = ReplicaLayout.for_samples(spp)              # R replicas of n samples
    plan = ChunkPlan(layout, chunk_size)                 # fixed chunks, lazily
    accumulator = ReplicaAccumulator(layout, (K, N))
    for chunk in plan:                                   # any order: see add()
        sums = integrator.render_chunk(scene, seed=seed, layout=layout,
                                       first=chunk.first, count=chunk.count)
        accumulator.add(chunk, sums)
    mean, stderr, dof = accumulator.mean(), accumulator.stderr(), accumulator.dof
    replicas = accumulator.replica_means()              # (R, K, N): their mean is `mean`

Memory: the accumulator holds the ``(R, K, N)`` float64 replica means and
a ``(K, N)`` partial sum, plus the chunks that arrived ahead of their
turn (:func:`render_memory_bytes`); a chunk's sums are
``(replicas it touches, K, N)``, and the kernel's histogram
``(ReplicaLayout.histogram_rows, K, N)`` (at most R rows; on the LLVM
backend one private copy per thread when it has at most 2^20 entries).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = ["checked_chunk", "DEFAULT_REPLICAS", "MAX_REPLICA_SIZE", "MAX_SAMPLES", "ReplicaLayout", "Chunk", "ChunkPlan",
           "ReplicaAccumulator", "render_memory_bytes"]

#: Replicas of a render unless asked otherwise. More replicas give a steadier
#: standard error (Student t with R - 1 degrees of freedom) but smaller point
#: sets: the error of a stratified estimate falls as n^(-3/4) per replica,
#: so the variance of the mean grows as R^(1/2) at a fixed sample count.
#: 32 keeps the t quantiles within 30 % of the normal ones at 1e-6 tails and
#: costs a factor 1.4 in variance against 16.
DEFAULT_REPLICAS = 32

#: Largest replica (samples): indices within a replica are 32-bit.
MAX_REPLICA_SIZE = 2**32 - 1

#: Largest render, samples: months on a CPU, hours on a datacentre GPU at the rates of docs/benchmarks.md.
MAX_SAMPLES = 2**48


@dataclass(frozen=True)
class ReplicaLayout:
    """R replicas of n samples each.

    Attributes
    ----------
    replicas : int
        R >= 2.
    size : int
        n >= 1, samples per replica, <= :data:`MAX_REPLICA_SIZE`.
    """

    replicas: int
    size: int

    def __post_init__(self):
        if not 2 <= self.replicas:
            raise ValueError(f"replicas: need at least 2 for a standard error, got {self.replicas}")
        if not 1 <= self.size <= MAX_REPLICA_SIZE:
            raise ValueError(f"replica size must be in [1, {MAX_REPLICA_SIZE}], got {self.size}")

    @property
    def samples(self) -> int:
        """S = R n."""
        return self.replicas * self.size

    @property
    def histogram_rows(self) -> int:
        """Replica rows of a chunk's histogram: enough for any chunk (<= 2^31 samples), the same for all.

        A histogram of one size for every chunk of a render keeps its
        compiled kernel the same (the size is baked into the scatter); it
        holds ``histogram_rows x K x N`` float64: all R replicas unless
        replicas are longer than 2^31 / (R - 2) samples.
        """
        return min(self.replicas, 2 + -(-2**31 // self.size))

    @classmethod
    def for_samples(cls, samples: int, replicas: int | None = None) -> "ReplicaLayout":
        """The layout of a render of about ``samples`` samples.

        Parameters
        ----------
        samples : int
            Requested sample count, 2 <= samples <= :data:`MAX_SAMPLES`.
        replicas : int, optional
            R (default :data:`DEFAULT_REPLICAS`, fewer if ``samples`` is
            smaller, more if a replica would exceed :data:`MAX_REPLICA_SIZE`).

        Returns
        -------
        ReplicaLayout
            n = ⌈samples / R⌉: the render draws R n >= samples samples
            (at most R - 1 more than asked).
        """
        samples = int(samples)
        if not 2 <= samples <= MAX_SAMPLES:
            raise ValueError(f"samples must be in [2, 2^48], got {samples}")
        if replicas is None:
            replicas = min(DEFAULT_REPLICAS, samples)
            replicas = max(replicas, -(-samples // MAX_REPLICA_SIZE))
        replicas = int(replicas)
        if not 2 <= replicas <= samples:
            raise ValueError(f"replicas must be in [2, samples = {samples}], got {replicas}")
        return cls(replicas, -(-samples // replicas))


@dataclass(frozen=True)
class Chunk:
    """Samples [first, first + count) of a render (global indices).

    Attributes
    ----------
    index : int
        Position in its :class:`ChunkPlan`.
    first, count : int
        First global sample index and number of samples (>= 1).
    """

    index: int
    first: int
    count: int

    def replicas(self, layout: ReplicaLayout) -> range:
        """The replicas this chunk touches, in order."""
        return range(self.first // layout.size, (self.first + self.count - 1) // layout.size + 1)


class ChunkPlan:
    """The chunks ``[i C, min((i + 1) C, S))`` of a layout, computed on demand (no list of them is kept).

    Parameters
    ----------
    layout : ReplicaLayout
    chunk_size : int
        C, samples per chunk, 1 <= C <= 2^31.
    start : int
        First sample to cover (a resumed render starts where it stopped).
    """

    def __init__(self, layout: ReplicaLayout, chunk_size: int, start: int = 0):
        if not 1 <= int(chunk_size) <= 2**31:
            raise ValueError(f"chunk_size: must be in [1, 2^31], got {chunk_size}")
        if not 0 <= int(start) <= layout.samples:
            raise ValueError(f"start must be in [0, {layout.samples}], got {start}")
        self.layout, self.chunk_size, self.start = layout, int(chunk_size), int(start)

    def __len__(self) -> int:
        return -(-(self.layout.samples - self.start) // self.chunk_size)

    def __getitem__(self, index: int) -> Chunk:
        if not 0 <= index < len(self):
            raise IndexError(index)
        first = self.start + index * self.chunk_size
        return Chunk(index, first, min(self.chunk_size, self.layout.samples - first))

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def render_memory_bytes(layout: ReplicaLayout, shape: tuple[int, int], copies: int = 1) -> int:
    """Bytes a render of this layout holds at most at once: replica means, partial sums, one chunk's histogram.

    Parameters
    ----------
    layout : ReplicaLayout
    shape : (int, int)
        (K sensors, N bins).
    copies : int
        Per-thread copies of the kernel's histogram
        (:func:`transient.common.per_thread_copies`).

    Returns
    -------
    int
        8 K N (R + 1 + 2 h) bytes, h = :attr:`ReplicaLayout.histogram_rows`
        (the kernel's histogram and its NumPy copy); with c > 1 copies
        8 K N (R + 1 + (2 c + 1) h), the relay-wall kernel's (the copies in
        Dr.Jit and in NumPy, and their sum), more than Dr.Jit's own
        ``Expand`` holds (its copies, the histogram and one NumPy copy).
    """
    cells = int(shape[0]) * int(shape[1])
    histograms = 2 if copies == 1 else 2 * int(copies) + 1
    return 8 * cells * (layout.replicas + 1 + histograms * layout.histogram_rows)


class _Folded(NamedTuple):
    """The accumulator's folded totals (replaced whole, never mutated, except rows past ``completed``)."""

    done: int                  # samples folded: a prefix of the render
    completed: int             # replicas complete: rows [0, completed) of the replica means hold them
    partial: np.ndarray        # Σc of the replica in progress


class ReplicaAccumulator:
    """Folds chunk sums into replica means, and those into an estimate, its standard error and dof.

    Chunks are folded in global sample order whatever order they arrive
    in (early ones wait), so the float64 result does not depend on the
    order of arrival. Each completed replica's mean is kept (``(R, K, N)``
    float64, :meth:`replica_means`): the estimate is their mean and the
    standard error their spread, computed in two passes with the
    deviations scaled by their largest magnitude, so that neither the
    squares of y ~ 1e-300 underflow nor those of large values overflow.
    A fold writes the new replica's row (unused until counted) and then
    replaces the totals in one assignment, so an interrupt (Ctrl-C,
    SIGTERM) between two Python bytecodes leaves either the old totals or
    the new ones, never a mix.

    Parameters
    ----------
    layout : ReplicaLayout
    shape : (int, int)
        (K sensors, N bins).
    """

    def __init__(self, layout: ReplicaLayout, shape: tuple[int, int]):
        self.layout, self.shape = layout, tuple(shape)
        self._replica_means = np.zeros((layout.replicas,) + self.shape)
        self._folded = _Folded(0, 0, np.zeros(self.shape))
        self._waiting: dict[int, tuple[Chunk, np.ndarray]] = {}

    @property
    def done(self) -> int:
        """Samples folded (a prefix of the render)."""
        return self._folded.done

    @property
    def completed(self) -> int:
        """Replicas complete."""
        return self._folded.completed

    def add(self, chunk: Chunk, sums: np.ndarray) -> None:
        """Fold a chunk's sums.

        Parameters
        ----------
        chunk : Chunk
        sums : numpy.ndarray
            ``(len(chunk.replicas(layout)), K, N)``: Σc per touched replica.
        """
        sums = np.asarray(sums, dtype=np.float64)
        expected = (len(chunk.replicas(self.layout)),) + self.shape
        if sums.shape != expected:
            raise ValueError(f"chunk {chunk.index}: sums of shape {sums.shape}, expected {expected}")
        if chunk.first < self.done or chunk.first in self._waiting:
            raise ValueError(f"chunk {chunk.index} (samples from {chunk.first}) was already added")
        if chunk.first + chunk.count > self.layout.samples:
            raise ValueError(f"chunk {chunk.index} ends after the render's {self.layout.samples} samples")
        self._waiting[chunk.first] = (chunk, sums)
        while self.done in self._waiting:
            self._folded = self._fold(self._folded, *self._waiting.pop(self.done))

    def _fold(self, folded: _Folded, chunk: Chunk, sums: np.ndarray) -> _Folded:
        size = self.layout.size
        completed, partial = folded.completed, folded.partial
        for row, replica in enumerate(chunk.replicas(self.layout)):
            partial = partial + sums[row]
            if chunk.first + chunk.count >= (replica + 1) * size:
                # Row `completed` is past the folded count until the new totals are assigned.
                self._replica_means[completed] = partial / size
                completed += 1
                partial = np.zeros(self.shape)
        return _Folded(chunk.first + chunk.count, completed, partial)

    @property
    def finished(self) -> bool:
        """Every replica is complete."""
        return self.completed == self.layout.replicas

    @property
    def samples(self) -> int:
        """Samples in the completed replicas (those the estimate uses)."""
        return self.completed * self.layout.size

    @property
    def dof(self) -> int:
        """Degrees of freedom of the standard error: completed replicas - 1."""
        return self.completed - 1

    def replica_means(self) -> np.ndarray:
        """``(completed, K, N)``: each completed replica's own estimate of y, in replica order."""
        return self._replica_means[:self.completed].copy()

    def mean(self) -> np.ndarray:
        """``(K, N)`` estimate of y: the mean of the completed replicas' means."""
        if self.completed == 0:
            raise ValueError("no replica is complete yet")
        return np.mean(self._replica_means[:self.completed], axis=0)

    def stderr(self) -> np.ndarray:
        """``(K, N)`` standard error of :meth:`mean`: sqrt(Σ (m_r - m)² / ((R - 1) R)).

        Raises
        ------
        ValueError
            Fewer than 2 replicas complete.
        """
        if self.completed < 2:
            raise ValueError("a standard error needs 2 complete replicas")
        means = self._replica_means[:self.completed]
        deviations = means - np.mean(means, axis=0)
        # Scaled by the largest deviation of each bin: its squares neither underflow nor overflow.
        scale = np.max(np.abs(deviations), axis=0)
        scaled = np.divide(deviations, scale, out=np.zeros_like(deviations), where=scale > 0.0)
        return scale * np.sqrt(np.sum(scaled * scaled, axis=0) / ((self.completed - 1) * self.completed))

    # -- checkpoints -------------------------------------------------------------

    def state(self) -> dict:
        """The folded totals as plain arrays and integers (chunks still waiting are not included).

        ``done``, ``completed``, ``partial`` (``(K, N)``: Σc of the replica
        in progress) and ``replica_means`` (``(completed, K, N)``).
        """
        folded = self._folded
        return {"done": int(folded.done), "completed": int(folded.completed), "partial": folded.partial.copy(),
                "replica_means": self._replica_means[:folded.completed].copy()}

    @classmethod
    def from_state(cls, layout: ReplicaLayout, shape, state: dict) -> "ReplicaAccumulator":
        """Rebuild from :meth:`state`, checking that it is consistent.

        Raises
        ------
        ValueError
            Wrong shapes, non-finite sums, or counts that do not fit the layout.
        """
        accumulator = cls(layout, shape)
        done, completed = int(state["done"]), int(state["completed"])
        if not 0 <= completed <= layout.replicas or not 0 <= done <= layout.samples:
            raise ValueError(f"counts out of range: {done} samples, {completed} replicas done "
                             f"of {layout.samples} in {layout.replicas}")
        if completed != done // layout.size:
            raise ValueError(f"{done} samples done but {completed} replicas complete "
                             f"(replicas of {layout.size})")
        expected = {"partial": accumulator.shape, "replica_means": (completed,) + accumulator.shape}
        arrays = {}
        for name, shape_expected in expected.items():
            array = np.asarray(state[name], dtype=np.float64)
            if array.shape != shape_expected:
                raise ValueError(f"{name} has shape {array.shape}, expected {shape_expected}")
            if not np.all(np.isfinite(array)):
                raise ValueError(f"{name} holds NaN or infinite values")
            arrays[name] = array
        if done % layout.size == 0 and np.any(arrays["partial"] != 0.0):
            raise ValueError("sums of a replica in progress although none is")
        accumulator._replica_means[:completed] = arrays["replica_means"]
        accumulator._folded = _Folded(done, completed, arrays["partial"])
        return accumulator


def checked_chunk(layout: ReplicaLayout, seed: int, first: int, count: int) -> tuple[int, int]:
    """A chunk's (first, count) as ints, checked against its render: what every integrator's chunk takes.

    Raises
    ------
    ValueError
        A seed outside [0, 2^32), or a sample range that is empty, longer than 2^31 or outside the
        render's R n samples.
    """
    if not 0 <= int(seed) < 2**32:
        raise ValueError(f"seed must be in [0, 2^32), got {seed}")
    first, count = int(first), int(count)
    if not (1 <= count <= 2**31 and 0 <= first and first + count <= layout.samples):
        raise ValueError(f"sample range [{first}, {first + count}) must be non-empty, at most 2^31 long "
                         f"and inside the render's {layout.samples} samples")
    return first, count
