"""One writer (atomic, read back) and one reader per file format: ``.npy``, JSON, text, EXR, PNG.

The EXR is float32: where float32 cannot hold the values
(:func:`float32_problem`), the caller leaves it unwritten and says why
(:class:`PrecisionWarning`); the float64 ``.npy`` is the exact record.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from analytic.errors import DataError
from analytic.values import exact

from .atomic import atomic_write

__all__ = ["save_npy", "read_npy", "save_json", "save_text", "json_ready", "json_default", "save_exr",
           "read_exr", "read_exr_channels", "save_png_image", "float32_problem", "PrecisionWarning"]


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


def read_npy(path: str | Path) -> np.ndarray:
    """A ``.npy`` array of real numbers (integer or floating), as float64.

    Raises
    ------
    DataError
        Unreadable, not a single array (an ``.npz`` archive), or of a type
        that is not a real number (text, complex, boolean, objects).
    """
    try:
        # mapped first: a header whose shape the file does not hold (truncated, or forged to 10^14
        # values) is refused by its size, not by an attempt to allocate it
        array = np.load(path, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise DataError(f"{path}: not a readable .npy ({error})") from None
    if not isinstance(array, np.ndarray):
        array.close()
        raise DataError(f"{path}: an .npz archive, not one .npy array; save the transient with numpy.save")
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise DataError(f"{path}: holds {array.dtype} values, not real numbers; save y as float64")
    return np.array(array, dtype=np.float64)


def json_default(value):
    """``json.dumps``' ``default``: NumPy numbers and arrays as Python ones, paths as text."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def json_ready(value):
    """The value as save_json writes it: NaN and infinity as None (JSON has neither), arrays as lists."""
    return json.loads(json.dumps(_finite_or_null(value), default=json_default, allow_nan=False))


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
    text = json.dumps(_finite_or_null(data), indent=2, sort_keys=True, default=json_default,
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


class PrecisionWarning(UserWarning):
    """A float32 copy (``transient.exr``) left unwritten: float32 cannot hold the values.

    The float64 file (``transient.npy``) is the exact record.
    """


#: float32's unit roundoff: rounding to nearest moves a normal value by at most this share of it.
_FLOAT32_ROUNDOFF = 2.0**-24


def float32_problem(values) -> str | None:
    """Why float32 cannot hold ``values`` to its own precision; None when it can.

    Parameters
    ----------
    values : array_like
        The numbers (any units).

    Returns
    -------
    str or None
        None when rounding to float32 moves no value by more than
        2^-24 of the largest |value|; else the reason, in a few words.

    Notes
    -----
    Float32 holds a value to 2^-24 of itself between its smallest normal
    (1.18e-38) and its largest (3.40e38). Above, values become infinite;
    below, subnormals keep 2^-150 absolutely and then zero. The error is
    measured, not inferred, so an array whose largest value is normal
    passes (its subnormals err by at most 2^-150 <= 2^-24 of the largest)
    and one whose largest lies below 1.18e-38 fails (1e-300 becomes 0).
    """
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return None
    if not np.all(np.isfinite(values)):
        return "it holds NaN or infinite values"
    largest = float(np.max(np.abs(values)))
    with np.errstate(over="ignore", under="ignore"):
        rounded = values.astype(np.float32)
    limits = np.finfo(np.float32)
    if not np.all(np.isfinite(rounded)):
        return f"its largest |value| {exact(largest)} exceeds float32's largest, {exact(limits.max)}"
    error = float(np.max(np.abs(rounded.astype(np.float64) - values)))
    if error > _FLOAT32_ROUNDOFF * largest:
        return (f"its largest |value| {exact(largest)} lies below float32's smallest normal, "
                f"{exact(limits.tiny)}: float32 would keep zeros and subnormals")
    return None


def save_exr(path: str | Path, image: np.ndarray, attributes: dict[str, Any] | None = None) -> Path:
    """Save a one-channel float32 EXR (channel ``Y``) with header attributes.

    Parameters
    ----------
    path : str or Path
        Destination.
    image : numpy.ndarray
        ``(height, width)`` values; float32 must hold them
        (:func:`float32_problem` returns None): check first.
    attributes : dict, optional
        Header attributes: numbers are stored as EXR doubles (ints as ints),
        strings as strings, 3-vectors as V3d; nested tables are flattened to
        ``table_key``; lists of other lengths are left to meta.json.

    Raises
    ------
    ValueError
        When float32 cannot hold the image (the caller's to avoid).
    ResourceError
        When the file cannot be written, or does not read back as the
        image rounded to float32.
    """
    import OpenEXR

    problem = float32_problem(image)
    if problem is not None:
        raise ValueError(f"{path}: a float32 EXR cannot hold this image: {problem}")
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
            back = np.array(handle.channels()["Y"].pixels)
        if back.shape != pixels.shape or back.dtype != np.float32:
            raise ValueError(f"read back {back.shape} {back.dtype}")
        if not (np.all(np.isfinite(back)) and np.array_equal(back, pixels)):
            raise ValueError("the values read back differ from those written")
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


def read_exr_channels(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Every channel of an EXR as float64 and its header, numbers as Python floats and ints.

    The OpenEXR binding groups R, G, B into one ``RGB`` channel of shape
    ``(height, width, 3)``; other channels are ``(height, width)``.

    Raises
    ------
    DataError
        Not a readable EXR.
    """
    import OpenEXR

    path = Path(path)
    try:
        with OpenEXR.File(str(path)) as handle:   # copies: header and pixels die with the handle
            channels = {name: np.array(channel.pixels, dtype=np.float64)
                        for name, channel in handle.channels().items()}
            header = {key: _header_value(value) for key, value in handle.header().items()}
    except Exception as error:  # the binding raises RuntimeError and others for a bad file
        raise DataError(f"{path}: cannot read it as an EXR ({type(error).__name__}: {error})") from None
    return channels, header


def read_exr(path: str | Path) -> tuple[np.ndarray, dict]:
    """The ``Y`` channel of an EXR as float64 and its header (:func:`read_exr_channels`).

    Raises
    ------
    DataError
        Unreadable, or without a ``Y`` channel.
    """
    channels, header = read_exr_channels(path)
    if "Y" not in channels:
        raise DataError(f"{path}: EXR has no channel Y (found {', '.join(sorted(channels))}); "
                        f"expected one of ours (width = bins, height = sensors)")
    return channels["Y"], header


def _header_value(value):
    """EXR doubles come back as 1-element arrays: give the number itself."""
    if isinstance(value, np.ndarray):
        return float(value.ravel()[0]) if value.size == 1 else value.copy()
    return value
