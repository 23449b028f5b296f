"""The verdict of ``check``: a transient from any tool judged against the exact model, as given and after a fit.

``check_transient(scene, data, ...)`` compares y from anywhere (our render,
another renderer, a measurement) with ``analytic.operator.matrix_free.forward(scene)``
in two steps:

1. **As given.** z = (y_data - y_model) / se per bin, judged by
   :func:`validation.judging.compare.compare_transients` (docs/design.md section 6).
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
import numbers

import numpy as np

from analytic.errors import DataError, OptionError
from analytic.scenes.common import Scene
from validation.judging.arrays import false_alarm_rate, real_array
from validation.judging.compare import Agreement, compare_transients, judged_bins, model_tolerance_for

from .conventions import Convention, check_expect, convention, diagnose
from .fit import ShiftedModel, fit_scale_offset
from .inputs import PYTHON_WORDS, Words, read_inputs, scene_of
from .result import CheckResult

__all__ = ["CheckResult", "check_transient", "check_derivative", "DerivativeColumn", "judge", "FIT_BINS", "MAX_DATA", "MAX_RELATIVE_STDERR",
           "DERIVATIVE_STEP"]

#: Largest |y| accepted: the squares that χ² and the L2 norms form stay float64 numbers.
MAX_DATA = 1e150

#: Bins are judged (and fitted) only where se < this x |y_data| (as compare_transients).
MAX_RELATIVE_STDERR = 0.1

#: Smallest standard error judged, relative to the largest |y| (data or model): below it z² overflows float64.
MIN_RELATIVE_STDERR = 1e-100

#: Fewest judged bins that a scale and a time offset are fitted to (two parameters and a residual).
FIT_BINS = 3

#: Step of the model's derivative along a time offset, in bins (the fit's: its models are reused).
DERIVATIVE_STEP = 1e-3


def _agreement(data, stderr, model, dof, false_alarm, replicas=None, directions=None) -> Agreement:
    """compare_transients: Student-t z on ``dof`` degrees of freedom, the replicas' own null when given, and
    the directed tests along ``directions``."""
    return compare_transients(data, stderr, model, dof=np.inf if dof is None and replicas is None else dof,
                              replicas=replicas, false_alarm=false_alarm, max_relative_stderr=MAX_RELATIVE_STDERR,
                              directions=directions)


def _relative_l2(data, model) -> float:
    norm = float(np.linalg.norm(model))
    return float(np.linalg.norm(data - model) / norm) if norm > 0 else float("inf")


def _checked_data(data: np.ndarray, words: Words) -> np.ndarray:
    """Data that χ² and L2 norms can square, with light to judge."""
    largest = float(np.max(np.abs(data))) if data.size else 0.0
    if largest > MAX_DATA:       # χ² and L2 norms square the values
        raise DataError(f"{words.data}: largest |y| is {largest:.3g}, beyond {MAX_DATA:g}, where their squares "
                        f"overflow float64; rescale the data")
    if largest == 0:
        raise DataError(f"{words.data}: every value is 0, no light to judge or fit; check the data against the "
                        f"scene")
    return data


def _judged_bins(data, error, replica_data, words: Words) -> np.ndarray:
    """The bins judged (:func:`validation.judging.compare.judged_bins`); refuse when none."""
    positive = error > 0
    if not np.any(positive):
        if replica_data is not None:
            raise DataError(f"{words.data}: the replicas are equal in every bin (zero spread), so no bin has an "
                            f"error to judge it by; give independent replicas (renders with different seeds)")
        raise DataError(f"{words.stderr}: the standard errors are all zero, so no bin has an error to judge it "
                        f"by; give each bin's standard error (zero only where no sample landed)")
    mask = judged_bins(data, error, MAX_RELATIVE_STDERR, replica_data)
    if not np.any(mask):
        raise DataError(f"{words.data}: no bin has a standard error under {MAX_RELATIVE_STDERR:g} of its value "
                        f"(about 100 samples; {int(positive.sum())} bin(s) with an error): too noisy to judge; "
                        f"render more samples")
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


def check_transient(scene, data, *, stderr=None, dof: int | None = None, shape_only: bool = False,
                    model=None, false_alarm: float = 1e-3, shape_tolerance: float = 1e-2, expect=None,
                    radius: float | None = None, evaluate=None) -> CheckResult:
    """Judge a transient against the exact model of ``scene`` and fit its conventions: ``check``'s work.

    Parameters
    ----------
    scene : Scene, RelayWallScene, str or Path
        The scene the data were rendered (or measured) from, or its file
        (TOML, or a tal YAML configuration), as ``check``'s SCENE.
    data : array_like, str, Path or list
        What ``check --data`` reads, in memory or by path
        (:mod:`validation.check.inputs`): one ``(K, N)`` transient (with
        ``stderr``), ``(R, K, N)`` R >= 3 independent replicas (renders with
        different seeds, our render's ``replicas.npy``, another tool's
        files) or a list of them, mitransient's films as ``np.array(film)``
        gives them (any of their shapes, sensors stacked or a list of one
        per sensor), a file or folder (our render's folder brings its own
        replicas or standard error; tal's HDF5 captures), or a list of
        files (replicas). Units of y. With replicas the per-bin error comes
        from their spread, and the limits of χ² and max |z| from their sign
        flips when R is large enough
        (:func:`validation.judging.compare.replica_null_resolves`), which holds
        whatever the correlation between bins.
    stderr : array_like, str or Path, optional
        ``(K, N)`` standard error of a single transient (units of y), or
        its file. Refused with replicas, whose error comes from their
        spread. Its limits assume independent bins (the result says so).
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
        α: probability that data consistent with the model fail
        (docs/design.md section 6), in [1e-12, 0.5].
    shape_tolerance : float
        Relative L2 error accepted when judging by shape only (> 0).
    expect : str or Convention, optional
        The convention the data are stated to follow: ``check --expect``'s
        names (``"irradiancemeter"``: mitransient's irradiancemeter spheres
        of radius ``radius``; ``"transient_nlos_path"``: its NLOS
        integrator) or a :class:`~validation.check.Convention`. The data
        are judged against scale · y_model(start_opl + offset_opl) as well,
        the fitted scale and offset tested against the stated ones
        (:attr:`CheckResult.agrees_as_expected`, :attr:`CheckResult.verdict`).
    radius : float, optional
        ``expect="irradiancemeter"``: the spheres' radius, metres (default
        the export's, :data:`interop.mitransient.export.RADIUS`).
    evaluate : callable, optional
        scene -> ``(K, N)``: judge and fit against this instead of the model
        (:class:`ShiftedModel`; e.g. :func:`interop.mitransient.offset_model`,
        mitransient's estimator in closed form).

    Returns
    -------
    CheckResult

    Raises
    ------
    DataError
        What ``check`` refuses: unreadable files, arrays that are not real
        and finite, shapes other than the scene's, a single transient with
        neither ``stderr`` nor ``shape_only``, contradictory options,
        standard errors all zero, or no bin precise enough to judge.
    OptionError
        ``false_alarm``, ``dof``, ``shape_tolerance``, ``expect`` or
        ``radius`` out of range or unknown.
    SceneError
        A bad scene file.

    Notes
    -----
    Replicas y_r: mean ȳ = Σ y_r / R, standard error
    se = sqrt(Σ (y_r - ȳ)² / (R (R - 1))), and z = (ȳ - y_model) / se follows
    Student's t with R - 1 degrees of freedom, which
    :func:`validation.judging.compare.compare_transients` judges (so its limits
    keep their false-alarm rate α). The fit minimises
    Σ ((y_data - s y_model(t0 + δ)) / σ)² over the judged bins
    (:func:`fit_scale_offset`), and needs :data:`FIT_BINS` of them: with
    fewer (a one-bin scene) the data are judged as given only, and the
    result says so. The verdicts as given and as stated also test the
    data's scale and offset against the stated ones along the model's
    derivatives (:mod:`validation.judging.directed`: their power is
    :attr:`CheckResult.detectable`); the verdict after the fit uses the
    same limits (two fitted parameters against D judged bins: a 2/D
    effect).
    """
    return judge(scene, data, stderr=stderr, dof=dof, shape_only=shape_only, model=model, false_alarm=false_alarm,
                 shape_tolerance=shape_tolerance, expect=expect, radius=radius, evaluate=evaluate)


class DerivativeColumn:
    """scene -> ``(K, N)`` ∂y/∂θ of one parameter (:func:`analytic.jacobian`'s column): what
    :func:`check_derivative` judges data against, shifted and fitted as ``check`` shifts and fits y."""

    def __init__(self, key: str):
        self.key = key

    def __call__(self, scene) -> np.ndarray:
        from analytic.operator.derivatives import jacobian

        return jacobian(scene, [self.key])[..., 0]


def check_derivative(scene, data, key: str, *, stderr=None, dof: int | None = None, false_alarm: float = 1e-3,
                     expect=None, radius: float | None = None) -> CheckResult:
    """Judge data that claim to be ∂y/∂θ (a differentiable renderer's forward-mode derivative) against the
    exact column: ``check --derivative KEY``'s work.

    Parameters
    ----------
    scene, data, stderr, dof, false_alarm, expect, radius
        As :func:`check_transient`; ``data`` (replicas, or one array with ``stderr``) in y's units per
        unit of θ.
    key : str
        The parameter θ, a key of docs/design.md section 9 (``sensors.positions.0.z``, ``sampling.start``).

    Returns
    -------
    CheckResult
        Its "model" is the exact column ∂y/∂θ (:class:`DerivativeColumn`), its fit a scale (a derivative
        off by a factor) and a time offset of the column, its verdicts section 6's statistics.

    Raises
    ------
    OptionError
        ``key`` is no parameter of the scene; and what :func:`check_transient` raises.
    """
    from analytic.operator.parameters import parameter

    scene = scene_of(scene)
    column = DerivativeColumn(parameter(scene, key).key)     # a bad key: before any reading
    return judge(scene, data, stderr=stderr, dof=dof, false_alarm=false_alarm, expect=expect, radius=radius,
                 evaluate=column)


def judge(scene, data, *, stderr=None, dof=None, shape_only=False, model=None, false_alarm=1e-3,
          shape_tolerance=1e-2, expect=None, radius=None, evaluate=None, words: Words = PYTHON_WORDS) -> CheckResult:
    """:func:`check_transient`, its messages in ``words`` (the command line's: ``check`` calls this)."""
    scene = scene_of(scene)
    false_alarm = false_alarm_rate(false_alarm)
    if isinstance(shape_tolerance, bool) or not (isinstance(shape_tolerance, numbers.Real)
                                                 and math.isfinite(shape_tolerance) and shape_tolerance > 0):
        raise OptionError(f"shape_tolerance: must be a finite number > 0, got {shape_tolerance!r}")
    check_expect(expect, scene, radius, words)                 # before any reading: a typo costs nothing
    inputs = read_inputs(scene, data, stderr, dof=dof, shape_only=shape_only, words=words)
    data = _checked_data(inputs.data, words)
    shape = (scene.sensor_count, scene.sampling.count)
    model_at = ShiftedModel(scene, None if model is None else real_array("model", model), evaluate)
    y_model = model_at(0.0)
    if y_model.shape != shape:
        raise DataError(f"model: shape {y_model.shape}, expected {shape}")
    expect = convention(expect, scene, radius, words, model=y_model)  # after the data: an emulation takes a while
    if shape_only:
        return _judge_by_shape(scene, data, model_at, expect, shape_tolerance, words)
    if inputs.replicas > 1:
        mean = data.mean(axis=0)
        unit = float(np.max(np.abs(data)))          # y ~ 1e-300: the squared deviations would underflow
        error = (data / unit).std(axis=0, ddof=1) * (unit / math.sqrt(inputs.replicas))
        # bit-identical replicas have no spread, but their mean's round-off gives std ~1e-17 and z ~1e15
        error[np.all(data == data[0], axis=0)] = 0.0
        return _judge_with_errors(scene, mean, error, inputs.replicas - 1, data, model_at, expect, false_alarm,
                                  words)
    return _judge_with_errors(scene, data, inputs.stderr, inputs.dof, None, model_at, expect, false_alarm, words)


def _precise_model(scene, data, error, model_at: ShiftedModel) -> tuple[ShiftedModel, float | None]:
    """The model at the tolerance the data's errors need (:func:`validation.judging.compare.model_tolerance_for`)
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


def _directions(model_at: ShiftedModel, scale: float, offset: float, bin_width_opl: float) -> np.ndarray:
    """``(2, K, N)`` the stated model's derivatives along a relative scale error and a time offset:
    s y(δ) and s ∂y/∂δ (a forward difference of :data:`DERIVATIVE_STEP` bins, as the fit's)."""
    step = DERIVATIVE_STEP * bin_width_opl
    at = model_at(offset)
    return np.stack([scale * at, scale * (model_at(offset + step) - at) / step])


def _judge_with_errors(scene, data, error, dof, replica_data, model_at, expect, false_alarm,
                       words: Words) -> CheckResult:
    """The statistical verdicts: as given, as stated, and after the fitted scale and offset.

    ``replica_data``: the ``(R, K, N)`` replicas ``data`` and ``error`` come from, or None for a
    transient with its standard error.
    """
    judged_by = "stderr" if replica_data is None else "replicas"
    mask = _judged_bins(data, error, replica_data, words)
    floor = MIN_RELATIVE_STDERR * max(float(np.max(np.abs(data))), float(np.max(np.abs(model_at(0.0)))))
    if np.any(error[mask] < floor):
        raise DataError(f"{words.data if judged_by == 'replicas' else words.stderr}: {int(np.sum(error[mask] < floor))} "
                        f"bin(s) have a standard error under {MIN_RELATIVE_STDERR:g} of the largest |y|, where "
                        f"z squared overflows; give each bin's standard error in the units of y")
    model_at, model_tolerance = _precise_model(scene, data, error, model_at)   # after refusals: it can be slow
    y_model = model_at(0.0)
    expected_model = _expected_model(model_at, expect)
    if not np.any(y_model[mask] != 0):
        raise DataError("scene: the model puts no light in the bins the data fill; check the scene's "
                        "sampling (start, period, count) against the data's")
    width = scene.sampling.bin_width_opl
    as_given = _agreement(data, error, y_model, dof, false_alarm, replica_data,
                          directions=_directions(model_at, 1.0, 0.0, width))
    as_expected = (None if expected_model is None else _agreement(
        data, error, expected_model, dof, false_alarm, replica_data,
        directions=_directions(model_at, expect.scale, expect.offset_opl, width)))
    skipped = _fit_skipped(int(mask.sum()), scene, f"have a standard error under {MAX_RELATIVE_STDERR:g} of "
                                                   f"their value")
    fit = after = None
    fitted = y_model
    if skipped is None:
        # fitted in units of the largest value: the fit squares y (its weights, its replicas' spread)
        unit = float(np.max(np.abs(data)))
        fit = fit_scale_offset(data / unit, np.where(mask, error / unit, 1.0), mask,
                               lambda offset: model_at(offset) / unit, scene.sampling.bin_width_opl,
                               replicas=None if replica_data is None else replica_data / unit)
        fitted = fit.scale * model_at(fit.offset_opl)
        after = _agreement(data, error, fitted, dof, false_alarm, replica_data)
        diagnosis = diagnose(fit, agrees=as_given.agrees, agrees_after_fit=after.agrees,
                             bin_width_opl=scene.sampling.bin_width_opl, stating=words.stating("irradiancemeter"))
    else:
        diagnosis = f"{'agrees' if as_given.agrees else 'disagrees'} as given; {skipped}."
    low, high = as_given.chi2_interval
    if (not as_given.agrees and as_given.chi2_per_dof < low and as_given.max_abs_z <= as_given.z_threshold
            and (as_given.directed is None or as_given.directed.agrees)):
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
        replica_data=replica_data, false_alarm=false_alarm)


def _judge_by_shape(scene, data, model_at, expect, shape_tolerance, words: Words) -> CheckResult:
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
                           bin_width_opl=scene.sampling.bin_width_opl, stating=words.stating("irradiancemeter"))
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

