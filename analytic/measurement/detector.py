"""Photon counting: the expected histogram a single-photon detector records from y, and a draw of it.

docs/design.md section 8. Per laser cycle, the photons reaching the
detector in bin n are Poisson with mean

    λ_n = photons · max(y_n, 0) + background,

(``photons`` signal photons per cycle per unit of y; ``background`` dark
and ambient photons per bin per cycle; a negative y, as the Butterworth
pulse's undershoot gives, brings no photons), independent across bins and
cycles. Integrated over ``cycles`` cycles:

- ``dead_time = "none"``: every photon is counted, c_n ~ Poisson(C λ_n),
  E c_n = C λ_n;
- ``dead_time = "cycle"``: the detector, armed at ``start_opl`` each cycle,
  records at most the first photon of the cycle (a time-correlated
  single-photon counter whose dead time outlasts the window; Coates,
  J. Phys. E 1 (1968) 878). Per cycle the bin of the first photon is n
  with probability p_n = e^{-Λ_n} (1 - e^{-λ_n}), Λ_n = Σ_{m<n} λ_m, and no
  photon arrives with probability e^{-Λ_N}; over C independent cycles the
  counts are multinomial, E c_n = C p_n. This is exact for one detection
  per cycle; photons after the first in a cycle are lost (pile-up), which
  skews the histogram toward early bins.

``1 - e^{-λ}`` is ``-expm1(-λ)`` (exact for the small λ of a low-flux
capture) and e^{-Λ_n} a running sum in the exponent, so every expected
count keeps its relative accuracy. :func:`coates_estimate` inverts the
dead-time histogram: λ̂_n = -log1p(-c_n / R_n), R_n = C - Σ_{m<n} c_m the
cycles still armed at bin n (the maximum-likelihood estimate), with its
delta-method variance c_n / (R_n (R_n - c_n)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DataError, SceneError
from ..values import _integer, _number, exact

__all__ = ["Detector", "DEAD_TIMES", "rates", "expected_counts", "detection_probabilities", "draw_counts",
           "sums_before", "coates_estimate", "excess_key", "MAX_CYCLES", "MAX_MEAN"]

DEAD_TIMES = ("none", "cycle")
#: Most laser cycles: counts stay exact integers in float64 and int64.
MAX_CYCLES = 2.0**53
#: Largest expected count a Poisson draw is asked for (NumPy's generator refuses means near 2^63).
MAX_MEAN = 1e15
_SEED_LIMIT = 2**32


@dataclass(frozen=True, kw_only=True)
class Detector:
    """A photon-counting detector: the scene's ``[detector]`` table (docs/design.md section 8).

    Parameters
    ----------
    photons : float
        Expected signal photons per laser cycle per unit of y (y in
        W m^-1 as the scene gives it), > 0. Required.
    background : float
        Expected dark and ambient photons per bin per cycle, >= 0. Default 0.
    cycles : float
        Laser cycles integrated, a whole number in [1, 2^53]. Default 1.
    dead_time : {"none", "cycle"}
        Every photon counted (Poisson), or at most the first per cycle
        (Coates). Default "none".
    seed : int
        Seed of the draw, 0 <= seed < 2^32. Default 0.
    """

    photons: float
    background: float = 0.0
    cycles: float = 1.0
    dead_time: str = "none"
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "photons", _number("detector.photons", self.photons, positive=True))
        object.__setattr__(self, "background", _number("detector.background", self.background, nonnegative=True))
        cycles = _number("detector.cycles", self.cycles, positive=True)
        if not (cycles.is_integer() and 1 <= cycles <= MAX_CYCLES):
            raise SceneError("detector.cycles", f"must be a whole number in [1, 2^53], got {exact(cycles)}")
        object.__setattr__(self, "cycles", cycles)
        if not isinstance(self.dead_time, str) or self.dead_time not in DEAD_TIMES:
            raise SceneError("detector.dead_time", f"must be one of {', '.join(map(repr, DEAD_TIMES))}, "
                                                   f"got {self.dead_time!r}")
        object.__setattr__(self, "seed", _integer("detector.seed", self.seed, minimum=0, maximum=_SEED_LIMIT - 1))

    def as_dict(self) -> dict:
        """The ``[detector]`` table (what scene files and meta.json hold)."""
        return {"photons": self.photons, "background": self.background, "cycles": self.cycles,
                "dead_time": self.dead_time, "seed": self.seed}


def rates(y, detector: Detector) -> np.ndarray:
    """λ_n = photons max(y_n, 0) + background: expected photons per bin per cycle, ``y.shape``.

    Parameters
    ----------
    y : array_like
        ``(..., N)`` transient, W m^-1 (the model's or a render's).
    detector : Detector
    """
    y = np.asarray(y, dtype=np.float64)
    if not np.all(np.isfinite(y)):
        raise ValueError("y must be finite")
    with np.errstate(over="ignore"):
        # beyond float64 the rate is inf: every cycle fires at once (dead time), or the count is refused (none)
        return detector.photons * np.maximum(y, 0.0) + detector.background


def sums_before(values) -> np.ndarray:
    """Σ_{m<n} values_m along the last axis, summed from the start, ``values.shape``.

    Λ_n of the photons (or counts) before bin n: ``cumsum(λ) - λ`` cancels when one λ dwarfs those before it
    (λ = 1e20 after λ = 1e-3 gives 0, not 1e-3).
    """
    lam = np.asarray(values, dtype=np.float64)
    before = np.zeros_like(lam)
    with np.errstate(over="ignore"):
        np.cumsum(lam[..., :-1], axis=-1, out=before[..., 1:])
    return before


def detection_probabilities(lam) -> tuple[np.ndarray, np.ndarray]:
    """Per cycle: (p_n, the probability of no detection) of a first-photon detector (Coates).

    Parameters
    ----------
    lam : array_like
        ``(..., N)`` expected photons per bin per cycle, >= 0.

    Returns
    -------
    p : numpy.ndarray
        ``(..., N)``, p_n = e^{-Λ_n} (1 - e^{-λ_n}), Λ_n = Σ_{m<n} λ_m.
    none : numpy.ndarray
        ``(...)``, e^{-Λ_N}; Σ p_n + none = 1.
    """
    lam = np.asarray(lam, dtype=np.float64)
    p = np.exp(-sums_before(lam)) * -np.expm1(-lam)
    with np.errstate(over="ignore"):
        none = np.exp(-np.sum(lam, axis=-1))
    # Σ p_n = 1 - e^{-Λ_N} exactly; the products' rounding (a few ulps each) must not lift it above 1
    total = np.sum(p, axis=-1, keepdims=True)
    p = np.where(total > 1.0, p * ((1.0 - 2.0**-48) / np.where(total > 1.0, total, 1.0)), p)
    return p, none


def expected_counts(y, detector: Detector) -> np.ndarray:
    """The expected histogram E c_n over the detector's cycles, ``y.shape`` (counts).

    Parameters
    ----------
    y : array_like
        ``(..., N)`` transient, W m^-1; bin 0 is where the detector is armed.
    detector : Detector

    Returns
    -------
    numpy.ndarray
        C λ_n (``dead_time = "none"``) or C e^{-Λ_n} (1 - e^{-λ_n})
        (``"cycle"``, summing to at most C); see the module docstring.

    Raises
    ------
    SceneError
        ``detector.photons`` (or ``detector.background`` when it alone is the cause: :func:`excess_key`):
        without dead time, an expected count beyond float64.
    """
    lam = rates(y, detector)
    if detector.dead_time == "cycle":
        return detector.cycles * detection_probabilities(lam)[0]
    with np.errstate(over="ignore"):
        counts = detector.cycles * lam
    if not np.all(np.isfinite(counts)):
        key = excess_key(detector, math.inf)
        raise SceneError(key, f"an expected count is beyond the range of float64 ({key.split('.')[1]} x cycles); "
                              f"lower {key.split('.')[1]} or cycles")
    return counts


def excess_key(detector: Detector, limit: float) -> str:
    """The key to name when an expected count passes ``limit``: ``detector.background`` when the background
    alone does (cycles x background per bin), else ``detector.photons``."""
    with np.errstate(over="ignore"):
        background = detector.cycles * detector.background
    return "detector.background" if not background < limit else "detector.photons"


def draw_counts(y, detector: Detector, rng: np.random.Generator | None = None) -> np.ndarray:
    """A histogram of counts drawn from the detector model, int64, ``y.shape``.

    Parameters
    ----------
    y : array_like
        ``(..., N)`` transient, W m^-1.
    detector : Detector
    rng : numpy.random.Generator, optional
        Default: ``numpy.random.default_rng(detector.seed)``.

    Returns
    -------
    numpy.ndarray
        Poisson(C λ_n) per bin (``"none"``), or per row a multinomial draw
        of C cycles over the N bins and "no detection", the latter dropped
        (``"cycle"``).

    Raises
    ------
    SceneError
        ``detector.photons`` (or ``detector.background``, :func:`excess_key`): an expected count beyond
        :data:`MAX_MEAN`.
    """
    rng = np.random.default_rng(detector.seed) if rng is None else rng
    lam = rates(y, detector)
    if detector.dead_time == "none":
        with np.errstate(over="ignore"):
            means = detector.cycles * lam
        if means.size and means.max() > MAX_MEAN:
            key = excess_key(detector, MAX_MEAN)
            raise SceneError(key, f"an expected count of {exact(means.max())} is beyond the {MAX_MEAN:g} a Poisson "
                                  f"draw supports; lower {key.split('.')[1]} or cycles")
        return rng.poisson(means).astype(np.int64)
    p, none = detection_probabilities(lam)
    rows = p.reshape(-1, p.shape[-1])
    counts = np.empty(rows.shape, dtype=np.int64)
    for i, (row, missed) in enumerate(zip(rows, none.reshape(-1))):
        # the "no detection" category last, and the probabilities made to sum to 1 exactly there
        probabilities = np.append(row, missed)
        probabilities /= math.fsum(probabilities)
        counts[i] = rng.multinomial(int(detector.cycles), probabilities)[:-1]
    return counts.reshape(p.shape)


def coates_estimate(counts, cycles: float) -> tuple[np.ndarray, np.ndarray]:
    """λ̂_n from a dead-time ("cycle") histogram, and its delta-method variance (Coates' correction).

    Parameters
    ----------
    counts : array_like
        ``(..., N)`` counts of first photons per bin over ``cycles`` cycles.
    cycles : float
        C.

    Returns
    -------
    estimate : numpy.ndarray
        λ̂_n = -log1p(-c_n / R_n), R_n = C - Σ_{m<n} c_m; inf where every
        armed cycle fired in bin n (R_n = c_n > 0), NaN where no cycle
        was armed (R_n = 0).
    variance : numpy.ndarray
        c_n / (R_n (R_n - c_n)) (the binomial's, through the logarithm).

    Raises
    ------
    DataError
        Negative or non-finite counts, cycles not finite and > 0, or more
        counts than cycles still armed.
    """
    counts = np.asarray(counts, dtype=np.float64)
    if np.any(counts < 0) or not np.all(np.isfinite(counts)):
        raise DataError("counts must be finite and >= 0")
    if not (math.isfinite(cycles) and cycles > 0):
        raise DataError(f"cycles must be finite and > 0, got {cycles!r}")
    armed = cycles - sums_before(counts)
    if np.any(counts > armed):
        raise DataError("more counts than cycles: the histogram cannot come from a first-photon detector")
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = counts / armed
        estimate = -np.log1p(-fraction)
        variance = fraction / (armed - counts)          # not c / (R (R - c)): R^2 overflows for huge C
    return estimate, variance
