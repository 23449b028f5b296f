"""A of a translation-invariant capture as an operator, by FFT: y = A f and Aᵀ r without A.

On the offset route (:mod:`.offsets`) pair k's entry for pixel (r, c) at bin n is its scale s_k times
the entry V_g[n] of its group g at the virtual pixel (r + a_k, c + b_k), (a_k, b_k) the pair's whole-pixel
offset inside the virtual rectangle (0 <= a_k, b_k <= Mv - M). So per group and bin

    y[k, n] = s_k Σ_{r,c} V_g[n][r + a_k, c + b_k] f[r, c],

a 2-D correlation of the image with the group's virtual kernel, read at each member's offset; and

    (Aᵀ r)[r, c] = Σ_g Σ_n Σ_{a,b} V_g[n][r + a, c + b] R_g[n][a, b],   R_g[n][a, b] = Σ_{k at (a, b)} s_k r[k, n].

Both are circular correlations of size L >= Mv (no index reaches past Mv - 1, so nothing wraps), done by
real FFTs: V's transforms are made once (G N L (L/2 + 1) complex numbers), each product then costs G N
transforms of L x L. Memory O(G N L²) plus the pairs' P N samples, never A's (P N x M², 102 million
non-zeros for a 64 x 64 confocal scan of 64 x 64 pixels, where this holds one 190 x 190 kernel per bin).
The products equal A's to rounding (tests/analytic/test_offset_operator.py holds them to the sparse A of
the same capture). Bins are transformed in chunks, so Ctrl-C stops a product within a fraction of a second.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
import scipy.sparse.linalg

from .blocks import thread_count
from .offsets import OffsetPlan

__all__ = ["OffsetOperator", "offset_operator_bytes", "capture_operator"]

#: Bins transformed together (bounds the temporaries, and how long Ctrl-C waits: a chunk is ~0.1 s).
_CHUNK_BINS = 32


def _side(plan: OffsetPlan) -> int:
    return scipy.fft.next_fast_len(plan.virtual.grid.pixels, real=True)


def offset_operator_bytes(plan: OffsetPlan) -> int:
    """Bytes :class:`OffsetOperator` holds for ``plan``: the kernels' transforms and its gather indices."""
    side = _side(plan)
    return 16 * len(plan.virtual.pairs) * plan.bins * side * (side // 2 + 1) + 40 * len(plan.groups)


class OffsetOperator(scipy.sparse.linalg.LinearOperator):
    """A (P N x M², row k N + n, column r M + c) of an offset plan, applied by FFT (module docstring).

    Parameters
    ----------
    plan : OffsetPlan
        :func:`.offsets.offset_plan` of the capture.
    runs : tuple
        :func:`.offsets.virtual_entries` of the plan (starts, firsts, values).
    factor : float
        Every entry divided by this (a power of two keeps the entries exact).

    Attributes
    ----------
    nnz : int
        A's non-zero entries (as the sparse A of the same plan holds them).
    largest_entry : float
        max |A| (after ``factor``).
    translation_invariant : bool
        True: AᵀA is close to a convolution (the reconstruction preconditions by it).
    """

    translation_invariant = True

    def __init__(self, plan: OffsetPlan, runs: tuple, *, factor: float = 1.0):
        pixels, bins, virtual = plan.pixels, plan.bins, plan.virtual.grid.pixels
        count, groups = len(plan.groups), len(plan.virtual.pairs)
        super().__init__(np.float64, (count * bins, pixels * pixels))
        self.plan, self.runs, self.factor = plan, runs, float(factor)
        self.side = side = _side(plan)
        self.scales = np.asarray(plan.scales, dtype=np.float64) / self.factor
        # pair k's offset (a_k, b_k) in the virtual rectangle, rows from the top (analytic.kernels.offsets._run)
        rows = (virtual - pixels) - plan.shift_r
        columns = plan.shift_c
        self._gather = (plan.groups, rows, columns)
        self._slot = (plan.groups * side + rows) * side + columns        # flat (g, a, b) per pair
        self._unique = np.unique(self._slot).size == count
        kernels = self._kernels(plan, runs)          # (G, N, Mv, Mv) dense virtual entries
        # per pair, over its own M x M window of the virtual rectangle: non-zero bins and the largest |entry|
        counts = np.count_nonzero(kernels, axis=1)              # (G, Mv, Mv)
        peaks = np.max(np.abs(kernels), axis=1, initial=0.0)    # (G, Mv, Mv)
        nnz, largest = 0, 0.0
        for k, (g, a, b) in enumerate(zip(plan.groups, rows, columns)):
            if self.scales[k] != 0.0:
                nnz += int(counts[g, a:a + pixels, b:b + pixels].sum())
                largest = max(largest, abs(self.scales[k]) * float(peaks[g, a:a + pixels, b:b + pixels].max()))
        self.nnz, self.largest_entry = nnz, largest
        self._transforms = np.empty((groups, bins, side, side // 2 + 1), dtype=np.complex128)
        for g in range(groups):
            for low in range(0, bins, _CHUNK_BINS):
                self._transforms[g, low:low + _CHUNK_BINS] = scipy.fft.rfft2(
                    kernels[g, low:low + _CHUNK_BINS], s=(side, side), workers=thread_count())
        self._absolute = None

    @staticmethod
    def _kernels(plan: OffsetPlan, runs: tuple) -> np.ndarray:
        starts, firsts, values = runs
        groups, virtual, bins = len(plan.virtual.pairs), plan.virtual.grid.pixels, plan.bins
        lengths = np.diff(starts)
        run = np.repeat(np.arange(lengths.size), lengths)
        n = firsts[run] + np.arange(values.size) - starts[run]
        keep = (n >= 0) & (n < bins)
        dense = np.zeros((groups * virtual * virtual, bins))
        dense[run[keep], n[keep]] = values[keep]
        return np.ascontiguousarray(dense.reshape(groups, virtual, virtual, bins).transpose(0, 3, 1, 2))

    def scaled(self, factor: float) -> "OffsetOperator":
        """A / factor (the transforms shared; a power of two keeps every entry exact)."""
        copy = object.__new__(OffsetOperator)
        copy.__dict__.update(self.__dict__)
        copy.factor = self.factor * float(factor)
        copy.scales = self.scales / float(factor)
        copy.largest_entry = self.largest_entry / float(factor)
        copy._absolute = None
        return copy

    def row_and_column_seen(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows of A with a non-zero entry, columns with one), from the virtual entries' pattern."""
        plan, pixels = self.plan, self.plan.pixels
        pattern = OffsetPlan(*plan)._replace(scales=(self.scales != 0).astype(np.float64))
        starts, firsts, values = self.runs
        ones = OffsetOperator(pattern, (starts, firsts, (values != 0).astype(np.float64)))
        rows = ones.matvec(np.ones(pixels * pixels)) > 0.5
        columns = ones.rmatvec(np.ones(ones.shape[0])) > 0.5
        return rows, columns

    def _matvec(self, f):
        groups, rows, columns = self._gather
        image = np.asarray(f, dtype=np.float64).reshape(self.plan.pixels, self.plan.pixels)
        spectrum = np.conj(scipy.fft.rfft2(image, s=(self.side, self.side)))
        y = np.empty((len(groups), self.plan.bins))
        for g in range(self._transforms.shape[0]):
            members = np.flatnonzero(groups == g)
            for low in range(0, self.plan.bins, _CHUNK_BINS):
                correlation = scipy.fft.irfft2(self._transforms[g, low:low + _CHUNK_BINS] * spectrum,
                                               s=(self.side, self.side), workers=thread_count())
                y[members, low:low + _CHUNK_BINS] = correlation[:, rows[members], columns[members]].T
        y *= self.scales[:, None]
        return y.ravel()

    def _rmatvec(self, r):
        groups, bins, side = self._transforms.shape[0], self.plan.bins, self.side
        weighted = np.asarray(r, dtype=np.float64).reshape(len(self.scales), bins) * self.scales[:, None]
        slots = np.zeros((groups * side * side, bins))
        if self._unique:
            slots[self._slot] = weighted
        else:
            np.add.at(slots, self._slot, weighted)
        slots = slots.reshape(groups, side, side, bins)
        total = np.zeros((side, side // 2 + 1), dtype=np.complex128)
        for g in range(groups):
            for low in range(0, bins, _CHUNK_BINS):
                chunk = np.moveaxis(slots[g, :, :, low:low + _CHUNK_BINS], -1, 0)
                spectra = scipy.fft.rfft2(chunk, workers=thread_count())
                total += np.einsum("nij,nij->ij", self._transforms[g, low:low + _CHUNK_BINS], np.conj(spectra))
        pixels = self.plan.pixels
        return scipy.fft.irfft2(total, s=(side, side))[:pixels, :pixels].ravel()

    def _adjoint(self):
        return _Adjoint(self)

    def toarray(self) -> np.ndarray:
        """A dense, from the same runs as the sparse A (for small captures only: the svd method's copy)."""
        from .offsets import offset_matrix

        plan = OffsetPlan(*self.plan)._replace(scales=self.scales)
        return offset_matrix(plan, self.runs, 8 * self.shape[0] * self.shape[1] + 2**20).toarray()


class _Adjoint(scipy.sparse.linalg.LinearOperator):
    def __init__(self, operator: OffsetOperator):
        super().__init__(np.float64, operator.shape[::-1])
        self.operator = operator

    def _matvec(self, r):
        return self.operator._rmatvec(r)

    def _rmatvec(self, f):
        return self.operator._matvec(f)


def capture_operator(scene, *, progress: bool = False, memory_limit: int | None = None) -> OffsetOperator | None:
    """A of ``scene`` as an :class:`OffsetOperator` when the offset route applies (:func:`.offsets.offset_plan`)
    and its transforms fit ``memory_limit`` (default half the memory available), else None (use
    :func:`analytic.operator.system.system_matrix`).

    The virtual entries are assembled as :func:`~analytic.operator.system.system_matrix` assembles them (the
    scene's tolerance; the same checks of the scene first), so the operator's products are A's to rounding.
    """
    from ..scenes.scene_file import scene_of
    from ..waveforms import make_waveform
    from .cost import may_be_impractical, refuse_impractical_illumination
    from .offsets import offset_plan, virtual_entries
    from .system import _assemble, _limit, _problem, check_tolerance

    scene = scene_of(scene)
    tolerance = check_tolerance(scene.tolerance)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    if may_be_impractical(waveform, scene.sampling):
        refuse_impractical_illumination(scene)
    rectangle, pairs = scene.geometry()
    plan = offset_plan(_problem(rectangle, pairs, scene.sampling, waveform))
    limit = _limit(memory_limit)
    if plan is None or offset_operator_bytes(plan) > limit:
        return None
    runs = virtual_entries(plan, lambda virtual: _assemble(virtual, tolerance, limit, progress, None))
    return OffsetOperator(plan, runs)
