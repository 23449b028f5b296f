"""Bins and their time kernels: which bins a path length reaches, and κ_n there (compiled).

A bin n of a :class:`TimeAxis` covers path lengths [t_n, t_n + T); light
leaving the rectangle at path length τ adds κ_n(τ) = S(t_{n+1} - τ) -
S(t_n - τ) to it, S the waveform's integral (:mod:`analytic.waveforms`).
Every route of :mod:`analytic.kernels` and :mod:`analytic.kernels.strips` reads
the bins and kernels through this module.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .cache import njit
from .formulas import bin_formula
from .pieces import ROUNDING, WaveformTerms, piece_of, piece_value
from .quadrature import implements, time_weight

__all__ = ["TimeAxis", "BinRun", "KernelProblem", "StepTable", "bin_edge", "bin_of", "pixel_bins", "kernel_cut",
           "kernel_values", "step_table", "step_cut", "step_kernels"]


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


#: :func:`.formulas.bin_formula`, compiled.
_bin_position = njit(cache=True, error_model="numpy", forceinline=True)(bin_formula(np.floor))


@njit(cache=True, error_model="numpy", forceinline=True)
def bin_of(tau, axis):
    """The bin of τ (:func:`.formulas.bin_formula`) clamped to [-1, count] in floating point (no integer overflow)."""
    index = _bin_position(tau, axis.start_opl, axis.bin_width_opl)
    if not index >= -1.0:       # also NaN
        return -1
    if index > axis.count:
        return axis.count
    return int(index)


@njit(cache=True, error_model="numpy", forceinline=True)
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


@njit(cache=True, error_model="numpy", forceinline=True)
def kernel_cut(low, high, terms, axis, run):
    """Whether a breakpoint of some κ_n (t_n shifted back by a kink of the waveform) lies strictly inside (low, high)."""
    for n in range(run.first, run.first + run.bins + 1):
        edge = bin_edge(axis, n)
        for i in range(terms.starts.size):
            if terms.kinks[i] and low < edge - terms.starts[i] < high:
                return True
    return False


@implements(time_weight, KernelProblem)
@njit(cache=True, error_model="numpy", forceinline=True)
def kernel_values(problem, tau, scale, values, noise):
    """values[i] = scale κ_{first + i}(τ), i < bins, and noise[i] a bound on its rounding.

    κ_n = S(t_{n+1} - τ) - S(t_n - τ), taken piece by piece
    (as :func:`analytic.waveforms.pieces.kernel_array` in NumPy): within one piece the
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


class StepTable(NamedTuple):
    """A waveform's pieces as plain arrays for the kernels' hot path (:mod:`analytic.kernels.assembly`).

    ``kinked``: the starts b_i where s or a derivative jumps (the kernels' breakpoints are the
    bin edges shifted back by them). ``steps``: whether S is a step function (every piece a
    constant, ``WaveformTerms.degree`` 0, as for the impulse); then S = K_i + F_i on piece i
    with ``starts``, ``constants`` K_i and ``forms`` F_i, and each κ_n is constant between
    breakpoints. Arrays read by compiled code through plain arguments, not through a record's
    fields, whose every read pays a reference count.
    """

    kinked: np.ndarray
    steps: bool
    starts: np.ndarray
    constants: np.ndarray
    forms: np.ndarray


@njit(cache=True, error_model="numpy")
def step_table(terms):
    """The :class:`StepTable` of a waveform's pieces."""
    kinked = terms.starts[terms.kinks].copy()
    steps = terms.degree == 0
    forms = np.zeros(terms.starts.size)
    for i in range(terms.starts.size):
        if steps and terms.offsets[i + 1] > terms.offsets[i]:
            forms[i] = piece_value(terms, i, 0.0)[0]    # a constant: its value anywhere
    return StepTable(kinked, steps, terms.starts.copy(), terms.constants.copy(), forms)


@njit(cache=True, error_model="numpy")
def step_cut(kinked, low, high, axis, run):
    """:func:`kernel_cut` from a :class:`StepTable`'s ``kinked`` starts."""
    for n in range(run.first, run.first + run.bins + 1):
        edge = bin_edge(axis, n)
        for i in range(kinked.size):
            if low < edge - kinked[i] < high:
                return True
    return False


@njit(cache=True, error_model="numpy")
def _step_of(starts, u):
    """:func:`analytic.kernels.pieces.piece_of` on plain arrays: the last piece starting below u, or -1.

    A step function has a few pieces (the impulse one): a scan from the end.
    """
    for piece in range(starts.size - 1, -1, -1):
        if starts[piece] < u:
            return piece
    return -1


@njit(cache=True, error_model="numpy")
def step_kernels(starts, constants, forms, axis, run, tau, scale, out):
    """out[i] = scale κ_{first + i}(τ), i < bins, for a step-function S (a :class:`StepTable` with ``steps``).

    κ_n = (K_j - K_i) + (F_j - F_i) at the bin's two edges, as :func:`kernel_values` and
    :func:`analytic.kernels.taylor.kernel_taylor` compute it, so the same numbers.
    """
    lower = _step_of(starts, bin_edge(axis, run.first) - tau)
    lower_constant = 0.0 if lower < 0 else constants[lower]
    lower_form = 0.0 if lower < 0 else forms[lower]
    for i in range(run.bins):
        upper = _step_of(starts, bin_edge(axis, run.first + i + 1) - tau)
        upper_constant = 0.0 if upper < 0 else constants[upper]
        upper_form = 0.0 if upper < 0 else forms[upper]
        out[i] = ((upper_constant - lower_constant) + (upper_form - lower_form)) * scale
        lower_constant, lower_form = upper_constant, upper_form
