"""Pieces shared by the estimator plugins: S(u), the attenuation, sample streams, points, the deposit.

Everything here is Dr.Jit code in float64 (``mi.Float64``, ``mi.UInt32``)
traced into the plugins' kernels:

- the illumination's cumulative S(u) = K_i + F_i(u) (:func:`constant_and_form`),
  from the pieces of :class:`analytic.waveforms.WaveformTerms` and the
  families' forms that NumPy (``Waveform.cumulative``) and Numba
  (``analytic.kernels.pieces.piece_value``) evaluate too
  (:func:`analytic.kernels.forms.piece_forms`);
- :func:`attenuation`: a_k(x) of docs/design.md section 2 (``lambertian``) at plane
  points, the twin of :func:`analytic.attenuation.attenuation`;
- :func:`sample_stream`: the per-sample PCG32 stream of (seed, global sample
  index), chunk-invariant;
- :func:`jittered_point`: the i-th of m jittered-stratified points of the
  unit square, in a coherent (Morton) order;
- :func:`replica_of`: which replica a sample belongs to, and its index there;
- :func:`deposit`: add w κ_n(τ) to the bins a path of length τ reaches.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from analytic.attenuation import LAMBERTIAN, attenuation_formula
from analytic.binning import bin_index
from analytic.scenes.common import Illumination
from analytic.waveforms import WaveformTerms, make_waveform
from analytic.waveforms.builders import illumination_options
from analytic.kernels import formulas as special
from analytic.kernels.forms import POLYNOMIAL, piece_forms

__all__ = ["constant_and_form", "attenuation", "attenuation_of_distances", "height_over_cube", "sample_stream",
           "jittered_point", "replica_of", "deposit", "reduce_mode", "per_thread_copies", "thread_copies", "block_copy", "opaque_u32", "opaque_f64", "is_diffuse", "time_axis_and_waveform"]


#: The attenuation of analytic.attenuation, with Dr.Jit's square root: one expression for every backend.
#: ``attenuation_of_distances(mode, source_height, source_squared, sensor_height, sensor_squared)``, 1/m⁴.
attenuation_of_distances = attenuation_formula(dr.sqrt)


def opaque_u32(value: int):
    """A UInt32 scalar the kernel reads from memory: changing it reuses the compiled kernel."""
    return dr.opaque(mi.UInt32, int(value))


def opaque_f64(value: float):
    """A Float64 scalar the kernel reads from memory (see :func:`opaque_u32`)."""
    return dr.opaque(mi.Float64, float(value))


# -- the waveform's cumulative --------------------------------------------------


def erfcx(v):
    """erfcx(v) = e^{v²} erfc(v) for v >= 0 in Dr.Jit Float64 (v < 0 clamped): Cody's three ranges of
    :mod:`analytic.kernels.special`, the expressions NumPy and Numba evaluate, chosen by ``dr.select``."""
    v = dr.maximum(v, 0.0)
    low = special.small(dr.minimum(v, special.SMALL), dr.exp)
    middle = special.middle(dr.clip(v, special.SMALL, special.LARGE), dr.exp)
    high = special.large(dr.maximum(v, special.LARGE), dr.exp)
    return dr.select(v <= special.SMALL, low, dr.select(v <= special.LARGE, middle, high))


def _piece_index(terms: WaveformTerms, u):
    """Index of the piece holding u (-1 where S = 0), as analytic.kernels.pieces.piece_of: the count of starts below u."""
    index = mi.Int32(-1)
    for start in terms.starts:
        index += dr.select(u > float(start), mi.Int32(1), mi.Int32(0))
    return index


#: The families' forms (:func:`analytic.kernels.forms.piece_forms`) with Dr.Jit's functions.
_FORMS = piece_forms(dr.exp, dr.cos, dr.sin, erfcx)


def _piece_form(terms: WaveformTerms, piece: int, u):
    """F_i(u) of one piece on every lane (u clipped to the piece, so lanes outside it stay finite)."""
    first, last = int(terms.offsets[piece]), int(terms.offsets[piece + 1])
    coefficients = [float(c) for c in terms.coefficients[first:last]]
    low = float(terms.starts[piece])
    high = float(terms.starts[piece + 1]) if piece + 1 < len(terms.starts) else float(terms.duration)
    x = dr.clip(u, low, max(high, low)) - float(terms.origins[piece])
    return mi.Float64(_FORMS[int(terms.families[piece])](coefficients, 0, len(coefficients), x)[0])


#: Above this many pieces of polynomials (a sampled response), a lane finds its piece by binary search and
#: gathers its coefficients, instead of evaluating every piece and selecting.
_GATHER_PIECES = 8


def _polynomial_tables(terms: WaveformTerms):
    """(starts, constants, origins, coefficients (piece-major, degree + 1 each)) as Dr.Jit arrays."""
    count = len(terms.starts)
    width = max(terms.degree, 0) + 1
    table = [0.0] * (count * width)
    for piece in range(count):
        first, last = int(terms.offsets[piece]), int(terms.offsets[piece + 1])
        for m in range(last - first):
            table[piece * width + m] = float(terms.coefficients[first + m])
    return (mi.Float64([float(v) for v in terms.starts]), mi.Float64([float(v) for v in terms.constants]),
            mi.Float64([float(v) for v in terms.origins]), mi.Float64(table), width)


def _gathered_constant_and_form(terms: WaveformTerms, u):
    """(K_i, F_i(u)) for polynomial pieces: the piece by binary search over the starts, its terms gathered."""
    starts, constants, origins, table, width = _polynomial_tables(terms)
    count = len(terms.starts)
    below = mi.UInt32(0)                    # how many starts lie below u (piece = below - 1)
    step = 1 << (count.bit_length() - 1)
    while step:
        candidate = below + step
        inside = candidate <= count
        start = dr.gather(mi.Float64, starts, dr.minimum(candidate, count) - 1, active=inside)
        below = dr.select(inside & (start < u), candidate, below)
        step >>= 1
    found = below > 0
    piece = dr.maximum(mi.Int32(below) - 1, 0)
    piece = mi.UInt32(piece)
    x = u - dr.gather(mi.Float64, origins, piece, active=found)
    powers = [dr.gather(mi.Float64, table, piece * width + m, active=found) for m in range(width)]
    form = mi.Float64(_FORMS[POLYNOMIAL](powers, 0, width, x)[0])
    constant = dr.gather(mi.Float64, constants, piece, active=found)
    return dr.select(found, constant, 0.0), dr.select(found, form, 0.0)


def constant_and_form(terms: WaveformTerms, u):
    """(K_i, F_i(u)) of each lane's piece (0, 0 where S = 0): S(u) = K_i + F_i(u)."""
    if terms.degree >= 0 and len(terms.starts) > _GATHER_PIECES:
        return _gathered_constant_and_form(terms, u)
    index = _piece_index(terms, u)
    constant, form = mi.Float64(0.0), mi.Float64(0.0)
    for piece in range(len(terms.starts)):
        inside = index == piece
        constant = dr.select(inside, float(terms.constants[piece]), constant)
        if terms.offsets[piece + 1] > terms.offsets[piece]:
            form = dr.select(inside, _piece_form(terms, piece, u), form)
    return constant, form


# -- geometry --------------------------------------------------------------------


def height_over_cube(x, y, point):
    """cos θ / d² = h / d³ of a point above the plane, seen from plane points, 1/m².

    Parameters
    ----------
    x, y : mi.Float64
        Plane points in the plane's frame (z = 0), metres.
    point : sequence of float
        (x, y, h) in the plane's frame, metres, h > 0 above it.
    """
    # Python floats: a NumPy scalar on the left of a Dr.Jit array would turn it into a NumPy array.
    px, py, height = (float(v) for v in point)
    squared = dr.square(x - px) + dr.square(y - py) + height * height
    return height / (squared * dr.sqrt(squared))


def attenuation(x, y, source, sensor, mode: int = LAMBERTIAN):
    """a_k(x) at plane points, 1/m⁴: :func:`analytic.kernels.formulas.attenuation_formula` in Dr.Jit.

    Parameters
    ----------
    x, y : mi.Float64
        Plane points in the plane's frame (z = 0), metres.
    source, sensor : sequence of float
        Positions (x, y, h) in the plane's frame, metres, h > 0 above it.
    mode : int
        :data:`analytic.attenuation.LAMBERTIAN` (physical, the default) or ``PAPER``.

    Returns
    -------
    mi.Float64
    """
    sx, sy, source_height = (float(v) for v in source)
    kx, ky, sensor_height = (float(v) for v in sensor)
    source_squared = dr.square(x - sx) + dr.square(y - sy) + source_height * source_height
    sensor_squared = dr.square(x - kx) + dr.square(y - ky) + sensor_height * sensor_height
    return attenuation_of_distances(mode, source_height, source_squared, sensor_height, sensor_squared)


# -- random numbers and sample points --------------------------------------------


def sample_stream(seed, index_low, index_high):
    """The PCG32 stream of one sample, a function of (seed, global sample index) only.

    Parameters
    ----------
    seed : mi.UInt32
        Render seed, 0 <= seed < 2^32 (opaque, so one kernel serves any seed).
    index_low, index_high : mi.UInt32
        Low and high 32-bit halves of each sample's global index.

    Returns
    -------
    mi.PCG32

    Notes
    -----
    ``sample_tea_32(seed, low)`` is a bijection of the 64-bit pair (seed, low),
    and ``high`` is added above bit 32 of the stream selector, so every
    (seed, index) pair gets its own stream; for indices below 2^32 they are
    the streams of Mitsuba's ``independent`` sampler.
    """
    v0, v1 = mi.sample_tea_32(seed, index_low)
    rng = mi.PCG32(dr.width(index_low))
    rng.seed(mi.UInt64(v0), mi.UInt64(v1) + (mi.UInt64(index_high) << 32))
    return rng


def _compact_even_bits(value):
    """Bits 0, 2, 4, ... of a UInt32 packed into bits 0, 1, 2, ... (Morton decoding)."""
    value = value & 0x55555555
    value = (value | (value >> 1)) & 0x33333333
    value = (value | (value >> 2)) & 0x0F0F0F0F
    value = (value | (value >> 4)) & 0x00FF00FF
    return (value | (value >> 8)) & 0x0000FFFF


def jittered_point(index, count, jitter_u, jitter_v):
    """Point ``index`` of ``count`` jittered-stratified points of [0, 1)², in Morton order.

    Parameters
    ----------
    index : mi.UInt32
        Position of each sample in its point set, 0 <= index < count.
    count : mi.UInt32
        Size m of the point set (1 <= m < 2^32).
    jitter_u, jitter_v : mi.Float64
        Independent uniform numbers in [0, 1), one pair per sample.

    Returns
    -------
    u, v : mi.Float64

    Notes
    -----
    m is split by its binary digits into blocks of 2^p points (largest
    first); a block is a 2^⌈p/2⌉ x 2^⌊p/2⌋ grid of equal cells, one jittered
    point per cell, cells visited in Morton (Z) order so that neighbouring
    samples lie in neighbouring cells (and mostly reach the same bins).
    Sample ``index`` lies in the block of size 2^p, p the highest bit where
    ``index`` and m differ, at position ``index mod 2^p``. Every point is
    uniform on the square, so any function's mean over the points is
    unbiased; within a block the cells stratify it.
    """
    bit = 31 - dr.lzcnt(count ^ index)                      # block of 2^bit points
    cell = index & ((mi.UInt32(1) << bit) - 1)
    columns_log = (bit + 1) >> 1
    rows_log = bit >> 1
    column = _compact_even_bits(cell)
    row = _compact_even_bits(cell >> 1)
    u = (mi.Float64(column) + jitter_u) * dr.exp2(-mi.Float64(columns_log))
    v = (mi.Float64(row) + jitter_v) * dr.exp2(-mi.Float64(rows_log))
    return u, v


def replica_of(position, replica_size):
    """(replica, index in it) of each sample, counted from the chunk's first replica.

    Parameters
    ----------
    position : mi.Float64
        Sample's offset from the start of the chunk's first replica (an
        integer below 2^53).
    replica_size : mi.Float64
        Samples per replica n (an integer).

    Returns
    -------
    replica, index : mi.UInt32
        Replica counted from the chunk's first one, and the sample's index in
        its replica (0 <= index < n).

    Notes
    -----
    ⌊(p + 1/2) / n⌋ in float64 is exact for p < 2^52 (the quotient is never
    within 2^-53 relative of an integer), and vector float division is far
    cheaper than integer division on CPUs.
    """
    replica = dr.floor((position + 0.5) / replica_size)
    return mi.UInt32(replica), mi.UInt32(position - replica * replica_size)


def is_diffuse(bsdf) -> bool:
    """A purely diffuse-reflecting BSDF: its value depends on wi only through its hemisphere."""
    if bsdf is None:
        return False
    flags = bsdf.flags()
    others = (mi.BSDFFlags.Glossy, mi.BSDFFlags.Delta, mi.BSDFFlags.Transmission)
    return (mi.has_flag(flags, mi.BSDFFlags.DiffuseReflection)
            and not any(mi.has_flag(flags, flag) for flag in others))


# -- the histogram ---------------------------------------------------------------


def reduce_mode():
    """How the deposit's scatter-adds are compiled on the active backend (chosen by measurement).

    LLVM: ``Auto``, which expands a histogram of up to ``dr.expand_threshold()``
    entries into one private copy per thread and adds without atomics (the
    fastest of Direct, Local and Expand on 2 cores; docs/benchmarks.md). CUDA:
    ``Local``: the 32 lanes of a warp hold neighbouring cells of the jittered
    grid (Morton order), mostly reach the same bin, and are reduced in the
    warp before one atomic.
    """
    return dr.ReduceMode.Local if dr.backend_v(mi.Float64) == dr.JitBackend.CUDA else dr.ReduceMode.Auto


#: Lanes per block when Dr.Jit's LLVM backend splits a launch of more than 2 x this x threads lanes
#: (drjit-core's ``jitc_llvm_block_size``); a smaller launch gets one block of count / threads per thread.
LLVM_BLOCK_LANES = 16384


def per_thread_copies(entries: int) -> int:
    """Copies of a histogram of ``entries`` float64 that a kernel keeps, one per LLVM thread.

    Dr.Jit's own ``Expand`` (the plane and path kernels' ``Auto``) keeps them
    up to ``dr.expand_threshold()`` entries, and the relay-wall kernel under
    the same limit (:func:`thread_copies`); 1 on CUDA or above the limit.
    """
    if dr.backend_v(mi.Float64) != dr.JitBackend.LLVM or entries > dr.expand_threshold():
        return 1
    return max(1, dr.thread_count())


def thread_copies(entries: int, replica_size: int) -> int:
    """The relay-wall kernel's copies of a histogram of ``entries`` float64 (see :func:`block_copy`).

    :func:`per_thread_copies` when a replica of ``replica_size`` samples is
    longer than a block, so that blocks running at once can add to one
    replica's rows; 1 when it is shorter (blocks running at once then hold
    different replicas, and each copy would cost a chunk 2 to 2.5 ms of
    zeroing, copying and summing).
    """
    return 1 if replica_size <= LLVM_BLOCK_LANES else per_thread_copies(entries)


def block_copy(lane, count: int, copies: int):
    """Which of ``copies`` histogram copies each lane of an LLVM launch of ``count`` lanes adds to.

    Its block's index mod ``copies``: Dr.Jit hands a launch's blocks to its
    threads in order, so the blocks that run at once are consecutive and,
    with a copy per thread, add to different copies. Atomic adds from two
    threads to one cache line make the line travel between the cores at
    each add, which multiplied the relay-wall kernel's time by up to 4 on 2
    free cores once a replica spanned consecutive blocks (docs/benchmarks.md).
    The blocks are taken as drjit-core cuts them: 16384 lanes, or about
    count / threads (drjit-core rounds it up to whole SIMD packets) for a
    launch of at most 2 x 16384 x threads lanes. The sums do not depend on
    it (the adds are atomic); only the speed does.

    Parameters
    ----------
    lane : mi.UInt32
        Lane index within the launch, 0 <= lane < count.
    count : int
        Lanes in the launch.
    copies : int
        :func:`thread_copies`.

    Returns
    -------
    mi.UInt32
        Copy index, 0 <= copy < copies.
    """
    if copies == 1:
        return mi.UInt32(0)
    threads = dr.thread_count()
    block = LLVM_BLOCK_LANES if count > 2 * LLVM_BLOCK_LANES * threads else -(-count // threads)
    return mi.UInt32(dr.floor((mi.Float64(lane) + 0.5) / opaque_f64(block))) % copies


def is_impulse(terms: WaveformTerms) -> bool:
    """Whether the waveform is the impulse (no duration): a path reaches its own bin only, with κ = 1."""
    return float(terms.duration) == float(terms.lead)


def deposit(histogram, row, weight, length, active, *, bins: int, start_opl: float, bin_width_opl: float,
            terms: WaveformTerms, taps: int, mode) -> None:
    """Add w κ_n(τ) to the bins n a path of length τ reaches, in one histogram row.

    Parameters
    ----------
    histogram : mi.Float64
        Flat accumulator; row r covers entries [r N, (r + 1) N).
    row : mi.UInt32 or int
        Row of each sample (replica and sensor).
    weight : mi.Float64
        w, the path's contribution per unit of the kernel.
    length : mi.Float64
        τ, the path's optical length, metres.
    active : mi.Bool
        Paths to deposit.
    bins, start_opl, bin_width_opl : int, float, float
        N bins [start_opl + n T, start_opl + (n + 1) T), metres.
    terms : WaveformTerms
        The illumination's closed form.
    taps : int
        Most consecutive bins of the window one path reaches
        (``Waveform.bins_touched(T, N)``: at most N).
    mode : drjit.ReduceMode
        Scatter strategy (:func:`reduce_mode`).

    Notes
    -----
    κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) with t_n = start_opl + n T. The bin
    of τ comes from :func:`analytic.binning.bin_index`, the model's own
    binning; the pulse spreads a path into that bin and the next ones, of
    which the loop visits the taps from the first inside the window.
    Neighbouring taps share an edge, so S is evaluated taps + 1 times.
    """
    first, _ = bin_index(length + terms.lead, start_opl, bin_width_opl, bins, floor=dr.floor)
    if is_impulse(terms):
        # The impulse: κ_n is 1 in τ's own bin and 0 elsewhere. (One tap alone does not say so: a
        # one-bin window caps every pulse at one tap, and that tap is still ∫_bin s.)
        inside = active & (first >= 0.0) & (first < bins)
        slot = mi.UInt32(dr.clip(first, 0.0, bins - 1.0)) + row * bins
        dr.scatter_reduce(dr.ReduceOp.Add, histogram, weight, slot, active=inside, mode=mode)
        return
    # From the first bin inside the window: a pulse longer than the window (taps capped at N) reaches it
    # from bins far before it, which no sample ever reads.
    start = dr.maximum(first, 0.0)
    lower = start_opl + start * bin_width_opl - length
    edge_constant, edge_form = constant_and_form(terms, lower)
    for tap in range(taps):
        upper_constant, upper_form = constant_and_form(terms, lower + (tap + 1) * bin_width_opl)
        n = start + tap
        inside = active & (n < bins)
        slot = mi.UInt32(dr.clip(n, 0.0, bins - 1.0)) + row * bins
        # κ_n = (K_j - K_i) + (F_j - F_i): within one piece the constants cancel exactly (a tail keeps its digits)
        kernel = (upper_constant - edge_constant) + (upper_form - edge_form)
        dr.scatter_reduce(dr.ReduceOp.Add, histogram, weight * kernel, slot, active=inside, mode=mode)
        edge_constant, edge_form = upper_constant, upper_form


def time_axis_and_waveform(props, plugin: str):
    """The bins and the illumination both integrators read from their properties, checked.

    Parameters
    ----------
    props : mi.Properties
        ``bins``, ``bin_width_opl`` (m), ``start_opl`` (m, default 0),
        ``waveform`` and its options, the plugin properties the waveform
        modules declare (:func:`analytic.waveforms.builders.illumination_options`;
        a sampled response's ``samples`` as one string of comma-separated
        numbers).
    plugin : str
        The plugin's name, for messages.

    Returns
    -------
    tuple
        (bins, start_opl, bin_width_opl, waveform).
    """
    if "bins" not in props or "bin_width_opl" not in props:
        raise ValueError(f"{plugin}: 'bins' and 'bin_width_opl' are required")
    bins = int(props.get("bins"))
    start_opl = float(props.get("start_opl", 0.0))
    bin_width_opl = float(props.get("bin_width_opl"))
    if bins < 1:
        raise ValueError(f"{plugin}: bins must be >= 1, got {bins}")
    if not (bin_width_opl > 0.0 and math.isfinite(bin_width_opl)):
        raise ValueError(f"{plugin}: bin_width_opl must be > 0, got {bin_width_opl}")
    if not math.isfinite(start_opl):
        raise ValueError(f"{plugin}: start_opl must be finite, got {start_opl}")
    try:
        options = illumination_options(lambda key: props.get(key) if key in props else None)
    except ValueError as error:
        raise ValueError(f"{plugin}: {error}") from None
    # Illumination validates names and values exactly as the scene file does.
    illumination = Illumination(waveform=props.get("waveform", "impulse"), **options)
    return bins, start_opl, bin_width_opl, make_waveform(illumination, bin_width_opl)
