"""What every reconstruction returns, the warnings it may raise, and the problem's checks and scaling.

Both regularisers (:mod:`.tikhonov`, :mod:`.tv`) solve a scaled copy of the
problem: A / a and y / c with a, c powers of two near max|A| and max|y|
(exact in floating point), so that data of any magnitude (1e-300 or 1e308)
gives the same image up to the factor c / a, never an overflow.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ..errors import DataError

__all__ = ["RankDeficiencyWarning", "NoiseLimitWarning", "RegularizationWarning", "Reconstruction", "Problem",
           "record_warning", "parse_rule"]


class RankDeficiencyWarning(RuntimeWarning):
    """The data fix well under what their measurements could: the regulariser fills the rest.

    Issued (see :mod:`.information`) when A's rank is at most half of
    min(measurements, unknowns) (the measurements repeat one another), when
    pixels are seen by no measurement, and, as :class:`NoiseLimitWarning`,
    when the noise hides most of what A fixes.
    """


class NoiseLimitWarning(RankDeficiencyWarning):
    """At their noise the data fix at most half of what A fixes without noise (singular values of A/σ
    above 1 against A's rank)."""


class RegularizationWarning(RuntimeWarning):
    """The λ rule could not do what it was asked (optimum at the edge of the range, no root)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class Reconstruction:
    """The result of :func:`reconstruct`.

    Attributes
    ----------
    image : numpy.ndarray
        ``(M, M)`` reconstructed reflectance (row 0 at the top), units of f.
    lam : float
        Chosen λ, weight of ||D f||² (units of y² per unit of f²; D has unit
        pixel spacing).
    rule : str
        ``"oracle"``, ``"gcv"``, ``"lcurve"``, ``"discrepancy"`` or ``"value"``.
    lambdas : numpy.ndarray
        The λ grid swept, ascending (one value for ``"value"``).
    criterion : numpy.ndarray
        The rule's criterion at each λ of ``lambdas``: squared image error
        (oracle), GCV function ||r||² / trace(I - H)² (gcv), signed curvature of
        (log ||r||, log ||D f||) (lcurve), ||r||² - m σ² (discrepancy);
        NaN for ``"value"``.
    residual_norms, seminorms : numpy.ndarray
        ||A f_λ - y|| and ||D f_λ|| at each λ of ``lambdas``.
    residual_norm, seminorm : float
        The same at the chosen λ.
    method : str
        ``"svd"`` or ``"lsqr"``.
    rank : int or None
        Numerical rank of A: how many numbers of the image noiseless data
        fix (svd method; the others when ``sigma`` was given and A fits a
        dense SVD; else None).
    effective_rank : int or None
        How many numbers of the image the data fix at their noise: singular
        values of A / σ above 1 (None without ``sigma``, or when A is too
        large for a dense SVD).
    sigma : float or None
        σ, units of y: the noise ``effective_rank`` counts against.
    degrees_of_freedom : float or None
        trace(H_λ) of the chosen fit, the unpenalised mean counted as one:
        how many numbers λ lets the data set (svd method; None otherwise).
    unknowns : int
        M².
    measurements : int
        m = K N, rows of A (all of them, zero rows included).
    seconds : float
        Wall time of the call, s (A's assembly excluded).
    stopping : str or None
        lsqr method: when its solves stopped (by the noise when σ was
        given: :mod:`analytic.inversion.iterative`) and the iterations they
        took; None for svd.
    warnings : tuple of str
        Messages of the warnings issued.
    """

    image: np.ndarray
    lam: float
    rule: str
    lambdas: np.ndarray
    criterion: np.ndarray
    residual_norms: np.ndarray
    seminorms: np.ndarray
    residual_norm: float
    seminorm: float
    method: str
    rank: int | None
    effective_rank: int | None = None
    sigma: float | None = None
    degrees_of_freedom: float | None = None
    unknowns: int
    measurements: int
    seconds: float
    stopping: str | None = None
    warnings: tuple = field(default_factory=tuple)


def record_warning(messages: list, message: str, category) -> None:
    """Issue a warning and keep its text for the result's ``warnings``."""
    messages.append(message)
    warnings.warn(message, category, stacklevel=4)


def parse_rule(rule, rules: tuple) -> float | None:
    """The numeric λ a rule names (None for a named rule); ValueError for anything else."""
    if isinstance(rule, (int, float, np.integer, np.floating)) and not isinstance(rule, bool):
        fixed = float(rule)
        if not (math.isfinite(fixed) and fixed > 0):
            raise ValueError(f"rule: a numeric λ must be finite and > 0, got {rule!r}")
        return fixed
    if rule not in rules:
        raise ValueError(f"rule: must be one of {', '.join(map(repr, rules))} or a positive number, "
                         f"got {rule!r}")
    return None


#: Powers of two that data and image scales must lie within (about 1e-150 .. 1e150): their squares stay normal.
SCALE_RANGE = (2.0**-500, 2.0**500)


def _power_of_two_near(value: float) -> float:
    return 1.0 if not value > 0 else float(2.0 ** round(math.log2(value)))


@dataclass(frozen=True, eq=False)
class Problem:
    """A checked reconstruction problem, scaled so that its numbers are near 1.

    Attributes
    ----------
    matrix : scipy.sparse array or numpy.ndarray
        A / a, ``(m, M²)``.
    y : numpy.ndarray
        y / c, ``(m,)``.
    pixels : int
        M.
    matrix_scale, data_scale : float
        a and c (powers of two): the image of the scaled problem times c / a
        is the image of the original one, and λ_original = a² λ_scaled for
        the squared-Laplacian penalty.
    live : numpy.ndarray of bool
        Rows of A that see some pixel; the others carry no information about f.
    seen : numpy.ndarray of bool
        Columns of A (pixels) that some row sees.
    """

    matrix: object
    y: np.ndarray
    pixels: int
    matrix_scale: float
    data_scale: float
    live: np.ndarray
    seen: np.ndarray

    @property
    def image_scale(self) -> float:
        """c / a: original image = image_scale x scaled image."""
        return self.data_scale / self.matrix_scale

    @classmethod
    def checked(cls, matrix, data, pixels) -> "Problem":
        """Validate (A, y, M) and scale them.

        Raises
        ------
        ValueError
            Naming the argument: shapes that disagree, a non-finite value.
        analytic.errors.DataError
            (a ValueError) Data, or the image they imply, beyond about
            1e±150: results and the λ rules' squared criteria could not be
            given back in the caller's units.
        """
        operator = isinstance(matrix, scipy.sparse.linalg.LinearOperator)
        if operator and not all(hasattr(matrix, name) for name in ("largest_entry", "scaled", "row_and_column_seen")):
            raise ValueError("matrix: a LinearOperator must also give largest_entry, scaled(factor) and "
                             "row_and_column_seen(), as analytic.operator.offset_operator.OffsetOperator does; "
                             "or give A as an array")
        if not (operator or scipy.sparse.issparse(matrix) or isinstance(matrix, np.ndarray)):
            matrix = np.asarray(matrix, dtype=np.float64)
        if isinstance(pixels, bool) or int(pixels) != pixels or pixels < 1:
            raise ValueError(f"pixels: expected a positive whole number, got {pixels!r}")
        pixels = int(pixels)
        rows, columns = matrix.shape
        if columns != pixels * pixels:
            raise ValueError(f"matrix: {columns} columns, expected pixels² = {pixels * pixels}")
        y = np.asarray(data, dtype=np.float64).ravel()
        if y.size != rows:
            raise ValueError(f"data: {y.size} samples, the matrix has {rows} rows")
        if not np.all(np.isfinite(y)):
            raise ValueError("data: contains NaN or infinity")
        values = (np.array([matrix.largest_entry]) if operator else
                  matrix.data if scipy.sparse.issparse(matrix) else matrix)
        if not np.all(np.isfinite(values)):
            raise ValueError("matrix: contains NaN or infinity")
        largest_entry = float(np.max(np.abs(values))) if values.size else 0.0
        largest_sample = float(np.max(np.abs(y))) if y.size else 0.0
        a, c = _power_of_two_near(largest_entry), _power_of_two_near(largest_sample)
        # Results go back to the caller's units: residuals by c, images by c / a, and the λ
        # rules' criteria by their squares, which must stay normal float64 numbers.
        if largest_entry > 0 and not SCALE_RANGE[0] <= a <= SCALE_RANGE[1]:
            raise ValueError(f"matrix: largest |entry| is {largest_entry:.3g}, outside [1e-150, 1e150] where "
                             f"λ (which scales with its square) stays a float64 number; rescale the matrix")
        if not SCALE_RANGE[0] <= c <= SCALE_RANGE[1]:
            raise DataError(f"data: largest |y| is {largest_sample:.3g}, outside [1e-150, 1e150] where "
                            f"the λ rules' squared residuals stay float64 numbers; rescale the data "
                            f"(y is linear in the source's intensity)")
        if not SCALE_RANGE[0] <= c / a <= SCALE_RANGE[1]:
            raise DataError(f"data: the image would be of order {c / a:.1g} (largest |y| {largest_sample:.3g} "
                            f"over A's largest entry {largest_entry:.3g}), outside [1e-150, 1e150] where its "
                            f"squares stay float64 numbers; rescale the data or the source's intensity")
        if operator:            # a power of two: the operator's entries stay exact
            scaled = matrix.scaled(a) if a != 1.0 else matrix
            live, seen = scaled.row_and_column_seen()
        else:
            scaled = matrix / a if a != 1.0 else matrix
            live = np.asarray(abs(scaled).sum(axis=1)).ravel() > 0
            seen = np.asarray(abs(scaled).sum(axis=0)).ravel() > 0
        if not live.any():
            raise ValueError("matrix: no row sees the plane (every entry is 0): nothing to reconstruct")
        return cls(scaled, y / c, pixels, a, c, live, seen)
