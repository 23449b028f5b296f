"""Judge photon counts against the exact model's expected histogram, and fit what a capture's claim got wrong.

A histogram of counts c (``(K, N)``, or any shape ending in the bins) is
judged against the expected histogram μ of the scene's model through its
detector (:func:`analytic.measurement.detector.expected_counts`) by the likelihood-ratio
statistic, the deviance against the saturated model:

- ``dead_time = "none"``: counts are independent Poisson(μ_n),
  D = 2 Σ_n [c_n log(c_n / μ_n) - (c_n - μ_n)];
- ``dead_time = "cycle"``: each row is one multinomial draw of the C cycles
  over its N bins and "no detection" (first-photon detection, Coates),
  D = 2 Σ c log(c / μ) over the N + 1 categories.

(c log(c/μ) = 0 at c = 0; a count where μ = 0 gives D = inf.) For low
counts D is far from its χ² limit, so its null distribution is drawn: D of
``draws`` histograms simulated from μ itself (seeded). The capture agrees
when D is at most that distribution's 1 - α quantile: the false-alarm
rate is α up to the quantile's Monte Carlo error (±√(α(1-α)/draws));
``tests/validation/check/test_counts.py`` measures it on simulated data.

Fits (:func:`fit_counts`): the scale (data / model, through the detector's
photons), the offset (``offset_opl``, metres: what must be added to the
data's start_opl, as :mod:`validation.check.fit`) and the instrument
response's width (``fwhm``, and ``tail`` for an EMG) minimise D, each model
evaluated exactly (:class:`SceneModel`); the scale is profiled out. The
verdict after a fit uses the null distribution of the fitted histogram; it
is conservative (fitting k parameters lowers D by about k), so a
capture that still fails after the fit is diagnosed with certainty. The
same fit on a transient with standard errors (another renderer's mean
over replicas) minimises χ² instead (:func:`fit_transient`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from analytic.measurement.detector import Detector, detection_probabilities, expected_counts, rates
from analytic.errors import DataError

__all__ = ["CountsVerdict", "IrfFit", "SceneModel", "deviance", "null_deviances", "judge_counts", "fit_counts",
           "fit_transient", "FIT_PARAMETERS", "DEFAULT_FALSE_ALARM", "DEFAULT_DRAWS"]

#: What :func:`fit_counts` and :func:`fit_transient` can fit.
FIT_PARAMETERS = ("scale", "offset_opl", "fwhm", "tail")
DEFAULT_FALSE_ALARM = 0.01
DEFAULT_DRAWS = 2000
# Null histograms drawn per batch (bounds the memory of a Poisson batch to ~_BATCH x the histogram).
_BATCH = 200


@dataclass(frozen=True)
class CountsVerdict:
    """The deviance of counts against an expected histogram and its calibrated limit.

    Attributes
    ----------
    agrees : bool
        deviance <= threshold.
    deviance : float
        D (see the module docstring).
    threshold : float
        The 1 - α quantile of D under the expected histogram (drawn).
    p_value : float
        (1 + #{null D >= D}) / (draws + 1).
    false_alarm : float
        α.
    statistic : {"poisson", "multinomial"}
    bins : int
        Bins judged (N per row; the multinomial adds a "no detection" per row).
    draws : int
        Null histograms drawn.
    """

    agrees: bool
    deviance: float
    threshold: float
    p_value: float
    false_alarm: float
    statistic: str
    bins: int
    draws: int

    def as_dict(self) -> dict:
        """Every attribute by name (metrics.json's ``counts``)."""
        return asdict(self)


def _categories(counts: np.ndarray, expected: np.ndarray, detector: Detector,
                floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(c, μ) with each row's "no detection" appended under dead time (its count: C minus the row's sum).

    ``floor``: every μ raised to it (a fit's objective stays finite where a trial model forbids a count).
    """
    expected = np.maximum(expected, floor)
    if detector.dead_time == "none":
        return counts, expected
    rows_c = counts.reshape(-1, counts.shape[-1])
    rows_m = expected.reshape(-1, expected.shape[-1])
    missed_c = detector.cycles - rows_c.sum(axis=1, keepdims=True)
    missed_m = detector.cycles - rows_m.sum(axis=1, keepdims=True)
    return np.hstack([rows_c, missed_c]), np.hstack([rows_m, np.maximum(missed_m, floor)])


def _saturated_terms(c: np.ndarray, m: np.ndarray) -> np.ndarray:
    """2 [c log(c/μ) - (c - μ)] elementwise (0 log 0 = 0; inf where c > 0 = μ)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        log_ratio = np.where(c > 0, c * np.log(np.where(c > 0, c, 1.0) / m), 0.0)
    return 2.0 * (log_ratio - (c - m))


def deviance(counts, expected, detector: Detector) -> float:
    """D of counts against an expected histogram (see the module docstring).

    Parameters
    ----------
    counts : array_like
        ``(..., N)`` counts (non-negative whole numbers).
    expected : array_like
        ``(..., N)`` expected counts, >= 0.
    detector : Detector
        Its ``dead_time`` chooses Poisson or multinomial, its ``cycles``
        the multinomial's trials.

    Returns
    -------
    float
        D >= 0; inf where a bin holds counts that its expectation 0 forbids.
    """
    c, m = _categories(np.asarray(counts, dtype=np.float64), np.asarray(expected, dtype=np.float64), detector)
    return float(np.sum(_saturated_terms(c, m)))


def _fit_deviance(counts, expected, detector: Detector) -> float:
    """D with every expected count floored at 1e-300: finite (huge) where a trial model forbids a count."""
    c, m = _categories(counts, np.asarray(expected, dtype=np.float64), detector, floor=1e-300)
    return float(np.sum(_saturated_terms(c, m)))


def null_deviances(expected, detector: Detector, draws: int, rng: np.random.Generator) -> np.ndarray:
    """D of ``draws`` histograms drawn from the expected one: the null distribution, ``(draws,)``."""
    expected = np.asarray(expected, dtype=np.float64)
    out = np.empty(draws)
    if detector.dead_time == "none":
        for first in range(0, draws, _BATCH):
            size = min(_BATCH, draws - first)
            simulated = rng.poisson(expected, size=(size,) + expected.shape).astype(np.float64)
            terms = _saturated_terms(simulated, np.broadcast_to(expected, simulated.shape))
            out[first:first + size] = terms.reshape(size, -1).sum(axis=1)
        return out
    rows = expected.reshape(-1, expected.shape[-1]) / detector.cycles
    total = np.zeros(draws)
    for row in rows:
        probabilities = np.append(row, max(1.0 - math.fsum(row), 0.0))
        probabilities /= math.fsum(probabilities)
        simulated = rng.multinomial(int(detector.cycles), probabilities, size=draws).astype(np.float64)
        total += _saturated_terms(simulated, detector.cycles * probabilities).sum(axis=1)
    out[:] = total
    return out


def judge_counts(counts, expected, detector: Detector, *, false_alarm: float = DEFAULT_FALSE_ALARM,
                 draws: int = DEFAULT_DRAWS, seed: int = 0) -> CountsVerdict:
    """Whether counts are consistent with an expected histogram, at false-alarm rate α.

    Parameters
    ----------
    counts : array_like
        ``(..., N)`` the capture's counts (a draw, a measurement).
    expected : array_like
        ``(..., N)`` the model's expected counts
        (:func:`analytic.measurement.detector.expected_counts`).
    detector : Detector
    false_alarm : float
        α in (0, 0.5]: the probability that counts drawn from ``expected``
        fail.
    draws : int
        Null histograms drawn; at least 10 / α so that the quantile is
        resolved.
    seed : int
        Seed of the null draws.

    Returns
    -------
    CountsVerdict

    Raises
    ------
    DataError
        Shapes that differ, negative, fractional or non-finite counts, more
        counts in a row than cycles under dead time, α or draws out of range.
    """
    counts = np.asarray(counts)
    expected = np.asarray(expected, dtype=np.float64)
    if counts.shape != expected.shape or counts.ndim == 0:
        raise DataError(f"counts: shape {counts.shape} differs from the expected histogram's {expected.shape}")
    values = counts.astype(np.float64)
    if not np.all(np.isfinite(values)) or np.any(values < 0) or np.any(values != np.round(values)):
        raise DataError("counts: every count must be a finite whole number >= 0")
    if not np.all(np.isfinite(expected)) or np.any(expected < 0):
        raise DataError("counts: the expected histogram must be finite and >= 0")
    if detector.dead_time == "cycle" and np.any(values.reshape(-1, values.shape[-1]).sum(axis=1) > detector.cycles):
        raise DataError(f"counts: a row holds more counts than the {detector.cycles:g} cycles a first-photon "
                        f"detector can record (dead_time = 'cycle')")
    if not 0.0 < false_alarm <= 0.5:
        raise DataError(f"false alarm rate must be in (0, 0.5], got {false_alarm}")
    if draws < 10 / false_alarm:
        raise DataError(f"draws = {draws} cannot resolve the {1 - false_alarm:g} quantile; use at least "
                        f"{math.ceil(10 / false_alarm)}")
    observed = deviance(values, expected, detector)
    # A stream of its own: seeded like a detector's draw (seed 0 by default), the first reference
    # histogram would be the capture itself whenever the capture is our own draw.
    null = null_deviances(expected, detector, draws, np.random.default_rng([seed, _REFERENCE_STREAM]))
    threshold = float(np.quantile(null, 1.0 - false_alarm, method="higher"))
    p_value = (1.0 + float(np.sum(null >= observed))) / (draws + 1.0)
    bins = int(values.size)
    return CountsVerdict(bool(observed <= threshold), observed, threshold, p_value, float(false_alarm),
                         "poisson" if detector.dead_time == "none" else "multinomial", bins, int(draws))


#: Second word of the reference draws' seed, apart from every detector draw's ``default_rng(seed)``.
_REFERENCE_STREAM = 0x636F756E


class SceneModel:
    """y of a scene with its bins moved and its pulse's width changed, by the exact model, memoised.

    ``model(offset_opl=0.0, fwhm=None, tail=None)`` is forward(scene) with
    every bin edge moved by +offset_opl metres and, for a Gaussian or EMG
    illumination, that fwhm and tail (None: the scene's own).

    Parameters
    ----------
    scene : analytic.Scene or analytic.RelayWallScene
    """

    def __init__(self, scene):
        self.scene = scene
        self.cache: dict = {}

    def __call__(self, offset_opl: float = 0.0, fwhm: float | None = None, tail: float | None = None) -> np.ndarray:
        from analytic.scenes.common import Illumination, Sampling
        from analytic.operator.matrix_free import forward     # Numba: loaded when a model is first needed

        key = (float(offset_opl), fwhm, tail)
        if key not in self.cache:
            sampling = self.scene.sampling
            illumination = self.scene.illumination
            if fwhm is not None or tail is not None:
                if illumination.waveform not in ("gaussian", "emg"):
                    raise DataError(f"fit: the pulse's width is fitted for a gaussian or emg illumination, "
                                    f"not {illumination.waveform!r}")
                illumination = Illumination(waveform=illumination.waveform,
                                            fwhm=illumination.fwhm if fwhm is None else fwhm,
                                            tail=illumination.tail if tail is None else tail)
            shifted = Sampling(bin_width_opl=sampling.bin_width_opl, start_opl=sampling.start_opl + float(offset_opl),
                               count=sampling.count)
            self.cache[key] = forward(self.scene.replace(sampling=shifted, illumination=illumination))
        return self.cache[key]


@dataclass(frozen=True)
class IrfFit:
    """What a fit found: the parameters, their standard errors, the statistic there, and the verdict after it.

    Attributes
    ----------
    parameters : dict
        Fitted name -> value (``scale`` dimensionless; ``offset_opl``,
        ``fwhm``, ``tail`` metres); the names not fitted are absent.
    stderr : dict
        Name -> standard error, from the curvature of the statistic
        (D/2 or χ²/2 is the negative log-likelihood up to a constant).
    statistic : float
        D (counts) or χ² (transient) at the fit.
    verdict : CountsVerdict or None
        Counts only: the judgement against the fitted histogram.
    evaluations : int
        Model evaluations (each an exact forward model).
    """

    parameters: dict
    stderr: dict
    statistic: float
    verdict: CountsVerdict | None = None
    evaluations: int = 0
    history: list = field(default_factory=list, repr=False)

    def as_dict(self) -> dict:
        return {"parameters": dict(self.parameters), "stderr": dict(self.stderr), "statistic": self.statistic,
                "verdict": None if self.verdict is None else self.verdict.as_dict(),
                "evaluations": self.evaluations}


def _check_names(fit) -> tuple[str, ...]:
    names = tuple(fit)
    unknown = [name for name in names if name not in FIT_PARAMETERS]
    if unknown or not names or len(set(names)) != len(names):
        raise DataError(f"fit: choose from {', '.join(FIT_PARAMETERS)} (each once), got {', '.join(names) or 'none'}")
    return names


def _fit(statistic_of, model, names, start: dict, steps: dict):
    """Minimise statistic_of(y, scale-profiled) over the non-scale parameters by Nelder–Mead.

    ``statistic_of(y) -> (value, best scale)``: the scale profiled out (or fixed at 1 when not fitted).
    Returns (parameters, statistic, evaluations, history).
    """
    from scipy import optimize

    free = [name for name in names if name != "scale"]
    history = []

    def evaluate(vector):
        values = dict(zip(free, vector))
        if any(values.get(name, 1.0) <= 0 for name in ("fwhm", "tail")):
            return math.inf, 1.0
        y = model(values.get("offset_opl", 0.0), values.get("fwhm"), values.get("tail"))
        value, scale = statistic_of(y)
        history.append((dict(values), scale, value))
        return value, scale

    if free:
        x0 = np.array([start[name] for name in free], dtype=np.float64)
        simplex = np.vstack([x0] + [x0 + steps[name] * np.eye(len(free))[i] for i, name in enumerate(free)])
        found = optimize.minimize(lambda v: evaluate(v)[0], x0, method="Nelder-Mead",
                                  options={"initial_simplex": simplex, "xatol": 1e-4 * min(steps.values()),
                                           "fatol": 1e-3, "maxfev": 300})
        best = found.x
    else:
        best = np.array([])
    value, scale = evaluate(best)
    parameters = dict(zip(free, map(float, best)))
    if "scale" in names:
        parameters = {"scale": float(scale), **parameters}
    return parameters, value, history


def _curvature_errors(objective, parameters: dict, steps: dict) -> dict:
    """Standard errors from the Hessian of objective/2 by central differences (the observed information)."""
    names = list(parameters)
    x = np.array([parameters[name] for name in names])
    h = np.array([steps[name] * 1e-2 for name in names])
    n = len(names)
    hessian = np.empty((n, n))
    centre = objective(x)
    for i in range(n):
        for j in range(i, n):
            if i == j:
                e = np.eye(n)[i] * h[i]
                hessian[i, i] = (objective(x + e) - 2 * centre + objective(x - e)) / h[i] ** 2
            else:
                ei, ej = np.eye(n)[i] * h[i], np.eye(n)[j] * h[j]
                hessian[i, j] = hessian[j, i] = (objective(x + ei + ej) - objective(x + ei - ej)
                                                 - objective(x - ei + ej) + objective(x - ei - ej)) / (4 * h[i] * h[j])
    try:
        covariance = np.linalg.inv(0.5 * hessian)
    except np.linalg.LinAlgError:
        return {name: math.nan for name in names}
    return {name: float(math.sqrt(covariance[i, i])) if covariance[i, i] > 0 else math.nan
            for i, name in enumerate(names)}


def _starts(model, names, start, scene_sampling_width):
    """Starting values and simplex steps: the scene's own pulse, no offset, steps of a fraction of a bin or width."""
    illumination = model.scene.illumination
    values = {"offset_opl": 0.0, "fwhm": illumination.fwhm, "tail": illumination.tail, "scale": 1.0}
    values.update(start or {})
    for name in names:
        if name != "scale" and values.get(name) is None:
            raise DataError(f"fit: {name} needs a starting value (the scene's illumination has none)")
    steps = {"offset_opl": 0.25 * scene_sampling_width, "scale": 0.05}
    for name in ("fwhm", "tail"):
        if values.get(name) is not None:
            steps[name] = 0.3 * values[name]
    return values, steps


def fit_counts(counts, model: SceneModel, detector: Detector, *, fit=("scale", "offset_opl"), start=None,
               false_alarm: float = DEFAULT_FALSE_ALARM, draws: int = DEFAULT_DRAWS, seed: int = 0) -> IrfFit:
    """Fit scale, offset and pulse width of counts against the exact model, minimising the deviance.

    Parameters
    ----------
    counts : array_like
        ``(K, N)`` counts.
    model : SceneModel
        The scene's model (its detector is ``detector``).
    detector : Detector
    fit : sequence of str
        Names from :data:`FIT_PARAMETERS`.
    start : dict, optional
        Starting values (default: the scene's: offset 0, its fwhm and tail).
    false_alarm, draws, seed
        As for :func:`judge_counts` (the verdict after the fit).

    Returns
    -------
    IrfFit
    """
    names = _check_names(fit)
    counts = np.asarray(counts, dtype=np.float64)
    values, steps = _starts(model, names, start, model.scene.sampling.bin_width_opl)

    def statistic_of(y, scale=None):
        if scale is not None or "scale" not in names:
            scale = 1.0 if scale is None else scale
            return _fit_deviance(counts, expected_counts(scale * y, detector), detector), scale
        return _profile_scale(lambda s: _fit_deviance(counts, expected_counts(s * y, detector), detector), y,
                              detector, counts)

    parameters, value, history = _fit(statistic_of, model, names, values, steps)

    def objective(vector):
        point = dict(zip(parameters, vector))
        y = model(point.get("offset_opl", 0.0), point.get("fwhm"), point.get("tail"))
        return statistic_of(y, point.get("scale", 1.0))[0]

    stderr = _curvature_errors(objective, parameters, steps)
    fitted = expected_counts(parameters.get("scale", 1.0) * model(parameters.get("offset_opl", 0.0),
                                                                   parameters.get("fwhm"), parameters.get("tail")),
                             detector)
    verdict = judge_counts(counts, fitted, detector, false_alarm=false_alarm, draws=draws, seed=seed)
    return IrfFit(parameters, stderr, value, verdict, len(model.cache), history)


def _profile_scale(statistic, y, detector, counts):
    """(min over s of statistic(s), s): Brent's method in log s, bracketed around the counts' ratio."""
    from scipy import optimize

    signal = np.sum(rates(y, detector) - detector.background) * detector.cycles
    excess = np.sum(counts) - detector.background * detector.cycles * counts.size
    guess = max(excess / signal, 1e-6) if signal > 0 else 1.0
    found = optimize.minimize_scalar(lambda log_s: statistic(math.exp(log_s)),
                                     bracket=(math.log(guess) - 0.5, math.log(guess) + 0.5),
                                     options={"xtol": 1e-10})
    return float(found.fun), float(math.exp(found.x))


def fit_transient(mean, stderr, model: SceneModel, *, fit=("scale", "offset_opl"), start=None) -> IrfFit:
    """The same fit for a transient with per-bin standard errors (χ² = Σ ((y - s y_model) / se)², s profiled).

    Parameters
    ----------
    mean, stderr : array_like
        ``(K, N)`` a transient (another tool's mean over replicas) and its
        standard error, units of y; bins with stderr 0 are left out.
    model : SceneModel
    fit, start
        As for :func:`fit_counts`.

    Returns
    -------
    IrfFit
        ``statistic`` χ², ``verdict`` None (judge with
        :func:`validation.check.verdict.check_transient`).
    """
    names = _check_names(fit)
    mean = np.asarray(mean, dtype=np.float64)
    stderr = np.asarray(stderr, dtype=np.float64)
    mask = stderr > 0
    if mask.sum() < 3:
        raise DataError("fit: fewer than 3 bins with a standard error")
    weights = np.where(mask, 1.0 / np.where(mask, stderr, 1.0) ** 2, 0.0)
    values, steps = _starts(model, names, start, model.scene.sampling.bin_width_opl)

    def statistic_of(y, scale=None):
        if scale is None:
            norm = float(np.sum(weights * y * y))
            scale = float(np.sum(weights * mean * y)) / norm if ("scale" in names and norm > 0) else 1.0
        return float(np.sum(weights * (mean - scale * y) ** 2)), scale

    parameters, value, history = _fit(statistic_of, model, names, values, steps)

    def objective(vector):
        point = dict(zip(parameters, vector))
        y = model(point.get("offset_opl", 0.0), point.get("fwhm"), point.get("tail"))
        return statistic_of(y, point.get("scale", 1.0))[0]

    return IrfFit(parameters, _curvature_errors(objective, parameters, steps), value, None, len(model.cache), history)
