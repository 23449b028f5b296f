"""Read the transients users bring to ``check`` (and ``reconstruct``), and our render's own errors beside them.

One reader per format, shared with every command: the ``.npy``, EXR and tal
HDF5 readers of :mod:`analytic.files`. On top of them this module checks a
file against the scene it claims to come from: the time axis a file states
(``meta.json`` beside it, the EXR header, the capture's ``t_start`` and
``delta_t``), tal's source and sensor positions, the shape, and finite
values; and it reads mitransient's films (a saved film tensor, or the
frames ``mitransient.vis.save_frames`` writes). A bad file raises
:class:`~analytic.errors.DataError` with one line.

Our render's own errors are found beside its output:
:func:`replicas_beside` (``replicas.npy``) and :func:`stderr_beside`.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from analytic.errors import DataError, OptionError
from analytic.files import TRANSIENT_FILES, read_exr, read_exr_channels, read_npy, transient_format, transient_in_folder
from interop.tal import CaptureError, read_capture
from analytic.scenes.common import Sampling, Scene
from analytic.scenes.kinds import is_scene, for_kind
from analytic.scenes.scene_file import load_scene, scene_of

__all__ = ["read_data", "scene_of", "read_stderr", "stderr_beside", "replicas_beside", "film_transient", "checked_transient"]


def _time_axis(name: str, start: float, width: float, sampling: Sampling) -> None:
    """Refuse a file whose time axis differs from the scene's (float32 storage allowed)."""
    slack = 1e-6 * sampling.bin_width_opl + 2.0**-23 * abs(sampling.start_opl)
    if abs(start - sampling.start_opl) > slack or abs(width - sampling.bin_width_opl) > 2.0**-22 * width:
        raise DataError(f"{name}: time axis start_opl = {start:.9g} m, bin_width_opl = {width:.9g} m "
                        f"differs from the scene's {sampling.start_opl:.9g} m, {sampling.bin_width_opl:.9g} m; "
                        f"check it against the scene it was rendered from")


def _finite_number(value) -> bool:
    """A JSON number (not a boolean) that is a finite float (a 400-digit integer is not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _meta_time_axis(path: Path, sampling: Sampling) -> None:
    """Check the time axis recorded in a ``meta.json`` beside our output, when there is one."""
    meta_path = path.parent / "meta.json"
    if not meta_path.is_file():
        return
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8-sig"))   # -sig: a byte-order mark is UTF-8 too
    except (OSError, ValueError):   # unreadable, not UTF-8, not JSON, integers beyond Python's digit limit
        return   # not ours: nothing to compare
    if not isinstance(meta, dict):
        return   # not ours either
    width = meta.get("bin_width_opl")
    if "start_opl" in meta and width is not None:
        start = meta["start_opl"]
        if not all(_finite_number(value) for value in (start, width)):
            raise DataError(f"{meta_path}: start_opl {start!r} and bin_width_opl {width!r} are not two finite "
                            f"numbers (metres); correct meta.json or remove it to judge {path.name} alone")
        _time_axis(f"{path} (meta.json)", float(start), float(width), sampling)


def _our_exr(path: Path, sampling: Sampling) -> np.ndarray:
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
    if sensors != 1:
        raise DataError(f"{path}: a folder of frames holds one sensor, the scene has {sensors}; "
                        f"save the films with numpy instead (see validation.check.read_data)")
    values = []
    for frame in frames:
        channels, _ = read_exr_channels(frame)
        name = next((n for n in ("Y", "RGB") if n in channels), None)
        if name is None:
            raise DataError(f"{frame}: no Y or RGB channel (channels {sorted(channels)})")
        image = channels[name]
        image = image.reshape(image.shape[:2] + (-1,))
        if image.shape[:2] != (1, 1):
            raise DataError(f"{frame}: a {image.shape[0]} x {image.shape[1]} frame; one sensor is a "
                            f"1 x 1 irradiancemeter film")
        values.append(_film_channels(str(frame), image[0, 0][None])[0])
    return np.array(values, dtype=np.float64)[None, :]


def _read_capture(path: Path, sampling: Sampling):
    """tal's capture with its time axis checked against the scene's."""
    try:
        capture = read_capture(path)
    except CaptureError as error:
        raise DataError(str(error)) from None
    _time_axis(str(path), capture.start_opl, capture.bin_width_opl, sampling)
    return capture


def _capture(path: Path, scene: Scene) -> np.ndarray:
    capture = _read_capture(path, scene.sampling)
    if capture.laser_count != 1:
        raise DataError(f"{path}: H holds {capture.laser_count} laser points ({capture.layout}); a plane scene has "
                        f"one source: give a capture of one laser point")
    tolerance = 1e-6 + 2.0**-22 * float(np.max(np.abs(scene.sensors)))
    if capture.source is not None and np.max(np.abs(capture.source - scene.source)) > tolerance:
        raise DataError(f"{path}: laser_xyz {capture.source.tolist()} is not the scene's source "
                        f"{scene.source.tolist()}; check it against the scene it was rendered from")
    if capture.accounts_first_and_last_bounces:
        # tal's path lengths then add |laser_xyz - laser point| + |sensor point - sensor_xyz|, which a plane's lack
        legs = [np.linalg.norm(points - end, axis=-1) for points, end in
                ((capture.lasers, capture.source), (capture.sensors, capture.sensor_position))
                if points is not None and end is not None]
        if len(legs) < 2 or max(float(np.max(leg)) for leg in legs) > tolerance:
            raise DataError(f"{path}: t_accounts_first_and_last_bounces is true: its path lengths add the legs "
                            f"laser_xyz -> laser grid and sensor grid -> sensor_xyz, which a plane scene's do "
                            f"not; give a capture written with it false (as ours are)")
    transient = capture.transient
    if capture.sensors is None or transient.shape[0] != scene.sensor_count:
        return transient   # the shape check in read_data reports a count mismatch
    # Sensors by position: a grid may be flattened in another order than the scene's. Sensors
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


def _pairs_text(scene) -> str:
    scan = scene.scan
    text = f"{scan.type} scan of {scan.grid[0]} x {scan.grid[1]} read points"
    if scan.type == "exhaustive":
        lasers = scan.laser_grid or scan.grid
        text += f" and {lasers[0]} x {lasers[1]} lit points"
    return f"{scene.sensor_count} pairs ({text})"


def _relay_wall_capture(path: Path, scene) -> np.ndarray:
    """A tal capture of a relay-wall scene, its columns matched to the scene's pairs by their points."""
    capture = _read_capture(path, scene.sampling)
    flag = scene.scan.account_first_and_last_bounces
    # a tal configuration's capture states the YAML's flag, which tal 0.20 does not render (interop.tal.config)
    stated = getattr(scene, "capture_accounts_flag", flag)
    if capture.accounts_first_and_last_bounces is not None and capture.accounts_first_and_last_bounces != stated:
        counts = "count" if capture.accounts_first_and_last_bounces else "do not count"
        raise DataError(f"{path}: t_accounts_first_and_last_bounces is "
                        f"{str(capture.accounts_first_and_last_bounces).lower()} (its path lengths {counts} "
                        f"|o_l - l| + |s - o_s|), the scene's scan.account_first_and_last_bounces is "
                        f"{str(stated).lower()}; set it to {str(not stated).lower()} in the scene to judge this "
                        f"file")
    lit, read = scene.pair_points
    tolerance = 1e-6 + 2.0**-22 * float(max(np.max(np.abs(read)), np.max(np.abs(scene.laser_position)),
                                            np.max(np.abs(scene.sensor_position))))
    ends = [("laser_xyz", capture.source, scene.laser_position, "laser.position")]
    if flag:   # the sensor's distance enters the path lengths only when the legs are counted
        ends.append(("sensor_xyz", capture.sensor_position, scene.sensor_position, "sensor.position"))
    for key, theirs, ours, scene_key in ends:
        if theirs is not None and np.max(np.abs(theirs - ours)) > tolerance:
            raise DataError(f"{path}: {key} {theirs.tolist()} is not the scene's {scene_key} {ours.tolist()}; "
                            f"check it against the scene it was rendered from")
    if capture.transient.shape[0] != len(read):
        raise DataError(f"{path}: H holds {capture.transient.shape[0]} (lit point, read point) columns "
                        f"({capture.layout}, H of {capture.laser_count} lit x {capture.transient.shape[0] // capture.laser_count} "
                        f"read points), the scene's {_pairs_text(scene)}; check it against the scene it was "
                        f"rendered from")
    if capture.sensors is None or capture.lasers is None:
        missing = "sensor_grid_xyz" if capture.sensors is None else "laser_grid_xyz"
        raise DataError(f"{path}: no {missing}, so its columns cannot be matched to the scene's pairs; give a "
                        f"capture that states its grids")
    # Columns by their (l, s) points: the file's grids may list them in another order than the scene's.
    order = np.full(len(read), -1)
    taken = np.zeros(len(read), dtype=bool)
    for p in range(len(read)):
        near = ((np.max(np.abs(capture.sensors - read[p]), axis=1) <= tolerance)
                & (np.max(np.abs(capture.lasers - lit[p]), axis=1) <= tolerance) & ~taken)
        if not near.any():
            raise DataError(f"{path}: no column of the capture reads s = {read[p].tolist()} lit at l = "
                            f"{lit[p].tolist()} (the scene's pair {p}): its grids differ from the scene's "
                            f"{_pairs_text(scene)} on a {scene.wall_size[0]:g} x {scene.wall_size[1]:g} m wall")
        order[p] = int(np.flatnonzero(near)[0])
        taken[order[p]] = True
    return capture.transient[order]


def _relay_wall_film(name: str, array: np.ndarray, scene) -> np.ndarray:
    """mitransient's developed NLOS film -> ``(P, N)`` in the scene's pair order.

    ``np.array(film)`` of an ``nlos_capture_meter``'s ``transient_hdr_film``
    is ``(H, W, T, C)``: row j, column i reads grid cell (i, j), pair j W + i
    (single; confocal once its per-point 1 x 1 films are placed there). An
    exhaustive film (``exhaustive_scan``) is ``(H, W, Lh, Lw, T, C)``, its
    lit point at flat index lj Lw + li of the two laser axes (mitransient's
    ``TransientImageBlock.put_``).
    """
    scan = scene.scan
    width, height = scan.grid
    bins = scene.sampling.count
    exhaustive = scan.type == "exhaustive"
    expected = (height, width) + ((tuple(reversed(scan.laser_grid or scan.grid))) if exhaustive else ())
    if array.ndim != len(expected) + 2:
        layout = "(H, W, Lh, Lw, T, C)" if exhaustive else "(H, W, T, C)"
        raise DataError(f"{name}: a film of shape {array.shape}; the scene's {scan.type} scan needs mitransient's "
                        f"{layout} film, np.array of the transient film, one file per render")
    if array.shape[:len(expected)] != expected or array.shape[len(expected)] != bins:
        what = "H x W" + (" x Lh x Lw" if exhaustive else "")
        raise DataError(f"{name}: film of {what} = {' x '.join(map(str, array.shape[:len(expected)]))} points and "
                        f"{array.shape[len(expected)]} bins, the scene's {' x '.join(map(str, expected))} and "
                        f"{bins} bins ({_pairs_text(scene)}); check it against the scene it was rendered from")
    values = _film_channels(name, array)
    if exhaustive:
        lasers = int(np.prod(expected[2:]))
        return np.ascontiguousarray(values.reshape(height * width, lasers, bins).transpose(1, 0, 2)
                                    .reshape(-1, bins))
    return values.reshape(height * width, bins)


@dataclass(frozen=True)
class _Layout:
    """How other tools' files hold a scene kind's transient.

    Attributes
    ----------
    capture : callable
        (path, scene) -> ``(rows, N)``: tal's HDF5 capture, matched to the scene's rows.
    film : callable
        (name, array, scene, sensors) -> ``(rows, N)``: mitransient's developed film(s).
    is_film : callable
        ndim -> whether a ``.npy`` of that many dimensions is a film of the kind.
    no_frames : str or None
        Why a folder of ``save_frames`` images cannot hold the kind's transient; None when it can.
    """

    capture: Callable
    film: Callable
    is_film: Callable[[int], bool]
    no_frames: str | None


def _plane_film(name: str, array: np.ndarray, scene, sensors: int | None) -> np.ndarray:
    return _film_tensor(name, array, scene.sensor_count if sensors is None else sensors)


def _relay_wall_films(name: str, array: np.ndarray, scene, sensors: int | None) -> np.ndarray:
    return _relay_wall_film(name, array, scene)


#: Each scene kind's layout in tal's captures and mitransient's films.
_LAYOUTS = {
    "plane": _Layout(_capture, _plane_film, lambda ndim: ndim in (4, 5), None),
    "relay_wall": _Layout(_relay_wall_capture, _relay_wall_films, lambda ndim: ndim >= 4,
                          "a folder of save_frames images holds no scan grid; save the NLOS film with "
                          "np.save(file, np.array(film)) instead, one file per render"),
}


def _layout(scene) -> _Layout:
    return for_kind(_LAYOUTS, scene, "reading another tool's captures and films")


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

        For a relay-wall (NLOS) scene the rows are its (l, s) pairs
        (docs/design.md section 7), and the captures and films are:

        - tal's NLOS capture (ours or ``tal render``'s; H_format T_Sx_Sy or
          T_Lx_Ly_Sx_Sy): time axis, ``laser_xyz`` (and ``sensor_xyz`` when
          the legs are counted) and ``t_accounts_first_and_last_bounces``
          checked against the scene, columns matched to the pairs by their
          lit and read points;
        - mitransient's ``nlos_capture_meter`` film, ``np.array(film)`` of
          one render: ``(H, W, T, C)`` (single, confocal) or
          ``(H, W, Lh, Lw, T, C)`` (exhaustive), row j and column i reading
          grid cell (i, j).
    scene : Scene, RelayWallScene, str or Path
        The scene the data were rendered from (or its file, :func:`scene_of`).

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64 y_k[n], sensors (or pairs) in the scene's order.

    Raises
    ------
    DataError
        No such file, unknown format, wrong shape, a time axis, source or sensor
        positions other than the scene's, NaN or infinity.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise DataError(f"path: expected a file or folder's path, got {type(path).__name__} (arrays are judged by "
                        f"validation.check_transient as they are)")
    scene = scene_of(scene)
    path = Path(path)
    sensors, bins = scene.sensor_count, scene.sampling.count
    if not path.exists():
        raise DataError(f"{path}: no such file or folder")
    name = str(path)
    kind = transient_format(path)
    if not (path.is_dir() or path.is_file()):   # a FIFO would block the reader, a device read without end
        raise DataError(f"{path}: not a file or folder (a named pipe, device or socket); save the data to a file")
    if path.is_dir():
        ours = transient_in_folder(path)
        if ours is not None:
            return read_data(ours, scene)
        frames = sorted((p for p in path.iterdir() if _FRAME.match(p.name)),
                        key=lambda p: int(_FRAME.match(p.name).group(1)))
        if not frames:
            raise DataError(f"{path}: a folder with neither {' nor '.join(TRANSIENT_FILES)} nor 000.exr "
                            f"frames; give the data file itself")
        no_frames = _layout(scene).no_frames
        if no_frames is not None:
            raise DataError(f"{path}: {no_frames}")
        data = _frames(path, frames, sensors)
    elif kind == "capture":
        data = _layout(scene).capture(path, scene)
    elif kind == "npy":
        array = read_npy(path)
        if array.ndim >= 4 and _layout(scene).is_film(array.ndim):
            data = film_transient(name, array, scene)
        else:
            _meta_time_axis(path, scene.sampling)
            data = array
    elif kind == "exr":
        data = _our_exr(path, scene.sampling)
        _meta_time_axis(path, scene.sampling)
    else:
        raise DataError(f"{path}: unknown format (expected .npy, .exr, .h5/.hdf5 or a folder of them)")
    return checked_transient(str(path), data, scene)


def film_transient(name: str, array: np.ndarray, scene: Scene, *, sensors: int | None = None) -> np.ndarray:
    """mitransient's developed film(s) of ``scene`` -> ``(K, N)``: a plane scene's irradiancemeter film
    ``(1, 1, N, C)`` or the K sensors' stacked ``(K, 1, 1, N, C)`` (``sensors`` of them, default the
    scene's); a relay wall's nlos_capture_meter film (see :func:`read_data`)."""
    return _layout(scene).film(name, array, scene, sensors)


def checked_transient(name: str, data: np.ndarray, scene: Scene) -> np.ndarray:
    """``data`` if it is one ``(K, N)`` transient of ``scene`` with finite values; else DataError naming
    ``name`` and what the shape looks like (transposed, a stack of replicas)."""
    sensors, bins = scene.sensor_count, scene.sampling.count
    if data.shape != (sensors, bins):
        rows = f"{scene.row_noun}s"
        if data.shape == (bins, sensors):
            hint = f"it looks transposed: save ({rows}, bins)"
        elif data.ndim == 3 and data.shape[1:] == (sensors, bins):
            hint = (f"it looks like a stack of {data.shape[0]} replicas (a render's replicas.npy): give the "
                    f"render's folder, or one file per replica")
        else:
            hint = f"save a ({sensors}, {bins}) array of the scene's {rows} and bins"
        raise DataError(f"{name}: shape {data.shape} does not match the scene's {sensors} {rows} x "
                        f"{bins} bins; {hint}")
    if not np.all(np.isfinite(data)):
        bad = int(np.sum(~np.isfinite(data)))
        raise DataError(f"{name}: {bad} value(s) are NaN or infinite; re-render or drop the file")
    return data


def _our_render_folder(path: Path) -> Path | None:
    """The folder of our render's output that ``path`` names (itself or its transient file), else None."""
    if path.is_dir():
        return path
    return path.parent if path.name in TRANSIENT_FILES else None


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
        dof = json.loads((folder / "meta.json").read_text(encoding="utf-8-sig")).get("dof")
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
    replicas = read_npy(name)
    expected = (scene.sensor_count, scene.sampling.count)
    if replicas.ndim != 3 or replicas.shape[1:] != expected:
        raise DataError(f"{name}: shape {replicas.shape}, expected (R, {expected[0]}, {expected[1]}) replicas "
                        f"of the scene's sensors x bins; re-render or remove it")
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

