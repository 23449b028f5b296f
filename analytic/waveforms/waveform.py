"""The :class:`Waveform` every illumination builds: its pieces, breakpoints, energy and kernels."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from .pieces import WaveformTerms, cumulative_array, derivative_array, kernel_array

__all__ = ["Waveform", "Parameter", "KINDS"]

#: How a parameter's value is checked where the scene is built (:class:`analytic.scenes.common.Illumination`):
#: ``length`` a length > 0 in metres, ``coordinate`` a path length of either sign in metres, ``positive``
#: a number > 0 (bounds that depend on the period are the waveform's own), ``integer`` a whole number;
#: ``samples`` and ``file`` are left to the waveform's own check.
KINDS = ("length", "coordinate", "positive", "integer", "samples", "file")


@dataclass(frozen=True)
class Parameter:
    """One ``[illumination]`` key a waveform takes: what a waveform module declares in ``PARAMETERS``.

    Attributes
    ----------
    name : str
        The scene file's key (and an attribute of :class:`analytic.scenes.common.Illumination`).
    kind : str
        One of :data:`KINDS`: how the scene checks its value.
    unit : str
        Its unit in words, for the docs (``"m"``, ``"cycles/m"``, ``""``).
    default : str
        Its default in words, or ``"required"``.
    plugin : str or None
        The renderer plugins' property carrying it (``None``: the module's ``plugin_entries`` handles it).
    """

    name: str
    kind: str
    unit: str
    default: str
    plugin: str | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"parameter {self.name!r}: kind must be one of {KINDS}, got {self.kind!r}")


@dataclass(frozen=True, eq=False)
class Waveform:
    """An intensity waveform s(t) of unit peak amplitude (unit area for the impulse).

    Attributes
    ----------
    name : str
        The scene's ``[illumination] waveform``.
    terms : WaveformTerms
        S(u) = ∫_{-∞}^u s(t) dt as pieces (:mod:`analytic.waveforms.pieces`):
        what the model's kernels, NumPy, Numba and Dr.Jit evaluate.
    description : str
        Parameters in words, for reports and file headers.
    peak_time : float
        First time at which s reaches its peak 1, metres of path length (0
        for the impulse and the square).
    parameters : dict
        The scene's illumination parameters with their defaults resolved
        (what the metadata records); empty for the impulse.
    """

    name: str
    terms: WaveformTerms
    description: str
    peak_time: float = 0.0
    parameters: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Where s ends, metres of path length (0 for the impulse): S is constant beyond."""
        return self.terms.duration

    @property
    def lead(self) -> float:
        """Where s starts, metres of path length (<= 0; 0 for a causal pulse, negative for a centred one)."""
        return self.terms.lead

    @property
    def breakpoints(self) -> tuple:
        """Times in [0, duration] where s or a derivative jumps, metres (the pieces' kinks)."""
        return tuple(float(b) for b, kink in zip(self.terms.starts, self.terms.kinks) if kink)

    def cumulative(self, u) -> np.ndarray:
        """S(u) = ∫_{-∞}^u s(t) dt, u in metres of path length; metres (1 for the impulse)."""
        return cumulative_array(self.terms, u)

    def intensity(self, t) -> np.ndarray:
        """s(t), per unit peak (not defined for the impulse).

        Parameters
        ----------
        t : array_like
            Time after the pulse starts, metres of path length.
        """
        if self.name == "impulse":
            raise ValueError("the impulse has no pointwise intensity; use cumulative()")
        t = np.asarray(t, dtype=np.float64)
        inside = (t >= self.lead) & (t <= self.duration)
        # at a piece's start the piece before it holds t (pieces are (b_i, b_{i+1}]); at the first start, the first
        first = self.terms.starts[0]
        value = derivative_array(self.terms, np.where(t == first, np.nextafter(first, np.inf), t))
        return np.where(inside, value, 0.0)

    @property
    def energy(self) -> float:
        """∫ s(t) dt: metres (W/sr times path length per W/sr of peak), 1 for the impulse."""
        return float(self.cumulative(max(self.duration, 0.0) + 1.0))

    def kernel(self, tau, sampling) -> np.ndarray:
        """κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) for every bin: ``(N,) + tau.shape``.

        Parameters
        ----------
        tau : array_like
            Path length at the plane's exit, metres.
        sampling : analytic.Sampling
            The bins.
        """
        tau = np.asarray(tau, dtype=np.float64)
        edges = sampling.edges.reshape((-1,) + (1,) * tau.ndim)
        return kernel_array(self.terms, edges[:-1] - tau, edges[1:] - tau)

    def bins_touched(self, period: float, count: int | None = None) -> int:
        """How many consecutive bins one path length can contribute to.

        Parameters
        ----------
        period : float
            Bin width T, metres of path length.
        count : int, optional
            Bins in the window, N. A square of width 1e300 m touches
            ~1e300 / T bins, but only the window's N are ever sampled: with
            ``count`` the answer is at most N, a bound callers can loop
            over. Such a loop must start at the first bin inside the
            window, max(n(τ), 0), not at the path's own bin n(τ), which may
            lie far before it.

        Returns
        -------
        int
            ceil((duration - lead) / T) + 1 (1 for the impulse), computed
            exactly in rational arithmetic (no overflow, no rounding),
            capped at ``count`` when given.
        """
        if (isinstance(period, bool) or not isinstance(period, (int, float, np.integer, np.floating))
                or not math.isfinite(period) or not period > 0):
            raise ValueError(f"period must be a finite number > 0, got {period!r}")
        if count is not None and (isinstance(count, bool) or not isinstance(count, (int, np.integer))
                                  or count < 1):
            raise ValueError(f"count must be a whole number >= 1, got {count!r}")
        span = Fraction(self.duration) - Fraction(self.lead)
        touched = math.ceil(span / Fraction(period)) + 1 if span > 0 else 1
        return touched if count is None else min(touched, int(count))
