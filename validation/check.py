"""Judge a transient from any tool against the exact model, and diagnose its conventions.

``check_transient(scene, data, ...)`` compares y from anywhere (our render,
another renderer, a measurement) with ``analytic.system.forward(scene)``
in two steps:

1. **As given.** z = (y_data - y_model) / se per bin, judged by
   :func:`validation.compare.compare_transients` (DESIGN.md section 6).
   The per-bin error se comes from ``stderr`` for one transient, or from R
   independent replicas (mean and standard error of the mean; z then
   follows Student's t with R - 1 degrees of freedom, and the limits of χ²
   and max |z| come from the replicas' sign flips, which hold whatever the
   correlation between bins, when R is large enough).
2. **After the two convention errors users make**: a global scale s and a
   time offset δ, y_data[n] ≈ s y_model(t0 + δ)[n], fitted by weighted least
   squares (Gauss–Newton on the exact model evaluated at the shifted
   start), with standard errors, and the verdict again against
   s y_model(t0 + δ). ``scale`` is data / model; ``offset_opl`` is what must
   be added to the data's start_opl for it to match the model, positive when
   the data read path lengths short (DESIGN.md section 5). The fit needs
   :data:`FIT_BINS` judged bins; with fewer (a one-bin scene) the data are
   judged as given only, and the result says so.

A convention the user expects (``expect``: a :class:`Convention`, such as
mitransient's :func:`irradiancemeter`) is judged too, with the same test
against s y_model(t0 + δ) for the stated s and δ.

One transient without ``stderr`` carries no noise level: it is judged by
shape only (relative L2 error against ``shape_tolerance``, the same fit
unweighted) and only when asked (``shape_only=True``), and the result says so.

Readers (:func:`read_data`) accept our ``transient.npy`` / ``transient.exr``
(or their folder), a ``(K, N)`` ``.npy`` from any tool, tal's HDF5 capture
(``analytic.capture``), and mitransient's film output (see
:func:`read_data`). A bad file raises :class:`DataError` with one line.
Our render's own errors are found beside its output:
:func:`replicas_beside` (``replicas.npy``) and :func:`stderr_beside`.
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

__all__ = ["Fit", "CheckResult", "Convention", "check_transient", "fit_scale_offset", "read_data",
           "read_stderr", "stderr_beside", "replicas_beside", "irradiancemeter", "diagnose",
           "write_check_report", "KNOWN_SCALES", "MAX_RELATIVE_STDERR", "FIT_BINS"]

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
    (0.25, "reads 1/4 of the fluence (the mean irradiance over a sphere)"),
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
    # Sensors by position: a T_Sx_Sy grid may be flattened in another order than the scene's. Sensors
    # that share a point are interchangeable: the k-th of the scene's there takes the k-th of the file's.
    order = []
    for k, position in enumerate(scene.sensors):
        near = np.max(np.abs(capture.sensors - position), axis=1) <= tolerance
        free = [j for j in np.flatnonzero(near) if j not in order]
        if not free:
            held = (f"only {int(near.sum())} sensor(s) of sensor_grid_xyz at the point of the scene's sensor {k} "
                    f"{position.tolist()}, where the scene places "
                    f"{int(np.sum(np.max(np.abs(scene.sensors - position), axis=1) <= tolerance))}" if near.any()
                    else f"no sensor of sensor_grid_xyz at the scene's sensor {k} {position.tolist()}")
            raise DataError(f"{path}: {held}; check it against the scene it was rendered from")
        order.append(int(free[0]))
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
        if data.shape == (bins, sensors):
            hint = "it looks transposed: save (sensors, bins)"
        elif data.ndim == 3 and data.shape[1:] == (sensors, bins):
            hint = (f"it looks like a stack of {data.shape[0]} replicas (a render's replicas.npy): give the "
                    f"render's folder, or one file per replica")
        else:
            hint = f"save a ({sensors}, {bins}) array of the scene's sensors and bins"
        raise DataError(f"{path}: shape {data.shape} does not match the scene's {sensors} sensors x "
                        f"{bins} bins; {hint}")
    if not np.all(np.isfinite(data)):
        bad = int(np.sum(~np.isfinite(data)))
        raise DataError(f"{path}: {bad} value(s) are NaN or infinite; re-render or drop the file")
    return data


def _our_render_folder(path: Path) -> Path | None:
    """The folder of our render's output that ``path`` names (itself or its transient file), else None."""
    if path.is_dir():
        return path
    return path.parent if path.name in ("transient.npy", "transient.exr") else None


def stderr_beside(path: str | Path, scene: Scene) -> tuple[np.ndarray, int | None] | None:
    """Our render's own standard error for its output (folder, ``transient.npy`` or ``.exr``).

    Returns
    -------
    tuple or None
        (``stderr.npy`` beside the data, the render's ``dof`` from
        ``meta.json``, None when absent), or None when ``path`` is not one of
        our render's outputs or has no ``stderr.npy``.
    """
    folder = _our_render_folder(Path(path))
    if folder is None or not (folder / "stderr.npy").is_file():
        return None
    dof = None
    try:
        dof = json.loads((folder / "meta.json").read_text(encoding="utf-8")).get("dof")
    except (OSError, ValueError, AttributeError):
        pass
    return read_stderr(folder / "stderr.npy", scene), dof if isinstance(dof, int) and dof >= 1 else None


def replicas_beside(path: str | Path, scene: Scene, data: np.ndarray) -> np.ndarray | None:
    """Our render's replicas for its output (folder, ``transient.npy`` or ``.exr``), when it wrote them.

    Parameters
    ----------
    path : str or Path
        What the user named as data.
    scene : Scene
        The scene.
    data : numpy.ndarray
        ``(K, N)`` the transient read from ``path``: the replicas must
        average to it (float32 rounding allowed for the EXR).

    Returns
    -------
    numpy.ndarray or None
        ``(R, K, N)`` the ``replicas.npy`` beside the data (R >= 3: each a
        complete estimate of y), or None when ``path`` is not our render's
        output, there is no ``replicas.npy``, or it holds fewer than 3
        (then ``stderr.npy`` serves).

    Raises
    ------
    DataError
        ``replicas.npy`` unreadable, of the wrong shape, not finite, or not
        averaging to the transient beside it.
    """
    folder = _our_render_folder(Path(path))
    if folder is None or not (folder / "replicas.npy").is_file():
        return None
    name = folder / "replicas.npy"
    try:
        replicas = np.load(name, allow_pickle=False)
    except (ValueError, OSError) as error:
        raise DataError(f"{name}: not a readable .npy ({error})") from None
    expected = (scene.sensor_count, scene.sampling.count)
    if replicas.ndim != 3 or replicas.shape[1:] != expected or not np.issubdtype(replicas.dtype, np.floating):
        raise DataError(f"{name}: shape {replicas.shape} ({replicas.dtype}), expected float (R, {expected[0]}, "
                        f"{expected[1]}) replicas of the scene's sensors x bins; re-render or remove it")
    replicas = np.asarray(replicas, dtype=np.float64)
    if not np.all(np.isfinite(replicas)):
        raise DataError(f"{name}: NaN or infinite values; re-render or remove it")
    if replicas.shape[0] < 3:
        return None
    mean = replicas.mean(axis=0)
    if np.any(np.abs(mean - data) > 2.0**-22 * np.abs(data) + 1e-12 * float(np.max(np.abs(data)))):
        raise DataError(f"{name}: the replicas do not average to the transient beside them (files of different "
                        f"renders?); re-render, or remove replicas.npy to judge by stderr.npy")
    return replicas


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


# --------------------------------------------------------------------------- stated conventions

#: Mitsuba's ``math::RayEpsilon`` in single-precision variants (1500 x 2⁻²⁴ m): an
#: irradiancemeter starts its rays this far off its sphere (mitransient runs float32 variants).
RAY_EPSILON_FLOAT32 = 1500 * 2.0**-24


@dataclass(frozen=True)
class Convention:
    """What the data are stated to read: scale · y_model(start_opl + offset_opl).

    Attributes
    ----------
    scale : float
        Data / model, dimensionless (as :attr:`Fit.scale`).
    offset_opl : float
        Metres of path length added to the model's start_opl before the
        comparison: positive when the data read path lengths short (as
        :attr:`Fit.offset_opl`).
    name : str
        What states it, for reports.
    """

    scale: float
    offset_opl: float
    name: str

    def __post_init__(self):
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"scale: the stated scale must be a finite number > 0, got {self.scale!r}")
        if not math.isfinite(self.offset_opl):
            raise ValueError(f"offset: the stated offset must be a finite number of metres, got {self.offset_opl!r}")

    def as_dict(self) -> dict:
        return {"name": self.name, "scale": self.scale, "offset_opl": self.offset_opl}


def irradiancemeter(scene: Scene, radius: float, *, ray_epsilon: float = RAY_EPSILON_FLOAT32) -> Convention:
    """What mitransient's irradiancemeter spheres read, against the model's point sensors.

    Parameters
    ----------
    scene : Scene
        The scene; each sensor is a sphere of ``radius`` centred on its
        position (``diffuse-imaging export --format mitransient``).
    radius : float
        Sphere radius r, metres: 0 < r < every sensor's height, so that no
        sphere reaches the plane (the export's bound).
    ray_epsilon : float
        Metres the meter moves each ray's origin off the sphere: Mitsuba's
        ``math::RayEpsilon``, :data:`RAY_EPSILON_FLOAT32` in the
        single-precision variants mitransient runs (1500 x 2⁻⁵³ m, i.e.
        negligible, in double ones).

    Returns
    -------
    Convention
        scale 1/4, offset_opl 2r/3 + ε.

    Raises
    ------
    ValueError
        A radius outside (0, lowest sensor height), or a negative ``ray_epsilon``.

    Notes
    -----
    Mitsuba's ``irradiancemeter`` (``src/sensors/irradiancemeter.cpp``)
    starts each ray at a uniform point of its sphere, in a cosine-weighted
    direction about the outward normal, with weight π, from the point moved
    ε along the ray, and mitransient's ``transient_path`` bins the path
    length from that origin. It reads the irradiance averaged over the
    sphere, Ē = P / (4π r²), P the power the sphere intercepts.

    *Scale: exactly 1/4, with no finite-sphere correction.* A Lambertian
    element dA of the plane, of radiance B/π, sends the sphere
    P = (B/π) dA Ω⊥, Ω⊥ the sphere's solid angle projected on dA's plane.
    By Nusselt's analogue Ω⊥ is the area of the orthographic projection,
    onto dA's plane, of the cap the sphere's cone cuts from the unit
    hemisphere: a circle of radius sin α = r/d tilted by θ, which projects
    to an ellipse of area π (r/d)² cos θ, exactly, whenever the whole cap
    lies above dA's horizon (the sphere above the plane). d is the distance
    from dA to the centre and θ the angle between the plane's normal and
    the centre's direction. The same element adds (B/π) dA cos θ / d² to
    the fluence rate Φ at the centre, which the model's point sensor reads,
    so every element, hence every bin of every sensor, gives Ē = Φ / 4,
    whatever r/d. (Light from an isotropic point source would give
    Ē / Φ = 1 / (2 (1 + sqrt(1 - (r/d)²))) = (1/4)(1 + (r/d)²/4 + ...):
    the Lambertian element's cosine is what removes the correction.)

    *Offset: 2r/3 + ε.* The light from dA that the sphere intercepts fills
    its cone with an intensity that varies across it only at first order in
    r/d, and oddly; to first order it crosses the plane through the centre
    perpendicular to the cone's axis uniformly within the disc of radius r,
    at distance b from the axis, after meeting the sphere sqrt(r² - b²)
    before that plane: path lengths short by 2r/3 on average, plus ε where
    the meter's rays start, for every element, sensor and bin.

    Neglected: O(r²/d) in the offset, the spread of the shortfall
    (standard deviation r/sqrt(18)) within a bin of width T, a relative
    O((r/T)²) effect, and the sphere's own shadow on the plane, O(r²)
    relative: ~1e-6 of y for r = 1 mm, d ~ 1 m, T ~ 0.05 m.
    """
    lowest = float(np.min(scene.sensors[:, 2]))
    radius = float(radius)
    if not (math.isfinite(radius) and 0.0 < radius < lowest):
        raise ValueError(f"radius: must lie in (0, {lowest:g}) m, below the lowest sensor's height (the spheres "
                         f"must not reach the plane), got {radius:g}")
    if not (math.isfinite(ray_epsilon) and ray_epsilon >= 0):
        raise ValueError(f"ray_epsilon: must be a finite number of metres >= 0, got {ray_epsilon!r}")
    return Convention(scale=0.25, offset_opl=2.0 * radius / 3.0 + float(ray_epsilon),
                      name=f"irradiancemeter spheres of radius {radius:g} m")


# --------------------------------------------------------------------------- the verdict

#: Fewest judged bins that a scale and a time offset are fitted to (two parameters and a residual).
FIT_BINS = 3


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
    fit : Fit or None
        Best scale and offset; None when too few bins allow no fit
        (``fit_skipped`` says why).
    agrees_after_fit : bool or None
        The data agree with scale · y_model(start_opl + offset) (None
        without a fit).
    judged_by : {"stderr", "replicas", "shape"}
        Where the per-bin error came from.
    replicas : int
        Number of data arrays averaged (1 unless replicas).
    dof : int or None
        Student-t degrees of freedom of z (R - 1), None for Gaussian z.
    relative_l2, relative_l2_after_fit : float
        ||y_data - y_model|| / ||y_model||, as given and after the fit
        (None without a fit).
    chi2_per_dof_after_fit, max_abs_z_after_fit : float or None
        After the fit.
    diagnosis : str
        One sentence for the user.
    as_given, after_fit : Agreement or None
        The full verdicts (None when judged by shape only, or without a fit).
    shape_tolerance : float or None
        The relative L2 tolerance when judged by shape only.
    data, stderr, model, fitted_model : numpy.ndarray
        ``(K, N)``: the (mean) data, its standard error (None by shape),
        the model as given and scale · y_model(start_opl + offset) (the
        model as given without a fit).
    edges : numpy.ndarray
        ``(N + 1,)`` bin edges of the scene, metres of path length.
    fit_skipped : str or None
        Why no scale and offset were fitted.
    expected : Convention or None
        The convention the user stated (``check --expect``).
    agrees_as_expected : bool or None
        The data agree with the stated convention's model.
    as_expected : Agreement or None
        Its full verdict (None by shape only or without a stated convention).
    relative_l2_as_expected : float or None
        ||y_data - y_expected|| / ||y_expected||.
    """

    agrees: bool
    chi2_per_dof: float | None
    max_abs_z: float | None
    fit: Fit | None
    agrees_after_fit: bool | None
    judged_by: str
    replicas: int
    dof: int | None
    relative_l2: float
    relative_l2_after_fit: float | None
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
    fit_skipped: str | None = None
    expected: Convention | None = None
    agrees_as_expected: bool | None = None
    as_expected: Agreement | None = field(default=None, repr=False)
    relative_l2_as_expected: float | None = None

    @property
    def verdict(self) -> bool:
        """What the exit status reports: agreement with the stated convention, else as given."""
        return bool(self.agrees_as_expected) if self.expected is not None else self.agrees

    def as_dict(self) -> dict:
        """metrics.json: DESIGN.md section 5's keys plus the figures behind them."""
        result = {"agrees": self.agrees, "chi2_per_dof": self.chi2_per_dof, "max_abs_z": self.max_abs_z,
                  "fit": None if self.fit is None else self.fit.as_dict(),
                  "agrees_after_fit": self.agrees_after_fit, "fit_skipped": self.fit_skipped,
                  "judged_by": self.judged_by, "replicas": self.replicas, "dof": self.dof,
                  "relative_l2": self.relative_l2, "relative_l2_after_fit": self.relative_l2_after_fit,
                  "chi2_per_dof_after_fit": self.chi2_per_dof_after_fit,
                  "max_abs_z_after_fit": self.max_abs_z_after_fit, "diagnosis": self.diagnosis}
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
        if self.expected is not None:
            lines.append(_expected_sentence(self))
        return "\n".join(lines + [self.diagnosis])


def _expected_sentence(result: CheckResult) -> str:
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
        explanation = ("a sensor that reads 1/4 of the fluence and path lengths short (an irradiancemeter? "
                       "--expect irradiancemeter states that convention)")
    return f"agrees after {scale_text} and {offset_text}: {explanation}."


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
                    expect: Convention | None = None) -> CheckResult:
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
        ``forward(scene)`` if already computed.
    false_alarm : float
        α: probability that data consistent with the model fail (section 6).
    shape_tolerance : float
        Relative L2 error accepted when judging by shape only.
    expect : Convention, optional
        The convention the data are stated to follow (e.g.
        :func:`irradiancemeter`): they are judged against
        scale · y_model(start_opl + offset_opl) as well
        (:attr:`CheckResult.agrees_as_expected`).

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
    model_at = _ShiftedModel(scene, model)
    y_model = model_at(0.0)
    if y_model.shape != shape:
        raise DataError(f"model: shape {y_model.shape}, expected {shape}")
    if shape_only:
        return _judge_by_shape(scene, data, model_at, expect, shape_tolerance)
    if replicas > 1:
        mean = data.mean(axis=0)
        error = data.std(axis=0, ddof=1) / math.sqrt(replicas)
        return _judge_with_errors(scene, mean, error, replicas - 1, data, model_at, expect, false_alarm)
    return _judge_with_errors(scene, data, _checked_stderr(stderr, dof, shape), dof, None, model_at, expect,
                              false_alarm)


def _expected_model(model_at, expect: Convention | None) -> np.ndarray | None:
    """scale · y_model(start_opl + offset_opl) of the stated convention (None without one)."""
    return None if expect is None else expect.scale * model_at(expect.offset_opl)


def _judge_with_errors(scene, data, error, dof, replica_data, model_at, expect, false_alarm) -> CheckResult:
    """The statistical verdicts: as given, as stated, and after the fitted scale and offset.

    ``replica_data``: the ``(R, K, N)`` replicas ``data`` and ``error`` come from, or None for a
    transient with its standard error.
    """
    y_model = model_at(0.0)
    expected_model = _expected_model(model_at, expect)
    judged_by = "stderr" if replica_data is None else "replicas"
    mask = _judged_bins(data, error, judged_by)
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
    return CheckResult(
        agrees=bool(as_given.agrees), chi2_per_dof=as_given.chi2_per_dof, max_abs_z=as_given.max_abs_z, fit=fit,
        agrees_after_fit=None if after is None else bool(after.agrees), judged_by=judged_by,
        replicas=1 if replica_data is None else replica_data.shape[0], dof=dof,
        relative_l2=_relative_l2(data, y_model),
        relative_l2_after_fit=None if fit is None else _relative_l2(data, fitted),
        chi2_per_dof_after_fit=None if after is None else after.chi2_per_dof,
        max_abs_z_after_fit=None if after is None else after.max_abs_z, diagnosis=diagnosis,
        as_given=as_given, after_fit=after, shape_tolerance=None, data=data, stderr=error, model=y_model,
        fitted_model=fitted, edges=scene.sampling.edges, fit_skipped=skipped, expected=expect,
        agrees_as_expected=None if as_expected is None else bool(as_expected.agrees), as_expected=as_expected,
        relative_l2_as_expected=None if expected_model is None else _relative_l2(data, expected_model))


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
        agrees=agrees, chi2_per_dof=None, max_abs_z=None, fit=fit, agrees_after_fit=agrees_fit,
        judged_by="shape", replicas=1, dof=None, relative_l2=relative, relative_l2_after_fit=relative_fit,
        chi2_per_dof_after_fit=None, max_abs_z_after_fit=None,
        diagnosis="judged by shape only (no errors given, no statistical test): " + verdict,
        as_given=None, after_fit=None, shape_tolerance=shape_tolerance, data=data, stderr=None, model=y_model,
        fitted_model=fitted, edges=scene.sampling.edges, fit_skipped=skipped, expected=expect,
        agrees_as_expected=None if expect is None else bool(relative_expected <= shape_tolerance),
        relative_l2_as_expected=relative_expected)


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
    lines = [f"# check: {scene_name or 'scene'}", ""]
    if data_paths:
        lines += ["Data: " + ", ".join(f"`{p}`" for p in data_paths), ""]
    lines += [f"**{'Agrees' if result.agrees else 'Disagrees'} as given.** {result.diagnosis}", ""]
    if result.expected is not None:
        lines += [f"**{_expected_sentence(result)}.**", ""]
    if result.judged_by == "shape":
        lines += _shape_lines(result)
    else:
        lines += _statistical_lines(result)
    lines += _fit_lines(result)
    with staged_writes():
        save_json(out / "metrics.json", metrics)
        if result.fit is not None:    # the figures draw the fitted model beside the data
            plot_check_transients(out / "check_transients.png", result)
            lines += ["![data against the model](check_transients.png)", ""]
            if result.as_given is not None:
                plot_check_z(out / "check_z.png", result)
                lines += ["![z by bin, as given and after the fit](check_z.png)", ""]
        write_markdown(out / "report.md", lines)
    return metrics


def _shape_lines(result: CheckResult) -> list[str]:
    rows = [("as given", result.relative_l2)]
    if result.expected is not None:
        rows.append(("as stated", result.relative_l2_as_expected))
    if result.fit is not None:
        rows.append(("after the fit", result.relative_l2_after_fit))
    return (["Judged by shape only: no standard error was given, so there is no statistical test; "
             f"the verdict is relative L2 ≤ {result.shape_tolerance:g}.", "",
             "| | relative L2 |", "|---|---|"] + [f"| {name} | {value:.3e} |" for name, value in rows])


def _statistical_lines(result: CheckResult) -> list[str]:
    source = (f"{result.replicas} independent replicas (z ~ Student's t, {result.dof} dof)"
              if result.judged_by == "replicas" else "the standard error given with the data"
              + ("" if result.dof is None else f" (z ~ Student's t, {result.dof} dof)"))
    given = result.as_given
    rows = [("as given", given, result.relative_l2)]
    if result.as_expected is not None:
        rows.append(("as stated", result.as_expected, result.relative_l2_as_expected))
    if result.after_fit is not None:
        rows.append(("after the fit", result.after_fit, result.relative_l2_after_fit))
    return ([f"Per-bin error from {source}, over {given.bins} judged bin(s) ({given.skipped} with too few "
             f"samples not judged). False-alarm rate {given.false_alarm:g}: {given.null_note}.", "",
             "| | verdict | χ²/dof [accepted] | max \\|z\\| (limit) | relative L2 |", "|---|---|---|---|---|"]
            + [f"| {name} | {'agrees' if agreement.agrees else 'disagrees'} | {agreement.chi2_per_dof:.4g} "
               f"[{agreement.chi2_interval[0]:.3f}, {agreement.chi2_interval[1]:.3f}] | {agreement.max_abs_z:.3g} "
               f"(≤ {agreement.z_threshold:.2f}) | {relative:.3e} |" for name, agreement, relative in rows])


def _fit_lines(result: CheckResult) -> list[str]:
    fit = result.fit
    if fit is None:
        return ["", "No figures: they draw the fitted model beside the data, and there is none.", ""]
    return ["", "| fitted | value | standard error |", "|---|---|---|",
            f"| scale (data / model) | {fit.scale:.6g} | {fit.scale_stderr:.2g} |",
            f"| offset_opl (m, add to the data's start_opl) | {fit.offset_opl:+.6g} | {fit.offset_stderr:.2g} |",
            "", f"Gauss–Newton: {fit.iterations} iteration(s), "
            f"{'converged' if fit.converged else 'NOT converged'}.", ""]
