"""Sample points of the relay-wall plugin: Owen-scrambled Sobol points and a density following the hidden texture.

Two pieces :mod:`transient.nlos` traces into its kernel, both measured
there (docs/benchmarks.md, the relay-wall renderer):

- :func:`owen_sobol_point`: point i of a replica's set is the i-th point
  of the 2-D Sobol sequence, nested-uniform (Owen) scrambled with a hash
  (Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020), the
  scramble drawn per replica and technique. Each point is uniform on the
  unit square (the scramble is a bijection of a uniform 32-bit value,
  plus a uniform jitter below 2^-32), so every mean stays unbiased; the
  set is a (0, m, 2)-net for every power of two, stratified at every
  scale at once, where the jittered grid stratifies one.
- :class:`PixelDensity`: a density constant on each texel of the hidden
  texture, proportional to its reflectance plus 1 % of the mean (never 0,
  so any filtering of the texture stays covered), drawn by inverting the
  rows' then the row's columns' cumulative sums (which keeps the
  stratification of the unit-square point). Samples then land where the
  light is, instead of on the dark texels: less variance per sample where
  the reflectance varies (measured), none lost where it does not.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["owen_sobol_point", "reverse_bits", "sobol_second", "PixelDensity", "FLOOR"]

#: The density's floor, as a fraction of the mean reflectance: a texel of reflectance 0 keeps this share.
FLOOR = 0.01

# Burley's Laine-Karras-style permutation: adding a uniform seed, then x ^= x * even constant (each output
# bit depends on itself and the bits below it only: a nested scramble, and a bijection).
_PERMUTATION = (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6)

_LARGEST_BELOW_ONE = 1.0 - 2.0**-53


def reverse_bits(value):
    """The 32 bits of a UInt32 in reverse order."""
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF)):
        value = ((value >> shift) & mask) | ((value & mask) << shift)
    return (value >> 16) | (value << 16)


def sobol_second(index):
    """The second dimension of the Sobol sequence at ``index`` (UInt32).

    Its generator matrix is Pascal's triangle mod 2 (directions v_0 = 2^31, v_k = v_{k-1} xor v_{k-1} / 2):
    on the bit-reversed index, a sum over bit subsets, done by five xor-shifts.
    """
    value = reverse_bits(index)
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF), (16, 0x0000FFFF)):
        value ^= (value & mask) << shift
    return value


def _owen_scramble(value, seed):
    """A hash-based nested uniform (Owen) scramble of 32-bit fractions, bit 31 first."""
    value = reverse_bits(value) + seed
    for constant in _PERMUTATION:
        value ^= value * mi.UInt32(constant)
    return reverse_bits(value)


def owen_sobol_point(index, seed_u, seed_v, jitter_u, jitter_v):
    """Point ``index`` of a replica's Owen-scrambled 2-D Sobol set, in [0, 1)², float64.

    Parameters
    ----------
    index : mi.UInt32
        Position of each sample in its point set (its technique's share of a replica).
    seed_u, seed_v : mi.UInt32
        The set's scramble, one per coordinate (uniform 32-bit values, the same for every point of a set).
    jitter_u, jitter_v : mi.Float64
        Independent uniform numbers in [0, 1): the digits below 2^-32.

    Returns
    -------
    u, v : mi.Float64
    """
    scale = 2.0**-32
    u = (mi.Float64(_owen_scramble(reverse_bits(index), seed_u)) + jitter_u) * scale
    v = (mi.Float64(_owen_scramble(sobol_second(index), seed_v)) + jitter_v) * scale
    # (2^32 - 1 + jitter) rounds up to 2^32 for jitter within 2^-21 of 1: keep the point inside the square
    return dr.minimum(u, _LARGEST_BELOW_ONE), dr.minimum(v, _LARGEST_BELOW_ONE)


class PixelDensity:
    """A density on the hidden rectangle, constant on each texel, proportional to ρ + :data:`FLOOR` mean ρ.

    Matched to a texture read with nearest filtering (our scenes and exports set it). A bitmap
    filtered bilinearly in a user's XML stays unbiased (the floor keeps every density above zero)
    but can cost variance where a bright texel's light spreads onto dark neighbours.

    Parameters
    ----------
    reflectance : numpy.ndarray
        ``(H, W)`` the texture's reflectance at each texel's centre, texel (j, i) covering
        u in [i / W, (i + 1) / W), v in [j / H, (j + 1) / H).
    area : float
        The rectangle's area, m².
    """

    def __init__(self, reflectance: np.ndarray, area: float):
        weights = np.asarray(reflectance, dtype=np.float64)
        weights = np.maximum(weights, 0.0) + FLOOR * max(float(np.mean(np.maximum(weights, 0.0))), 1e-300)
        self.height, self.width = weights.shape
        total = weights.sum()
        rows = weights.sum(axis=1)
        self._row_cdf = mi.Float64(np.concatenate([[0.0], np.cumsum(rows)]) / total)
        self._row_pmf = mi.Float64(rows / total)
        columns = weights / rows[:, None]
        self._column_cdf = mi.Float64(np.concatenate([np.zeros((self.height, 1)), np.cumsum(columns, axis=1)],
                                                     axis=1).ravel())
        self._column_pmf = mi.Float64(columns.ravel())
        #: density per texel, 1/m²: its probability over its area
        self._density = mi.Float64((weights / total * (self.width * self.height / area)).ravel())

    def sample(self, u, v):
        """(u, v) in [0, 1)² to texture coordinates distributed by the density, and the density there (1/m²)."""
        row = _interval(self._row_cdf, 0, self.height, v)
        fraction_v = (v - dr.gather(mi.Float64, self._row_cdf, row)) / dr.gather(mi.Float64, self._row_pmf, row)
        start = row * (self.width + 1)
        column = _interval(self._column_cdf, start, self.width, u) - start
        cell = row * self.width + column
        fraction_u = ((u - dr.gather(mi.Float64, self._column_cdf, start + column))
                      / dr.gather(mi.Float64, self._column_pmf, cell))
        fraction_u = dr.clip(fraction_u, 0.0, _LARGEST_BELOW_ONE)
        fraction_v = dr.clip(fraction_v, 0.0, _LARGEST_BELOW_ONE)
        return ((mi.Float64(column) + fraction_u) / self.width, (mi.Float64(row) + fraction_v) / self.height,
                dr.gather(mi.Float64, self._density, cell))


def _interval(cdf, start, count: int, value):
    """The k in [start, start + count) with cdf[k] <= value < cdf[k + 1] (cdf[start] = 0, cdf[start + count] = 1),
    by binary search: the count of cdf[start + 1 .. start + count - 1] at or below value, plus start."""
    below = mi.UInt32(0)
    step = 1 << max(count - 1, 1).bit_length() - 1 if count > 1 else 0
    while step:
        candidate = below + step
        inside = candidate <= count - 1
        edge = dr.gather(mi.Float64, cdf, start + dr.minimum(candidate, count - 1), active=inside)
        below = dr.select(inside & (edge <= value), candidate, below)
        step >>= 1
    return start + below
