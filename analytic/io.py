"""Output files of DESIGN.md section 5: written atomically, checked, in a locked folder.

Every file is written to a temporary name in its destination folder,
flushed, fsynced and checked (non-empty, and read back: the array's shape,
the JSON, the EXR's channel, the HDF5's datasets) before it is renamed over
the final name, so an interrupted command never leaves a torn file. Inside
:func:`staged_writes` the renames wait for the end of the block: a command
that fails half-way leaves its folder as it was. :func:`output_folder`
locks a folder for one command at a time and removes the temporaries a
killed command left there. Every file-system failure (disk full, read-only,
``--out`` naming a file, no permission) becomes one
:class:`~analytic.errors.ResourceError` line naming the path.

Metadata has one schema for every command, built by :func:`build_meta`
(DESIGN.md section 5 names its keys), written to ``meta.json`` and, as
numbers, into the EXR header.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import fcntl
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from .errors import DataError, ResourceError

__all__ = ["atomic_write", "staged_writes", "output_folder", "save_npy", "save_json", "save_text",
           "save_exr", "save_png_image", "write_transient", "read_transient", "read_exr", "build_meta",
           "remove_temporaries", "json_ready", "LOCK_FILE", "UNITS"]

#: Held (flock) by the command writing a folder; holds its process id.
LOCK_FILE = ".diffuse-imaging.lock"
_TEMPORARY_MARK = ".tmp-"

#: How y's units follow from the source's intensity (DESIGN.md section 1).
UNITS = ("lengths in metres; time as optical path length in metres (c = 1); y in W/sr x m^-2 x m "
         "of path length: the source's peak radiant intensity I (W/sr) times the pulse's "
         "integral over the bin (m of path length) times the attenuation (m^-4) times area (m^2); "
         "noise sigma in the units of y")

_staged: contextvars.ContextVar[list | None] = contextvars.ContextVar("staged", default=None)


def _resource_error(error: OSError, path: Path, action: str) -> ResourceError:
    fixes = {errno.ENOSPC: "free some space or choose another --out",
             errno.EDQUOT: "free some space or choose another --out",
             errno.EROFS: "the file system is read-only; choose another --out",
             errno.EACCES: "no permission; choose another --out",
             errno.EPERM: "no permission; choose another --out",
             errno.ENOTDIR: "a parent of it is a file, not a folder; choose another --out",
             errno.EEXIST: "a file of that name is in the way; choose another --out",
             errno.EISDIR: "a folder of that name is in the way; choose another --out"}
    fix = fixes.get(error.errno, "check the path")
    return ResourceError(f"{path}: cannot {action} ({error.strerror or error}); {fix}")


def _temporary_path(path: Path) -> Path:
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}{_TEMPORARY_MARK}", suffix=path.suffix,
                                         dir=path.parent)
    os.close(handle)
    return Path(temporary)


def _make_folder(folder: Path) -> None:
    try:
        if folder.exists() and not folder.is_dir():
            raise ResourceError(f"{folder}: is a file, not a folder; choose another --out")
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise _resource_error(error, folder, "create the folder") from None


def _rename(temporary: Path, path: Path) -> None:
    try:
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise _resource_error(error, path, "write") from None


def atomic_write(path: str | Path, write: Callable[[str], None],
                 verify: Callable[[str], None] | None = None) -> Path:
    """Write a file through a temporary name, check it, then rename it onto ``path``.

    Parameters
    ----------
    path : str or Path
        Final file; its folder is created.
    write : callable
        ``write(temporary_path)`` writes the whole file.
    verify : callable, optional
        ``verify(temporary_path)`` reads it back and raises if it is not what
        was meant (any exception: the write failed, e.g. a full disk).

    Returns
    -------
    Path
        ``path``. Inside :func:`staged_writes` the rename waits for the end
        of the block.

    Raises
    ------
    ResourceError
        When the file system refuses (full, read-only, a file in the way).
    """
    path = Path(path)
    _make_folder(path.parent)
    try:
        temporary = _temporary_path(path)
    except OSError as error:
        raise _resource_error(error, path, "write") from None
    try:
        write(str(temporary))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)   # mkstemp makes 0600; give the usual mode
        with open(temporary, "rb+") as stream:
            os.fsync(stream.fileno())
        if temporary.stat().st_size == 0:
            raise ResourceError(f"{path}: the written file is empty (disk full?); free some space "
                                f"or choose another --out")
        if verify is not None:
            try:
                verify(str(temporary))
            except Exception as error:  # any failure to read it back means the write failed
                raise ResourceError(f"{path}: the written file does not read back ({error}); "
                                    f"is the disk full?") from None
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise _resource_error(error, path, "write") from None
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    staged = _staged.get()
    if staged is not None:
        staged.append((temporary, path))
    else:
        _rename(temporary, path)
    return path


@contextlib.contextmanager
def staged_writes() -> Iterator[None]:
    """Rename every file :func:`atomic_write` writes in this block together, at its end.

    If the block raises, its temporaries are removed and no final file has
    changed: a command that fails half-way leaves its folder as it was.
    """
    if _staged.get() is not None:   # nested: the outer block commits
        yield
        return
    token = _staged.set([])
    try:
        yield
        staged = _staged.get()
        _staged.reset(token)
        token = None
        for temporary, path in staged:
            _rename(temporary, path)
    except BaseException:
        if token is not None:
            for temporary, _ in _staged.get():
                temporary.unlink(missing_ok=True)
            _staged.reset(token)
        raise


def remove_temporaries(folder: str | Path) -> int:
    """Remove the temporaries a killed command left in ``folder`` (not in its subfolders' locks).

    Returns the number removed. Call it only while holding the folder's lock.
    """
    removed = 0
    for path in Path(folder).rglob(f".*{_TEMPORARY_MARK}*"):
        if path.is_file():
            path.unlink(missing_ok=True)
            removed += 1
    return removed


@contextlib.contextmanager
def output_folder(folder: str | Path, *, option: str = "--out") -> Iterator[Path]:
    """Create and lock an output folder for one command; undo its creation if the command fails.

    Parameters
    ----------
    folder : str or Path
        The folder.
    option : str
        The command-line option that named it, for messages.

    Raises
    ------
    ResourceError
        When the folder is a file, cannot be created or written, or another
        command holds its lock (its process id is named).
    """
    if not str(folder).strip():      # Path("") is the current folder: never write there unasked
        raise ResourceError(f"{option}: an empty path; name the output folder")
    folder = Path(folder)
    created = not folder.exists()
    if folder.exists() and not folder.is_dir():
        raise ResourceError(f"{option} {folder}: is a file, not a folder; choose another {option}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        lock = os.open(folder / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as error:
        raise _resource_error(error, folder, "create the folder") from None
    try:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            other = os.pread(lock, 32, 0).decode(errors="replace").strip() or "unknown"
            raise ResourceError(f"{option} {folder}: another diffuse-imaging command (process {other}) "
                                f"is writing this folder; wait for it or choose another {option}") from None
        os.ftruncate(lock, 0)
        os.pwrite(lock, str(os.getpid()).encode(), 0)
        remove_temporaries(folder)
        try:
            yield folder
        except BaseException:
            if created:
                _remove_if_only_lock(folder)
            raise
    finally:
        os.close(lock)   # releases the flock
    with contextlib.suppress(OSError):
        (folder / LOCK_FILE).unlink()


def _remove_if_only_lock(folder: Path) -> None:
    """Remove a folder this command created, if it holds nothing but empty folders and the lock."""
    with contextlib.suppress(OSError):
        for inner in sorted((p for p in folder.rglob("*") if p.is_dir()), reverse=True):
            inner.rmdir()   # fails, and stops everything, at the first one that holds a file
        if {p.name for p in folder.iterdir()} <= {LOCK_FILE}:
            (folder / LOCK_FILE).unlink(missing_ok=True)
            folder.rmdir()


def _verify_npy(expected: np.ndarray) -> Callable[[str], None]:
    def verify(temporary):
        back = np.load(temporary, mmap_mode="r", allow_pickle=False)
        if back.shape != expected.shape or back.dtype != expected.dtype:
            raise ValueError(f"read back {back.shape} {back.dtype}")
    return verify


def save_npy(path: str | Path, array: np.ndarray) -> Path:
    """Save an array as ``.npy``, atomically, checking its shape and dtype on disk."""
    array = np.asarray(array)

    def write(temporary):
        with open(temporary, "wb") as stream:
            np.save(stream, array)
    return atomic_write(path, write, _verify_npy(array))


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def json_ready(value):
    """The value as save_json writes it: NaN and infinity as None (JSON has neither), arrays as lists."""
    return json.loads(json.dumps(_finite_or_null(value), default=_json_default, allow_nan=False))


def _finite_or_null(value):
    """JSON has no NaN or infinity: write them as null."""
    if isinstance(value, dict):
        return {key: _finite_or_null(v) for key, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(v) for v in value]
    if isinstance(value, np.ndarray):
        return _finite_or_null(value.tolist())
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    return value


def save_json(path: str | Path, data: Any) -> Path:
    """Save JSON (sorted keys, indented, NaN and infinity as null), atomically."""
    text = json.dumps(_finite_or_null(data), indent=2, sort_keys=True, default=_json_default,
                      allow_nan=False) + "\n"
    return save_text(path, text, verify=lambda temporary: json.loads(Path(temporary).read_text()))


def save_text(path: str | Path, text: str, verify: Callable[[str], None] | None = None) -> Path:
    """Save UTF-8 text (a report, a CSV), atomically, checking its length on disk.

    File names that are not UTF-8 (held as surrogate escapes) are written back as their bytes.
    """
    data = text.encode("utf-8", "surrogateescape")

    def write(temporary):
        with open(temporary, "wb") as stream:
            stream.write(data)

    def check(temporary):
        if os.path.getsize(temporary) != len(data):
            raise ValueError(f"{os.path.getsize(temporary)} bytes on disk, {len(data)} written")
        if verify is not None:
            verify(temporary)
    return atomic_write(path, write, check)


def _exr_value(value):
    """A header attribute: numbers as numbers (doubles: float32 would misplace t0 = 800 m by a
    fine bin), strings as strings, vectors of 3 as V3d; None for what EXR cannot hold."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value) if -2**31 <= int(value) < 2**31 else np.array(float(value))
    if isinstance(value, (float, np.floating)):
        return np.array(float(value), dtype=np.float64)
    if isinstance(value, str):
        return value
    array = np.asarray(value) if isinstance(value, (list, tuple, np.ndarray)) else None
    if array is not None and array.shape == (3,) and np.issubdtype(array.dtype, np.number):
        return array.astype(np.float64)
    return None


def save_exr(path: str | Path, image: np.ndarray, attributes: dict[str, Any] | None = None) -> Path:
    """Save a one-channel float32 EXR (channel ``Y``) with header attributes.

    Parameters
    ----------
    path : str or Path
        Destination.
    image : numpy.ndarray
        ``(height, width)`` values.
    attributes : dict, optional
        Header attributes: numbers are stored as EXR doubles (ints as ints),
        strings as strings, 3-vectors as V3d; nested tables are flattened to
        ``table_key``; lists of other lengths are left to meta.json.
    """
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in _flatten(attributes or {}).items():
        converted = _exr_value(value)
        if converted is not None:
            header[key] = converted
    pixels = np.ascontiguousarray(image, dtype=np.float32)

    def write(temporary):
        with OpenEXR.File(header, {"Y": pixels}) as handle:
            handle.write(temporary)

    def verify(temporary):
        with OpenEXR.File(temporary) as handle:
            back = handle.channels()["Y"].pixels
            if back.shape != pixels.shape:
                raise ValueError(f"read back {back.shape}")
    return atomic_write(path, write, verify)


def _flatten(table: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in table.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}_"))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def save_png_image(path: str | Path, image: np.ndarray) -> Path:
    """Save a [0, 1] grey image as 16-bit PNG (value * 65535, no sRGB), atomically."""
    from PIL import Image

    data = np.round(np.clip(image, 0.0, 1.0) * 65535.0).astype(np.uint16)

    def write(temporary):
        Image.fromarray(data).save(temporary, format="PNG")

    def verify(temporary):
        with Image.open(temporary) as handle:
            if handle.size != (data.shape[1], data.shape[0]):
                raise ValueError(f"read back {handle.size}")
    return atomic_write(path, write, verify)


def build_meta(scene, *, kind: str, samples: int = 0, seed: int | None = None,
               window_share: float | None = None, **extra) -> dict:
    """The one metadata record of every command (DESIGN.md section 5).

    Parameters
    ----------
    scene : analytic.Scene
        The scene the transient belongs to.
    kind : {"model", "render"}
        Who computed it.
    samples : int
        Monte Carlo samples (0 for the model).
    seed : int, optional
        The render's seed, or the noise seed of a model with noise.
    window_share : float, optional
        Share of the light the window holds (:func:`analytic.window_share`).
    **extra
        Further keys (a command's own: variant, timings, ...); they may not
        redefine the schema's keys.

    Returns
    -------
    dict
        ``kind``, ``samples``, ``seed``, ``scene``, ``plane_size``, ``pixels``,
        ``source``, ``intensity``, ``sensor_positions``, ``attenuation``,
        ``illumination`` (the waveform's name) and ``illumination_parameters``,
        ``tolerance`` (the model's; None for a render), ``window_share``,
        ``noise`` (the scene's, None when noiseless), ``start_opl``,
        ``bin_width_opl``, ``bins``, ``sensors``, ``units``.
    """
    from .waveforms import make_waveform

    if kind not in ("model", "render"):
        raise ValueError(f"kind: 'model' or 'render', got {kind!r}")
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    noise = scene.noise
    meta = {
        "kind": kind,
        "samples": int(samples),
        "seed": None if seed is None else int(seed),
        "scene": scene.name,
        "plane_size": float(scene.size),
        "pixels": int(scene.pixels),
        "source": [float(v) for v in scene.source],
        "intensity": float(scene.intensity),
        "sensor_positions": np.asarray(scene.sensors, dtype=np.float64).tolist(),
        # the renderer renders physical transport only
        "attenuation": scene.attenuation if kind == "model" else "lambertian",
        "illumination": waveform.name,
        "illumination_parameters": dict(waveform.parameters),
        "tolerance": float(scene.tolerance) if kind == "model" else None,
        "window_share": None if window_share is None else float(window_share),
        "noise": None if noise is None else {"kind": noise.kind, "sigma": noise.sigma,
                                             "photons": noise.photons, "seed": noise.seed},
        "start_opl": float(scene.sampling.start_opl),
        "bin_width_opl": float(scene.sampling.bin_width_opl),
        "bins": int(scene.sampling.count),
        "sensors": int(scene.sensor_count),
        "units": UNITS,
    }
    clash = sorted(set(extra) & set(meta))
    if clash:
        raise ValueError(f"extra: {', '.join(clash)} are schema keys")
    meta.update(extra)
    return meta


def write_transient(out_dir: str | Path, transient: np.ndarray, meta: dict[str, Any], *,
                    stderr: np.ndarray | None = None, noisy: np.ndarray | None = None) -> dict[str, Path]:
    """Write ``transient.{npy,exr,h5}``, ``meta.json`` (+ ``stderr.npy``, ``transient_noisy.npy``), together.

    ``transient.h5`` is tal's HDF5 capture (:mod:`analytic.capture`), readable
    by ``tal.io.read_capture``, with the metadata as its ``scene_info``.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    transient : numpy.ndarray
        ``(K, N)`` samples y_k[n]; saved as float64 ``.npy``, float32 EXR
        (width N = time, height K = sensors) and tal's HDF5 capture.
    meta : dict
        From :func:`build_meta`; all of it goes to meta.json, its numbers and
        strings to the EXR header.
    stderr : numpy.ndarray, optional
        ``(K, N)`` per-bin standard error (renders).
    noisy : numpy.ndarray, optional
        ``(K, N)`` noisy samples (model with noise).

    Returns
    -------
    dict
        Name -> path of every file written. The files are renamed into place
        together (see :func:`staged_writes`).
    """
    from .capture import write_capture   # capture imports this module

    out_dir = Path(out_dir)
    transient = np.asarray(transient, dtype=np.float64)
    if transient.shape != (meta["sensors"], meta["bins"]):
        raise ValueError(f"transient: shape {transient.shape}, meta says "
                         f"({meta['sensors']}, {meta['bins']})")
    written = {}
    with staged_writes():
        written["transient.npy"] = save_npy(out_dir / "transient.npy", transient)
        if stderr is not None:
            written["stderr.npy"] = save_npy(out_dir / "stderr.npy", np.asarray(stderr, dtype=np.float64))
        if noisy is not None:
            written["transient_noisy.npy"] = save_npy(out_dir / "transient_noisy.npy",
                                                      np.asarray(noisy, dtype=np.float64))
        written["transient.exr"] = save_exr(out_dir / "transient.exr", transient, meta)
        written["transient.h5"] = write_capture(out_dir / "transient.h5", transient,
                                                start_opl=meta["start_opl"],
                                                bin_width_opl=meta["bin_width_opl"], source=meta["source"],
                                                sensors=meta["sensor_positions"],
                                                scene_info=_finite_or_null(meta))
        written["meta.json"] = save_json(out_dir / "meta.json", meta)
    return written


def read_exr(path: str | Path) -> tuple[np.ndarray, dict]:
    """The ``Y`` channel of an EXR as float64 and its header, numbers as Python floats and ints.

    Raises
    ------
    DataError
        Unreadable, or without a ``Y`` channel.
    """
    import OpenEXR

    path = Path(path)
    try:
        with OpenEXR.File(str(path)) as handle:   # copies: header and pixels die with the handle
            channels = handle.channels()
            if "Y" not in channels:
                raise DataError(f"{path}: EXR has no channel Y (found {', '.join(sorted(channels))}); "
                                f"expected one of ours (width = bins, height = sensors)")
            pixels = np.array(channels["Y"].pixels, dtype=np.float64)
            header = {key: _header_value(value) for key, value in handle.header().items()}
    except DataError:
        raise
    except Exception as error:  # the binding raises RuntimeError and others for a bad file
        raise DataError(f"{path}: cannot read it as an EXR ({type(error).__name__}: {error})") from None
    return pixels, header


def _header_value(value):
    """EXR doubles come back as 1-element arrays: give the number itself."""
    if isinstance(value, np.ndarray):
        return float(value.ravel()[0]) if value.size == 1 else value.copy()
    return value


def read_transient(path: str | Path) -> np.ndarray:
    """Read a transient from ``.npy``, ``.exr`` (channel ``Y``) or tal's ``.h5``, or from a folder holding them.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64.

    Raises
    ------
    DataError
        Missing, unreadable or not a (K, N) array.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "transient.npy" if (path / "transient.npy").exists() else path / "transient.exr"
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        if path.suffix == ".npy":
            data = np.load(path, allow_pickle=False)
        elif path.suffix == ".exr":
            data, _ = read_exr(path)
        elif path.suffix in (".h5", ".hdf5"):
            from .capture import read_capture   # capture imports this module

            data = read_capture(path).transient
        else:
            raise DataError(f"{path}: expected a .npy, .exr or .h5 (tal capture) transient")
    except DataError:
        raise
    except Exception as error:  # NumPy raises many types for a bad file
        raise DataError(f"{path}: cannot read it ({type(error).__name__}: {error})") from None
    if not np.issubdtype(np.asarray(data).dtype, np.number):
        raise DataError(f"{path}: holds {np.asarray(data).dtype} values, not numbers")
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2:
        raise DataError(f"{path}: expected a (sensors, bins) array, got shape {data.shape}")
    return data
