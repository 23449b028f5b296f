"""The exact, sparse, time-binned system matrix A of docs/design.md section 2.

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx,   row k N + n, column r M + c.

The plane scene is one geometry of :mod:`analytic.geometry` (a rectangle and
one point pair per sensor); :func:`rectangle_matrix` assembles A for any
rectangle and any pairs, rows pair-major then bin. The compiled kernels that
compute one pair's entries over one pixel are :mod:`analytic.kernels`; the
compiled passes that count and fill A's entries are :mod:`analytic.kernels.assembly`;
this module checks the resources, allocates and drives them.

How it is computed
------------------
κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) is smooth in τ except at the bin edges
t_n shifted by the waveform's breakpoints (its pieces' kinks). For each
(pixel, pair), with [d_lo, d_hi] the exact range of d over the pixel, one of
four routes:

- *Smooth pixels* (no breakpoint inside (d_lo, d_hi), and the pixel clear of
  the peaks of a under the source's and sensor's feet, see
  :data:`analytic.kernels.routes.FOOT_CLEARANCE`): every entry a_k κ_n(d) is analytic on the pixel,
  and each κ_n a short Taylor polynomial over the pixel's range of d, so the
  entries are a few moments of the pixel's path lengths
  (:func:`analytic.kernels.moments.smooth_by_moments`), integrated by the tensor
  Gauss ladder with its error check (or, where the moments do not serve,
  every kernel by :func:`analytic.kernels.quadrature.tensor_integrate`); most pairs
  take this route, more of them at larger M. Assembly settles most of them
  from d and ∇d at the pixel's centre (:func:`analytic.kernels.isochrone.range_bound`),
  without the exact range.
- *Cut pixels by strips* (clear of the feet and of x*): the slabs between
  the kinks' isochrones, each a region with conic sides whose limits are
  closed-form (:mod:`analytic.kernels.strips`), by G_4 x G_4 judged by G_3 x G_3;
  when that rule does not meet the tolerance, the next route. For the
  impulse (the one waveform whose S is a step, so each κ_n is constant on
  either side of a breakpoint; the square pulse's S is a ramp), assembly's
  first pass takes such a pixel first: the part below each breakpoint's
  isochrone by a ladder from G_3 x G_3 judged by G_2 x G_2
  (:func:`analytic.kernels.strips.single_cut` for one,
  :func:`analytic.kernels.cuts.multi_cut` for several: a slab is the difference
  of two parts, judged by the sum of their error estimates), each slab's
  constant kernels taken once.
- *Cut pixels*: in isochrone coordinates (τ, φ) (see :mod:`analytic.kernels.isochrone`)
  the entry is ∫ κ_n(τ) G(τ) dτ with G(τ) = ∫_{isochrone ∩ pixel} a J dφ.
  G is smooth except where an isochrone passes a pixel corner, touches an
  edge (a square-root branch point), is born at x*, or passes a foot; the
  τ-range is cut there and at κ's breakpoints, and each piece is mapped
  by :func:`analytic.kernels.arcs.piece_map`, which turns a square-root end
  into an entire function and leaves a regular end alone. Each piece is
  integrated by the tensor rule in (τ, φ)
  (:func:`analytic.kernels.arcs.isochrone_rule`) under the adaptive driver,
- or, near x* or a foot, or where that rule fails, by adaptive φ-integrals
  inside adaptive τ-integrals (:func:`analytic.kernels.quadrature.integrate`, the
  *adaptive* route, the slowest and most general).

:func:`pair_entries` computes one (sensor, pixel) by any route, so that each fast route
can be checked against the adaptive one.

Each rule's error is estimated by the next rung of its Gauss ladder (and the
rungs' trend), and the value estimated is the one kept, relative to
∫ |integrand|; the quadrature asks for :data:`analytic.kernels.routes.SAFETY` x ``tolerance`` and
the inner integrals for a tenth of that. Every entry, hence every row's
largest, is accurate to ``tolerance``, and the achieved error follows the
tolerance (each entry's relative error 2 to 4 times below it from 1e-2 to
1e-8 on the default scene: benchmarks/bench_model.py), so that a looser
tolerance is faster.

Assembly (geometry -> entries) runs once, compiled and in parallel over
blocks of pixels x chunks of pairs (:mod:`analytic.operator.blocks`: each
short, so that Ctrl-C stops it within about a second), straight into CSR
(:mod:`analytic.kernels.assembly`): a counting pass, a filling pass, then the
general routes on the (pixel, pair)s the fill left
(:mod:`analytic.operator.general_routes`, a bounded batch at a time); the
result is a SciPy sparse matrix to apply, transpose and slice. Its memory is
proportional to nnz(A), counted exactly, per block and row, before anything
of that size is allocated, and estimated before any work on a large scene
(:func:`analytic.operator.blocks.assembly_bytes`: A, its row pointers and
counts and a bounded working set).
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np
import scipy.sparse

from ..attenuation import attenuation_code
from ..errors import ResourceError
from ..geometry import PointPairs, Rectangle, pair_table
from ..kernels import assembly
from ..kernels.assembly import Assembly, ImageGrid, Jobs, Slots, StepAssembly, auto_entries, pair_frame_of, pixel_box
from ..kernels.isochrone import rectangle_range
from ..kernels import routes
from ..kernels.routes import SAFETY, Route, TimeAxis, make_scratch, pixel_bins
from .blocks import ROUTE_SLOTS, Layout, assembly_bytes, assembly_layout, index_bytes, run_blocks
from .general_routes import left_pairs, progress_bar, run_left, run_route
from .offsets import offset_matrix, offset_plan, virtual_entries
from .cost import may_be_impractical, model_cost, refuse_impractical_illumination, refuse_unaffordable
from ..resources import available_memory
from ..scenes.scene_file import scene_of
from ..scenes.common import MAX_TOLERANCE, MIN_TOLERANCE, Sampling, Scene, check_heights, check_tolerance
from ..waveforms import Waveform, make_waveform

__all__ = ["system_matrix", "rectangle_matrix", "count_entries", "check_tolerance", "pair_entries",
           "METHODS", "QuadratureWarning", "MIN_TOLERANCE", "MAX_TOLERANCE"]

# The tolerance's range (analytic.scenes.common.MIN_TOLERANCE, MAX_TOLERANCE): from
# 1e-9 down, a few dozen τ-pieces near tangencies stop at the rounding of
# their geometry (a QuadratureWarning says so); below 1e-10 the quadrature no
# longer converges: on the default scene 1e-11 takes about 10 times the time
# of 1e-6 with ~500 such pieces, 1e-12 about 60 times with ~5000, and 1e-300
# would refine every piece to its limit.
#: (pixel, pair)s above which :func:`system_matrix` refuses, before counting, an A estimated not to fit in memory
#: (:func:`analytic.operator.cost.refuse_unaffordable`; below, the exact count takes less than the estimate).
_ESTIMATED_FROM = 2**20

#: Quadrature routes :func:`pair_entries` can be asked for ("auto": what assembly does).
METHODS = ("auto", "smooth", "isochrone", "adaptive", "strip")


class QuadratureWarning(RuntimeWarning):
    """Some quadrature pieces stopped refining before meeting the tolerance."""


class _Problem(NamedTuple):
    """What assembly needs, in compiled form."""

    pairs: np.ndarray       # analytic.geometry.PAIR_DTYPE records
    mode: int
    grid: ImageGrid
    axis: TimeAxis
    waveform: Waveform
    scales: np.ndarray      # (P,) factor of each pair's row block


def _problem(rectangle: Rectangle, pairs: PointPairs, sampling: Sampling, waveform: Waveform) -> _Problem:
    return _Problem(pair_table(rectangle, pairs), attenuation_code(pairs.attenuation),
                    ImageGrid(rectangle.width, rectangle.height, rectangle.pixels),
                    TimeAxis(sampling.start_opl, sampling.bin_width_opl, sampling.count), waveform,
                    np.asarray(pairs.scales, dtype=np.float64))


def _record(problem: _Problem, rtol: float, *, first_pass: bool = False) -> Assembly | StepAssembly:
    """The compiled kernels' record of the problem, their quadrature asked for ``rtol``.

    For the first pass of :func:`analytic.kernels.assembly.fill_block`, its type says whether S is a
    step function (the impulse), for which that pass is compiled without the moments route
    (:class:`~analytic.kernels.assembly.StepAssembly`); every other kernel takes an
    :class:`~analytic.kernels.assembly.Assembly` (one compile for both).
    """
    kind = StepAssembly if first_pass and problem.waveform.terms.degree == 0 else Assembly
    return kind(problem.pairs, problem.mode, problem.grid, problem.axis, problem.waveform.terms, float(rtol),
                problem.scales)


def _gib(size: float) -> str:
    return f"{size / 2**30:.3g} GiB"


def _layout(problem: _Problem, limit: int) -> Layout:
    return assembly_layout(len(problem.pairs), problem.axis.count, problem.grid.pixels, limit)


def _check_columns(pixels: int, needed: int, limit: int) -> None:
    """Refuse pixels whose column counts alone would not fit in ``limit`` (``needed``: the counts' bytes)."""
    if pixels ** 2 * 8 > limit:
        raise ResourceError(f"plane.pixels: {pixels}² pixels need {_gib(needed)} just to index "
                            f"A's columns, over the {_gib(limit)} limit; use fewer pixels")


def _check_layout(problem: _Problem, layout: Layout, limit: int) -> None:
    """Refuse, before allocating anything, what the column counts and the row pointers alone cannot fit."""
    pixels = problem.grid.pixels
    columns = pixels ** 2
    rows = len(problem.pairs) * problem.axis.count
    # counting: per-column non-zeros (a copy per pair chunk) and each block of pixels' count per row
    # (its slots later, in place); the rows' pointers
    chunks = len(layout.pair_bounds) - 1
    needed = chunks * columns * 8 + layout.pixel_blocks * rows * 8 + (rows + 1) * 8
    _check_columns(pixels, needed, limit)
    if needed > limit:
        raise ResourceError(f"sampling.count: {len(problem.pairs)} sensors x {problem.axis.count:,} "
                            f"bins need {_gib(needed)} just to index A's rows, over the {_gib(limit)} "
                            f"limit; use fewer bins")


class _Counts(NamedTuple):
    """What the counting pass found."""

    per_pixel: np.ndarray   # (M²,) entries of each column
    per_block: np.ndarray   # (B, rows) entries of each block of pixels in each row
    widest: np.ndarray      # (blocks,) most bins of one (pixel, pair) in each block


def _limit(memory_limit: int | None) -> int:
    return memory_limit if memory_limit is not None else available_memory() // 2


def _chunk_records(record, layout: Layout) -> list:
    """The record of each chunk of pairs: its pairs and scales (views), so that a block's kernels see only
    its pairs (their frames are built per block) and write only its rows."""
    bounds = layout.pair_bounds
    return [record._replace(pairs=record.pairs[bounds[c]:bounds[c + 1]], scales=record.scales[bounds[c]:bounds[c + 1]])
            for c in range(len(bounds) - 1)]


def _count(problem: _Problem, layout: Layout, limit: int, *, progress: bool = False) -> _Counts:
    """Count every block's entries in every row, refusing what would not fit in ``limit`` bytes."""
    _check_layout(problem, layout, limit)
    columns = problem.grid.pixels ** 2
    bins = problem.axis.count
    rows = len(problem.pairs) * bins
    chunks = len(layout.pair_bounds) - 1
    per_pixel = np.empty((chunks, columns), dtype=np.int64)
    per_block = np.zeros((layout.pixel_blocks, rows), dtype=np.int64)
    records = _chunk_records(_record(problem, 0.0), layout)

    def arguments(b):
        i, begin, end, first, last = layout.block(b)
        return records[b // layout.pixel_blocks], begin, end, per_pixel[b // layout.pixel_blocks], \
            per_block[i, first * bins:last * bins]

    bar = progress_bar(progress, layout.combinations().sum(), "counting A's entries", "pixel-pair")
    try:
        widest = run_blocks(assembly.count_block, arguments, layout.blocks, threads=layout.threads, bar=bar,
                            weights=layout.combinations())
    finally:
        if bar is not None:
            bar.close()
    counts = _Counts(per_pixel.sum(axis=0) if chunks > 1 else per_pixel[0], per_block,
                     np.asarray(widest, dtype=np.int64))
    nnz = int(counts.per_pixel.sum())
    needed = assembly_bytes(nnz, len(problem.pairs), bins, problem.grid.pixels, layout,
                            widest=int(np.max(counts.widest, initial=0)))
    if needed > limit:
        raise ResourceError(f"sampling: the system matrix would hold {nnz:,} entries "
                            f"({_gib(needed)} while it is assembled), over the {_gib(limit)} limit; "
                            f"use fewer bins (sampling.count / period) or fewer pixels")
    return counts


def count_entries(scene: Scene, *, memory_limit: int | None = None) -> np.ndarray:
    """Exact number of non-zeros of each column of A, counted before A is allocated.

    Parameters
    ----------
    scene : Scene
        The scene.
    memory_limit : int, optional
        Bytes A may use; default half the memory available now.

    Returns
    -------
    numpy.ndarray
        ``(M²,)`` int64: entries of column p (pixel p, every sensor).

    Raises
    ------
    ResourceError
        When A, or its index arrays alone, would not fit in ``memory_limit``
        (the message names the setting to reduce).
    """
    rectangle, pairs = scene.geometry()
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    problem = _problem(rectangle, pairs, scene.sampling, waveform)
    limit = _limit(memory_limit)
    return _count(problem, _layout(problem, limit), limit).per_pixel


def system_matrix(scene: Scene, *, tolerance: float | None = None, memory_limit: int | None = None,
                  progress: bool = False, statistics: dict | None = None) -> scipy.sparse.csr_array:
    """Assemble A for a scene.

    Parameters
    ----------
    scene : Scene, RelayWallScene, str or Path
        Geometry, sampling, illumination and attenuation; or the scene's file (TOML, or a tal YAML
        configuration).
    tolerance : float, optional
        Relative accuracy of every entry (hence relative to its row's largest
        entry), in [MIN_TOLERANCE, MAX_TOLERANCE). Default: ``scene.tolerance``
        (1e-6). The achieved error follows it (see the module docstring).
    memory_limit : int, optional
        Bytes A may use; see :func:`count_entries`.
    progress : bool
        Show a progress bar over the pixels.
    statistics : dict, optional
        Filled with ``pairs`` (the (pair, pixel) combinations whose light
        reaches a bin) and ``smooth_pairs`` (those the smooth route served;
        the others were cut by a kernel breakpoint or near a foot).

    Returns
    -------
    scipy.sparse.csr_array
        ``(K N, M²)`` float64; row k N + n, column r M + c; units of
        I x a_k x area x path length: W/sr x m⁻⁴ x m² x m = W m⁻¹ per unit
        reflectance (the source's intensity I in W/sr is included).

    Raises
    ------
    SceneError
        A tolerance outside the supported range (``model.tolerance``), a
        source or sensor too low to resolve (see
        :func:`analytic.scenes.common.check_heights`), or an illumination that would
        make A take impractically long (:func:`analytic.operator.cost.impractical_illumination`:
        the estimate and what to change), as every command refuses it.
    ResourceError
        An A that does not fit in memory (the need and the limit named): estimated before any work on a
        large scene, and after the exact count of its entries on every scene.

    Warns
    -----
    QuadratureWarning
        When some quadrature pieces stopped refining before the tolerance.

    Notes
    -----
    y = A f with f = ``image.ravel()`` gives y_k[n] = ∫ (g_k * s)(t) dt over
    bin n, with g_k(t) = ∫ f a_k δ(t - d_k) dx (docs/design.md section 2).
    """
    scene = scene_of(scene)
    tolerance = check_tolerance(scene.tolerance if tolerance is None else tolerance)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    if may_be_impractical(waveform, scene.sampling):
        refuse_impractical_illumination(scene)      # as every command does, before any work
    if scene.sensor_count * scene.pixels ** 2 > _ESTIMATED_FROM:
        _check_columns(scene.pixels, 8 * scene.pixels ** 2, _limit(memory_limit))
        refuse_unaffordable(model_cost(scene, memory_limit=memory_limit), memory_limit=memory_limit)
    rectangle, pairs = scene.geometry()
    return rectangle_matrix(rectangle, pairs, scene.sampling, waveform, statistics=statistics, tolerance=tolerance,
                            memory_limit=memory_limit, progress=progress)


def rectangle_matrix(rectangle: Rectangle, pairs: PointPairs, sampling: Sampling, waveform: Waveform, *,
                     tolerance: float = 1e-6, memory_limit: int | None = None,
                     progress: bool = False, statistics: dict | None = None) -> scipy.sparse.csr_array:
    """Assemble A for a rectangle seen through point pairs (:mod:`analytic.geometry`).

    Parameters
    ----------
    rectangle : Rectangle
        The Lambertian rectangle and its M x M pixels.
    pairs : PointPairs
        P pairs; pair k fills rows k N ... k N + N - 1.
    sampling : Sampling
        The N bins (each pair's added path length is binned with its paths).
    waveform : Waveform
        The illumination.
    tolerance : float
        Relative accuracy of every entry, in [MIN_TOLERANCE, MAX_TOLERANCE).
    memory_limit : int, optional
        Bytes A may use (default half the memory available).
    progress : bool
        Show a progress bar over the pixels.
    statistics : dict, optional
        Filled as :func:`system_matrix` says.

    Returns
    -------
    scipy.sparse.csr_array
        ``(P N, M²)`` float64, each pair's rows multiplied by its scale.
    """
    tolerance = check_tolerance(tolerance)
    problem = _problem(rectangle, pairs, sampling, waveform)
    limit = _limit(memory_limit)
    plan = offset_plan(problem) if statistics is None else None     # statistics: the general route's own
    if plan is not None:
        runs = virtual_entries(plan, lambda virtual: _assemble(virtual, tolerance, limit, progress, None))
        return offset_matrix(plan, runs, limit)
    return _assemble(problem, tolerance, limit, progress, statistics)


def _assemble(problem: _Problem, tolerance: float, limit: int, progress: bool, statistics: dict | None,
              tally: list | None = None):
    """A of ``problem`` by the general route (:func:`rectangle_matrix`); its pieces that stopped refining
    appended to ``tally`` if given, else a QuadratureWarning."""
    layout = _layout(problem, limit)
    counts = _count(problem, layout, limit, progress=progress)
    bins = problem.axis.count
    rows = len(problem.pairs) * bins
    columns = problem.grid.pixels ** 2
    # each block of pixels' first slot in each row: the row's start and the earlier blocks' entries there,
    # in place; as the blocks fill, each moves to its end (the next block's start)
    cursors = np.cumsum(counts.per_block, axis=0, out=counts.per_block)
    indptr = np.zeros(rows + 1, dtype=np.int64)
    indptr[1:] = cursors[-1]
    np.cumsum(indptr, out=indptr)
    nnz = int(indptr[-1])
    for block in range(cursors.shape[0] - 1, 0, -1):
        cursors[block] = cursors[block - 1]
    cursors[0] = 0
    cursors += indptr[:-1]
    index_type = np.int32 if index_bytes(nnz, rows, columns) == 4 else np.int64
    indices = np.empty(nnz, dtype=index_type)
    data = np.empty(nnz, dtype=np.float64)
    records = _chunk_records(_record(problem, SAFETY * tolerance, first_pass=True), layout)
    widest = counts.widest

    def arguments(b):
        i, begin, end, first, last = layout.block(b)
        return (records[b // layout.pixel_blocks], begin, end, widest[b],
                Slots(cursors[i, first * bins:last * bins], indices, data))

    bar = progress_bar(progress, layout.combinations().sum(), "system matrix", "pixel-pair")
    try:
        totals = np.array(run_blocks(assembly.fill_block, arguments, layout.blocks, threads=layout.threads, bar=bar,
                                     weights=layout.combinations()), dtype=np.int64).reshape(-1, 4)
    finally:
        if bar is not None:
            bar.close()
    failures, served, reached, left = (int(total) for total in totals.sum(axis=0))
    if left:
        more_failures, more_served = left_pairs(_record(problem, SAFETY * tolerance), layout, totals[:, 3],
                                                 cursors, indptr, indices, data, bins, progress=progress)
        failures += more_failures
        served += more_served
    del counts, cursors         # before the row pointers' copy and A's zeros: the peak stays the fill's
    if statistics is not None:
        statistics.update(pairs=reached, smooth_pairs=served)
    if tally is not None:
        tally.append(failures)
    elif failures:
        warnings.warn(f"{failures} quadrature pieces stopped refining before reaching "
                      f"tolerance {tolerance:g}", QuadratureWarning, stacklevel=3)
    nnz = _drop_zeros(data, indices, indptr)
    return scipy.sparse.csr_array((data[:nnz], indices[:nnz], indptr.astype(index_type, copy=False)),
                                  shape=(rows, columns))


def _drop_zeros(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray) -> int:
    """A's exact zeros removed in place, a window of rows at a time (no copy of A, as SciPy's
    ``eliminate_zeros`` makes when it drops half); the entries left, first in ``data`` and ``indices``."""
    if np.count_nonzero(data) == data.size:
        return data.size
    rows = indptr.size - 1
    kept, read, row = 0, 0, 0        # entries kept so far; where the window's entries start; its first row
    while row < rows:
        stop = max(row + 1, int(np.searchsorted(indptr[row + 1:], read + ROUTE_SLOTS, side="right")) + row)
        stop = min(stop, rows)
        end = int(indptr[stop])
        keep = data[read:end] != 0.0
        ends = np.cumsum(keep)[indptr[row + 1:stop + 1] - read - 1] if end > read else np.zeros(stop - row, np.int64)
        ends[indptr[row + 1:stop + 1] == read] = 0      # rows before the window's first entry keep none
        count = int(np.count_nonzero(keep))
        data[kept:kept + count] = data[read:end][keep]
        indices[kept:kept + count] = indices[read:end][keep]
        indptr[row + 1:stop + 1] = kept + ends
        kept, read, row = kept + count, end, stop
    return kept


def pair_entries(scene: Scene, sensor: int, pixel: int, *, method: str = "auto",
                 tolerance: float | None = None, taylor: bool = True) -> tuple[int, np.ndarray]:
    """The non-zero run of column ``pixel`` for one sensor, by a chosen quadrature route.

    For tests and diagnosis: each fast route can be checked against the
    adaptive one on the same pair.

    Parameters
    ----------
    scene : Scene
    sensor : int
        Sensor index k.
    pixel : int
        Column p = r M + c.
    method : {"auto", "smooth", "isochrone", "adaptive", "strip"}
        "auto": what :func:`system_matrix` does. "smooth": the tensor rule
        on the whole pixel (only where no kernel breakpoint crosses it and
        it is clear of the feet). "isochrone": the cut quadrature with the
        tensor rule in (τ, φ) on each τ-piece. "adaptive": the cut
        quadrature with adaptive φ-integrals inside adaptive τ-integrals.
        "strip": the cut pixel as slabs between isochrones with closed-form
        limits (:mod:`analytic.kernels.strips`; clear of the feet and of x* only).
    tolerance : float, optional
        As for :func:`system_matrix`.
    taylor : bool
        For the three named routes: through the pixel's (or τ-piece's)
        moments and the kernels' Taylor coefficients (:mod:`analytic.kernels.taylor`,
        what "auto" does), or with every kernel at every quadrature node
        (False), so that the two can be held to each other.

    Returns
    -------
    first : int
        The first bin n of the run.
    values : numpy.ndarray
        A[(k, first + i), p], units of A.

    Raises
    ------
    ValueError
        An unknown method, index out of range, or "smooth" where it does not
        apply or does not converge.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if not 0 <= sensor < scene.sensor_count or not 0 <= pixel < scene.pixels ** 2:
        raise ValueError(f"sensor {sensor} or pixel {pixel} out of range")
    tolerance = check_tolerance(scene.tolerance if tolerance is None else tolerance)
    rectangle, pairs = scene.geometry()
    problem = _problem(rectangle, pairs, scene.sampling,
                       make_waveform(scene.illumination, scene.sampling.bin_width_opl))
    record = _record(problem, SAFETY * tolerance)
    terms = problem.waveform.terms
    frame = pair_frame_of(problem.pairs, sensor, problem.mode)
    box = pixel_box(problem.grid, pixel)
    axis = problem.axis._replace(start_opl=problem.axis.start_opl - float(problem.pairs[sensor]["offset"]))
    low, high = rectangle_range(frame, box)
    run = pixel_bins(low, high, axis, terms.lead, terms.duration)
    jobs = Jobs(np.array([sensor]), np.array([pixel]), np.array([run.first]), np.array([0, run.bins]),
                np.arange(run.bins), np.array([low]), np.array([high]))
    data = np.zeros(max(run.bins, 1))
    failures = 0
    if method == "auto":
        # assembly's own run of bins (the tests hold it to the exact range's, which the other routes use)
        scratch = make_scratch(max(run.bins, 1))
        column, served, _ = auto_entries(frame, box, terms, axis, SAFETY * tolerance, data, scratch)
        failures = int(scratch.work.failures[0] + scratch.inner.failures[0] + scratch.moments.failures[0])
        run = column.run
        data[:run.bins] *= problem.scales[sensor]
        if not served:
            jobs = jobs._replace(firsts=np.array([run.first]), offsets=np.array([0, run.bins]),
                                 slots=np.arange(run.bins), lows=np.array([column.low]),
                                 highs=np.array([column.high]))
            failures += run_left(record, jobs, data, 1)[0]
    elif run.bins > 0:
        code, arcs = {"smooth": (routes.MOMENTS if taylor else routes.DIRECT, routes.AUTO_ARCS),
                      "strip": (routes.STRIP, routes.AUTO_ARCS), "isochrone": (routes.CUT, routes.SMOOTH_ARCS),
                      "adaptive": (routes.CUT, routes.ADAPTIVE_ARCS)}[method]
        outcomes, failures = run_route(Route(code, arcs, bool(taylor)), record, jobs, data, 1)
        if outcomes[0] == routes.DOES_NOT_APPLY:
            raise ValueError(f"the {method} rule does not apply to pixel {pixel}, sensor {sensor}: "
                             + ("x* or a foot is near" if method == "strip" else
                                "a kernel breakpoint crosses it or a foot is near"))
        if outcomes[0] == routes.NOT_CONVERGED:
            raise ValueError(f"the {method} rule did not converge on pixel {pixel}, sensor {sensor}")
    if failures > 0:
        warnings.warn(f"{failures} quadrature pieces stopped refining before reaching tolerance "
                      f"{tolerance:g}", QuadratureWarning, stacklevel=2)
    return run.first, data[:run.bins]
