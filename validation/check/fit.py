"""The best global scale and time offset of data against the exact model: weighted Gauss–Newton.

y_data[n] ≈ s y_model(t0 + δ)[n]: ``scale`` s is data / model and
``offset_opl`` δ what must be added to the data's start_opl for them to
match the model (docs/design.md section 5). The model is evaluated exactly at every
δ tried (:class:`ShiftedModel`); the standard errors come from the
replicas' jackknife when there are replicas, else from the per-bin errors
(:func:`fit_scale_offset`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from analytic.errors import DataError
from analytic.scenes.common import Sampling, Scene

__all__ = ["Fit", "ShiftedModel", "fit_scale_offset"]


@dataclass(frozen=True)
class Fit:
    """Best scale and time offset: y_data ≈ scale · y_model(start_opl + offset_opl).

    Attributes
    ----------
    scale, scale_stderr : float
        s = data / model (dimensionless) and its standard error.
    offset_opl, offset_stderr : float
        δ, metres of path length, and its standard error; positive when the
        data read path lengths short.
    iterations : int
        Gauss–Newton iterations used.
    converged : bool
        Whether the proposed or the accepted step fell below 1 % of the
        standard errors (False when the line search found no lower χ²).
    stderr_from : {"replicas", "bins"}
        Standard errors from the replicas' spread, or from per-bin errors
        assuming independent bins (see :func:`fit_scale_offset`).
    """

    scale: float
    scale_stderr: float
    offset_opl: float
    offset_stderr: float
    iterations: int
    converged: bool
    stderr_from: str

    def as_dict(self) -> dict:
        return {"scale": self.scale, "scale_stderr": self.scale_stderr, "offset_opl": self.offset_opl,
                "offset_stderr": self.offset_stderr, "iterations": self.iterations,
                "converged": self.converged, "stderr_from": self.stderr_from}


class ShiftedModel:
    """y_model with bin edges moved by δ: forward(scene) with start_opl + δ, memoised.

    Parameters
    ----------
    scene : Scene
        The scene whose model is shifted.
    model : numpy.ndarray, optional
        ``(K, N)`` ``evaluate(scene)`` when already computed (δ = 0).
    evaluate : callable, optional
        scene -> ``(K, N)``: what is shifted (default :func:`analytic.operator.matrix_free.forward`, the model;
        :func:`interop.mitransient.offset_model` judges against mitransient's estimator the same way).

    Attributes
    ----------
    evaluations : int
        Model evaluations made so far (each :meth:`__call__` at a new δ and each :meth:`widened` window).
    """

    def __init__(self, scene: Scene, model: np.ndarray | None = None, evaluate=None):
        self.scene = scene
        self.evaluate = evaluate
        self.cache = {} if model is None else {0.0: np.asarray(model, dtype=np.float64)}
        self.evaluations = 0

    def _at(self, start_opl: float, count: int) -> np.ndarray:
        from analytic.operator.matrix_free import forward   # Numba: loaded when a model is first needed

        sampling = Sampling(bin_width_opl=self.scene.sampling.bin_width_opl, start_opl=start_opl, count=count)
        self.evaluations += 1
        return (self.evaluate or forward)(self.scene.replace(sampling=sampling))

    def __call__(self, offset: float) -> np.ndarray:
        """``(K, N)`` y_model with every bin edge moved by +``offset`` metres of path length."""
        offset = float(offset)
        if offset not in self.cache:
            sampling = self.scene.sampling
            self.cache[offset] = self._at(sampling.start_opl + offset, sampling.count)
        return self.cache[offset]

    def widened(self, offset: float, reach: int) -> np.ndarray:
        """``(K, N + 2 reach)`` y_model over the window widened by ``reach`` bins at each end, every edge
        moved by +``offset`` metres: column ``reach + k + n`` is bin n moved by ``offset`` + k bins, so one
        evaluation gives the model at every whole-bin shift within ``reach`` (memoised)."""
        key = ("widened", float(offset), int(reach))
        if key not in self.cache:
            sampling = self.scene.sampling
            self.cache[key] = self._at(sampling.start_opl + float(offset) - reach * sampling.bin_width_opl,
                                       sampling.count + 2 * int(reach))
        return self.cache[key]


#: The starting offset is scanned over shifts of 1/SCAN_FRACTIONS of a bin.
SCAN_FRACTIONS = 4


def _scan_offset(data, sigma, mask, model_at, bin_width_opl: float) -> float:
    """Starting offset: the least χ² over shifts of a quarter bin, up to half the window either way.

    With a :class:`ShiftedModel`, the model is exact at every shift tried:
    one widened window per quarter-bin fraction (:meth:`ShiftedModel.widened`,
    SCAN_FRACTIONS evaluations in all) holds every whole-bin shift of it.
    Another callable is scanned on the interpolated as-given model instead:
    its cumulative sum is the integral C(t) at the bin edges, and
    y_n(δ) ≈ C(t_{n+1} + δ) - C(t_n + δ) with C linear between edges (exact
    at whole bins, for light inside the window). Either way Gauss–Newton then
    starts in the basin of the global optimum, for shifts of whole bins and
    for fractions alike, whatever the waveform.
    """
    count = data.shape[1]
    reach = max(1, math.ceil(count / 2))
    weights = np.where(mask, 1.0 / np.where(mask, sigma, 1.0) ** 2, 0.0)
    weighted_data = weights * data
    if isinstance(model_at, ShiftedModel):
        windows = [(j / SCAN_FRACTIONS, model_at.widened(j / SCAN_FRACTIONS * bin_width_opl, reach))
                   for j in range(SCAN_FRACTIONS)]
    else:
        model = model_at(0.0)
        edges = np.arange(-reach, count + reach + 1, dtype=np.float64)
        cumulative = np.concatenate([np.zeros((model.shape[0], 1)), np.cumsum(model, axis=1)], axis=1)
        at_edges = np.arange(count + 1, dtype=np.float64)
        windows = [(j / SCAN_FRACTIONS, np.diff(np.array([np.interp(edges + j / SCAN_FRACTIONS, at_edges, row)
                                                          for row in cumulative]), axis=1))
                   for j in range(SCAN_FRACTIONS)]
    best, best_chi2 = 0.0, math.inf
    for fraction, window in windows:
        for whole in range(-reach, reach):
            y = window[:, reach + whole:reach + whole + count]
            norm = float(np.sum(weights * y * y))
            if not norm > 0:
                continue
            scale = float(np.sum(weighted_data * y)) / norm
            chi2 = float(np.sum(weights * (data - scale * y) ** 2))
            shift = whole + fraction
            # ties (a flat χ²) go to the smaller shift
            if chi2 < best_chi2 or (chi2 == best_chi2 and abs(shift) < abs(best)):
                best, best_chi2 = shift, chi2
    return best * bin_width_opl


@dataclass(frozen=True)
class _Optimum:
    """Gauss–Newton's end point with what the standard errors need."""

    scale: float
    offset: float
    jacobian: np.ndarray      # (D, 2) whitened: ∂(s y / σ)/∂(s, δ) over the fitted bins
    residual: np.ndarray      # (D,) whitened: (y_data - s y_model) / σ
    sigma: np.ndarray         # (D,)
    iterations: int
    converged: bool


def _gauss_newton(data, sigma, mask, model_at, bin_width_opl: float, max_iterations: int) -> _Optimum:
    d, s_ = data[mask], sigma[mask]
    if d.size < 3:
        raise DataError("fit: fewer than 3 bins to fit a scale and an offset")
    step_h = 1e-3 * bin_width_opl
    limit = 0.5 * data.shape[1] * bin_width_opl

    def whitened(offset):
        return model_at(offset)[mask] / s_

    def chi2(scale, offset):
        return float(np.sum((d / s_ - scale * whitened(offset)) ** 2))

    def linearised(scale, offset):
        y = whitened(offset)   # evaluated already by the line search: one new model per iteration
        slope = (whitened(offset + step_h) - y) / step_h
        return np.column_stack([y, scale * slope]), d / s_ - scale * y

    offset = _scan_offset(data, sigma, mask, model_at, bin_width_opl)
    y = whitened(offset)
    scale = float(y @ (d / s_)) / float(y @ y) if float(y @ y) > 0 else 0.0
    if scale == 0.0:
        raise DataError("fit: the data hold no light where the model does (or none at all): no scale to fit; "
                        "check the file against the scene")
    current = chi2(scale, offset)
    converged, iterations = False, 0
    for iterations in range(1, max_iterations + 1):
        jacobian, residual = linearised(scale, offset)
        step, *_ = np.linalg.lstsq(jacobian, residual, rcond=None)
        errors = np.sqrt(np.maximum(np.diag(np.linalg.pinv(jacobian.T @ jacobian)), 0.0))
        step[1] = float(np.clip(step[1], -bin_width_opl, bin_width_opl))   # trust region: a bin per step
        small = bool(np.all(np.abs(step) <= 1e-2 * np.maximum(errors, 1e-300)))
        # Halve the step until χ² does not grow (Gauss–Newton can overshoot a kink).
        moved = None
        for _ in range(30):
            trial = (scale + float(step[0]), float(np.clip(offset + step[1], -limit, limit)))
            value = chi2(*trial)
            if value <= current * (1 + 1e-12):
                moved = np.array([trial[0] - scale, trial[1] - offset])
                scale, offset, current = trial[0], trial[1], value
                break
            step = step / 2
        # Converged too when the line search moves less than 1 % of an error: the model's own roughness
        # (its quadrature error varies with the offset) then misleads each new step by as much again, and
        # iterating on cost 30 models per iteration without moving (a relay-wall check took 217 s).
        if small or (moved is not None and bool(np.all(np.abs(moved) <= 1e-2 * np.maximum(errors, 1e-300)))):
            converged = True
            break
        if moved is None:                # no step of a halving lowers χ²: stuck, not converged
            break
    jacobian, residual = linearised(scale, offset)
    return _Optimum(scale, offset, jacobian, residual, s_, iterations, converged)


def fit_scale_offset(data, sigma, mask, model_at, bin_width_opl: float, *, replicas=None,
                     sigma_known: bool = True, max_iterations: int = 30) -> Fit:
    """Weighted least-squares scale and time offset of data against a shiftable model.

    Parameters
    ----------
    data : numpy.ndarray
        ``(K, N)`` y_data (the replicas' mean when ``replicas`` are given).
    sigma : numpy.ndarray
        ``(K, N)`` per-bin standard error (ones for an unweighted fit).
    mask : numpy.ndarray
        ``(K, N)`` bool: the bins fitted.
    model_at : callable
        δ (metres) -> ``(K, N)`` y_model with every bin edge moved by +δ.
    bin_width_opl : float
        T, metres: sets the derivative step and the largest step per iteration.
    replicas : numpy.ndarray, optional
        ``(R, K, N)`` the independent replicas ``data`` is the mean of: the
        standard errors then come from their spread (see Notes).
    sigma_known : bool
        Whether ``sigma`` is each bin's true standard error (True) or only
        relative weights, e.g. ones for a shape-only fit (False: the noise
        level is estimated from the residuals). Refused False with replicas.
    max_iterations : int
        Gauss–Newton iterations at most.

    Returns
    -------
    Fit

    Notes
    -----
    Minimises χ²(s, δ) = Σ_fitted ((y_data - s y_model(t0 + δ)) / σ)². The
    model is re-evaluated exactly at each δ (the scene's sampling with
    start_opl + δ; no interpolation), so the fit converges to the
    least-squares optimum of the exact model; ∂y/∂δ is a forward difference
    with step h = 10⁻³ T (one extra model per iteration), whose error
    (~10⁻³ relative from the step, ~10⁻³ from the model's 10⁻⁶ accuracy
    over h) only slows convergence and changes the standard errors by
    ~10⁻³ of themselves, never moves the optimum. The starting δ is the
    least χ² over shifts of a quarter bin up to half the window either way
    (:func:`_scan_offset`: with a :class:`ShiftedModel`, exact at each,
    from SCAN_FRACTIONS widened model evaluations), so the fit finds the
    global optimum's basin for data off by several bins of either sign.

    Standard errors. With replicas y_r: the delete-one jackknife,
    cov θ̂ = (R - 1)/R Σ_r (θ̂_(r) - θ̄)(θ̂_(r) - θ̄)ᵀ, each θ̂_(r) one
    Gauss–Newton step from θ̂ on the other R - 1 replicas' mean with their
    own per-bin weights (the model and its slope at θ̂ are reused). It holds
    whatever the correlation between bins, and it counts the noise of the
    weights themselves, which come from the same replicas (a fixed-weight
    formula would miss that the heaviest bins are those whose replicas
    happened to lie close together). Without them only per-bin errors are
    known: cov θ̂ = (JᵀJ)⁻¹ max(1, χ²_min / (D - 2)), exact for independent
    bins with correct errors and inflated when the fit is worse than they
    allow; with ``sigma_known=False``, (JᵀJ)⁻¹ χ²_min / (D - 2). A Monte
    Carlo renderer whose every sample lands in one bin has negatively
    correlated neighbouring bins: then the offset's error from
    bins alone is too small and the scale's too large; replicas give honest
    ones.
    """
    if replicas is not None and not sigma_known:
        raise ValueError("sigma_known: replicas give each bin's error; refused False with them")
    data = np.asarray(data, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    optimum = _gauss_newton(data, sigma, mask, model_at, bin_width_opl, max_iterations)
    jacobian = optimum.jacobian
    inverse = np.linalg.pinv(jacobian.T @ jacobian)
    if replicas is not None:
        replicas = np.asarray(replicas, dtype=np.float64)[:, mask]       # (R, D)
        count = replicas.shape[0]
        if count < 3:
            raise ValueError("replicas: the jackknife needs at least 3")
        model = jacobian[:, 0] * optimum.sigma                           # y_model(t0 + δ̂), fitted bins
        slope = jacobian[:, 1] * optimum.sigma / optimum.scale
        estimates = np.empty((count, 2))
        for r in range(count):
            rest = np.delete(replicas, r, axis=0)
            spread = rest.std(axis=0, ddof=1)
            weight = np.divide(1.0, spread, out=np.zeros_like(spread), where=spread > 0)
            left_out = np.column_stack([model * weight, optimum.scale * slope * weight])
            step, *_ = np.linalg.lstsq(left_out, (rest.mean(axis=0) - optimum.scale * model) * weight,
                                       rcond=None)
            estimates[r] = (optimum.scale, optimum.offset) + step
        deviations = estimates - estimates.mean(axis=0)
        covariance = deviations.T @ deviations * (count - 1) / count
        method = "replicas"
    else:
        residual = optimum.residual
        size = residual.size
        variance = float(residual @ residual) / (size - 2)
        # Known errors: (JᵀJ)⁻¹, inflated when the fit is worse than they allow.
        covariance = inverse * (max(1.0, variance) if sigma_known else variance)
        method = "bins"
    errors = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    return Fit(scale=float(optimum.scale), scale_stderr=float(errors[0]), offset_opl=float(optimum.offset),
               offset_stderr=float(errors[1]), iterations=optimum.iterations, converged=optimum.converged,
               stderr_from=method)

