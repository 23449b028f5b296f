"""Output files of DESIGN.md section 5, every one written atomically.

A file is written to a temporary name in its destination folder, flushed
and fsynced, then renamed over the final name: an interrupted command never
leaves a torn file, only the previous version or the new one.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = ["atomic_write", "save_npy", "save_json", "save_exr", "save_png_image", "save_figure",
           "write_transient", "read_transient"]


def atomic_write(path: str | Path, write: Callable[[str], None]) -> Path:
    """Call ``write(temporary_path)`` and rename the result onto ``path``.

    Parameters
    ----------
    path : str or Path
        Final file.
    write : callable
        Writes the whole file at the path it is given.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix,
                                         dir=path.parent)
    os.close(handle)
    try:
        write(temporary)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)   # mkstemp makes 0600; give the usual mode
        with open(temporary, "rb+") as stream:
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
    return path


def save_npy(path: str | Path, array: np.ndarray) -> Path:
    """Save an array as ``.npy``, atomically."""
    def write(temporary):
        with open(temporary, "wb") as stream:
            np.save(stream, np.asarray(array))
    return atomic_write(path, write)


def save_json(path: str | Path, data: Any) -> Path:
    """Save JSON (sorted keys, indented), atomically."""
    def write(temporary):
        with open(temporary, "w") as stream:
            json.dump(data, stream, indent=2, sort_keys=True, default=_json_default)
            stream.write("\n")
    return atomic_write(path, write)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def save_exr(path: str | Path, image: np.ndarray, attributes: dict[str, Any] | None = None) -> Path:
    """Save a one-channel float32 EXR (channel ``Y``) with header attributes.

    Parameters
    ----------
    path : str or Path
        Destination.
    image : numpy.ndarray
        ``(height, width)`` values.
    attributes : dict, optional
        Header attributes. Integers are stored as EXR ints; floats as their
        exact decimal ``repr`` string, because EXR float attributes are
        float32 and t0 ≈ 800 m in float32 is off by more than a fine bin.
    """
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        if isinstance(value, bool):
            header[key] = str(value)
        elif isinstance(value, (int, np.integer)):
            header[key] = int(value)
        elif isinstance(value, (float, np.floating)):
            header[key] = repr(float(value))
        else:
            header[key] = str(value)
    pixels = np.ascontiguousarray(image, dtype=np.float32)

    def write(temporary):
        with OpenEXR.File(header, {"Y": pixels}) as handle:
            handle.write(temporary)
    return atomic_write(path, write)


def save_png_image(path: str | Path, image: np.ndarray) -> Path:
    """Save a [0, 1] grey image as 16-bit PNG (value * 65535, no sRGB), atomically."""
    from PIL import Image

    data = np.round(np.clip(image, 0.0, 1.0) * 65535.0).astype(np.uint16)

    def write(temporary):
        Image.fromarray(data).save(temporary, format="PNG")
    return atomic_write(path, write)


def save_figure(figure, path: str | Path, dpi: int = 110) -> Path:
    """Write a matplotlib figure as PNG, atomically, and close it."""
    import matplotlib.pyplot as plt

    def write(temporary):
        figure.savefig(temporary, format="png", dpi=dpi)
    try:
        return atomic_write(path, write)
    finally:
        plt.close(figure)


def write_transient(out_dir: str | Path, transient: np.ndarray, meta: dict[str, Any], *,
                    stderr: np.ndarray | None = None, noisy: np.ndarray | None = None) -> dict[str, Path]:
    """Write ``transient.exr``, ``transient.npy``, ``meta.json`` (+ ``stderr.npy``, ``transient_noisy.npy``).

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    transient : numpy.ndarray
        ``(K, N)`` samples y_k[n]; saved as float64 ``.npy`` and float32 EXR
        (width N = time, height K = sensors).
    meta : dict
        Must hold ``start_opl``, ``period_opl``, ``samples``, ``seed``,
        ``attenuation`` and ``illumination``; all of it goes to meta.json and
        the EXR header.
    stderr : numpy.ndarray, optional
        ``(K, N)`` per-bin standard error (renders).
    noisy : numpy.ndarray, optional
        ``(K, N)`` noisy samples (model with noise).

    Returns
    -------
    dict
        Name -> path of every file written.
    """
    out_dir = Path(out_dir)
    transient = np.asarray(transient, dtype=np.float64)
    meta = dict(meta)
    meta.setdefault("units", "time as optical path length in metres (c = 1); "
                             "y in W/sr-normalised units (unit source intensity)")
    meta["sensors"], meta["bins"] = transient.shape
    attributes = {key: value for key, value in meta.items()
                  if isinstance(value, (str, int, float, np.integer, np.floating))}
    attributes = {("t0" if k == "start_opl" else "T" if k == "period_opl" else k): v
                  for k, v in attributes.items()}
    written = {}
    written["transient.npy"] = save_npy(out_dir / "transient.npy", transient)
    if stderr is not None:
        written["stderr.npy"] = save_npy(out_dir / "stderr.npy", np.asarray(stderr, dtype=np.float64))
    if noisy is not None:
        written["transient_noisy.npy"] = save_npy(out_dir / "transient_noisy.npy",
                                                  np.asarray(noisy, dtype=np.float64))
    written["transient.exr"] = save_exr(out_dir / "transient.exr", transient, attributes)
    written["meta.json"] = save_json(out_dir / "meta.json", meta)
    return written


def read_transient(path: str | Path) -> np.ndarray:
    """Read a transient from ``.npy`` or ``.exr`` (channel ``Y``), or from a folder holding them.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "transient.npy" if (path / "transient.npy").exists() else path / "transient.exr"
    if not path.is_file():
        raise FileNotFoundError(f"no transient at {path}")
    if path.suffix == ".npy":
        data = np.load(path, allow_pickle=False)
    elif path.suffix == ".exr":
        import OpenEXR
        with OpenEXR.File(str(path)) as handle:   # copy: the pixels die with the handle
            data = np.array(handle.channels()["Y"].pixels, dtype=np.float64)
    else:
        raise ValueError(f"{path.name}: expected .npy or .exr")
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2:
        raise ValueError(f"{path.name}: expected a (sensors, bins) array, got shape {data.shape}")
    return data
