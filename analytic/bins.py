"""Bins and their time kernels: which bins a path length reaches, and κ_n there (compiled).

A bin n of a :class:`TimeAxis` covers path lengths [t_n, t_n + T); light
leaving the rectangle at path length τ adds κ_n(τ) = S(t_{n+1} - τ) -
S(t_n - τ) to it, S the waveform's integral (:mod:`analytic.waveforms`).
Every route of :mod:`analytic.kernels` and :mod:`analytic.strips` reads
the bins and kernels through this module.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .kernel_cache import njit
from .waveforms.pieces import ROUNDING, WaveformTerms, piece_of, piece_value

__all__ = ["TimeAxis", "BinRun", "KernelProblem", "bin_edge", "bin_of", "pixel_bins", "kernel_cut", "kernel_values"]


class TimeAxis(NamedTuple):
    """Bins n = 0 ... count - 1 covering [start_opl + n T, start_opl + (n + 1) T), metres of path length.

    For a pair whose paths carry an added length (its ``offset``), the
    pair's axis starts that much earlier, so that the pair's geometric
    path d is binned as d + offset.
    """

    start_opl: float
    bin_width_opl: float
    count: int


class BinRun(NamedTuple):
    """The bins a (pair, pixel) reaches: ``first`` ... ``first + bins - 1`` (``bins`` 0: none)."""

    first: int
    bins: int


class KernelProblem(NamedTuple):
    """The time kernels κ_n of a run of bins (:func:`_kernels`)."""

    terms: WaveformTerms
    axis: TimeAxis
    run: BinRun


@njit(cache=True, error_model="numpy", inline="always")
def bin_of(tau, axis):
    """floor((τ - start) / period) clamped to [-1, count] in floating point (no integer overflow)."""
    index = np.floor((tau - axis.start_opl) / axis.bin_width_opl)
    if not index >= -1.0:       # also NaN
        return -1
    if index > axis.count:
        return axis.count
    return int(index)


@njit(cache=True, error_model="numpy", inline="always")
def pixel_bins(low, high, axis, lead, duration):
    """The :class:`BinRun` that light leaving a pixel at d in [low, high] reaches (``bins`` 0 if none).

    Light leaving at path length τ lands in [τ + lead, τ + duration] (the waveform's support).
    """
    first = max(0, bin_of(low + lead, axis))
    last = min(axis.count - 1, bin_of(high + duration, axis))
    if last < first:
        return BinRun(0, 0)
    return BinRun(first, last - first + 1)


@njit(cache=True, error_model="numpy")
def bin_edge(axis, n):
    """t_n, the lower edge of bin n, metres (as Sampling.edges computes it)."""
    return axis.start_opl + axis.bin_width_opl * n


@njit(cache=True, error_model="numpy", inline="always")
def kernel_cut(low, high, terms, axis, run):
    """Whether a breakpoint of some κ_n (t_n shifted back by a kink of the waveform) lies strictly inside (low, high)."""
    for n in range(run.first, run.first + run.bins + 1):
        edge = bin_edge(axis, n)
        for i in range(terms.starts.size):
            if terms.kinks[i] and low < edge - terms.starts[i] < high:
                return True
    return False


@njit(cache=True, error_model="numpy", inline="always")
def kernel_values(problem, tau, scale, values, noise):
    """values[i] = scale κ_{first + i}(τ), i < bins, and noise[i] a bound on its rounding.

    κ_n = S(t_{n+1} - τ) - S(t_n - τ), taken piece by piece
    (:func:`analytic.waveforms.kernel_scalar`): within one piece the
    constants cancel exactly, so a kernel far in a pulse's tail keeps its
    own relative accuracy; the rounding bound counts each term's size.
    """
    terms = problem.terms
    axis = problem.axis
    first = problem.run.first
    lower_u = bin_edge(axis, first) - tau
    lower_piece = piece_of(terms, lower_u)
    lower_value, lower_size = (0.0, 0.0) if lower_piece < 0 else piece_value(terms, lower_piece, lower_u)
    lower_constant = 0.0 if lower_piece < 0 else terms.constants[lower_piece]
    size = abs(scale) * ROUNDING
    for i in range(problem.run.bins):
        upper_u = bin_edge(axis, first + i + 1) - tau
        upper_piece = piece_of(terms, upper_u)
        upper_value, upper_size = (0.0, 0.0) if upper_piece < 0 else piece_value(terms, upper_piece, upper_u)
        upper_constant = 0.0 if upper_piece < 0 else terms.constants[upper_piece]
        constant = upper_constant - lower_constant
        values[i] = scale * (constant + (upper_value - lower_value))
        noise[i] = size * (abs(constant) + upper_size + lower_size)
        lower_value, lower_size, lower_constant = upper_value, upper_size, upper_constant
