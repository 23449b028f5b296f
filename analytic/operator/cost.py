"""What assembling A will cost, before it starts, and a refusal when the illumination makes it impractical.

The model (:mod:`analytic.operator.system`) integrates each (pixel, pair) over the
pixel's range of path lengths [d_lo, d_hi], cut at every kink b_i of the
waveform shifted to a bin edge t_n (τ = t_n - b_i), and fills every bin the
pixel's light reaches (τ + lead to τ + duration). Its work therefore grows
with three numbers per (pixel, pair) that this module counts exactly on a
sample of pixels and pairs, without assembling anything:

- the bins reached (the pulse's span over the period: a Gaussian of FWHM
  1000 m on 1 cm bins reaches 745,204 of them),
- the τ-pieces (a sampled response's every sample is a kink: 100,000 samples
  1 µm apart cut a 5 cm range of path lengths 50,000 times per bin edge),
- the kinks listed per pixel, (bins + 1) x kinks (the kernels list every
  kink at every edge before keeping those in range; that list is their
  scratch memory, per thread).

:func:`model_cost` turns them into seconds with constants measured on the
benchmark machine (AMD EPYC, per thread; see ``_SECONDS``; within 2-3 times
of the measured assembly of Gaussian, EMG and sampled responses from 0.3 s
to 70 s), and into bytes. :func:`refuse_impractical_illumination` refuses, in
one line stating both and what to change, a scene whose illumination makes A
take longer than :data:`LIMIT_SECONDS` with a single (pixel, pair) longer than
:data:`PAIR_LIMIT_SECONDS`, or whose kink lists would not fit in memory: the
cost that many pixels and pairs ask for is not refused here (it is the
scene's size, not its response).

The kernels could follow what the scene needs more closely (the fix is
theirs, :mod:`analytic.kernels`): list only the kinks whose shift falls in a
pixel's range (binary search, as :func:`_breakpoints` counts them), judge a
pixel smooth or cut per bin rather than for all its bins at once (an EMG's
lead, cut at 8.77 σ, makes every bin of a pixel take the slow cut route
when one bin's edge crosses it), and drop the pieces of a waveform no bin
can reach (:attr:`ModelCost.reach`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..binning import bin_index
from ..errors import ResourceError, SceneError
from ..resources import available_memory
from ..geometry import pair_table
from ..kernels.assembly import ImageGrid
from .blocks import assembly_bytes, assembly_layout, index_bytes
from .offsets import ENTRY_SECONDS, offset_work

__all__ = ["ModelCost", "model_cost", "impractical_illumination", "refuse_impractical_illumination",
           "refuse_unaffordable", "estimate_text", "LIMIT_SECONDS", "PAIR_LIMIT_SECONDS"]

#: A model estimated to take longer than this is refused when its illumination is the cause (below).
LIMIT_SECONDS = 180.0
#: ... that is, when one (pixel, pair) alone takes longer than this: the pixels and pairs are not the cause
#: (examples/spad.toml's EMG over 170 bins: 0.4 s per (pixel, pair) estimated at 8 x 8 pixels, 5.5 s in
#: all measured; the pieces per pixel, hence that cost, shrink with the pixels).
PAIR_LIMIT_SECONDS = 0.1
#: Seconds per unit of work on one thread, measured (benchmark machine): per bin of a cut τ-piece, by the
#: closed forms of the waveform's pieces (polynomials: nothing beyond the piece's own cost, its moments
#: serving every bin; exponentials; error functions, per term squared); per τ-piece; per bin of a smooth
#: pixel; per kink listed at a bin edge (and its share of the sort); per (pixel, pair).
_SECONDS = {"cut": (0.0, 3e-6, 10e-6), "piece": 10e-6, "smooth": 2e-6, "listed": 3e-9, "pixel": 20e-6}
#: Bytes of the kernels' scratch per kink listed at a bin edge (the value, its flag, the sort's order and copy).
_LISTED_BYTES = 26
#: Bytes per entry of the offset route's virtual A while it becomes runs (its COO copy, the sort, the runs).
_RUN_BYTES = 48
#: Pairs and pixels per side sampled (at most 8 x 12 x 12 (pixel, pair) ranges).
_SAMPLED_PAIRS, _SAMPLED_SIDE = 8, 12


@dataclass(frozen=True)
class ModelCost:
    """The estimated cost of assembling A, and what drives it.

    Attributes
    ----------
    seconds : float
        Wall time on this machine's threads (within a few times).
    pair_seconds : float
        Thread time of one (pixel, pair), on average.
    entries : float
        Non-zeros of A (bins reached, summed over pixels and pairs).
    memory : float
        Peak bytes of the assembly: A (12 or 16 per entry), its row pointers and counts, the working
        set of its blocks and every thread's kink lists (:func:`analytic.operator.blocks.assembly_bytes`).
    list_memory : float
        Bytes of the kink lists alone (every thread's), which the kernels allocate per pixel.
    bins : float
        Bins a (pixel, pair) reaches, on average.
    pieces : float
        τ-pieces a (pixel, pair) is cut into, on average.
    kinks : int
        The waveform's kinks.
    span : float
        The waveform's support, duration - lead, metres of path.
    threads : int
        Threads the assembly runs on.
    listing_share : float
        The share of ``seconds`` spent listing kinks (most of them out of reach of the pixel's range).
    reach : (float, float)
        The part of the waveform's support [t_0 - max d, t_N - min d] that any bin can reach from any
        sampled path length, metres (the rest changes no entry of A).
    offset_share : float or None
        Where the offset route runs (:mod:`analytic.operator.offsets`), the share of the (pixel, pair)s
        it computes; None for the general route.
    virtual_memory : float
        The offset route's peak bytes besides A (or y): its virtual pairs' assembly and runs.
    """

    seconds: float
    pair_seconds: float
    entries: float
    memory: float
    list_memory: float
    bins: float
    pieces: float
    kinks: int
    span: float
    threads: int
    listing_share: float
    reach: tuple
    offset_share: float | None = None
    virtual_memory: float = 0.0


def _family_cost(terms) -> float:
    """Seconds per bin of a cut τ-piece for the costliest closed form among the waveform's pieces.

    Error-function pieces cost in proportion to their terms squared (measured: a Gaussian's one term
    per piece 8 µs, an EMG's up to three 90 µs: more terms, and more of its Taylor series to keep).
    """
    from ..waveforms.pieces import ERRORFUNCTIONS, EXPONENTIALS, SIGMOIDS, TERM_SIZES

    families = np.asarray(terms.families)
    polynomial, exponential, special = _SECONDS["cut"]
    if np.any(families == ERRORFUNCTIONS):
        sizes = np.diff(np.asarray(terms.offsets))[families == ERRORFUNCTIONS] // TERM_SIZES[ERRORFUNCTIONS]
        return special * float(np.max(sizes)) ** 2
    return exponential if np.any((families == EXPONENTIALS) | (families == SIGMOIDS)) else polynomial


def _ranges(rectangle, pairs, pixels: int) -> np.ndarray:
    """``(S, 2)`` [d_lo, d_hi] + the pair's offset of a sample of (pixel, pair), metres."""
    from ..geometry import pair_table
    from ..kernels.formulas import LAMBERTIAN
    from ..kernels.isochrone import table_ranges

    count = len(pairs)
    chosen = np.unique(np.linspace(0, count - 1, min(count, _SAMPLED_PAIRS)).round().astype(int))
    side = np.unique(np.linspace(0, pixels - 1, min(pixels, _SAMPLED_SIDE)).round().astype(int))
    dx, dy = rectangle.width / pixels, rectangle.height / pixels
    columns, rows = np.repeat(side, side.size), np.tile(side, side.size)       # column-major, as before
    boxes = np.stack([columns * dx, (columns + 1) * dx, rows * dy, (rows + 1) * dy], axis=1)
    table = np.concatenate([pair_table(rectangle, pairs.block(int(index), int(index) + 1)) for index in chosen])
    # compiled whole: no Frame boxed for Python (analytic.kernels.isochrone.table_ranges)
    ranges = table_ranges(table, boxes, LAMBERTIAN) + table["offset"][:, None, None]
    return ranges.reshape(-1, 2)


def _bin_of(length: float, sampling) -> int:
    """The bin of a length (:func:`analytic.binning.bin_index`) clamped to [-1, N] (a pulse of 1e308 m ends
    past every bin, not at an overflow)."""
    with np.errstate(over="ignore", invalid="ignore"):
        index, _ = bin_index(np.float64(length), sampling.start_opl, sampling.bin_width_opl, sampling.count)
    if not index >= -1.0:
        return -1
    return sampling.count if index > sampling.count else int(index)


def _breakpoints(kinks: np.ndarray, start: float, width: float, first: int, bins: int, low: float,
                 high: float) -> int:
    """How many t_n - b_i lie in (low, high): t_n = start + n width, n = first ... first + bins, b_i the kinks
    (sorted); by binary search over the shorter of the two lists (the edges only built when they are)."""
    if kinks.size == 0 or not high > low:
        return 0
    if bins + 1 <= kinks.size:
        edges = start + width * np.arange(first, first + bins + 1, dtype=np.float64)
        inside = np.searchsorted(kinks, edges - low, side="left") - np.searchsorted(kinks, edges - high, side="right")
    else:
        # edges in (b_i + low, b_i + high): the indices between, clipped to the run (a kink at 1e308 m: none)
        with np.errstate(over="ignore", invalid="ignore"):
            lowest = np.maximum(np.floor((kinks + low - start) / width) + 1, first)
            highest = np.minimum(np.ceil((kinks + high - start) / width) - 1, first + bins)
            inside = np.where(np.isfinite(lowest) & np.isfinite(highest), highest - lowest + 1, 0)
    return int(np.sum(np.maximum(inside, 0)))


def model_cost(scene, *, memory_limit: int | None = None) -> ModelCost:
    """The estimated cost of assembling the scene's A (:mod:`analytic.operator.system`), from a sample of its ranges.

    Parameters
    ----------
    scene : Scene or RelayWallScene
    memory_limit : int, optional
        Bytes A may use (default half the memory available): how assembly cuts A into blocks follows it.

    Returns
    -------
    ModelCost

    Notes
    -----
    For each sampled (pixel, pair) with path lengths [d_lo, d_hi] (the pair's
    added legs included): the bins reached, n from ⌊(d_lo + lead - t_0)/T⌋ to
    ⌊(d_hi + duration - t_0)/T⌋ within the window; the cuts, the t_n - b_i in
    (d_lo, d_hi) (counted by binary search); the kinks listed, K (bins + 1).
    Seconds: Σ (cuts + 1) (c_piece + bins c_family) over cut ranges + Σ bins
    c_smooth over the others + Σ L log2 L c_list over the lists L + c_pixel per range,
    scaled to every (pixel, pair) and divided among the threads.
    """
    from .blocks import thread_count
    from ..waveforms import make_waveform

    sampling = scene.sampling
    waveform = make_waveform(scene.illumination, sampling.bin_width_opl)
    terms = waveform.terms
    kinks = np.sort(np.asarray(terms.starts, dtype=np.float64)[np.asarray(terms.kinks, dtype=bool)])
    rectangle, pairs = scene.geometry()
    pixels = int(scene.pixels)
    ranges = _ranges(rectangle, pairs, pixels)
    start, width, count = sampling.start_opl, sampling.bin_width_opl, sampling.count
    per_bin = _family_cost(terms)
    thread_seconds = listing_seconds = bins_total = pieces_total = largest_list = widest = 0.0
    for low, high in ranges:
        thread_seconds += _SECONDS["pixel"]
        first = max(0, _bin_of(low + waveform.lead, sampling))
        last = min(count - 1, _bin_of(high + waveform.duration, sampling))
        bins = max(last - first + 1, 0)
        if bins == 0:
            continue
        cuts = _breakpoints(kinks, start, width, first, bins, max(low, start - waveform.duration),
                            min(high, start + width * (first + bins) - waveform.lead))
        listed = kinks.size * (bins + 1)
        listing_seconds += _SECONDS["listed"] * listed * math.log2(listed + 2)
        if cuts:
            thread_seconds += (cuts + 1) * (_SECONDS["piece"] + per_bin * bins)
        else:
            thread_seconds += _SECONDS["smooth"] * bins
        bins_total += bins
        pieces_total += cuts + 1
        largest_list = max(largest_list, listed)
        widest = max(widest, bins)
    thread_seconds += listing_seconds
    threads = thread_count()
    samples = len(ranges)
    combinations = len(pairs) * pixels * pixels
    entries = combinations * bins_total / samples
    list_memory = _LISTED_BYTES * largest_list * threads
    limit = available_memory() // 2 if memory_limit is None else memory_limit
    memory = assembly_bytes(entries, len(pairs), count, pixels, assembly_layout(len(pairs), count, pixels, limit,
                                                                                threads=threads),
                            widest=int(widest), list_bytes=list_memory)
    reach = (start - float(ranges[:, 1].max()), start + width * count - float(ranges[:, 0].min()))
    seconds = combinations * thread_seconds / samples / threads
    share = virtual_memory = None
    work = offset_work(pair_table(rectangle, pairs), ImageGrid(rectangle.width, rectangle.height, pixels))
    if work is not None:
        # the distinct offsets' (pixel, pair)s assembled, then every entry of A summed or written from them
        groups, side = work
        share = groups * side**2 / combinations
        virtual = entries * share
        virtual_memory = (assembly_bytes(virtual, groups, count, side, assembly_layout(groups, count, side, limit,
                                                                                         threads=threads),
                                         widest=int(widest), list_bytes=list_memory)
                          + _RUN_BYTES * virtual + 16 * groups * side**2)
        seconds = seconds * share + entries * ENTRY_SECONDS / threads
        rows = len(pairs) * count
        memory = entries * (8 + index_bytes(int(entries), rows, pixels**2)) + 20 * (rows + 1) + virtual_memory
    return ModelCost(seconds=seconds,
                     pair_seconds=thread_seconds / samples, entries=entries, memory=memory,
                     list_memory=list_memory, bins=bins_total / samples, pieces=pieces_total / samples,
                     kinks=int(kinks.size), span=float(waveform.duration - waveform.lead), threads=threads,
                     listing_share=listing_seconds / thread_seconds, reach=reach, offset_share=share,
                     virtual_memory=virtual_memory or 0.0)


def _duration_text(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.2g} {unit}"
    return f"{seconds:.2g} s"


def estimate_text(cost: ModelCost) -> str:
    """"about 68 s and 0.13 GiB": the estimated wall time and peak memory of assembling A."""
    return f"about {_duration_text(cost.seconds)} and {cost.memory / 2**30:.2g} GiB"


def impractical_illumination(scene, cost: ModelCost | None = None) -> str | None:
    """Why the scene's illumination makes its model impractical, and what to change; None when it does not.

    Impractical: A estimated to take longer than :data:`LIMIT_SECONDS` with one (pixel, pair) alone
    longer than :data:`PAIR_LIMIT_SECONDS` (each pixel's integrals cut into thousands of pieces by a
    densely sampled response, or spread over the hundred thousand bins of a pulse far longer than
    the period), or the kernels' kink lists not fitting in half the memory available.
    """
    cost = model_cost(scene) if cost is None else cost
    memory_limit = available_memory() // 2
    slow = cost.seconds > LIMIT_SECONDS and cost.pair_seconds > PAIR_LIMIT_SECONDS
    if not slow and cost.list_memory <= memory_limit:
        return None
    illumination, sampling = scene.illumination, scene.sampling
    estimate = (f"the exact model would take about {_duration_text(cost.seconds)} on {cost.threads} threads and "
                f"{cost.memory / 2**30:.3g} GiB ({cost.entries:.3g} entries of A; half the memory available is "
                f"{memory_limit / 2**30:.3g} GiB)")
    # how much less work would do: the estimate brought to half the limit
    factor = max(cost.seconds / (0.5 * LIMIT_SECONDS), 1.0)
    spacing = _sample_spacing(illumination) if illumination.waveform == "sampled" else None
    if cost.listing_share > 0.5 or cost.list_memory > memory_limit:
        # the kernels list every kink at every bin edge a pixel reaches, most of them out of its range
        low, high = cost.reach
        detail = (f"its {cost.kinks:,} kinks (a sampled response's every sample is one) are listed at each of the "
                  f"{cost.bins:,.0f} bins a pixel reaches ({cost.list_memory / 2**30:.3g} GiB of lists), though only "
                  f"the response between {low:.6g} and {high:.6g} m can reach a bin of this window")
        change = ("keep only the samples in that span (the others change no bin), or resample the response "
                  f"at least {factor:.2g} times more coarsely")
    elif cost.pieces > cost.bins:
        # the kinks cut each pixel's range of path lengths into many pieces (work ~ pieces, ~ 1 / period^2)
        detail = (f"its {cost.kinks:,} kinks (a sampled response's every sample is one) cut each pixel's range of "
                  f"path lengths into {cost.pieces:,.0f} pieces on average")
        period = f"a sampling.period of at least {sampling.bin_width_opl * math.sqrt(factor):.2g} m"
        change = (f"resample the response at least {factor:.2g} times more coarsely (every {spacing * factor:.2g} m "
                  f"instead of {spacing:.2g} m), or use {period}" if spacing is not None else f"use {period}")
    else:
        # the pulse spreads each pixel's light over many bins (work ~ bins ~ 1 / period)
        detail = (f"the pulse spans {cost.span:.6g} m of path, so the light of each pixel reaches "
                  f"{cost.bins:,.0f} bins of {sampling.bin_width_opl:g} m on average")
        change = (f"use a sampling.period of at least {sampling.bin_width_opl * factor:.2g} m, or a shorter "
                  f"pulse")
    return f"{detail}: {estimate}; {change}"


def _sample_spacing(illumination) -> float:
    from ..waveforms.measured import sample_width_metres

    return sample_width_metres(illumination.sample_width, illumination.sample_width_ps)


#: Below these, an illumination cannot make A impractical (:func:`may_be_impractical` skips the estimate).
_FEW_KINKS, _FEW_BINS = 256, 256


def may_be_impractical(waveform, sampling) -> bool:
    """Whether a waveform's kinks or span over the period are many enough for :func:`impractical_illumination`
    to be worth its estimate (a few tens of milliseconds): the model's every call pays this test instead."""
    kinks = int(np.count_nonzero(np.asarray(waveform.terms.kinks)))
    span = float(waveform.duration - waveform.lead)
    return kinks > _FEW_KINKS or not span <= _FEW_BINS * sampling.bin_width_opl


def refuse_impractical_illumination(scene) -> ModelCost:
    """The scene's :class:`ModelCost`, or a refusal in one line when its illumination makes A impractical.

    Raises
    ------
    SceneError
        ``illumination.<its first key>``: :func:`impractical_illumination` says why, with the estimate
        (time, memory) and what to change.
    """
    cost = model_cost(scene)
    problem = impractical_illumination(scene, cost)
    if problem is not None:
        raise SceneError(_illumination_key(scene.illumination), problem)
    return cost


def _illumination_key(illumination) -> str:
    """The key a refusal of the illumination names: its response's samples, or its width."""
    for name in ("file", "samples", "tail", "fwhm", "width", "duration", "cutoff"):
        if getattr(illumination, name, None) is not None:
            return f"illumination.{name}"
    return "illumination.waveform"


def refuse_unaffordable(cost: ModelCost, *, memory_limit: int | None = None) -> None:
    """Refuse, before any work, an A whose assembly is estimated not to fit in memory.

    Parameters
    ----------
    cost : ModelCost
        The scene's estimate (:func:`model_cost`).
    memory_limit : int, optional
        Bytes A may use; default half the memory available now.

    Raises
    ------
    ResourceError
        Naming the estimate, the entries of A and the limit, and what to reduce. (The exact count of A's
        entries, which assembly makes first, is checked again: :func:`analytic.operator.system.count_entries`.)
    """
    limit = available_memory() // 2 if memory_limit is None else memory_limit
    if cost.memory > limit:
        raise ResourceError(f"sampling: the system matrix would take about {cost.memory / 2**30:.3g} GiB while it "
                            f"is assembled ({cost.entries:.3g} entries of A estimated), over the "
                            f"{limit / 2**30:.3g} GiB limit; use fewer sensors or scan points, fewer pixels or fewer "
                            f"bins (sampling.count / period)")
