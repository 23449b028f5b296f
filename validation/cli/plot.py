"""``diffuse-imaging plot``: draw any transient this project reads, ours or another tool's, into ``--out``.

What it reads, and where each file's time axis comes from:

- our output (a folder, or its ``transient.npy``/``.exr``/``.h5``): the
  ``meta.json`` beside it (an EXR's header, a capture's ``t_start`` and
  ``delta_t`` serve too), with the render's standard error from
  ``stderr.npy`` beside it and the model's noisy samples from
  ``transient_noisy.npy``; a relay-wall capture's (its ``meta.json``
  records the scan) is drawn per pair and over the scan
  (:func:`validation.plots.relay_wall.relay_wall_figure`);
- tal's HDF5 capture: its ``t_start`` and ``delta_t``; drawn as the light
  each wall point receives and a few traces (:func:`validation.plots.captures.capture_figure`);
- with ``--scene SCENE.toml``: anything ``check`` reads
  (:func:`validation.check.read_data`: mitransient's films and frame folders,
  a ``(K, N)`` array from any tool), on the scene's time axis, which a file
  that states its own must match.

The figure is ``DIR/transient.png`` (:func:`validation.plots.transients.transient_figure`), written
atomically; nothing else is written, and a file that cannot be drawn ends the
command with one line and exit status 2 before anything is.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .common import add_quiet, load_scene_argument

__all__ = ["add_commands", "command_plot", "read_for_plot", "Drawable", "render_title", "FIGURE_NAME"]

#: The figure ``plot`` writes into ``--out``.
FIGURE_NAME = "transient.png"


@dataclass(frozen=True)
class Drawable:
    """A transient read for drawing, with its time axis and what to call it.

    Attributes
    ----------
    transient : numpy.ndarray
        ``(K, N)`` values per sensor (or wall point) and bin.
    sampling : analytic.Sampling
        Its bins, metres of path length.
    label : str
        What it is: "model", "render", "data".
    title : str
        The figure's title.
    stderr, noisy : numpy.ndarray or None
        ``(K, N)`` a render's standard error; a model's noisy samples.
    positions : numpy.ndarray or None
        ``(K, 3)`` the points of a capture not written by us (drawn as a
        map), else None.
    scan : validation.plots.WallScan or None
        A relay-wall capture's scan (its rows are pairs), else None.
    """

    transient: np.ndarray
    sampling: object
    label: str
    title: str
    stderr: np.ndarray | None = None
    noisy: np.ndarray | None = None
    positions: np.ndarray | None = None
    scan: object | None = None


def render_title(name: str, *, samples: int, replicas: int, complete: bool = True) -> str:
    """The title of a render's figure: its scene, samples and replicas, and PARTIAL when unfinished."""
    title = f"{name}: render of {samples:,} samples ({replicas} replicas), ±1 standard error"
    return title if complete else f"{title}; PARTIAL: an unfinished render's estimate"


def _sampling(start_opl, bin_width_opl, count, source: str):
    """The bins a file states, or a DataError naming the file when they are not bins."""
    from analytic.errors import DataError
    from analytic.scenes.common import Sampling

    try:
        return Sampling(bin_width_opl=float(bin_width_opl), start_opl=float(start_opl), count=int(count))
    except (TypeError, ValueError) as error:
        raise DataError(f"{source}: its time axis is not usable ({' '.join(str(error).split())})") from None


def _meta_beside(path: Path) -> dict | None:
    """Our ``meta.json`` beside a transient file, or None when there is none."""
    from analytic.errors import DataError

    meta_path = path.parent / "meta.json"
    if not meta_path.is_file():
        return None
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise DataError(f"{meta_path}: not readable JSON ({error}); remove it or give --scene SCENE.toml") \
            from None
    return meta if _is_ours(meta) else None


def _is_ours(meta) -> bool:
    """Whether a record is our metadata (docs/design.md section 5), which states the time axis."""
    return isinstance(meta, dict) and meta.get("kind") in ("model", "render") \
        and all(key in meta for key in ("start_opl", "bin_width_opl", "bins", "sensors"))


def _title_of(meta: dict, fallback: str) -> tuple[str, str]:
    """(label, title) from our metadata."""
    name = str(meta.get("scene", fallback))
    if meta.get("kind") == "render":
        return "render", render_title(name, samples=int(meta.get("samples", 0)),
                                      replicas=int(meta.get("replicas", 0)),
                                      complete=meta.get("complete", True) is not False)
    if meta.get("geometry") == "relay_wall" and isinstance(meta.get("scan"), dict):
        return "model", f"{name}: {meta['scan'].get('type')} scan through a relay wall, " \
                        f"{meta.get('illumination', 'impulse')} illumination (model)"
    return "model", f"{name}: {meta.get('illumination', 'impulse')} illumination, " \
                    f"{meta.get('attenuation', 'lambertian')} attenuation (model)"


def _beside(path: Path, name: str, shape: tuple) -> np.ndarray | None:
    """An array of ours beside a transient file (``stderr.npy``, ``transient_noisy.npy``) of its shape."""
    from analytic.errors import DataError
    from analytic.files import read_npy

    other = path.parent / name
    if not other.is_file():
        return None
    array = read_npy(other)
    if array.shape != shape:
        raise DataError(f"{other}: shape {array.shape}, the transient beside it is {shape}; re-render or "
                        f"remove it")
    return array


def _finite(path, array: np.ndarray) -> np.ndarray:
    from analytic.errors import DataError

    if array.ndim != 2:
        raise DataError(f"{path}: shape {array.shape}; expected a (sensors, bins) transient")
    if not np.all(np.isfinite(array)):
        raise DataError(f"{path}: {int(np.sum(~np.isfinite(array)))} value(s) are NaN or infinite; "
                        f"nothing to draw there")
    return array


def _no_time_axis(path: Path, what: str):
    from analytic.errors import DataError

    return DataError(f"{path}: {what} carries no time axis (no meta.json of ours beside it); give --scene "
                     f"SCENE.toml, the scene it was rendered from")


def _ours(path: Path, transient: np.ndarray, meta: dict) -> Drawable:
    """Our transient file with the metadata beside it."""
    from analytic.errors import DataError

    shape = (int(meta["sensors"]), int(meta["bins"]))
    if transient.shape != shape:
        raise DataError(f"{path}: shape {transient.shape}, its meta.json says {shape[0]} sensors x {shape[1]} "
                        f"bins; the files are of different commands: write them again")
    label, title = _title_of(meta, path.parent.name)
    stderr = _beside(path, "stderr.npy", shape) if label == "render" else None
    noisy = _beside(path, "transient_noisy.npy", shape) if label == "model" else None
    sampling = _sampling(meta["start_opl"], meta["bin_width_opl"], shape[1], str(path.parent / "meta.json"))
    return Drawable(transient, sampling, label, title, stderr=stderr, noisy=noisy, scan=_scan_of(path, meta))


def _scan_of(path: Path, meta: dict):
    """A relay-wall capture's scan from our metadata (None for a plane's); a DataError when it is incomplete."""
    from analytic.errors import DataError
    from validation.plots import WallScan

    if meta.get("geometry") != "relay_wall":
        return None
    try:
        return WallScan.of_meta(meta)
    except ValueError as error:
        raise DataError(f"{path.parent / 'meta.json'}: a relay-wall capture's metadata, but {error}; write the "
                        f"files again") from None


def _capture(path: Path) -> Drawable:
    """tal's HDF5 capture (ours or tal's): its own time axis; ours drawn as a transient, tal's as a map."""
    from interop.tal import read_capture

    capture = read_capture(path)
    transient = _finite(path, capture.transient)
    sampling = _sampling(capture.start_opl, capture.bin_width_opl, transient.shape[1], str(path))
    info = capture.scene_info
    if _is_ours(info):
        label, title = _title_of(info, path.parent.name)
        stderr = _beside(path, "stderr.npy", transient.shape) if label == "render" else None
        return Drawable(transient, sampling, label, title, stderr=stderr, scan=_scan_of(path, info))
    title = f"{path.name}: tal capture, {transient.shape[0]} points x {transient.shape[1]} bins"
    return Drawable(transient, sampling, "data", title, positions=capture.sensors)


def _without_scene(path: Path) -> Drawable:
    """A file (or our folder) that states its own time axis."""
    from analytic.errors import DataError
    from analytic.files import TRANSIENT_FILES, read_exr, read_npy, transient_format, transient_in_folder

    if path.is_dir():
        found = transient_in_folder(path)
        if found is None:
            partial = path / "partial"
            hint = (f"; an unfinished render: its partial estimate is in {partial}"
                    if transient_in_folder(partial) is not None else
                    "; give the transient file itself (mitransient's frames need --scene SCENE.toml)")
            raise DataError(f"{path}: a folder without {' or '.join(TRANSIENT_FILES)}{hint}")
        path = found
    kind = transient_format(path)
    if kind == "capture":
        return _capture(path)
    if kind == "npy":
        array = read_npy(path)
        if array.ndim in (4, 5):
            raise _no_time_axis(path, "a mitransient film")
        meta = _meta_beside(path)
        if meta is None:
            raise _no_time_axis(path, "a bare .npy array")
        return _ours(path, _finite(path, array), meta)
    if kind == "exr":
        array, header = read_exr(path)
        meta = _meta_beside(path)
        if meta is not None:
            return _ours(path, _finite(path, array), meta)
        header = {key: _header_value(value) for key, value in header.items()}
        if _is_ours(header):
            return _ours(path, _finite(path, array), header)
        raise _no_time_axis(path, "an EXR without our header")
    raise DataError(f"{path}: unknown format (expected our folder, .npy, .exr, tal's .h5/.hdf5, or with --scene "
                    f"mitransient's film)")


def _header_value(value):
    """An EXR header's number (stored as a one-element array) as a Python number; anything else as it is."""
    if isinstance(value, np.ndarray) and value.size == 1:
        return value.reshape(()).item()
    return value


def _with_scene(path: Path, scene) -> Drawable:
    """Anything ``check`` reads, on the scene's time axis (a file that states its own must match it)."""
    from validation.check import read_data, stderr_beside
    from validation.plots import WallScan
    transient = read_data(path, scene)
    beside = stderr_beside(path, scene)
    stderr = beside[0] if beside is not None else None
    label = "render" if stderr is not None else "data"
    scan = WallScan.for_scene(scene)
    return Drawable(transient, scene.sampling, label, f"{scene.name}: {path.name}", stderr=stderr, scan=scan)


def read_for_plot(path: str | Path, scene=None) -> Drawable:
    """Read what ``plot`` draws (see the module docstring).

    Parameters
    ----------
    path : str or Path
        A transient file or our folder.
    scene : analytic.Scene, optional
        The scene the data belong to: its time axis and sensors (needed for
        files that carry no time axis).

    Raises
    ------
    analytic.errors.DataError
        No such file, an unknown format, no time axis and no scene, a shape
        or time axis that does not match, NaN or infinity.
    """
    from analytic.errors import DataError

    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such file or folder")
    return _with_scene(path, scene) if scene is not None else _without_scene(path)


def _figure(drawable: Drawable):
    from validation.plots.captures import capture_figure
    from validation.plots.relay_wall import relay_wall_figure
    from validation.plots.transients import transient_figure

    if drawable.scan is not None:
        return relay_wall_figure(drawable.sampling, drawable.transient, drawable.scan, stderr=drawable.stderr,
                                 noisy=drawable.noisy, label=drawable.label, title=drawable.title)
    if drawable.positions is not None:
        return capture_figure(drawable.sampling, drawable.transient, drawable.positions, title=drawable.title)
    return transient_figure(drawable.sampling, drawable.transient, stderr=drawable.stderr, noisy=drawable.noisy,
                            label=drawable.label, title=drawable.title)


def command_plot(args) -> int:
    """Draw one transient into ``--out``/transient.png; exit status 0."""
    from analytic.files import output_folder, reading_folder
    from validation.plots import save_figure

    scene = load_scene_argument(args.scene) if args.scene is not None else None
    with reading_folder(args.path, option="PATH"):
        drawable = read_for_plot(args.path, scene)
    figure = _figure(drawable)
    with output_folder(args.out) as out:
        save_figure(figure, out / FIGURE_NAME)
    if not args.quiet:
        sensors, bins = drawable.transient.shape
        points = "points" if drawable.positions is not None else "pairs" if drawable.scan is not None else "sensors"
        print(f"plot: {args.path} ({sensors} {points} x {bins} bins of {drawable.sampling.bin_width_opl:g} m "
              f"from {drawable.sampling.start_opl:g} m) -> {Path(args.out) / FIGURE_NAME}")
    return 0


def add_commands(subparsers) -> None:
    """Add ``plot``."""
    plot = subparsers.add_parser(
        "plot", help="draw any transient we read (ours, mitransient's, tal's) as a figure",
        description="Draw a transient into DIR/transient.png: our output folder or file (transient.npy, "
                    ".exr, .h5 with the meta.json beside it; a render's standard error as a band), tal's HDF5 "
                    "capture (the light per wall point and a few traces), or, with --scene, anything check "
                    "reads (mitransient's films, a (K, N) .npy), on the scene's time axis.")
    plot.add_argument("path", metavar="PATH", help="a transient file or our output folder")
    plot.add_argument("--scene", metavar="SCENE",
                      help="scene TOML: its time axis and sensors, for files that carry none (mitransient's "
                           "films, a bare .npy); a file that states its own must match it")
    plot.add_argument("--out", required=True, metavar="DIR", help="output folder (transient.png)")
    add_quiet(plot)
    plot.set_defaults(run=command_plot)
