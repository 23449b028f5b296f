"""The exact, sparse, time-binned system matrix A of docs/design.md section 2.

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx,   row k N + n, column r M + c.

The plane scene is one geometry of :mod:`analytic.geometry` (a rectangle and
one point pair per sensor); :func:`rectangle_matrix` assembles A for any
rectangle and any pairs, rows pair-major then bin. The compiled kernels that
compute one pair's entries over one pixel are :mod:`analytic.kernels`; this
module counts, allocates and fills.

How it is computed
------------------
κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) is smooth in τ except at the bin edges
t_n shifted by the waveform's breakpoints (its pieces' kinks). For each
(pixel, pair), with [d_lo, d_hi] the exact range of d over the pixel, one of
four routes:

- *Smooth pixels* (no breakpoint inside (d_lo, d_hi), and the pixel clear of
  the peaks of a under the source's and sensor's feet, see
  :data:`analytic.kernels.FOOT_CLEARANCE`): every entry a_k κ_n(d) is analytic on the pixel,
  integrated by the tensor Gauss ladder
  (:func:`analytic.quadrature.tensor_integrate`) with its error check; most
  pairs take this route, more of them at larger M.
- *Cut pixels by strips* (clear of the feet and of x*): the slabs between
  the kinks' isochrones, each a region with conic sides whose limits are
  closed-form (:mod:`analytic.strips`), by G_4 x G_4 judged by G_3 x G_3;
  when that rule does not meet the tolerance, the next route.
- *Cut pixels*: in isochrone coordinates (τ, φ) (see :mod:`analytic.isochrone`)
  the entry is ∫ κ_n(τ) G(τ) dτ with G(τ) = ∫_{isochrone ∩ pixel} a J dφ.
  G is smooth except where an isochrone passes a pixel corner, touches an
  edge (a square-root branch point), is born at x*, or passes a foot; the
  τ-range is cut there and at κ's breakpoints, and each piece is mapped
  by :func:`analytic.quadrature.piece_map`, which turns a square-root end
  into an entire function and leaves a regular end alone. Each piece is
  integrated by the tensor rule in (τ, φ)
  (:func:`analytic.quadrature.isochrone_rule`) under the adaptive driver,
- or, near x* or a foot, or where that rule fails, by adaptive φ-integrals
  inside adaptive τ-integrals (:func:`analytic.quadrature.integrate`, the
  *adaptive* route, the slowest and most general).

:func:`pair_entries` computes one (sensor, pixel) by any route, so that each fast route
can be checked against the adaptive one.

Each rule's error is estimated by the next rung of its Gauss ladder (and the
rungs' trend), and the value estimated is the one kept, relative to
∫ |integrand|; the quadrature asks for :data:`analytic.kernels.SAFETY` x ``tolerance`` and
the inner integrals for a tenth of that. Every entry, hence every row's
largest, is accurate to ``tolerance``, and the achieved error follows the
tolerance (each entry's relative error 2 to 4 times below it from 1e-2 to
1e-8 on the default scene: benchmarks/bench_model.py), so that a looser
tolerance is faster.

Assembly (geometry -> entries) runs once, compiled and in parallel over
pixels (all pairs of a pixel together, pixels dealt out in strides so the
threads stay balanced); the result is a SciPy sparse matrix to apply,
transpose and slice. Its memory is proportional to nnz(A), which is counted
exactly, per column, before anything of that size is allocated.
"""

from __future__ import annotations

import itertools
import warnings
from typing import NamedTuple

import numpy as np
import scipy.sparse
from numba import prange

from .attenuation import attenuation_code
from .errors import ResourceError
from .geometry import PointPairs, Rectangle, pair_table, plane_geometry
from .isochrone import PixelBox, pair_frame, rectangle_range
from .kernel_cache import njit
from .kernels import SAFETY, TimeAxis, make_scratch, pair_by_method, pair_entries as _pair_entries, pixel_bins
from .resources import available_memory
from .scene import MAX_TOLERANCE, MIN_TOLERANCE, Sampling, Scene, check_heights, check_tolerance
from .waveforms import Waveform, make_waveform

__all__ = ["system_matrix", "rectangle_matrix", "forward", "count_entries", "check_tolerance", "pair_entries",
           "METHODS", "QuadratureWarning", "MIN_TOLERANCE", "MAX_TOLERANCE"]

# The tolerance's range (analytic.scene.MIN_TOLERANCE, MAX_TOLERANCE): from
# 1e-9 down, a few dozen τ-pieces near tangencies stop at the rounding of
# their geometry (a QuadratureWarning says so); below 1e-10 the quadrature no
# longer converges: on the default scene 1e-11 takes about 10 times the time
# of 1e-6 with ~500 such pieces, 1e-12 about 60 times with ~5000, and 1e-300
# would refine every piece to its limit.
_BLOCKS_PER_THREAD = 16  # parallel jobs per thread; pixels are dealt to them in strides

#: Quadrature routes of :func:`pair_entries`, in the order of analytic.kernels' route codes.
METHODS = ("auto", "smooth", "isochrone", "adaptive", "strip")


class QuadratureWarning(RuntimeWarning):
    """Some quadrature pieces stopped refining before meeting the tolerance."""


class ImageGrid(NamedTuple):
    """The rectangle's pixels as compiled code sees them: sides (metres) and M."""

    width: float
    height: float
    pixels: int


@njit(cache=True, error_model="numpy")
def pixel_box(grid, p):
    """The :class:`~analytic.isochrone.PixelBox` of pixel p = r M + c (row r from the top), metres."""
    du = grid.width / grid.pixels
    dv = grid.height / grid.pixels
    r = p // grid.pixels
    c = p % grid.pixels
    return PixelBox(c * du, (c + 1) * du, (grid.pixels - r - 1) * dv, (grid.pixels - r) * dv)


@njit(cache=True, error_model="numpy")
def _pair_axis(axis, pair):
    """The pair's time axis: its added path length moves the bins' edges back."""
    return TimeAxis(axis.start_opl - pair.offset, axis.bin_width_opl, axis.count)


@njit(parallel=True, cache=True, error_model="numpy")
def _count(pairs, mode, grid, axis, lead, duration, per_pixel, widest):
    """per_pixel[p] = non-zeros of column p; widest[p] = most bins of one of its pairs."""
    for p in prange(grid.pixels * grid.pixels):
        box = pixel_box(grid, p)
        total = 0
        most = 0
        for k in range(pairs.shape[0]):
            frame = pair_frame(pairs[k], mode)
            low, high = rectangle_range(frame, box)
            bins = pixel_bins(low, high, _pair_axis(axis, pairs[k]), lead, duration).bins
            total += bins
            most = max(most, bins)
        per_pixel[p] = total
        widest[p] = most


@njit(parallel=True, cache=True, error_model="numpy")
def _fill(pairs, mode, grid, axis, terms, rtol, width, begin, end, indptr, rows, data, failures, smooth, lit):
    """Entries of columns begin ... end - 1 into their CSC slots (rows, data), in blocks dealt to the threads."""
    blocks = failures.shape[0]
    for block in prange(blocks):
        failed, served, reached = _fill_block(pairs, mode, grid, axis, terms, rtol, width, begin + block, end,
                                              blocks, indptr, rows, data)
        failures[block] += failed
        smooth[block] += served
        lit[block] += reached


@njit(cache=True, error_model="numpy")
def _fill_block(pairs, mode, grid, axis, terms, rtol, width, first, end, stride, indptr, rows, data):
    """Columns first, first + stride, ... < end.

    Returns (quadrature pieces failed, pairs the smooth route served, pairs whose light reaches a bin).

    One sequential function per block, so that the per-pair kernels inline into it (a real call per
    pair would pay a reference count on each of the scratch's arrays; inlined into the parallel loop
    itself they would be at the mercy of its transformations).
    """
    scratch = make_scratch(width)
    served = 0
    reached = 0
    for p in range(first, end, stride):
        box = pixel_box(grid, p)
        offset = indptr[p]
        for k in range(pairs.shape[0]):
            frame = pair_frame(pairs[k], mode)
            pair_axis = _pair_axis(axis, pairs[k])
            low, high = rectangle_range(frame, box)
            run = pixel_bins(low, high, pair_axis, terms.lead, terms.duration)
            if run.bins == 0:
                continue
            reached += 1
            for i in range(run.bins):
                rows[offset + i] = k * axis.count + run.first + i
            if _pair_entries(frame, box, low, high, terms, pair_axis, run, rtol, data[offset:offset + run.bins],
                             scratch):
                served += 1
            offset += run.bins
    return scratch.work.failures[0] + scratch.inner.failures[0] + scratch.moments.failures[0], served, reached


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


def _index_bytes(limit: int) -> int:
    return 4 if limit < 2**31 else 8


def _gib(count: float) -> str:
    return f"{count / 2**30:.3g} GiB"


def _check_layout(problem: _Problem, limit: int) -> None:
    """Refuse, before allocating anything, what the column and row pointers alone cannot fit."""
    pixels = problem.grid.pixels
    columns = pixels ** 2
    rows = len(problem.pairs) * problem.axis.count
    # counting: per-column non-zeros and widest pair; then CSC and CSR pointers
    needed = columns * (8 + 4) + (columns + 1) * 8 + (rows + 1) * 8
    if columns * 12 > limit or (columns + 1) * 8 > limit:
        raise ResourceError(f"plane.pixels: {pixels}² pixels need {_gib(needed)} just to index "
                            f"A's columns, over the {_gib(limit)} limit; use fewer pixels")
    if needed > limit:
        raise ResourceError(f"sampling.count: {len(problem.pairs)} sensors x {problem.axis.count:,} "
                            f"bins need {_gib(needed)} just to index A's rows, over the {_gib(limit)} "
                            f"limit; use fewer bins")


def _count_columns(problem: _Problem, memory_limit: int | None):
    """(non-zeros per column, most bins of one pair), refusing what would not fit."""
    limit = memory_limit if memory_limit is not None else available_memory() // 2
    _check_layout(problem, limit)
    columns = problem.grid.pixels ** 2
    per_pixel = np.empty(columns, dtype=np.int64)
    widest = np.empty(columns, dtype=np.int32)
    _count(problem.pairs, problem.mode, problem.grid, problem.axis, problem.waveform.lead,
           problem.waveform.duration, per_pixel, widest)
    nnz = int(per_pixel.sum())
    needed = _matrix_bytes(nnz, columns, len(problem.pairs) * problem.axis.count)
    if needed > limit:
        raise ResourceError(f"sampling: the system matrix would hold {nnz:,} entries "
                            f"({_gib(needed)} while it is assembled), over the {_gib(limit)} limit; "
                            f"use fewer bins (sampling.count / period) or fewer pixels")
    return per_pixel, int(widest.max()) if len(widest) else 0


def _matrix_bytes(nnz: int, columns: int, rows: int) -> int:
    """Peak bytes of assembly: CSC and CSR copies (data + index) and their pointers."""
    index = _index_bytes(max(nnz, rows, columns))
    return 2 * nnz * (8 + index) + (columns + 1) * 8 + (rows + 1) * 8 + columns * 12


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
    return _count_columns(_problem(rectangle, pairs, scene.sampling, waveform), memory_limit)[0]


def system_matrix(scene: Scene, *, tolerance: float | None = None, memory_limit: int | None = None,
                  progress: bool = False, statistics: dict | None = None) -> scipy.sparse.csr_array:
    """Assemble A for a scene.

    Parameters
    ----------
    scene : Scene
        Geometry, sampling, illumination and attenuation.
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
        A tolerance outside the supported range (``model.tolerance``), or a
        source or sensor too low to resolve (see
        :func:`analytic.scene.check_heights`).
    ResourceError
        An A that does not fit in memory (the need and the limit named).

    Warns
    -----
    QuadratureWarning
        When some quadrature pieces stopped refining before the tolerance.

    Notes
    -----
    y = A f with f = ``image.ravel()`` gives y_k[n] = ∫ (g_k * s)(t) dt over
    bin n, with g_k(t) = ∫ f a_k δ(t - d_k) dx (docs/design.md section 2).
    """
    tolerance = check_tolerance(scene.tolerance if tolerance is None else tolerance)
    rectangle, pairs = scene.geometry()
    return rectangle_matrix(rectangle, pairs, scene.sampling,
                            make_waveform(scene.illumination, scene.sampling.bin_width_opl), statistics=statistics,
                            tolerance=tolerance, memory_limit=memory_limit, progress=progress)


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
    per_pixel, width = _count_columns(problem, memory_limit)
    columns = rectangle.pixels ** 2
    shape = (len(pairs) * sampling.count, columns)
    indptr = np.zeros(columns + 1, dtype=np.int64)
    np.cumsum(per_pixel, out=indptr[1:])
    del per_pixel
    nnz = int(indptr[-1])
    index_type = np.int32 if _index_bytes(max(nnz, shape[0], shape[1])) == 4 else np.int64
    rows = np.empty(nnz, dtype=index_type)
    data = np.empty(nnz, dtype=np.float64)
    blocks = max(1, _BLOCKS_PER_THREAD * _threads())
    failures = np.zeros(blocks, dtype=np.int64)
    smooth = np.zeros(blocks, dtype=np.int64)
    lit = np.zeros(blocks, dtype=np.int64)
    chunks = min(100, columns) if progress else 1
    bounds = np.linspace(0, columns, chunks + 1).astype(np.int64)
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=columns, desc="system matrix", unit="pixel", leave=False)
    for begin, end in itertools.pairwise(bounds):
        _fill(problem.pairs, problem.mode, problem.grid, problem.axis, waveform.terms, SAFETY * tolerance, width,
              int(begin), int(end), indptr, rows, data, failures, smooth, lit)
        if bar is not None:
            bar.update(int(end - begin))
    if bar is not None:
        bar.close()
    if statistics is not None:
        statistics.update(pairs=int(lit.sum()), smooth_pairs=int(smooth.sum()))
    if failures.sum():
        warnings.warn(f"{int(failures.sum())} quadrature pieces stopped refining before reaching "
                      f"tolerance {tolerance:g}", QuadratureWarning, stacklevel=2)
    # each pair's constant factors (the source's intensity I for the plane) scale its rows exactly
    scales = problem.scales
    if np.all(scales == scales[0]):
        data *= scales[0]
    else:
        data *= scales[rows // sampling.count]
    matrix = scipy.sparse.csc_array((data, rows, indptr.astype(index_type)), shape=shape)
    del data, rows
    matrix = matrix.tocsr()
    matrix.eliminate_zeros()
    return matrix


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


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
        limits (:mod:`analytic.strips`; clear of the feet and of x* only).
    tolerance : float, optional
        As for :func:`system_matrix`.
    taylor : bool
        For the three named routes: through the pixel's (or τ-piece's)
        moments and the kernels' Taylor coefficients (:mod:`analytic.taylor`,
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
    terms = problem.waveform.terms
    frame = _frame_of(problem.pairs, sensor, problem.mode)
    box = pixel_box(problem.grid, pixel)
    low, high = rectangle_range(frame, box)
    run = pixel_bins(low, high, problem.axis, terms.lead, terms.duration)
    out = np.zeros(run.bins)
    outcome = pair_by_method(frame, box, low, high, terms, problem.axis, run, SAFETY * tolerance,
                             METHODS.index(method), bool(taylor), out, make_scratch(max(run.bins, 1)))
    if not outcome.applies:
        raise ValueError(f"the {method} rule does not apply to pixel {pixel}, sensor {sensor}: "
                         + ("x* or a foot is near" if method == "strip" else
                            "a kernel breakpoint crosses it or a foot is near"))
    if not outcome.converged:
        raise ValueError(f"the {method} rule did not converge on pixel {pixel}, sensor {sensor}")
    if outcome.failures > 0:
        warnings.warn(f"{outcome.failures} quadrature pieces stopped refining before reaching tolerance "
                      f"{tolerance:g}", QuadratureWarning, stacklevel=2)
    return run.first, out * problem.scales[sensor]


@njit(cache=True, error_model="numpy")
def _frame_of(pairs, k, mode):
    return pair_frame(pairs[k], mode)


def forward(scene: Scene, matrix=None) -> np.ndarray:
    """The model's noiseless samples y_k[n].

    Parameters
    ----------
    scene : Scene
        The scene (its reflectance image is f).
    matrix : sparse matrix, optional
        A, if already assembled.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64.
    """
    if matrix is None:
        matrix = system_matrix(scene)
    y = matrix @ scene.reflectance.ravel()
    return y.reshape(scene.sensor_count, scene.sampling.count)
