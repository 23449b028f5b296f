"""The verdict of ``check``: a transient from any tool judged against the exact model, as given and after a fit.

``check_transient(scene, data, ...)`` compares y from anywhere (our render,
another renderer, a measurement) with ``analytic.system.forward(scene)``
in two steps:

1. **As given.** z = (y_data - y_model) / se per bin, judged by
   :func:`validation.compare.compare_transients` (docs/design.md section 6).
   The per-bin error se comes from ``stderr`` for one transient, or from R
   independent replicas (mean and standard error of the mean; z then
   follows Student's t with R - 1 degrees of freedom, and the limits of χ²
   and max |z| come from the replicas' sign flips, which hold whatever the
   correlation between bins, when R is large enough).
2. **After the two convention errors users make**: a global scale s and a
   time offset δ, y_data[n] ≈ s y_model(t0 + δ)[n], fitted by weighted least
   squares (:mod:`validation.check.fit`), and the verdict again against
   s y_model(t0 + δ). The fit needs :data:`FIT_BINS` judged bins; with
   fewer (a one-bin scene) the data are judged as given only, and the
   result says so.

A convention the user expects (``expect``: a
:class:`~validation.check.conventions.Convention`, such as mitransient's
:func:`~validation.check.conventions.irradiancemeter`) is judged too, with
the same test against s y_model(t0 + δ) for the stated s and δ.

One transient without ``stderr`` carries no noise level: it is judged by
shape only (relative L2 error against ``shape_tolerance``, the same fit
unweighted) and only when asked (``shape_only=True``), and the result says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from analytic.errors import DataError
from analytic.scene import Scene
from validation.compare import Agreement, compare_transients, model_tolerance_for, tighter_model_note

from .conventions import Convention, diagnose
from .fit import Fit, ShiftedModel, fit_scale_offset

__all__ = ["CheckResult", "check_transient", "expected_sentence", "FIT_BINS", "MAX_DATA", "MAX_RELATIVE_STDERR"]

#: Largest |y| accepted: the squares that χ² and the L2 norms form stay float64 numbers.
MAX_DATA = 1e150

#: Bins are judged (and fitted) only where se < this x |y_data| (as compare_transients).
MAX_RELATIVE_STDERR = 0.1

#: Smallest standard error judged, relative to the largest |y| (data or model): below it z² overflows float64.
MIN_RELATIVE_STDERR = 1e-100

#: Fewest judged bins that a scale and a time offset are fitted to (two parameters and a residual).
FIT_BINS = 3


@dataclass(frozen=True, kw_only=True)
class CheckResult:
    """What ``check`` found: the verdict as given, the fitted conventions, the verdict after them.

    Built by keyword; what a judgement did not make (a fit, a stated
    convention, the statistical verdicts of a shape-only judgement) keeps
    its default, None.

    Attributes
    ----------
    agrees : bool
        The data agree with the model as given.
    judged_by : {"stderr", "replicas", "shape"}
        Where the per-bin error came from.
    relative_l2 : float
        ||y_data - y_model|| / ||y_model|| as given.
    diagnosis : str
        One sentence for the user.
    data, model, fitted_model : numpy.ndarray
        ``(K, N)``: the (mean) data, the model as given and
        scale · y_model(start_opl + offset) (the model as given without a
        fit).
    edges : numpy.ndarray
        ``(N + 1,)`` bin edges of the scene, metres of path length.
    stderr : numpy.ndarray or None
        ``(K, N)`` the data's standard error (None by shape).
    replicas : int
        Number of data arrays averaged (1 unless replicas).
    dof : int or None
        Student-t degrees of freedom of z (R - 1), None for Gaussian z.
    as_given : Agreement or None
        The full verdict as given (None when judged by shape only). With
        replicas z is judged as Student's t (see Notes of
        :func:`check_transient`).
    fit : Fit or None
        Best scale and offset; None when too few bins allow no fit
        (``fit_skipped`` says why).
    fit_skipped : str or None
        Why no scale and offset were fitted.
    agrees_after_fit : bool or None
        The data agree with scale · y_model(start_opl + offset) (None
        without a fit).
    relative_l2_after_fit : float or None
        After the fit (None without a fit).
    after_fit : Agreement or None
        The full verdict after the fit (None by shape only, or without a fit).
    expected : Convention or None
        The convention the user stated (``check --expect``).
    agrees_as_expected : bool or None
        The data agree with the stated convention's model.
    relative_l2_as_expected : float or None
        ||y_data - y_expected|| / ||y_expected||.
    as_expected : Agreement or None
        Its full verdict (None by shape only or without a stated convention).
    shape_tolerance : float or None
        The relative L2 tolerance when judged by shape only.
    model_tolerance : float or None
        The tolerance the model was evaluated at when the data's errors
        needed a tighter one than the scene's
        (:func:`validation.compare.model_tolerance_for`); None: the scene's.
    scene_tolerance : float or None
        The scene's own tolerance.
    replica_data : numpy.ndarray or None
        ``(R, K, N)`` the replicas judged (None for one transient): sums over
        bins take their error from them.
    """

    agrees: bool
    judged_by: str
    relative_l2: float
    diagnosis: str
    data: np.ndarray = field(repr=False)
    model: np.ndarray = field(repr=False)
    fitted_model: np.ndarray = field(repr=False)
    edges: np.ndarray = field(repr=False)
    stderr: np.ndarray | None = field(default=None, repr=False)
    replicas: int = 1
    dof: int | None = None
    as_given: Agreement | None = field(default=None, repr=False)
    fit: Fit | None = None
    fit_skipped: str | None = None
    agrees_after_fit: bool | None = None
    relative_l2_after_fit: float | None = None
    after_fit: Agreement | None = field(default=None, repr=False)
    expected: Convention | None = None
    agrees_as_expected: bool | None = None
    relative_l2_as_expected: float | None = None
    as_expected: Agreement | None = field(default=None, repr=False)
    shape_tolerance: float | None = None
    model_tolerance: float | None = None
    scene_tolerance: float | None = None
    replica_data: np.ndarray | None = field(default=None, repr=False)

    @property
    def chi2_per_dof(self) -> float | None:
        """χ²/dof as given (None when judged by shape only)."""
        return None if self.as_given is None else self.as_given.chi2_per_dof

    @property
    def max_abs_z(self) -> float | None:
        """max |z| as given (None when judged by shape only)."""
        return None if self.as_given is None else self.as_given.max_abs_z

    @property
    def chi2_per_dof_after_fit(self) -> float | None:
        """χ²/dof after the fit (None by shape only or without a fit)."""
        return None if self.after_fit is None else self.after_fit.chi2_per_dof

    @property
    def max_abs_z_after_fit(self) -> float | None:
        """max |z| after the fit (None by shape only or without a fit)."""
        return None if self.after_fit is None else self.after_fit.max_abs_z


    @property
    def model_tolerance_note(self) -> str | None:
        """Why the model was evaluated at a tighter tolerance than the scene's (None when it was not)."""
        if self.model_tolerance is None:
            return None
        return tighter_model_note(self.model_tolerance, self.scene_tolerance)

    @property
    def verdict(self) -> bool:
        """What the exit status reports: agreement with the stated convention, else as given."""
        return bool(self.agrees_as_expected) if self.expected is not None else self.agrees

    def as_dict(self) -> dict:
        """metrics.json: docs/design.md section 5's keys plus the figures behind them."""
        result = {"agrees": self.agrees, "chi2_per_dof": self.chi2_per_dof, "max_abs_z": self.max_abs_z,
                  "fit": None if self.fit is None else self.fit.as_dict(),
                  "agrees_after_fit": self.agrees_after_fit, "fit_skipped": self.fit_skipped,
                  "judged_by": self.judged_by, "replicas": self.replicas, "dof": self.dof,
                  "relative_l2": self.relative_l2, "relative_l2_after_fit": self.relative_l2_after_fit,
                  "chi2_per_dof_after_fit": self.chi2_per_dof_after_fit,
                  "max_abs_z_after_fit": self.max_abs_z_after_fit, "diagnosis": self.diagnosis,
                  "model_tolerance": self.model_tolerance}
        if self.expected is not None:
            result["expected"] = self.expected.as_dict() | {
                "agrees": self.agrees_as_expected, "relative_l2": self.relative_l2_as_expected}
            if self.as_expected is not None:
                result["expected"] |= {"chi2_per_dof": self.as_expected.chi2_per_dof,
                                       "max_abs_z": self.as_expected.max_abs_z}
        if self.as_given is not None:
            result["null"] = self.as_given.null
            result["as_given_detail"] = self.as_given.as_dict()
            result["after_fit_detail"] = None if self.after_fit is None else self.after_fit.as_dict()
            if self.as_expected is not None:
                result["as_expected_detail"] = self.as_expected.as_dict()
        else:
            result["shape_tolerance"] = self.shape_tolerance
        return result

    def summary(self) -> str:
        """The verdict as given, the stated convention's when there is one, and the diagnosis."""
        if self.judged_by == "shape":
            head = (f"{'AGREES' if self.agrees else 'DISAGREES'} by shape only (no errors given): "
                    f"relative L2 = {self.relative_l2:.3e} (tolerance {self.shape_tolerance:g})")
        else:
            source = (f"{self.replicas} replicas, t with {self.dof} dof" if self.judged_by == "replicas"
                      else "given standard errors")
            head = (f"{'AGREES' if self.agrees else 'DISAGREES'} as given ({source}; {self.as_given.null_note}): "
                    f"χ²/dof = {self.chi2_per_dof:.3f}, max |z| = {self.max_abs_z:.2f}, "
                    f"relative L2 = {self.relative_l2:.3e}")
        lines = [head]
        if self.model_tolerance_note:
            lines.append(f"({self.model_tolerance_note})")
        if self.expected is not None:
            lines.append(expected_sentence(self))
        return "\n".join(lines + [self.diagnosis])


def expected_sentence(result: CheckResult) -> str:
    expected = result.expected
    stated = (f"{expected.name}: scale {expected.scale:.6g}, offset {expected.offset_opl:+.6g} m")
    if result.as_expected is None:
        figures = f"relative L2 = {result.relative_l2_as_expected:.3e}"
    else:
        figures = (f"χ²/dof = {result.as_expected.chi2_per_dof:.3f}, "
                   f"max |z| = {result.as_expected.max_abs_z:.2f}")
    verdict = "AGREES" if result.agrees_as_expected else "DISAGREES"
    return f"{verdict} with the stated convention ({stated}): {figures}"


def _agreement(data, stderr, model, dof, false_alarm, replicas=None) -> Agreement:
    """compare_transients: Student-t z on ``dof`` degrees of freedom, and the replicas' own null, when given."""
    return compare_transients(data, stderr, model, dof=np.inf if dof is None and replicas is None else dof,
                              replicas=replicas, false_alarm=false_alarm, max_relative_stderr=MAX_RELATIVE_STDERR)


def _relative_l2(data, model) -> float:
    norm = float(np.linalg.norm(model))
    return float(np.linalg.norm(data - model) / norm) if norm > 0 else float("inf")


def _checked_data(data, shape) -> np.ndarray:
    """The data as float64, ``(K, N)`` or ``(R, K, N)``, finite, not all zero, squarable."""
    data = np.asarray(data, dtype=np.float64)
    if data.ndim == 3 and data.shape[0] == 1:
        data = data[0]
    if data.shape != shape and data.shape[1:] != shape:
        raise DataError(f"data: shape {data.shape} is neither {shape} (one transient) nor "
                        f"(R, {shape[0]}, {shape[1]}) (R replicas) for the scene's sensors x bins")
    if not np.all(np.isfinite(data)):
        raise DataError("data: contains NaN or infinity; re-render or drop the replica")
    largest = float(np.max(np.abs(data))) if data.size else 0.0
    if largest > MAX_DATA:       # χ² and L2 norms square the values
        raise DataError(f"data: largest |y| is {largest:.3g}, beyond {MAX_DATA:g}, where their squares overflow "
                        f"float64; rescale the data")
    if largest == 0:
        raise DataError("data: every value is 0, no light to judge or fit; check the file against the scene")
    return data


def _check_options(replicas: int, stderr, shape_only: bool) -> None:
    """Refuse the combinations of data, ``stderr`` and ``shape_only`` that mean nothing."""
    if replicas == 2:
        raise DataError("data: two replicas give each bin's error one degree of freedom; give at least 3 "
                        "(or one transient with its standard error)")
    if replicas > 1 and (stderr is not None or shape_only):
        raise DataError("replicas carry their own error: give neither stderr nor shape_only with them")
    if stderr is not None and shape_only:
        raise DataError("shape_only: refused together with stderr (a standard error allows the real test)")
    if replicas == 1 and stderr is None and not shape_only:
        raise DataError("one transient without errors: give its standard error (--stderr FILE), several "
                        "independent replicas, or ask for a shape-only judgement (--shape-only)")


def _checked_stderr(stderr, dof, shape) -> np.ndarray:
    error = np.asarray(stderr, dtype=np.float64)
    if error.shape != shape:
        raise DataError(f"stderr: shape {error.shape} does not match the data's {shape}")
    if not np.all(np.isfinite(error)) or np.any(error < 0):
        raise DataError("stderr: must be finite and >= 0 in every bin")
    if dof is not None and not (isinstance(dof, (int, np.integer)) and dof >= 1):
        raise DataError(f"dof: the standard error's degrees of freedom must be an integer >= 1, got {dof!r}")
    return error


def _judged_bins(data, error, judged_by: str) -> np.ndarray:
    """Bins with a standard error, and one under MAX_RELATIVE_STDERR of the value; refuse when none."""
    positive = error > 0
    if not np.any(positive):
        if judged_by == "replicas":
            raise DataError("data: the replicas are equal in every bin (zero spread), so no bin has an error to "
                            "judge it by; give independent replicas (renders with different seeds)")
        raise DataError("stderr: the standard errors are all zero, so no bin has an error to judge it by; "
                        "give each bin's standard error (zero only where no sample landed)")
    mask = positive & (error < MAX_RELATIVE_STDERR * np.abs(data))
    if not np.any(mask):
        raise DataError(f"data: no bin has a standard error under {MAX_RELATIVE_STDERR:g} of its value "
                        f"({int(positive.sum())} bin(s) with an error): too noisy to judge; render more samples")
    return mask


def _fit_skipped(bins: int, scene: Scene, what: str) -> str | None:
    """Why no scale and offset are fitted to ``bins`` bins (``what`` they are), or None when they can be."""
    if bins >= FIT_BINS:
        return None
    total = scene.sensor_count * scene.sampling.count
    if total < FIT_BINS:
        return (f"no scale or time offset fitted: the scene's {total} bin(s) cannot fit them (two parameters "
                f"need at least {FIT_BINS} bins)")
    return (f"no scale or time offset fitted: only {bins} bin(s) {what}, and two parameters need at least "
            f"{FIT_BINS}")


def check_transient(scene: Scene, data, *, stderr=None, dof: int | None = None, shape_only: bool = False,
                    model=None, false_alarm: float = 1e-3, shape_tolerance: float = 1e-2,
                    expect: Convention | None = None, evaluate=None) -> CheckResult:
    """Judge a transient against the exact model of ``scene`` and fit its conventions.

    Parameters
    ----------
    scene : Scene
        The scene the data were rendered (or measured) from.
    data : array_like
        ``(K, N)`` one transient, or ``(R, K, N)`` R >= 3 independent
        replicas (renders with different seeds, our render's
        ``replicas.npy``, another tool's files); units of y. With replicas
        the per-bin error comes from their spread, and the limits of χ² and
        max |z| from their sign flips when R is large enough
        (:func:`validation.compare.replica_null_resolves`), which holds
        whatever the correlation between bins.
    stderr : array_like, optional
        ``(K, N)`` standard error of a single transient (units of y).
        Refused with replicas, whose error comes from their spread. Its
        limits assume independent bins (the result says so).
    dof : int, optional
        Degrees of freedom of ``stderr`` when it comes from replicas (our
        render's: ``replicas - 1``): z is then judged as Student's t.
        None: z is judged as normal.
    shape_only : bool
        Judge a single transient without ``stderr`` by shape only: relative
        L2 error against ``shape_tolerance``, unweighted fit. Refused
        together with ``stderr`` or replicas.
    model : array_like, optional
        ``forward(scene)`` (or ``evaluate(scene)``) if already computed.
    false_alarm : float
        α: probability that data consistent with the model fail (docs/design.md section 6).
    shape_tolerance : float
        Relative L2 error accepted when judging by shape only.
    expect : Convention, optional
        The convention the data are stated to follow (e.g.
        :func:`irradiancemeter`): they are judged against
        scale · y_model(start_opl + offset_opl) as well
        (:attr:`CheckResult.agrees_as_expected`).
    evaluate : callable, optional
        scene -> ``(K, N)``: judge and fit against this instead of the model
        (:class:`ShiftedModel`; e.g. :func:`validation.check.offset_model`,
        mitransient's estimator in closed form).

    Returns
    -------
    CheckResult

    Raises
    ------
    DataError
        Wrong shapes, NaN, a single transient with neither ``stderr`` nor
        ``shape_only``, contradictory options, standard errors all zero, or
        no bin precise enough to judge.

    Notes
    -----
    Replicas y_r: mean ȳ = Σ y_r / R, standard error
    se = sqrt(Σ (y_r - ȳ)² / (R (R - 1))), and z = (ȳ - y_model) / se follows
    Student's t with R - 1 degrees of freedom, which
    :func:`validation.compare.compare_transients` judges (so its limits
    keep their false-alarm rate α). The fit minimises
    Σ ((y_data - s y_model(t0 + δ)) / se)² over the judged bins
    (:func:`fit_scale_offset`), and needs :data:`FIT_BINS` of them: with
    fewer (a one-bin scene) the data are judged as given only, and the
    result says so. The verdict after the fit uses the same limits (two
    fitted parameters against D judged bins: a 2/D effect).
    """
    shape = (scene.sensor_count, scene.sampling.count)
    data = _checked_data(data, shape)
    replicas = 1 if data.ndim == 2 else data.shape[0]
    _check_options(replicas, stderr, shape_only)
    model_at = ShiftedModel(scene, model, evaluate)
    y_model = model_at(0.0)
    if y_model.shape != shape:
        raise DataError(f"model: shape {y_model.shape}, expected {shape}")
    if shape_only:
        return _judge_by_shape(scene, data, model_at, expect, shape_tolerance)
    if replicas > 1:
        mean = data.mean(axis=0)
        error = data.std(axis=0, ddof=1) / math.sqrt(replicas)
        # bit-identical replicas have no spread, but their mean's round-off gives std ~1e-17 and z ~1e15
        error[np.all(data == data[0], axis=0)] = 0.0
        return _judge_with_errors(scene, mean, error, replicas - 1, data, model_at, expect, false_alarm)
    return _judge_with_errors(scene, data, _checked_stderr(stderr, dof, shape), dof, None, model_at, expect,
                              false_alarm)


def _precise_model(scene, data, error, model_at: ShiftedModel) -> tuple[ShiftedModel, float | None]:
    """The model at the tolerance the data's errors need (:func:`validation.compare.model_tolerance_for`)
    and that tolerance, or ``model_at`` and None when the scene's serves."""
    tolerance = model_tolerance_for(scene.tolerance, data, error, MAX_RELATIVE_STDERR)
    if tolerance is None:
        return model_at, None
    return ShiftedModel(scene.replace(tolerance=tolerance), None, model_at.evaluate), tolerance


def _expected_model(model_at, expect: Convention | None) -> np.ndarray | None:
    """scale · y_model(start_opl + offset_opl) (+ added) of the stated convention (None without one)."""
    if expect is None:
        return None
    expected = expect.scale * model_at(expect.offset_opl)
    if expect.added is not None:
        if expect.added.shape != expected.shape:
            raise DataError(f"expect: the stated difference has shape {expect.added.shape}, the model "
                            f"{expected.shape}")
        expected = expected + expect.added
    return expected


def _judge_with_errors(scene, data, error, dof, replica_data, model_at, expect, false_alarm) -> CheckResult:
    """The statistical verdicts: as given, as stated, and after the fitted scale and offset.

    ``replica_data``: the ``(R, K, N)`` replicas ``data`` and ``error`` come from, or None for a
    transient with its standard error.
    """
    judged_by = "stderr" if replica_data is None else "replicas"
    mask = _judged_bins(data, error, judged_by)
    floor = MIN_RELATIVE_STDERR * max(float(np.max(np.abs(data))), float(np.max(np.abs(model_at(0.0)))))
    if np.any(error[mask] < floor):
        raise DataError(f"{'data' if judged_by == 'replicas' else 'stderr'}: {int(np.sum(error[mask] < floor))} "
                        f"bin(s) have a standard error under {MIN_RELATIVE_STDERR:g} of the largest |y|, where "
                        f"z squared overflows; give each bin's standard error in the units of y")
    model_at, model_tolerance = _precise_model(scene, data, error, model_at)   # after refusals: it can be slow
    y_model = model_at(0.0)
    expected_model = _expected_model(model_at, expect)
    if not np.any(y_model[mask] != 0):
        raise DataError("scene: the model puts no light in the bins the data fill; check the scene's "
                        "sampling (start, period, count) against the data's")
    as_given = _agreement(data, error, y_model, dof, false_alarm, replica_data)
    as_expected = (None if expected_model is None
                   else _agreement(data, error, expected_model, dof, false_alarm, replica_data))
    skipped = _fit_skipped(int(mask.sum()), scene, f"have a standard error under {MAX_RELATIVE_STDERR:g} of "
                                                   f"their value")
    fit = after = None
    fitted = y_model
    if skipped is None:
        fit = fit_scale_offset(data, np.where(mask, error, 1.0), mask, model_at, scene.sampling.bin_width_opl,
                               replicas=replica_data)
        fitted = fit.scale * model_at(fit.offset_opl)
        after = _agreement(data, error, fitted, dof, false_alarm, replica_data)
        diagnosis = diagnose(fit, agrees=as_given.agrees, agrees_after_fit=after.agrees,
                             bin_width_opl=scene.sampling.bin_width_opl)
    else:
        diagnosis = f"{'agrees' if as_given.agrees else 'disagrees'} as given; {skipped}."
    low, high = as_given.chi2_interval
    if not as_given.agrees and as_given.chi2_per_dof < low and as_given.max_abs_z <= as_given.z_threshold:
        # refused only for fitting too well: no scale or offset explains that, and "a bug?" would mislead
        diagnosis = (f"disagrees only by χ²/dof = {as_given.chi2_per_dof:.3g} below its accept interval "
                     f"[{low:.3g}, {high:.3g}]: the data lie closer to the model than their standard errors "
                     f"allow (errors overstated, or data that are not noisy estimates: the model itself?).")
    return CheckResult(
        agrees=bool(as_given.agrees), judged_by=judged_by, relative_l2=_relative_l2(data, y_model),
        diagnosis=diagnosis, data=data, model=y_model, fitted_model=fitted, edges=scene.sampling.edges,
        stderr=error, replicas=1 if replica_data is None else replica_data.shape[0], dof=dof, as_given=as_given,
        fit=fit, fit_skipped=skipped, agrees_after_fit=None if after is None else bool(after.agrees),
        relative_l2_after_fit=None if fit is None else _relative_l2(data, fitted), after_fit=after,
        expected=expect, agrees_as_expected=None if as_expected is None else bool(as_expected.agrees),
        relative_l2_as_expected=None if expected_model is None else _relative_l2(data, expected_model),
        as_expected=as_expected, model_tolerance=model_tolerance, scene_tolerance=scene.tolerance,
        replica_data=replica_data)


def _judge_by_shape(scene, data, model_at, expect, shape_tolerance) -> CheckResult:
    """Relative L2 errors as given, as stated and after an unweighted fit: no statistical test."""
    y_model = model_at(0.0)
    expected_model = _expected_model(model_at, expect)
    shape = y_model.shape
    if not np.any(y_model != 0):
        raise DataError("scene: the model puts no light in the window; check the scene's sampling (start, "
                        "period, count) against the data's")
    mask = (y_model != 0) | (data != 0)
    relative = _relative_l2(data, y_model)
    agrees = bool(relative <= shape_tolerance)
    skipped = _fit_skipped(int(mask.sum()), scene, "hold light")
    fit, fitted, relative_fit, agrees_fit = None, y_model, None, None
    if skipped is None:
        fit = fit_scale_offset(data, np.ones(shape), mask, model_at, scene.sampling.bin_width_opl,
                               sigma_known=False)
        fitted = fit.scale * model_at(fit.offset_opl)
        relative_fit = _relative_l2(data, fitted)
        agrees_fit = bool(relative_fit <= shape_tolerance)
        verdict = diagnose(fit, agrees=agrees, agrees_after_fit=agrees_fit,
                           bin_width_opl=scene.sampling.bin_width_opl)
    else:
        verdict = f"{'agrees' if agrees else 'disagrees'} as given; {skipped}."
    relative_expected = None if expected_model is None else _relative_l2(data, expected_model)
    return CheckResult(
        agrees=agrees, judged_by="shape", relative_l2=relative,
        diagnosis="judged by shape only (no errors given, no statistical test): " + verdict, data=data,
        model=y_model, fitted_model=fitted, edges=scene.sampling.edges, fit=fit, fit_skipped=skipped,
        agrees_after_fit=agrees_fit, relative_l2_after_fit=relative_fit, expected=expect,
        agrees_as_expected=None if expect is None else bool(relative_expected <= shape_tolerance),
        relative_l2_as_expected=relative_expected, shape_tolerance=shape_tolerance)

