"""Reflectance images: the built-in test pattern and PNG / EXR loading.

An image is an ``M x M`` float64 array of linear reflectance values in [0, 1],
oriented as DESIGN.md section 1 says: ``image[r, c]`` is the pixel seen by a
camera above the plane, row ``r`` counted from the top (largest y).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import ImageError

__all__ = ["builtin_reflectance", "read_reflectance"]


def builtin_reflectance(pixels: int) -> np.ndarray:
    """The default scene's reflectance: sharp edges beside smooth regions.

    A smooth diagonal ramp carries a soft Gaussian blob (smooth regions), a
    bright bar and a dark disc with hard edges, and a small high-contrast
    checker (fine detail) in one corner. The pattern is defined on the unit
    square and sampled at pixel centres, so it looks the same at any ``M``.

    Parameters
    ----------
    pixels : int
        Image side ``M``.

    Returns
    -------
    numpy.ndarray
        ``(M, M)`` float64 reflectance in [0, 1], row 0 at the top.
    """
    centres = (np.arange(pixels) + 0.5) / pixels
    x = centres[None, :]                       # to the right
    y = (1.0 - centres)[:, None]               # up (row 0 is the top)
    image = 0.25 + 0.2 * (x + y) / 2.0
    image = image + 0.25 * np.exp(-((x - 0.3) ** 2 + (y - 0.3) ** 2) / (2 * 0.12**2))
    bar = (np.abs(x - 0.7) < 0.08) & (np.abs(y - 0.45) < 0.3)
    image = np.where(bar, 0.9, image)
    disc = (x - 0.32) ** 2 + (y - 0.72) ** 2 < 0.13**2
    image = np.where(disc, 0.05, image)
    checker = (x > 0.78) & (y > 0.8)
    checker_value = np.where(((x * 10).astype(int) + (y * 10).astype(int)) % 2 == 0, 1.0, 0.1)
    image = np.where(checker, checker_value, image)
    return np.clip(image, 0.0, 1.0).astype(np.float64)


def read_reflectance(path: str | Path, pixels: int) -> np.ndarray:
    """Read an ``M x M`` reflectance image from PNG or EXR.

    PNG: 8- or 16-bit grey (or RGB with equal channels), value/255 or
    value/65535, no sRGB decoding. EXR: channel ``Y``, or equal ``R``, ``G``,
    ``B``; values are used as stored (linear).

    Parameters
    ----------
    path : str or Path
        Image file.
    pixels : int
        Expected side ``M``; any other size is an error.

    Returns
    -------
    numpy.ndarray
        ``(M, M)`` float64 reflectance, row 0 at the top.

    Raises
    ------
    ImageError
        Missing or unreadable file, unsupported format, colour image, wrong
        size, or values outside [0, 1] or not finite.
    """
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".png":
        image = _read_png(path)
    elif suffix == ".exr":
        image = _read_exr(path)
    else:
        raise ImageError(f"{path.name}: unsupported format {suffix!r} (use .png or .exr)")
    if image.shape != (pixels, pixels):
        raise ImageError(
            f"{path.name}: image is {image.shape[1]} x {image.shape[0]} pixels, "
            f"plane.pixels asks for {pixels} x {pixels}"
        )
    if not np.all(np.isfinite(image)):
        raise ImageError(f"{path.name}: image has NaN or infinite values")
    if image.min() < 0.0 or image.max() > 1.0:
        raise ImageError(
            f"{path.name}: reflectance must lie in [0, 1], found "
            f"[{image.min():.4g}, {image.max():.4g}]"
        )
    return image


def _read_png(path: Path) -> np.ndarray:
    from PIL import Image

    try:
        with Image.open(path) as handle:
            mode = handle.mode
            data = np.asarray(handle)
    except Exception as error:  # Pillow raises many types for a bad file
        raise ImageError(f"{path.name}: cannot read PNG ({error})") from None
    if mode in ("I;16", "I;16B", "I;16L", "I"):
        scale = 65535.0
    elif mode in ("L", "RGB", "RGBA", "LA"):
        scale = 255.0
    else:
        raise ImageError(f"{path.name}: unsupported PNG mode {mode!r} (use 8/16-bit grey)")
    data = data.astype(np.float64)
    if data.ndim == 3:
        colour = data[..., :3] if data.shape[2] >= 3 else data[..., :1]
        if not np.all(colour == colour[..., :1]):
            raise ImageError(f"{path.name}: colour PNG; reflectance must be grey (equal R, G, B)")
        data = colour[..., 0]
    return data / scale


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    try:
        with OpenEXR.File(str(path)) as handle:
            channels = {name: np.array(ch.pixels, dtype=np.float64)   # copy before close
                        for name, ch in handle.channels().items()}
    except Exception as error:  # the binding raises RuntimeError and others
        raise ImageError(f"{path.name}: cannot read EXR ({error})") from None
    if "Y" in channels:
        return channels["Y"]
    if {"R", "G", "B"} <= channels.keys():
        red, green, blue = channels["R"], channels["G"], channels["B"]
        if not (np.array_equal(red, green) and np.array_equal(red, blue)):
            raise ImageError(f"{path.name}: colour EXR; reflectance must be grey (equal R, G, B)")
        return red
    if "RGB" in channels and channels["RGB"].ndim == 3:
        rgb = channels["RGB"]
        if not np.all(rgb == rgb[..., :1]):
            raise ImageError(f"{path.name}: colour EXR; reflectance must be grey (equal R, G, B)")
        return rgb[..., 0]
    raise ImageError(f"{path.name}: EXR has no Y channel nor R, G, B (found {sorted(channels)})")
