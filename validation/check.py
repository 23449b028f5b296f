"""Judge a transient from any tool against the exact model, and diagnose its conventions.

``check_transient(scene, data, ...)`` compares y from anywhere (our render,
another renderer, a measurement) with ``analytic.system.forward(scene)``
in two steps:

1. **As given.** z = (y_data - y_model) / se per bin, judged by
   :func:`validation.compare.compare_transients` (DESIGN.md section 6).
   The per-bin error se comes from ``stderr`` for one transient, or from R
   independent replicas (mean and standard error of the mean; z then
   follows Student's t with R - 1 degrees of freedom).
2. **After the two convention errors users make**: a global scale s and a
   time offset δ, y_data[n] ≈ s y_model(t0 + δ)[n], fitted by weighted least
   squares (Gauss–Newton on the exact model evaluated at the shifted
   start), with standard errors, and the verdict again against
   s y_model(t0 + δ). ``scale`` is data / model; ``offset_opl`` is what must
   be added to the data's start_opl for it to match the model, positive when
   the data read path lengths short (DESIGN.md section 5).

One transient without ``stderr`` carries no noise level: it is judged by
shape only (relative L2 error against ``shape_tolerance``, the same fit
unweighted) and only when asked (``shape_only=True``), and the result says so.

Readers (:func:`read_data`) accept our ``transient.npy`` / ``transient.exr``
(or their folder), a ``(K, N)`` ``.npy`` from any tool, tal's HDF5 capture
(``analytic.capture``), and mitransient's film output (see
:func:`read_data`). A bad file raises :class:`DataError` with one line.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analytic.errors import DataError
from analytic.scene import Sampling, Scene
from validation.compare import Agreement, compare_transients

__all__ = ["Fit", "CheckResult", "check_transient", "fit_scale_offset", "read_data",
           "read_stderr", "stderr_beside", "diagnose", "write_check_report", "KNOWN_SCALES", "MAX_RELATIVE_STDERR"]

#: Largest |y| accepted: the squares that χ² and the L2 norms form stay float64 numbers.
MAX_DATA = 1e150

#: Bins are judged (and fitted) only where se < this x |y_data| (as compare_transients).
MAX_RELATIVE_STDERR = 0.1

# Relative accuracy of the model (the system matrix's default tolerance): a
# fitted scale within it of 1, or an offset within it of a bin of 0, is none.
_RESOLUTION = 1e-6

#: Scale factors (data / model) that a known convention explains.
KNOWN_SCALES = (
    (1.0, "reads the fluence, as the model"),
    (0.25, "reads 1/4 of the fluence (the mean irradiance over a small sphere)"),
    (4.0, "reads 4 times the fluence"),
    (1.0 / math.pi, "reads 1/π of the fluence (an extra 1/π: BRDF or sensor normalisation)"),
    (math.pi, "reads π times the fluence (a missing 1/π: BRDF or sensor normalisation)"),
    (0.25 / math.pi, "reads radiance averaged over directions (fluence / 4π)"),
    (4.0 * math.pi, "reads 4π times the fluence"),
)


# --------------------------------------------------------------------------- readers

def _time_axis(name: str, start: float, width: float, sampling: Sampling) -> None:
    """Refuse a file whose time axis differs from the scene's (float32 storage allowed)."""
    slack = 1e-6 * sampling.bin_width_opl + 2.0**-23 * abs(sampling.start_opl)
    if abs(start - sampling.start_opl) > slack or abs(width - sampling.bin_width_opl) > 2.0**-22 * width:
        raise DataError(f"{name}: time axis start_opl = {start:.9g} m, bin_width_opl = {width:.9g} m "
                        f"differs from the scene's {sampling.start_opl:.9g} m, {sampling.bin_width_opl:.9g} m; "
                        f"check it against the scene it was rendered from")


def _meta_time_axis(path: Path, sampling: Sampling) -> None:
    """Check the time axis recorded in a ``meta.json`` beside our output, when there is one."""
    meta_path = path.parent / "meta.json"
    if not meta_path.is_file():
        return
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, json.JSONDecodeError):
        return   # not ours: nothing to compare
    width = meta.get("bin_width_opl")
    if "start_opl" in meta and width is not None:
        _time_axis(f"{path} (meta.json)", float(meta["start_opl"]), float(width), sampling)


def _our_exr(path: Path, sampling: Sampling) -> np.ndarray:
    from analytic.io import read_exr

    data, header = read_exr(path)
    if "start_opl" in header and "bin_width_opl" in header:
        _time_axis(str(path), float(header["start_opl"]), float(header["bin_width_opl"]), sampling)
    return data


def _film_channels(name: str, array: np.ndarray) -> np.ndarray:
    """Last axis of a mitransient film: one channel (mono variants) or three equal ones (RGB)."""
    channels = array.shape[-1]
    if channels == 1:
        return array[..., 0]
    if channels == 3:
        spread = np.max(np.abs(array - array.mean(axis=-1, keepdims=True)))
        if spread > 1e-5 * max(float(np.max(np.abs(array))), np.finfo(float).tiny):
            raise DataError(f"{name}: the three colour channels differ; the scene is grey, "
                            f"render it in a mono variant (llvm_ad_mono)")
        return array.mean(axis=-1)
    raise DataError(f"{name}: {channels} channels in the last axis; expected 1 (mono) or 3 (RGB) "
                    f"as mitransient's developed film holds")


def _film_tensor(name: str, array: np.ndarray, sensors: int) -> np.ndarray:
    """mitransient's developed ``transient_hdr_film`` tensor(s) -> ``(K, N)``.

    ``(height, width, bins, channels)`` for one sensor, or ``(K, height,
    width, bins, channels)`` for the K sensors stacked; each film is 1 x 1
    (an irradiancemeter's).
    """
    if array.ndim == 4:
        array = array[None]
    if array.shape[1:3] != (1, 1):
        raise DataError(f"{name}: film of {array.shape[1]} x {array.shape[2]} pixels; one sensor is one "
                        f"1 x 1 irradiancemeter film (shape (1, 1, bins, channels))")
    if array.shape[0] != sensors:
        raise DataError(f"{name}: {array.shape[0]} film(s) for the scene's {sensors} sensors; stack one "
                        f"film per sensor, in the scene's order, as (K, 1, 1, bins, channels)")
    return _film_channels(name, array[:, 0, 0])


_FRAME = re.compile(r"^(\d+)\.exr$")


def _frames(path: Path, frames: list[Path], sensors: int) -> np.ndarray:
    """mitransient's ``vis.save_frames`` folder (``000.exr`` ... one image per bin) -> ``(1, N)``."""
    import OpenEXR

    if sensors != 1:
        raise DataError(f"{path}: a folder of frames holds one sensor, the scene has {sensors}; "
                        f"save the films with numpy instead (see validation.check.read_data)")
    values = []
    for frame in frames:
        try:
            with OpenEXR.File(str(frame)) as handle:
                channels = handle.channels()
                # The Python binding groups R, G, B into one "RGB" channel of shape (h, w, 3).
                name = next((n for n in ("Y", "RGB") if n in channels), None)
                if name is None:
                    raise DataError(f"{frame}: no Y or RGB channel (channels {sorted(channels)})")
                image = np.array(channels[name].pixels, dtype=np.float64)
        except DataError:
            raise
        except Exception as error:   # OpenEXR raises bare exceptions for unreadable files
            raise DataError(f"{frame}: not a readable EXR ({error})") from None
        image = image.reshape(image.shape[:2] + (-1,))
        if image.shape[:2] != (1, 1):
            raise DataError(f"{frame}: a {image.shape[0]} x {image.shape[1]} frame; one sensor is a "
                            f"1 x 1 irradiancemeter film")
        values.append(_film_channels(str(frame), image[0, 0][None])[0])
    return np.array(values, dtype=np.float64)[None, :]


def _capture(path: Path, scene: Scene) -> np.ndarray:
    from analytic.capture import CaptureError, read_capture

    try:
        capture = read_capture(path)
    except CaptureError as error:
        raise DataError(str(error)) from None
    _time_axis(str(path), capture.start_opl, capture.bin_width_opl, scene.sampling)
    tolerance = 1e-6 + 2.0**-22 * float(np.max(np.abs(scene.sensors)))
    if capture.source is not None and np.max(np.abs(capture.source - scene.source)) > tolerance:
        raise DataError(f"{path}: laser_xyz {capture.source.tolist()} is not the scene's source "
                        f"{scene.source.tolist()}; check it against the scene it was rendered from")
    transient = capture.transient
    if capture.sensors is None or transient.shape[0] != scene.sensor_count:
        return transient   # the shape check in read_data reports a count mismatch
    # Sensors by position: a T_Sx_Sy grid may be flattened in another order than the scene's.
    order = []
    for k, position in enumerate(scene.sensors):
        distance = np.max(np.abs(capture.sensors - position), axis=1)
        j = int(np.argmin(distance))
        if distance[j] > tolerance or j in order:
            raise DataError(f"{path}: no sensor of sensor_grid_xyz at the scene's sensor {k} "
                            f"{position.tolist()}; check it against the scene it was rendered from")
        order.append(j)
    return transient[order]


def read_data(path: str | Path, scene: Scene) -> np.ndarray:
    """Read one transient of ``scene`` from any of the formats users produce.

    Parameters
    ----------
    path : str or Path
        One of:

        - our output: ``transient.npy`` or ``transient.exr`` (channel Y,
          width = bins, height = sensors), or the folder holding them; the
          time axis in ``meta.json`` or the EXR header is checked;
        - a ``(K, N)`` float ``.npy`` from any tool (sensors in the scene's
          order, bins on the scene's time axis);
        - tal's HDF5 capture (``.h5`` / ``.hdf5``, H in T_Si or T_Sx_Sy
          layout): time axis and source checked, sensors matched to the
          scene's by position;
        - mitransient's developed film, as its users save it:
          ``np.save(f, np.array(mi.render(scene, sensor=k)[1]))`` gives
          ``(1, 1, N, C)`` for one sensor; the K sensors of an exported
          scene stacked in the scene's order give ``(K, 1, 1, N, C)``;
          C = 1 (mono variants) or 3 equal channels (RGB). Or, for a
          one-sensor scene, the folder of ``000.exr``, ``001.exr``, ...
          that ``mitransient.vis.save_frames`` writes. mitransient's files
          carry no time axis: the film's ``start_opl`` and
          ``bin_width_opl`` must be the scene's (the exported scene's are).
    scene : Scene
        The scene the data were rendered from.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64 y_k[n], sensors in the scene's order.

    Raises
    ------
    DataError
        No such file, unknown format, wrong shape, a time axis, source or sensor
        positions other than the scene's, NaN or infinity.
    """
    path = Path(path)
    sensors, bins = scene.sensor_count, scene.sampling.count
    if not path.exists():
        raise DataError(f"{path}: no such file or folder")
    name = str(path)
    if path.is_dir():
        ours = [path / n for n in ("transient.npy", "transient.exr") if (path / n).is_file()]
        frames = sorted((p for p in path.iterdir() if _FRAME.match(p.name)),
                        key=lambda p: int(_FRAME.match(p.name).group(1)))
        if ours:
            return read_data(ours[0], scene)
        if not frames:
            raise DataError(f"{path}: a folder with neither transient.npy/.exr nor 000.exr frames; "
                            f"give the data file itself")
        data = _frames(path, frames, sensors)
    elif path.suffix.lower() in (".h5", ".hdf5"):
        data = _capture(path, scene)
    elif path.suffix.lower() == ".npy":
        try:
            array = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as error:
            raise DataError(f"{path}: not a readable .npy ({error})") from None
        if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
            raise DataError(f"{path}: dtype {array.dtype} is not a real number type; save y as float64")
        array = np.asarray(array, dtype=np.float64)
        if array.ndim in (4, 5):
            data = _film_tensor(name, array, sensors)
        else:
            _meta_time_axis(path, scene.sampling)
            data = array
    elif path.suffix.lower() == ".exr":
        data = _our_exr(path, scene.sampling)
        _meta_time_axis(path, scene.sampling)
    else:
        raise DataError(f"{path}: unknown format (expected .npy, .exr, .h5/.hdf5 or a folder of them)")
    if data.shape != (sensors, bins):
        hint = ("it looks transposed: save (sensors, bins)" if data.shape == (bins, sensors)
                else f"save a ({sensors}, {bins}) array of the scene's sensors and bins")
        raise DataError(f"{path}: shape {data.shape} does not match the scene's {sensors} sensors x "
                        f"{bins} bins; {hint}")
    if not np.all(np.isfinite(data)):
        bad = int(np.sum(~np.isfinite(data)))
        raise DataError(f"{path}: {bad} value(s) are NaN or infinite; re-render or drop the file")
    return data


def stderr_beside(path: str | Path, scene: Scene) -> tuple[np.ndarray, int | None] | None:
    """Our render's own standard error for its output (folder, ``transient.npy`` or ``.exr``).

    Returns
    -------
    tuple or None
        (``stderr.npy`` beside the data, the render's ``dof`` from
        ``meta.json``, None when absent), or None when ``path`` is not one of
        our render's outputs.
    """
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    if not (path.is_dir() or path.name in ("transient.npy", "transient.exr")):
        return None
    if not (folder / "stderr.npy").is_file():
        return None
    dof = None
    try:
        dof = json.loads((folder / "meta.json").read_text(encoding="utf-8")).get("dof")
    except (OSError, ValueError, AttributeError):
        pass
    return read_stderr(folder / "stderr.npy", scene), dof if isinstance(dof, int) and dof >= 1 else None


def read_stderr(path: str | Path, scene: Scene) -> np.ndarray:
    """Read a per-bin standard error (any :func:`read_data` format); it must be >= 0."""
    error = read_data(path, scene)
    if np.any(error < 0):
        raise DataError(f"{path}: {int(np.sum(error < 0))} negative standard error(s); "
                        f"give the standard error of each bin (>= 0)")
    return error


# --------------------------------------------------------------------------- the fit

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
        Whether the steps fell below 1 % of the standard errors.
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


class _ShiftedModel:
    """y_model with bin edges moved by δ: forward(scene) with start_opl + δ, memoised."""

    def __init__(self, scene: Scene, model: np.ndarray | None):
        self.scene = scene
        self.cache = {} if model is None else {0.0: np.asarray(model, dtype=np.float64)}

    def __call__(self, offset: float) -> np.ndarray:
        from analytic.system import forward

        offset = float(offset)
        if offset not in self.cache:
            sampling = self.scene.sampling
            shifted = Sampling(bin_width_opl=sampling.bin_width_opl, start_opl=sampling.start_opl + offset,
                               count=sampling.count)
            self.cache[offset] = forward(self.scene.replace(sampling=shifted))
        return self.cache[offset]


def _coarse_offset(data, sigma, mask, model, bin_width) -> float:
    """Starting offset: χ² minimised over a grid of shifts of the interpolated as-given model.

    The cumulative sum of the model's bins is the integral C(t) at the bin
    edges; y_n(δ) ≈ C(t_{n+1} + δ) - C(t_n + δ) with C linear between edges.
    Shifts up to half the window, in steps of a quarter bin, keep
    Gauss–Newton in the right basin when the data are off by whole bins.
    """
    count = model.shape[1]
    edges = np.arange(count + 1, dtype=np.float64)
    cumulative = np.concatenate([np.zeros((model.shape[0], 1)), np.cumsum(model, axis=1)], axis=1)
    best, best_chi2 = 0.0, np.inf
    weights = np.where(mask, 1.0 / np.where(mask, sigma, 1.0) ** 2, 0.0)
    for shift in np.arange(-count / 2, count / 2 + 0.125, 0.25):
        shifted = np.array([np.interp(edges + shift, edges, row) for row in cumulative])
        y = np.diff(shifted, axis=1)
        norm = np.sum(weights * y * y)
        if norm <= 0:
            continue
        scale = np.sum(weights * data * y) / norm
        chi2 = np.sum(weights * (data - scale * y) ** 2)
        if chi2 < best_chi2 - 1e-12 * abs(best_chi2) or (chi2 <= best_chi2 and abs(shift) < abs(best)):
            best, best_chi2 = float(shift), chi2
    return best * bin_width


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

    offset = _coarse_offset(data, sigma, mask, model_at(0.0), bin_width_opl)
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
        for _ in range(30):
            trial = (scale + float(step[0]), float(np.clip(offset + step[1], -limit, limit)))
            value = chi2(*trial)
            if value <= current * (1 + 1e-12):
                scale, offset, current = trial[0], trial[1], value
                break
            step = step / 2
        if small:
            converged = True
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
    ~10⁻³ of themselves, never moves the optimum. A coarse search over
    shifts of a quarter bin picks the starting δ.

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
    allow; with ``sigma_known=False``, (JᵀJ)⁻¹ χ²_min / (D - 2). A Monte Carlo renderer whose every sample lands in one bin has
    negatively correlated neighbouring bins: then the offset's error from
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


# --------------------------------------------------------------------------- the verdict

@dataclass(frozen=True)
class CheckResult:
    """What ``check`` found: the verdict as given, the fitted conventions, the verdict after them.

    Attributes
    ----------
    agrees : bool
        The data agree with the model as given.
    chi2_per_dof, max_abs_z : float or None
        As given (None when judged by shape only). With replicas z is
        judged as Student's t (see Notes of :func:`check_transient`).
    fit : Fit
        Best scale and offset.
    agrees_after_fit : bool
        The data agree with scale · y_model(start_opl + offset).
    judged_by : {"stderr", "replicas", "shape"}
        Where the per-bin error came from.
    replicas : int
        Number of data arrays averaged (1 unless replicas).
    dof : int or None
        Student-t degrees of freedom of z (R - 1), None for Gaussian z.
    relative_l2, relative_l2_after_fit : float
        ||y_data - y_model|| / ||y_model||, as given and after the fit.
    chi2_per_dof_after_fit, max_abs_z_after_fit : float or None
        After the fit.
    diagnosis : str
        One sentence for the user.
    as_given, after_fit : Agreement or None
        The full verdicts (None when judged by shape only).
    shape_tolerance : float or None
        The relative L2 tolerance when judged by shape only.
    data, stderr, model, fitted_model : numpy.ndarray
        ``(K, N)``: the (mean) data, its standard error (None by shape),
        the model as given and scale · y_model(start_opl + offset).
    edges : numpy.ndarray
        ``(N + 1,)`` bin edges of the scene, metres of path length.
    """

    agrees: bool
    chi2_per_dof: float | None
    max_abs_z: float | None
    fit: Fit
    agrees_after_fit: bool
    judged_by: str
    replicas: int
    dof: int | None
    relative_l2: float
    relative_l2_after_fit: float
    chi2_per_dof_after_fit: float | None
    max_abs_z_after_fit: float | None
    diagnosis: str
    as_given: Agreement | None = field(repr=False)
    after_fit: Agreement | None = field(repr=False)
    shape_tolerance: float | None
    data: np.ndarray = field(repr=False)
    stderr: np.ndarray | None = field(repr=False)
    model: np.ndarray = field(repr=False)
    fitted_model: np.ndarray = field(repr=False)
    edges: np.ndarray = field(repr=False)

    def as_dict(self) -> dict:
        """metrics.json: DESIGN.md section 5's keys plus the figures behind them."""
        result = {"agrees": self.agrees, "chi2_per_dof": self.chi2_per_dof, "max_abs_z": self.max_abs_z,
                  "fit": self.fit.as_dict(), "agrees_after_fit": self.agrees_after_fit,
                  "judged_by": self.judged_by, "replicas": self.replicas, "dof": self.dof,
                  "relative_l2": self.relative_l2, "relative_l2_after_fit": self.relative_l2_after_fit,
                  "chi2_per_dof_after_fit": self.chi2_per_dof_after_fit,
                  "max_abs_z_after_fit": self.max_abs_z_after_fit, "diagnosis": self.diagnosis}
        if self.as_given is not None:
            result["as_given_detail"] = self.as_given.as_dict()
            result["after_fit_detail"] = self.after_fit.as_dict()
        else:
            result["shape_tolerance"] = self.shape_tolerance
        return result

    def summary(self) -> str:
        """Two lines: the verdict as given, and the diagnosis."""
        if self.judged_by == "shape":
            head = (f"{'AGREES' if self.agrees else 'DISAGREES'} by shape only (no errors given): "
                    f"relative L2 = {self.relative_l2:.3e} (tolerance {self.shape_tolerance:g})")
        else:
            source = (f"{self.replicas} replicas, t with {self.dof} dof" if self.judged_by == "replicas"
                      else "given standard errors")
            head = (f"{'AGREES' if self.agrees else 'DISAGREES'} as given ({source}): "
                    f"χ²/dof = {self.chi2_per_dof:.3f}, max |z| = {self.max_abs_z:.2f}, "
                    f"relative L2 = {self.relative_l2:.3e}")
        return f"{head}\n{self.diagnosis}"


def _agreement(data, stderr, model, dof, false_alarm) -> Agreement:
    """compare_transients, with Student-t z on ``dof`` degrees of freedom when the error comes from replicas."""
    return compare_transients(data, stderr, model, dof=np.inf if dof is None else dof,
                              false_alarm=false_alarm, max_relative_stderr=MAX_RELATIVE_STDERR)


def _relative_l2(data, model) -> float:
    norm = float(np.linalg.norm(model))
    return float(np.linalg.norm(data - model) / norm) if norm > 0 else float("inf")


def _plus_minus(value: float, error: float, unit: str = "") -> str:
    """'+1.55e-4 ± 0.10e-4 m': value and error to the error's precision, one exponent."""
    if value == 0 and error == 0:
        return f"+0 ± 0{unit}"
    magnitude = max(abs(value), error)
    exponent = int(math.floor(math.log10(magnitude)))
    if -2 <= exponent <= 2:
        exponent = 0
    factor = 10.0**exponent
    if error > 0:
        # One significant digit of the error, two when it starts with 1 or 2.
        leading = int(math.floor(math.log10(error / factor)))
        digits = 2 if error / factor / 10.0**leading < 3 else 1
        decimals = max(0, digits - 1 - leading)
    else:
        decimals = 4
    suffix = f"e{exponent}" if exponent else ""
    return f"{value / factor:+.{decimals}f}{suffix} ± {error / factor:.{decimals}f}{suffix}{unit}"


def diagnose(fit: Fit, *, agrees: bool, agrees_after_fit: bool, bin_width_opl: float) -> str:
    """One sentence naming the conventions that explain the fitted scale and offset.

    Parameters
    ----------
    fit : Fit
        The fitted scale and offset.
    agrees, agrees_after_fit : bool
        Verdicts as given and after the fit.
    bin_width_opl : float
        T, metres: an offset of whole bins is named as such.
    """
    scale_text = f"scale {_plus_minus(fit.scale, fit.scale_stderr)}".replace("scale +", "scale ")
    offset_text = f"offset {_plus_minus(fit.offset_opl, fit.offset_stderr, ' m')}"
    if agrees:
        return f"agrees as given ({scale_text}, {offset_text})."
    if not agrees_after_fit:
        return (f"disagrees even after the best {scale_text} and {offset_text}: not a scale or "
                f"time-offset convention (a different model, scene or a bug?).")
    margin = max(3 * fit.scale_stderr, 0.01 * abs(fit.scale))
    factor, meaning = min(KNOWN_SCALES, key=lambda item: abs(math.log(abs(fit.scale) / item[0])))
    parts = []
    # Differences under the model's own accuracy (_RESOLUTION) are no convention.
    if abs(fit.scale - factor) <= margin and factor != 1.0:
        parts.append(f"a sensor that {meaning}")
    elif abs(fit.scale - 1.0) > max(3 * fit.scale_stderr, _RESOLUTION):
        parts.append(f"y scaled by {fit.scale:.4g} (units or source intensity?)")
    shifted = abs(fit.offset_opl) > max(3 * fit.offset_stderr, _RESOLUTION * bin_width_opl)
    bins = fit.offset_opl / bin_width_opl
    if shifted and round(bins) != 0 and abs(bins - round(bins)) * bin_width_opl <= max(
            3 * fit.offset_stderr, 0.01 * bin_width_opl):
        parts.append(f"a time axis off by {round(bins):+d} bin(s) (another start_opl convention?)")
    elif shifted and fit.offset_opl > 0:
        parts.append("path lengths short (paths that start on a sphere's surface, not its centre?)")
    elif shifted:
        parts.append("path lengths long (an extra leg or a late start?)")
    explanation = " and ".join(parts) if parts else "within its errors of the model"
    if factor == 0.25 and parts and parts[0].startswith("a sensor") and shifted and fit.offset_opl > 0:
        explanation = "a sensor that reads 1/4 of the fluence and path lengths short (an irradiancemeter?)"
    return f"agrees after {scale_text} and {offset_text}: {explanation}."


def check_transient(scene: Scene, data, *, stderr=None, dof: int | None = None, shape_only: bool = False,
                    model=None, false_alarm: float = 1e-3, shape_tolerance: float = 1e-2) -> CheckResult:
    """Judge a transient against the exact model of ``scene`` and fit its conventions.

    Parameters
    ----------
    scene : Scene
        The scene the data were rendered (or measured) from.
    data : array_like
        ``(K, N)`` one transient, or ``(R, K, N)`` R >= 3 independent
        replicas (e.g. renders with different seeds); units of y.
    stderr : array_like, optional
        ``(K, N)`` standard error of a single transient (units of y).
        Refused with replicas, whose error comes from their spread.
    dof : int, optional
        Degrees of freedom of ``stderr`` when it comes from replicas (our
        render's: ``replicas - 1``): z is then judged as Student's t.
        None: z is judged as normal.
    shape_only : bool
        Judge a single transient without ``stderr`` by shape only: relative
        L2 error against ``shape_tolerance``, unweighted fit. Refused
        together with ``stderr`` or replicas.
    model : array_like, optional
        ``forward(scene)`` if already computed.
    false_alarm : float
        α: probability that data consistent with the model fail (section 6).
    shape_tolerance : float
        Relative L2 error accepted when judging by shape only.

    Returns
    -------
    CheckResult

    Raises
    ------
    DataError
        Wrong shapes, NaN, a single transient with neither ``stderr`` nor
        ``shape_only``, or contradictory options.

    Notes
    -----
    Replicas y_r: mean ȳ = Σ y_r / R, standard error
    se = sqrt(Σ (y_r - ȳ)² / (R (R - 1))), and z = (ȳ - y_model) / se follows
    Student's t with R - 1 degrees of freedom, which
    :func:`validation.compare.compare_transients` judges with its t
    thresholds (so they keep their false-alarm rate α). The fit minimises
    Σ ((y_data - s y_model(t0 + δ)) / se)² over the judged bins
    (:func:`fit_scale_offset`); the verdict after it uses the same
    thresholds (two fitted parameters against D judged bins: the χ²
    interval's D is not reduced by them, a 2/D effect).
    """
    shape = (scene.sensor_count, scene.sampling.count)
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
    replicas = 1 if data.ndim == 2 else data.shape[0]
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
    edges = scene.sampling.edges
    model_at = _ShiftedModel(scene, model)
    y_model = model_at(0.0)
    if y_model.shape != shape:
        raise DataError(f"model: shape {y_model.shape}, expected {shape}")
    dof = dof if stderr is not None else None        # replicas set their own below
    replica_data = data if replicas > 1 else None
    if replicas > 1:
        mean = data.mean(axis=0)
        error = data.std(axis=0, ddof=1) / math.sqrt(replicas)
        judged_by, dof, data = "replicas", replicas - 1, mean
    elif stderr is not None:
        error = np.asarray(stderr, dtype=np.float64)
        if error.shape != shape:
            raise DataError(f"stderr: shape {error.shape} does not match the data's {shape}")
        if not np.all(np.isfinite(error)) or np.any(error < 0):
            raise DataError("stderr: must be finite and >= 0 in every bin")
        if dof is not None and not (isinstance(dof, (int, np.integer)) and dof >= 1):
            raise DataError(f"dof: the standard error's degrees of freedom must be an integer >= 1, got {dof!r}")
        judged_by = "stderr"
    else:
        judged_by, error = "shape", None

    if judged_by == "shape":
        mask = (y_model != 0) | (data != 0)
        if mask.sum() < 3 or not np.any(y_model != 0):
            raise DataError("data: fewer than 3 bins with light, or none in the model; check the scene's "
                            "sampling (start, period, count) against the data's")
        fit = fit_scale_offset(data, np.ones(shape), mask, model_at, scene.sampling.bin_width_opl,
                               sigma_known=False)
        fitted = fit.scale * model_at(fit.offset_opl)
        relative, relative_fit = _relative_l2(data, y_model), _relative_l2(data, fitted)
        agrees, agrees_fit = bool(relative <= shape_tolerance), bool(relative_fit <= shape_tolerance)
        diagnosis = ("judged by shape only (no errors given, no statistical test): "
                     + diagnose(fit, agrees=agrees, agrees_after_fit=agrees_fit,
                                bin_width_opl=scene.sampling.bin_width_opl))
        return CheckResult(agrees, None, None, fit, agrees_fit, judged_by, replicas, dof, relative,
                           relative_fit, None, None, diagnosis, None, None, shape_tolerance, data, None,
                           y_model, fitted, edges)

    mask = (error > 0) & (error < MAX_RELATIVE_STDERR * np.abs(data))
    if mask.sum() < 3:
        raise DataError(f"data: {int(mask.sum())} bin(s) with a standard error under "
                        f"{MAX_RELATIVE_STDERR:g} of the value; render more samples to judge them")
    if not np.any(y_model[mask] != 0):
        raise DataError("scene: the model puts no light in the bins the data fill; check the scene's "
                        "sampling (start, period, count) against the data's")
    as_given = _agreement(data, error, y_model, dof, false_alarm)
    fit = fit_scale_offset(data, np.where(mask, error, 1.0), mask, model_at, scene.sampling.bin_width_opl,
                           replicas=replica_data)
    fitted = fit.scale * model_at(fit.offset_opl)
    after = _agreement(data, error, fitted, dof, false_alarm)
    diagnosis = diagnose(fit, agrees=as_given.agrees, agrees_after_fit=after.agrees,
                         bin_width_opl=scene.sampling.bin_width_opl)
    return CheckResult(bool(as_given.agrees), as_given.chi2_per_dof, as_given.max_abs_z, fit, bool(after.agrees),
                       judged_by, replicas, dof, _relative_l2(data, y_model), _relative_l2(data, fitted),
                       after.chi2_per_dof, after.max_abs_z, diagnosis, as_given, after, None, data, error,
                       y_model, fitted, edges)


# --------------------------------------------------------------------------- the report

def write_check_report(out: str | Path, result: CheckResult, *, scene_name: str = "",
                       data_paths=()) -> dict:
    """Write report.md (embedding its figures), metrics.json and the PNGs into ``out``, together.

    Parameters
    ----------
    out : str or Path
        Output folder (created).
    result : CheckResult
        What :func:`check_transient` returned.
    scene_name : str
        The scene's label, for the report.
    data_paths : sequence of str
        The files judged, listed in the report.

    Returns
    -------
    dict
        The metrics written to metrics.json (NaN and infinity as None).
    """
    from analytic.io import json_ready, save_json, staged_writes
    from validation.plots import plot_check_transients, plot_check_z
    from validation.report import write_markdown

    out = Path(out)
    metrics = json_ready(result.as_dict() | {"scene": scene_name, "data": [str(p) for p in data_paths]})
    fit = result.fit
    lines = [f"# check: {scene_name or 'scene'}", ""]
    if data_paths:
        lines += ["Data: " + ", ".join(f"`{p}`" for p in data_paths), ""]
    lines += [f"**{'Agrees' if result.agrees else 'Disagrees'} as given.** {result.diagnosis}", ""]
    if result.judged_by == "shape":
        lines += ["Judged by shape only: no standard error was given, so there is no statistical test; "
                  f"the verdict is relative L2 ≤ {result.shape_tolerance:g}.", "",
                  "| | relative L2 |", "|---|---|",
                  f"| as given | {result.relative_l2:.3e} |",
                  f"| after the fit | {result.relative_l2_after_fit:.3e} |"]
    else:
        source = (f"{result.replicas} independent replicas (z ~ Student's t, {result.dof} dof)"
                  if result.judged_by == "replicas" else "the standard error given with the data"
                  + ("" if result.dof is None else f" (z ~ Student's t, {result.dof} dof)"))
        given, after = result.as_given, result.after_fit
        low, high = given.chi2_interval
        lines += [f"Per-bin error from {source}. Thresholds: χ²/dof in [{low:.3f}, {high:.3f}] and max |z| ≤ "
                  f"{given.z_threshold:.2f} over {given.bins} judged bins ({given.skipped} with too few "
                  f"samples not judged); false-alarm rate {given.false_alarm:g}.", "",
                  "| | verdict | χ²/dof | max \\|z\\| | relative L2 |", "|---|---|---|---|---|",
                  f"| as given | {'agrees' if given.agrees else 'disagrees'} | {given.chi2_per_dof:.4g} | "
                  f"{given.max_abs_z:.3g} | {result.relative_l2:.3e} |",
                  f"| after the fit | {'agrees' if after.agrees else 'disagrees'} | {after.chi2_per_dof:.4g} | "
                  f"{after.max_abs_z:.3g} | {result.relative_l2_after_fit:.3e} |"]
    lines += ["", "| fitted | value | standard error |", "|---|---|---|",
              f"| scale (data / model) | {fit.scale:.6g} | {fit.scale_stderr:.2g} |",
              f"| offset_opl (m, add to the data's start_opl) | {fit.offset_opl:+.6g} | {fit.offset_stderr:.2g} |",
              "", f"Gauss–Newton: {fit.iterations} iteration(s), "
              f"{'converged' if fit.converged else 'NOT converged'}.", ""]
    with staged_writes():
        save_json(out / "metrics.json", metrics)
        plot_check_transients(out / "check_transients.png", result)
        lines += ["![data against the model](check_transients.png)", ""]
        if result.as_given is not None:
            plot_check_z(out / "check_z.png", result)
            lines += ["![z by bin, as given and after the fit](check_z.png)", ""]
        write_markdown(out / "report.md", lines)
    return metrics
