"""``calibrate``: the scene's free parameters and a scale fitted to a capture, and the verdict on the fit.

:func:`calibrate` reads DATA as ``check`` does (:func:`validation.check.inputs.read_inputs`:
replicas, a transient with its standard error, our render's folder), fits
the free parameters (docs/design.md section 9 keys) and an overall scale by
:func:`validation.calibration.fit.levenberg_marquardt` on the exact Jacobian
(:func:`analytic.jacobian`), weighted by the data's standard errors, and
judges the fitted model against the data with the statistics of section 6
(:func:`validation.judging.compare.compare_transients`).

With ``sampling.start`` free, the time axis the data state (``meta.json``
beside our files, the EXR header, a capture's ``t_start``) is its starting
value rather than a constraint: a capture whose time zero is off is what
the fit is for.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from analytic.errors import DataError
from analytic.operator.derivatives import jacobian as exact_jacobian
from analytic.operator.parameters import parameters, value_of, with_values
from analytic.operator.matrix_free import forward
from validation.check.inputs import PYTHON_WORDS, Words, read_inputs, scene_of
from validation.judging.arrays import false_alarm_rate, real_array
from validation.judging.compare import Agreement, compare_transients, judged_bins, model_tolerance_for

from .fit import SCALE, FitOutcome, FitProblem, levenberg_marquardt

__all__ = ["Calibration", "calibrate", "calibrate_inputs", "stated_start_opl", "UNDETERMINED",
           "MAX_RELATIVE_STDERR"]

#: What an undetermined parameter's value says.
UNDETERMINED = "not determined by the data"

#: Bins judged where se < this x |data| (as ``check``).
MAX_RELATIVE_STDERR = 0.1


@dataclass
class Calibration:
    """A calibration's result: the fitted values, their errors, and whether the fit agrees with the data.

    Attributes
    ----------
    parameters : dict
        ``{key: {"value", "stderr", "start", "unit"}}``; for a key the data
        do not fix, ``value`` and ``stderr`` are None and ``"determined":
        False`` with the direction(s) it lies on.
    scale : dict
        ``{"value", "stderr"}``: data / model (1 and 0 with a fixed scale).
    chi2_dof : float
        χ² / (bins - fitted parameters) at the solution.
    converged : bool
    agreement : Agreement
        Section 6's verdict on data against the fitted model.
    covariance : dict
        ``{"names": [...], "matrix": [[...]]}`` of the determined parameters (and the scale).
    degenerate : list of dict
        ``{"direction": {name: component}, "text": ...}``: the directions the data do not fix.
    scene, start_scene : SceneKind
        The scene with the fitted values, and the one the fit started from.
    data, stderr, model, start_model : numpy.ndarray
        ``(K, N)``: the data (the replicas' mean), their standard errors,
        the fitted model s y(θ) and the model at the start.
    """

    parameters: dict
    scale: dict
    chi2_dof: float
    converged: bool
    agreement: Agreement
    covariance: dict
    degenerate: list
    scene: object
    start_scene: object
    data: np.ndarray
    stderr: np.ndarray
    model: np.ndarray
    start_model: np.ndarray
    start_chi2_dof: float
    iterations: int
    false_alarm: float
    sources: tuple = field(default=())

    @property
    def agrees(self) -> bool:
        """The data agree with the fitted model at the false-alarm rate (section 6)."""
        return bool(self.agreement.agrees)

    @property
    def verdict(self) -> bool:
        """Converged and agrees: ``calibrate``'s exit status 0."""
        return self.converged and self.agrees

    def as_dict(self) -> dict:
        """calibration.json's content (docs/design.md section 9)."""
        return {"parameters": self.parameters, "scale": self.scale, "chi2_dof": self.chi2_dof,
                "converged": self.converged, "covariance": self.covariance, "degenerate": self.degenerate,
                "agrees": self.agrees, "agreement": self.agreement.as_dict(), "start_chi2_dof": self.start_chi2_dof,
                "iterations": self.iterations, "false_alarm": self.false_alarm, "data": list(self.sources)}

    def rows(self) -> list[tuple[str, str, str, str, str]]:
        """(name, start, fitted value, standard error, unit) as text per parameter and for the scale; the
        value of one the data do not fix is :data:`UNDETERMINED` and its error empty."""
        entries = [*self.parameters.items(), ("scale", {**self.scale, "start": None, "unit": "1"})]
        return [(name, "" if entry["start"] is None else format(entry["start"], ".9g"),
                 UNDETERMINED if entry["value"] is None else format(entry["value"], ".9g"),
                 "" if entry["value"] is None else format(entry["stderr"], ".3g"), entry["unit"])
                for name, entry in entries]

    def summary(self) -> str:
        """A few lines: each parameter (start -> value ± error), the scale, χ²/dof and the verdict."""
        lines = []
        for name, start, value, error, unit in self.rows():
            unit = "" if unit == "1" else f" {unit}"
            start = f"{start}{unit if not error else ''} -> " if start else ""
            lines.append(f"  {name}: {start}{value} ± {error}{unit}" if error else f"  {name}: {start}{value}")
        for entry in self.degenerate:
            lines.append(f"  not determined by the data: the direction {entry['text']}")
        verdict = "AGREE" if self.agrees else "DISAGREE"
        state = "converged" if self.converged else "did NOT converge"
        lines.append(f"calibrate: {state} in {self.iterations} iteration(s); χ²/dof {self.start_chi2_dof:.3g} -> "
                     f"{self.chi2_dof:.3g}; the data {verdict} with the fitted model: {self.agreement.summary()}")
        return "\n".join(lines)


def stated_start_opl(path) -> float | None:
    """The ``start_opl`` a data file states (``meta.json`` beside it or in its folder, an EXR header, a tal
    capture's ``t_start``), or None when it states none (a bare ``.npy``, a list of arrays)."""
    from analytic.files import read_exr, transient_format, transient_in_folder

    path = Path(path)
    if path.is_dir():
        inner = transient_in_folder(path)
        return None if inner is None else stated_start_opl(inner)
    if not path.is_file():
        return None
    kind = transient_format(path)
    if kind == "capture":
        from interop.tal import read_capture

        return float(read_capture(path).start_opl)
    if kind == "exr":
        header = read_exr(path)[1]
        if "start_opl" in header:
            return float(header["start_opl"])
    meta = path.parent / "meta.json"
    if kind in ("exr", "npy") and meta.is_file():
        try:
            start = json.loads(meta.read_text(encoding="utf-8-sig")).get("start_opl")
        except (OSError, ValueError, AttributeError):
            return None          # not ours: read_data says what is wrong with it, if anything
        if isinstance(start, (int, float)) and not isinstance(start, bool) and np.isfinite(start):
            return float(start)
    return None


def _first_path(data):
    """The data's first file (a list's first item), or None for arrays."""
    if isinstance(data, (list, tuple)):
        return _first_path(data[0]) if data else None
    return data if isinstance(data, (str, Path)) else None


def _mean_and_error(inputs) -> tuple[np.ndarray, np.ndarray, float, np.ndarray | None]:
    """(data, standard error, degrees of freedom, replicas) of what :func:`read_inputs` read."""
    if inputs.replicas > 1:
        replicas = inputs.data
        error = replicas.std(axis=0, ddof=1) / np.sqrt(inputs.replicas)
        error[np.all(replicas == replicas[0], axis=0)] = 0.0
        return replicas.mean(axis=0), error, float(inputs.replicas - 1), replicas
    return inputs.data, inputs.stderr, float(np.inf if inputs.dof is None else inputs.dof), None


def _problem(scene, keys, data, error, free_scale: bool) -> FitProblem:
    """The fit of ``keys`` of ``scene`` to ``data``: the model, its Jacobian, the start."""
    items = parameters(scene, list(keys))
    names = [item.key for item in items]
    start = np.array([value_of(scene, item) for item in items])
    # a reflectance key is a scale relative to the scene it is differentiated in (∂y/∂s at s = 1 is y): per
    # unit of the value fitted here, relative to ``scene``, the column is divided by that value
    relative = np.array([item.stem.endswith(".reflectance") for item in items])

    def moved(theta):
        return with_values(scene, dict(zip(names, map(float, theta))))

    def jacobian(theta):
        columns = exact_jacobian(moved(theta), names)
        return np.where(relative, columns / np.where(relative, theta, 1.0), columns)

    return FitProblem(names=names, start=start, model=lambda theta: forward(moved(theta)), jacobian=jacobian,
                      data=data, stderr=error, free_scale=free_scale)


def calibrate(scene, data, free, *, stderr=None, dof: int | None = None, counts: bool = False,
              fixed_scale: bool = False, false_alarm: float = 1e-3) -> Calibration:
    """Fit the free parameters of ``scene`` (and a scale) to a capture; ``calibrate``'s work.

    Parameters
    ----------
    scene : SceneKind, str or Path
        The scene (or its file) whose parameters are calibrated; the
        parameters not named in ``free`` are held at its values.
    data : array_like, str, Path or list
        What ``check`` reads (:func:`validation.check_transient`): ``(R, K, N)``
        replicas, one ``(K, N)`` transient with ``stderr``, files, our
        render's folder (its replicas or standard error come with it).
        Units of y.
    free : sequence of str
        Keys of docs/design.md section 9 (``sensors.positions.0.z``,
        ``sampling.start``, ``illumination.fwhm``, ...).
    stderr : array_like or path, optional
        ``(K, N)`` standard error of one transient, units of y.
    dof : int, optional
        Its degrees of freedom (Student's t in the verdict).
    counts : bool
        ``data`` is a ``(K, N)`` histogram of photon counts (an array, a ``.npy``, or a folder holding
        ``counts.npy``) of the scene's ``[detector]`` without dead time: fitted by its Poisson likelihood
        (reweighted least squares, σ² = the fitted mean) and judged by check's deviance test
        (:func:`validation.check.counts.judge_counts`).
    fixed_scale : bool
        Hold the scale at 1 (data in the model's absolute units).
    false_alarm : float
        α of the verdict (docs/design.md section 6).

    Returns
    -------
    Calibration

    Raises
    ------
    DataError, OptionError, SceneError
        What ``check`` refuses, an unknown or repeated key, a bad α.
    """
    return calibrate_inputs(scene, data, free, stderr=stderr, dof=dof, counts=counts, fixed_scale=fixed_scale,
                            false_alarm=false_alarm)


def calibrate_inputs(scene, data, free, *, stderr=None, dof=None, counts=False, fixed_scale=False,
                     false_alarm=1e-3, words: Words = PYTHON_WORDS, checked=None) -> Calibration:
    """:func:`calibrate`, its messages in ``words``; ``checked``: called once the inputs are accepted."""
    scene = scene_of(scene)
    false_alarm = false_alarm_rate(false_alarm)
    if isinstance(free, str):
        free = [free]
    keys = [item.key for item in parameters(scene, list(free))]     # a bad key: before any reading
    start_opl = None
    if "sampling.start" in keys and _first_path(data) is not None:
        start_opl = stated_start_opl(_first_path(data))
        if start_opl is not None:
            scene = with_values(scene, {"sampling.start": start_opl})
    if counts:
        if stderr is not None or dof is not None:
            raise DataError(f"{words.stderr}: counts carry their own (Poisson) error; give no standard error with "
                            f"them")
        histogram, sources = _histogram(scene, data, words)
        values, error, reweight = _counts_as_y(histogram, scene.detector)
        degrees, replicas = np.inf, None
    else:
        inputs = _read(scene, data, stderr, dof, words)
        values, error, degrees, replicas = _mean_and_error(inputs)
        reweight, sources = None, inputs.sources
    if not np.any(values != 0):
        raise DataError(f"{words.data}: every value is 0, no light to fit; check the data against the scene")
    if not np.any(error > 0):
        raise DataError(f"{words.data}: every standard error is 0, so no bin can weight the fit; give each bin's "
                        f"standard error")
    tolerance = model_tolerance_for(scene.tolerance, values, error, MAX_RELATIVE_STDERR)
    fitted_scene = scene if tolerance is None else scene.replace(tolerance=tolerance)
    if checked is not None:
        checked()
    weights = _fitted_errors(values, error, degrees, replicas)
    if not np.any(weights > 0):
        raise DataError(f"{words.data}: no bin has a standard error under {MAX_RELATIVE_STDERR:g} of its value "
                        f"(about 100 samples), so none can weight the fit; render more samples")
    problem = _problem(fitted_scene, keys, values, weights, not fixed_scale)
    outcome = levenberg_marquardt(replace(problem, reweight=reweight))
    if counts:
        agreement = CountsAgreement.of(histogram, outcome.model, scene.detector, false_alarm)
        error = reweight(outcome.model)
    else:
        agreement = compare_transients(values, error, outcome.model, dof=degrees if replicas is None else None,
                                       replicas=replicas, false_alarm=false_alarm,
                                       max_relative_stderr=MAX_RELATIVE_STDERR)
    return _calibration(scene, keys, outcome, agreement, values, error, false_alarm, sources)


def _read(scene, data, stderr, dof, words: Words):
    """:func:`read_inputs`, its refusal of a transient without errors in calibrate's words (no shape-only fit)."""
    try:
        return read_inputs(scene, data, stderr, dof=dof, words=words)
    except DataError as error:
        if not str(error).startswith("one transient without errors"):
            raise
        counts = "--counts" if words.stderr.startswith("--") else "counts=True"
        raise DataError(f"one transient without errors: give its standard error ({words.stderr_value}), several "
                        f"independent replicas, or photon counts ({counts}); a fit needs the data's errors") from None


def _fitted_errors(values, error, degrees, replicas) -> np.ndarray:
    """The errors the fit weights by: zero (not fitted) outside the bins check judges where they were
    estimated from a few replicas (their own spread, or a render's standard error with finite degrees of
    freedom): a bin that a handful of samples reached has an error that is itself far off, and one such bin
    can outweigh all the others (:func:`validation.judging.compare.judged_bins`). Stated Gaussian errors
    (infinite degrees of freedom) weight every bin where they are positive."""
    if replicas is None and np.isinf(degrees):
        return error
    return np.where(judged_bins(values, error, MAX_RELATIVE_STDERR, replicas), error, 0.0)


def _histogram(scene, data, words: Words) -> tuple[np.ndarray, tuple]:
    """The ``(K, N)`` histogram of counts ``data`` gives (an array, a .npy, a folder holding counts.npy)."""
    from analytic.files import read_npy, reading_folder

    detector = scene.detector
    if detector is None:
        raise DataError(f"{words.data}: counts need the scene's [detector] table to model them by; add one "
                        f"(photons, background, cycles, dead_time; docs/detector.md)")
    if detector.dead_time != "none":
        raise DataError(f"{words.data}: calibrate fits counts without dead time (the scene's [detector] "
                        f"dead_time = {detector.dead_time!r}); a first-photon histogram is not fitted yet: "
                        f"correct it (Coates) or judge it with check --counts")
    if isinstance(data, (str, Path)):
        with reading_folder(data, option=words.data):
            path = Path(data) / "counts.npy" if Path(data).is_dir() else Path(data)
            if not path.is_file() or path.suffix.lower() != ".npy":
                raise DataError(f"{path}: counts are read from a .npy histogram ((K, N) whole numbers) or the "
                                f"folder holding counts.npy")
            histogram, sources = read_npy(path), (str(path),)
    else:
        histogram, sources = real_array(words.data, data), ()
    shape = (scene.sensor_count, scene.sampling.count)
    values = np.asarray(histogram, dtype=np.float64)
    if values.shape != shape:
        raise DataError(f"{words.data}: counts of shape {values.shape}, the scene's rows x bins are {shape}")
    if not np.all(np.isfinite(values)) or np.any(values < 0) or np.any(values != np.round(values)):
        raise DataError(f"{words.data}: every count must be a finite whole number >= 0")
    return values, sources


def _counts_as_y(histogram, detector):
    """Counts c as data in y's units (d = (c / C - b) / p: their mean is y without dead time), their first
    standard errors sqrt(max(c, 1)) / (C p), and the reweighting σ(model) = sqrt(C (p y + b)) / (C p)."""
    cycles, photons, background = detector.cycles, detector.photons, detector.background

    def reweight(model):
        return np.sqrt(cycles * (photons * np.maximum(model, 0.0) + background)) / (cycles * photons)

    return ((histogram / cycles - background) / photons, np.sqrt(np.maximum(histogram, 1.0)) / (cycles * photons),
            reweight)


@dataclass(frozen=True)
class CountsAgreement:
    """Counts against the fitted expected histogram: check's deviance test, with ``Agreement``'s reading."""

    verdict: object

    @classmethod
    def of(cls, histogram, model, detector, false_alarm: float) -> CountsAgreement:
        from analytic.measurement.detector import expected_counts
        from validation.check.counts import DEFAULT_DRAWS, judge_counts

        draws = max(DEFAULT_DRAWS, int(np.ceil(20.0 / false_alarm)))     # the quantile resolved at α
        return cls(judge_counts(histogram, expected_counts(model, detector), detector, false_alarm=false_alarm,
                                draws=draws))

    @property
    def agrees(self) -> bool:
        return bool(self.verdict.agrees)

    def as_dict(self) -> dict:
        return self.verdict.as_dict()

    def summary(self) -> str:
        v = self.verdict
        return (f"{'AGREE' if v.agrees else 'DISAGREE'}: {v.statistic} deviance {v.deviance:.2f} "
                f"{'<=' if v.agrees else '>'} {v.threshold:.2f} (the {1 - v.false_alarm:g} quantile of {v.draws} "
                f"histograms drawn from the fitted model), p = {v.p_value:.3g}, {v.bins} bins")


def _calibration(scene, keys, outcome: FitOutcome, agreement, values, error, false_alarm, sources) -> Calibration:
    items = parameters(scene, keys)
    fitted = with_values(scene, {key: outcome.values[key] for key in keys})
    directions = [{"direction": d.direction, "text": d.text()} for d in outcome.degenerate]
    entries = {}
    for item in items:
        entry = {"value": None, "stderr": outcome.stderr[item.key], "start": value_of(scene, item),
                 "unit": item.unit}
        if entry["stderr"] is None:
            entry["determined"] = False
            entry["directions"] = [d["text"] for d in directions if item.key in d["direction"]]
        else:
            entry["value"] = outcome.values[item.key]
        entries[item.key] = entry
    scale_error = outcome.stderr[SCALE]
    scale = {"value": None if scale_error is None else outcome.values[SCALE], "stderr": scale_error}
    chi2_dof_start = outcome.start_chi2 / max(outcome.bins - len(outcome.determined), 1)
    return Calibration(
        parameters=entries, scale=scale, chi2_dof=outcome.chi2_dof, converged=outcome.converged,
        agreement=agreement,
        covariance={"names": outcome.determined, "matrix": outcome.covariance.tolist()},
        degenerate=directions, scene=fitted, start_scene=scene, data=values, stderr=error, model=outcome.model,
        start_model=outcome.start_model, start_chi2_dof=float(chi2_dof_start), iterations=outcome.iterations,
        false_alarm=false_alarm, sources=sources)
