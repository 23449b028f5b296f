"""Pieces shared by the estimator plugins: S(u), the attenuation, sample streams, points, the deposit.

Everything here is Dr.Jit code in float64 (``mi.Float64``, ``mi.UInt32``)
traced into the plugins' kernels:

- :func:`cumulative`: the illumination's cumulative S(u), the closed form of
  :class:`analytic.waveforms.WaveformTerms` that NumPy
  (``Waveform.cumulative``) and Numba (``cumulative_scalar``) evaluate too;
- :func:`attenuation`: a_k(x) of DESIGN.md section 2 (``lambertian``) at plane
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

from analytic.binning import bin_index
from analytic.scene import Illumination
from analytic.waveforms import EXPONENTIAL_SUM, IMPULSE, SQUARE, WaveformTerms, make_waveform

__all__ = ["cumulative", "attenuation", "height_over_cube", "sample_stream", "jittered_point", "replica_of", "deposit",
           "reduce_mode", "opaque_u32", "opaque_f64", "is_diffuse", "time_axis_and_waveform"]


def opaque_u32(value: int):
    """A UInt32 scalar the kernel reads from memory: changing it reuses the compiled kernel."""
    return dr.opaque(mi.UInt32, int(value))


def opaque_f64(value: float):
    """A Float64 scalar the kernel reads from memory (see :func:`opaque_u32`)."""
    return dr.opaque(mi.Float64, float(value))


# -- the waveform's cumulative --------------------------------------------------


def cumulative(terms: WaveformTerms, u):
    """S(u) = ∫_{-∞}^u s(t) dt in Dr.Jit Float64, the closed form of ``terms``.

    Parameters
    ----------
    terms : WaveformTerms
        The waveform's closed form (``Waveform.terms``).
    u : mi.Float64
        Time after the pulse's start, metres of path length (c = 1).

    Returns
    -------
    mi.Float64
        S(u): dimensionless for the impulse (a step), metres for the others.

    Notes
    -----
    S(u) = 0 for u <= 0. For u > 0: IMPULSE 1; SQUARE min(u, duration);
    EXPONENTIAL_SUM, with v = min(u, duration),

        S = Σ_m series_m v^m                       (v < series_limit),
        S = constant + Σ_i e^{a_i v} (b_i cos ω_i v + c_i sin ω_i v)   (else),

    exactly as ``analytic.waveforms.cumulative_scalar``. The two terms of a
    complex-conjugate pole pair (ω and -ω) are evaluated as one (cos is even
    and sin odd): the same sum with half the transcendentals, which dominate
    the cost of a Butterworth render.
    """
    zero = mi.Float64(0.0)
    if terms.kind == IMPULSE:
        return dr.select(u > 0.0, mi.Float64(1.0), zero)
    if terms.kind == SQUARE:
        return dr.clip(u, 0.0, terms.duration)
    if terms.kind != EXPONENTIAL_SUM:
        raise ValueError(f"waveform kind {terms.kind}: no closed form for it")
    clipped = dr.clip(u, 0.0, terms.duration)
    value = mi.Float64(float(terms.constant))
    for decay, frequency, cos_coefficient, sin_coefficient in _conjugates_merged(terms):
        if frequency:
            term = cos_coefficient * dr.cos(frequency * clipped) + sin_coefficient * dr.sin(frequency * clipped)
        else:
            term = mi.Float64(cos_coefficient)
        value += dr.exp(decay * clipped) * term
    # Near u = 0 the exponentials cancel to S ~ u^order: the Taylor series there.
    series = mi.Float64(0.0)
    for coefficient in terms.series[::-1]:
        series = series * clipped + float(coefficient)
    value = dr.select(clipped < terms.series_limit, series, value)
    return dr.select(u <= 0.0, zero, value)


def _conjugates_merged(terms: WaveformTerms) -> list[tuple[float, float, float, float]]:
    """The terms (a, ω >= 0, b, c) of ``terms`` with each complex-conjugate pair added into one."""
    merged: dict[tuple[float, float], list[float]] = {}
    for a, w, b, c in zip(terms.decay, terms.frequency, terms.cos_coefficient, terms.sin_coefficient):
        a, w, b, c = float(a), float(w), float(b), float(c)
        if w < 0.0:
            w, c = -w, -c
        key = next((k for k in merged if math.isclose(k[0], a, rel_tol=1e-12)
                    and math.isclose(k[1], w, rel_tol=1e-12, abs_tol=1e-300)), (a, w))
        entry = merged.setdefault(key, [0.0, 0.0])
        entry[0] += b
        entry[1] += c
    return [(a, w, b, c) for (a, w), (b, c) in merged.items()]


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


def attenuation(x, y, source, sensor):
    """a_k(x) = cos θ_s cos θ_k / (π d_s² d_k²) at plane points, 1/m⁴ (``lambertian``).

    Parameters
    ----------
    x, y : mi.Float64
        Plane points in the plane's frame (z = 0), metres.
    source, sensor : sequence of float
        Positions (x, y, h) in the plane's frame, metres, h > 0 above it.

    Returns
    -------
    mi.Float64

    Notes
    -----
    With h the heights above the plane, cos θ = h / d, so
    a_k = h_s h_k / (π d_s³ d_k³): the expression of
    :func:`analytic.isochrone.attenuation_at` (Numba) and
    :func:`analytic.attenuation.attenuation` (NumPy).
    """
    return height_over_cube(x, y, source) * height_over_cube(x, y, sensor) / math.pi


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
    fastest of Direct, Local and Expand on 2 cores; see the README). CUDA:
    ``Local``: the 32 lanes of a warp hold neighbouring cells of the jittered
    grid (Morton order), mostly reach the same bin, and are reduced in the
    warp before one atomic.
    """
    return dr.ReduceMode.Local if dr.backend_v(mi.Float64) == dr.JitBackend.CUDA else dr.ReduceMode.Auto


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
    first, _ = bin_index(length, start_opl, bin_width_opl, bins, floor=dr.floor)
    if taps == 1:
        # The impulse: κ_n is 1 in τ's own bin and 0 elsewhere.
        inside = active & (first >= 0.0) & (first < bins)
        slot = mi.UInt32(dr.clip(first, 0.0, bins - 1.0)) + row * bins
        dr.scatter_reduce(dr.ReduceOp.Add, histogram, weight, slot, active=inside, mode=mode)
        return
    # From the first bin inside the window: a pulse longer than the window (taps capped at N) reaches it
    # from bins far before it, which no sample ever reads.
    start = dr.maximum(first, 0.0)
    lower = start_opl + start * bin_width_opl - length
    edge = cumulative(terms, lower)
    for tap in range(taps):
        upper = cumulative(terms, lower + (tap + 1) * bin_width_opl)
        n = start + tap
        inside = active & (n < bins)
        slot = mi.UInt32(dr.clip(n, 0.0, bins - 1.0)) + row * bins
        dr.scatter_reduce(dr.ReduceOp.Add, histogram, weight * (upper - edge), slot, active=inside, mode=mode)
        edge = upper


def time_axis_and_waveform(props, plugin: str):
    """The bins and the illumination both integrators read from their properties, checked.

    Parameters
    ----------
    props : mi.Properties
        ``bins``, ``bin_width_opl`` (m), ``start_opl`` (m, default 0),
        ``waveform`` and its options (``pulse_width``, ``cutoff``,
        ``duration``, ``order``), named as the scene file names them.
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
    options = {name: props.get(key) if key in props else None
               for name, key in (("width", "pulse_width"), ("cutoff", "cutoff"), ("duration", "duration"),
                                 ("order", "order"))}
    # Illumination validates names and values exactly as the scene file does.
    illumination = Illumination(waveform=props.get("waveform", "impulse"), **options)
    return bins, start_opl, bin_width_opl, make_waveform(illumination, bin_width_opl)
