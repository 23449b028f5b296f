"""Directed tests: the data's scale and time offset against the stated ones, and the power they state.

χ² and max |z| (:func:`validation.judging.compare.compare_transients`) are
omnibus tests: they see any difference, but a small global scale error
spread over D bins moves χ²/D by only (its z)²/D. The directed tests look
along the two differences a convention makes (docs/design.md section 6):
data ≈ (1 + ε) s₀ y(t₀ + δ₀ + η) + added, with s₀ and δ₀ the stated scale
and offset (1 and 0 as given). Linearised at the stated point, the
residual r = y_data − y_stated ≈ ε u + η v with the two columns of the
model's Jacobian

    u = s₀ y(t₀ + δ₀)            (∂/∂ε: a relative scale error)
    v = s₀ ∂y/∂δ (t₀ + δ₀)       (∂/∂η: a time offset, metres of path),

and the weighted least-squares estimate (ε̂, η̂) = F⁻¹ Jᵀ W r, F = Jᵀ W J
the Fisher information of (ε, η), is tested against 0, each with its
share of the false-alarm rate (:func:`directed_tests`).

Standard errors:

- **per-bin errors given** (W = 1/se²): cov = F⁻¹ (independent bins), and
  t = ε̂ / se(ε̂) is normal, or Student's t on the errors' degrees of
  freedom when they come from replicas;
- **R replicas**: each replica r gets its own estimate e_r = F_r⁻¹ J W_r d_r
  of its deviation d_r from the stated model, with weights W_r from the
  second moments of the *other* replicas' deviations (leave one out:
  weights from the same replica would favour bins whose spread happened to
  come out small, and understate the error by 15-35 % at R = 16-4); then
  ε̂ = mean e_r and se = sd(e_r) / sqrt(R), whatever the correlation
  between bins (e_r is one number per replica), and t follows Student's t
  with R − 1 degrees of freedom. Flipping a replica's sign flips its e_r
  and leaves every weight unchanged, so under the hypothesis the e_r are
  uncorrelated and symmetric.

Power: an error of size d = t* se is flagged with probability about 1/2
(t is then centred on the limit t*): ``detectable`` = {"scale": t* se(ε̂),
"shift_opl": t* se(η̂)}, the smallest relative scale error and offset these
data flag half the time at the stated false-alarm rate. se falls as
1/sqrt(samples), so a test needing a detectable error d' of a render
whose detectable is d needs (d / d')² times its samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = ["DirectedTests", "directed_tests", "directed_columns", "DIRECTION_NAMES", "MIN_DIRECTED_BINS"]

#: The two directions, in the order of ``directions``' first axis.
DIRECTION_NAMES = ("scale", "shift_opl")

#: Fewest judged bins the two directions are estimated from (two parameters and a residual).
MIN_DIRECTED_BINS = 3

# 1 - ρ² of the two whitened directions below which the offset cannot be told from the scale
_DEGENERATE = 1e-10


@dataclass(frozen=True)
class DirectedTests:
    """The stated scale and offset tested along the model's two convention directions.

    Attributes
    ----------
    scale_error : float
        ε̂, the data's relative scale error against the stated scale
        (data ≈ (1 + ε̂) x stated).
    scale_stderr : float
        Its standard error.
    shift_opl : float or None
        η̂, metres of path to add to the stated offset (positive when the
        data read path lengths shorter still); None where the offset is not
        tested (it cannot be told from the scale).
    shift_stderr : float or None
        Its standard error.
    scale_t, shift_t : float or None
        ε̂ / se and η̂ / se.
    limit : float
        t*: each test rejects beyond |t| > t*, its share of the false-alarm
        rate split over both tails.
    dof : float
        Degrees of freedom of t (``inf``: normal).
    false_alarm_each : float
        The false-alarm rate of each directed test.
    stderr_from : {"replicas", "bins"}
        Standard errors from the replicas' own estimates, or from F⁻¹.
    """

    scale_error: float
    scale_stderr: float
    shift_opl: float | None
    shift_stderr: float | None
    scale_t: float
    shift_t: float | None
    limit: float
    dof: float
    false_alarm_each: float
    stderr_from: str

    @property
    def agrees(self) -> bool:
        """Neither the scale nor the offset is beyond its limit."""
        return abs(self.scale_t) <= self.limit and (self.shift_t is None or abs(self.shift_t) <= self.limit)

    @property
    def detectable(self) -> dict:
        """{"scale": relative error, "shift_opl": metres} flagged with probability 1/2 (None: not tested)."""
        return {"scale": self.limit * self.scale_stderr,
                "shift_opl": None if self.shift_stderr is None else self.limit * self.shift_stderr}

    @property
    def count(self) -> int:
        """Tests made: 2, or 1 where the offset cannot be told from the scale."""
        return 1 if self.shift_t is None else 2

    def text(self) -> str:
        """One clause for summaries: each estimate, its t and the limit."""
        parts = [f"scale {100 * self.scale_error:+.3g} ± {100 * self.scale_stderr:.2g} % of the stated "
                 f"(t = {self.scale_t:+.2f})"]
        if self.shift_t is not None:
            parts.append(f"offset {self.shift_opl:+.3g} ± {self.shift_stderr:.2g} m beyond it (t = {self.shift_t:+.2f})")
        reference = "normal" if math.isinf(self.dof) else f"Student t, {self.dof:g} dof"
        return f"Directed tests: {', '.join(parts)}; accept |t| ≤ {self.limit:.2f} ({reference})"

    def as_dict(self) -> dict:
        return {"agrees": self.agrees, "scale_error": self.scale_error, "scale_stderr": self.scale_stderr,
                "scale_t": self.scale_t, "shift_opl": self.shift_opl, "shift_stderr": self.shift_stderr,
                "shift_t": self.shift_t, "limit": self.limit, "dof": float(self.dof),
                "false_alarm_each": self.false_alarm_each, "stderr_from": self.stderr_from,
                "detectable": self.detectable}


def directed_columns(directions, stderr, judged) -> np.ndarray | None:
    """``(P, D)`` the directions tested, over the D judged bins: both; the scale alone where the offset
    cannot be told from it (a response within one bin); None where no test can be made (fewer than
    :data:`MIN_DIRECTED_BINS` judged bins, or no light of the model in them).

    Parameters
    ----------
    directions : array_like
        ``(2, K, N)`` u and v (see :func:`directed_tests`).
    stderr : numpy.ndarray
        ``(K, N)`` per-bin standard errors, > 0 where judged.
    judged : numpy.ndarray
        ``(K, N)`` bool.
    """
    if int(judged.sum()) < MIN_DIRECTED_BINS:
        return None
    columns = np.asarray(directions, dtype=np.float64)[:, judged]
    whitened = columns / stderr[judged]
    norms = np.linalg.norm(whitened, axis=1)
    if not norms[0] > 0:
        return None
    if not norms[1] > 0:
        return columns[:1]
    correlation = float(whitened[0] @ whitened[1]) / (norms[0] * norms[1])
    return columns if 1.0 - correlation**2 > _DEGENERATE else columns[:1]


def _estimates_from_replicas(columns, deviations) -> np.ndarray:
    """``(R, P)``: each replica's estimate with weights from the others' second moments (leave one out)."""
    count = deviations.shape[0]
    squares = deviations * deviations
    total = squares.sum(axis=0)
    estimates = np.empty((count, columns.shape[0]))
    for r in range(count):
        others = (total - squares[r]) / (count - 1)
        weights = np.divide(1.0, others, out=np.zeros_like(others), where=others > 0)
        information = (columns * weights) @ columns.T
        estimates[r] = np.linalg.lstsq(information, (columns * weights) @ deviations[r], rcond=None)[0]
    return estimates


def directed_tests(residual, stderr, columns, *, dof: float, false_alarm_each: float,
                   deviations=None) -> DirectedTests:
    """Test the stated scale and offset along the model's convention directions.

    Parameters
    ----------
    residual : numpy.ndarray
        ``(D,)`` y_data − y_stated over the judged bins.
    stderr : numpy.ndarray
        ``(D,)`` the data's standard error there (weights without ``deviations``).
    columns : numpy.ndarray
        ``(P, D)`` from :func:`directed_columns`: u = ∂y_stated/∂ε (the
        stated model without any ``added`` part) and, when P = 2,
        v = ∂y_stated/∂η (units of y per metre).
    dof : float
        Degrees of freedom of ``stderr`` (``inf``: normal); ignored with
        ``deviations`` (R − 1).
    false_alarm_each : float
        α of each test (two-sided).
    deviations : numpy.ndarray, optional
        ``(R, D)`` each replica's y_r − y_stated: standard errors from
        the replicas' own estimates (see the module's docstring).

    Returns
    -------
    DirectedTests
    """
    if deviations is not None:
        per_replica = _estimates_from_replicas(columns, deviations)
        count = per_replica.shape[0]
        estimate = per_replica.mean(axis=0)
        errors = per_replica.std(axis=0, ddof=1) / math.sqrt(count)
        dof, source = float(count - 1), "replicas"
    else:
        weights = 1.0 / stderr**2
        covariance = np.linalg.inv((columns * weights) @ columns.T)
        estimate = covariance @ ((columns * weights) @ residual)
        errors = np.sqrt(np.maximum(np.diag(covariance), 0.0))
        source = "bins"
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(errors > 0, estimate / errors, np.where(estimate == 0, 0.0, np.copysign(np.inf, estimate)))
    limit = float(stats.norm.isf(false_alarm_each / 2) if math.isinf(dof)
                  else stats.t.isf(false_alarm_each / 2, dof))
    shifted = columns.shape[0] == 2
    return DirectedTests(
        scale_error=float(estimate[0]), scale_stderr=float(errors[0]),
        shift_opl=float(estimate[1]) if shifted else None, shift_stderr=float(errors[1]) if shifted else None,
        scale_t=float(t[0]), shift_t=float(t[1]) if shifted else None, limit=limit, dof=float(dof),
        false_alarm_each=float(false_alarm_each), stderr_from=source)
