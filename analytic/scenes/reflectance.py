"""Reflectance images: the built-in test pattern and PNG / EXR loading.

An image is an ``M x M`` float64 array of linear reflectance values in [0, 1],
oriented as docs/design.md section 1 says: ``image[r, c]`` is the pixel seen by a
camera above the plane, row ``r`` counted from the top (largest y).
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import stat
import sys
import tempfile
import threading
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ImageError, SceneError
from ..values import _number

__all__ = ["builtin_reflectance", "read_reflectance", "reflectance_image", "regular_file_problem"]

#: First bytes of every OpenEXR file (its magic number, little-endian 20000630).
_EXR_MAGIC = b"\x76\x2f\x31\x01"

_FLATTEN = "reflectance has no transparency; flatten the image (remove its alpha)"
_MAKE_GREY = "reflectance must be grey; save the image as grey, or with R = G = B"

# control characters (a NUL, a newline in a file name) shown escaped, so a message stays one line
_ESCAPED_CONTROLS = {code: f"\\x{code:02x}" for code in [*range(0x20), 0x7F]}

# file descriptors 1 and 2 are the process's: one capture of the library's output at a time
_CAPTURE_LOCK = threading.Lock()


def reflectance_image(key: str, value: Any, pixels: int) -> np.ndarray:
    """A read-only M x M image in [0, 1] from a number or an array of numbers, or SceneError naming ``key``.

    An array of strings, booleans or objects is refused (``np.array(["1"], float)`` would read "1" as 1).
    """
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise SceneError(key, f"expected an image of numbers, got an array of dtype {value.dtype}")
        image = np.array(value, dtype=np.float64)
        if image.shape != (pixels, pixels):
            raise SceneError(key, f"image shape {image.shape} differs from ({pixels}, {pixels})")
        if not np.all(np.isfinite(image)) or image.min() < 0 or image.max() > 1:
            raise SceneError(key, "values must be finite and in [0, 1]")
    else:
        number = _number(key, value)
        if not 0.0 <= number <= 1.0:
            raise SceneError(key, f"must lie in [0, 1], got {number}")
        image = np.full((pixels, pixels), number)
    image.setflags(write=False)
    return image


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

    PNG, every colour type at every bit depth d it allows (1, 2, 4, 8, 16):
    the reflectance is the stored sample divided by 2^d - 1 (255 for 8 bits,
    65535 for 16), exactly, taken as stored: gAMA, sRGB, iCCP, cHRM and sBIT
    chunks are not applied, because the numbers are reflectances, not display
    colours. Grey (colour type 0) is read as it is. RGB (2) is accepted only
    where R = G = B in every pixel; a palette image (3) only where every
    palette entry the image uses is grey, and then the value is that entry
    over 255 (palette entries are always 8-bit). An alpha channel (grey +
    alpha, 4; RGBA, 6) or a tRNS transparency is accepted only where every
    pixel is fully opaque (alpha = 2^d - 1; no pixel of the tRNS colour, no
    used palette entry below 255); any transparency is refused, since a
    reflectance has none: flatten the image first. Anything else is refused
    in one line naming the colour type or the alpha.

    EXR (single-part): channel ``Y``, or channels ``R``, ``G``, ``B`` equal
    in every pixel, each HALF or FLOAT, values as stored (linear); an ``A``
    channel is accepted only when it is 1 everywhere (opaque). Any other
    channel (layers such as ``diffuse.R``, chroma ``RY``/``BY``, depth ``Z``),
    or ``Y`` together with ``R``, ``G``, ``B``, is refused naming what was
    found.

    Parameters
    ----------
    path : str or Path
        Image file, ``.png`` or ``.exr``.
    pixels : int
        Expected side ``M``; any other size is an error.

    Returns
    -------
    numpy.ndarray
        ``(M, M)`` float64 reflectance, row 0 at the top.

    Raises
    ------
    ImageError
        Empty path; missing, unreadable or not a regular file (a folder, a
        FIFO, a device, a broken or looping symbolic link); empty or
        malformed file; unsupported format; colour or transparent image;
        wrong size; values outside [0, 1] or not finite.
    """
    if isinstance(path, str) and not path:
        raise ImageError("empty image path; give a .png or .exr file name")
    path = Path(path)
    shown = printable(str(path))
    problem = regular_file_problem(path)
    if problem is not None:
        raise ImageError(f"{shown}: cannot read the image: {problem}")
    suffix = path.suffix.lower()
    if suffix not in (".png", ".exr"):
        what = f"unsupported format {suffix!r}" if suffix else "no file suffix"
        raise ImageError(f"{shown}: {what}; give a .png or .exr image")
    if path.stat().st_size == 0:
        raise ImageError(f"{shown}: the file is empty (0 bytes); give a PNG or EXR image file")
    image = _read_png(path, shown, pixels) if suffix == ".png" else _read_exr(path, shown, pixels)
    if not np.all(np.isfinite(image)):
        raise ImageError(f"{shown}: image has NaN or infinite values")
    if image.min() < 0.0 or image.max() > 1.0:
        raise ImageError(
            f"{shown}: reflectance must lie in [0, 1], found "
            f"[{image.min():.4g}, {image.max():.4g}]"
        )
    return image


def printable(text: str) -> str:
    """Text as one printable line: bytes that are not UTF-8 (surrogate escapes) as U+FFFD, controls as \\xNN."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace").translate(_ESCAPED_CONTROLS)


def regular_file_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be read as a regular file, in a few words; None when it can.

    Looks with ``stat`` only, so a FIFO is never opened (opening one would
    block until a writer comes).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    str or None
        E.g. ``"no such file"``, ``"a folder, not a regular file"``,
        ``"a symbolic link loop"``; None for a readable regular file.
    """
    try:
        status = os.stat(path)
    except ValueError:           # os.stat's answer to an embedded NUL
        return "the path contains a NUL character"
    except FileNotFoundError:
        if os.path.islink(path):
            target = printable(os.readlink(path))
            return f"a broken symbolic link (its target {target} does not exist)"
        return "no such file"
    except OSError as error:
        return _stat_error(error)
    kind = _file_kind(status.st_mode)
    if kind is not None:
        return f"{kind}, not a regular file"
    if not os.access(path, os.R_OK):
        return "permission denied; make the file readable"
    return None


def _stat_error(error: OSError) -> str:
    if error.errno == errno.ELOOP:
        return "a symbolic link loop (the link leads back to itself)"
    if error.errno == errno.ENOTDIR:
        return "a part of the path before the file name is a file, not a folder"
    if error.errno == errno.EACCES:
        return "permission denied on a folder of the path"
    if error.errno == errno.ENAMETOOLONG:
        return "the path or a name in it is too long"
    return error.strerror or str(error)


def _file_kind(mode: int) -> str | None:
    """What a non-regular file is, for a message; None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    for test, kind in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "a special file"


def _check_size(shown: str, width: int, height: int, pixels: int) -> None:
    if (height, width) != (pixels, pixels):
        raise ImageError(f"{shown}: image is {width} x {height} pixels, "
                         f"plane.pixels asks for {pixels} x {pixels}")


# --------------------------------------------------------------------------- PNG

def _read_png(path: Path, shown: str, pixels: int) -> np.ndarray:
    """Every PNG colour type and bit depth at full precision (pypng, not Pillow).

    Pillow reads 16-bit RGB and grey + alpha as 8 bits, so a value such as
    200/65535 became 0: pypng gives the stored samples themselves.
    """
    import png

    try:
        with open(path, "rb") as stream, warnings.catch_warnings():
            # pypng warns and goes on for a misplaced PLTE or tRNS: such a file is malformed
            warnings.simplefilter("error")
            reader = png.Reader(file=stream)
            reader.preamble()
            _check_size(shown, reader.width, reader.height, pixels)
            _, _, rows, info = reader.read()
            dtype = np.uint16 if reader.bitdepth == 16 else np.uint8
            decoded = [np.frombuffer(row, dtype=dtype) for row in rows]
    except ImageError:
        raise
    except OSError as error:
        raise ImageError(f"{shown}: cannot read the PNG ({error.strerror or error})") from None
    except Exception as error:  # pypng raises FormatError, ChunkError, zlib.error, EOFError, ...
        raise ImageError(f"{shown}: not a readable PNG ({_one_line(error)})") from None
    expected = reader.width * reader.planes
    if len(decoded) != reader.height or any(row.size != expected for row in decoded):
        raise ImageError(f"{shown}: truncated PNG ({len(decoded)} of {reader.height} rows decoded)")
    samples = np.stack(decoded).reshape(reader.height, reader.width, reader.planes)
    if reader.colormap:
        return _png_palette_grey(shown, samples[..., 0], info["palette"])
    maximum = 2**reader.bitdepth - 1
    colour = samples[..., :reader.color_planes]
    if reader.alpha:
        _refuse_png_alpha(shown, samples[..., reader.color_planes], maximum)
    if "transparent" in info:
        _refuse_png_transparent_colour(shown, colour, info["transparent"])
    if reader.color_planes == 3:
        _refuse_unequal_rgb(shown, colour, f"colour PNG (colour type {reader.color_type})")
    return colour[..., 0].astype(np.float64) / maximum


def _refuse_png_alpha(shown: str, alpha: np.ndarray, maximum: int) -> None:
    transparent = int(np.count_nonzero(alpha != maximum))
    if transparent:
        raise ImageError(f"{shown}: PNG alpha channel is below {maximum} (not opaque) in "
                         f"{_counted(transparent, 'pixel')}; {_FLATTEN}")


def _refuse_png_transparent_colour(shown: str, colour: np.ndarray, transparent: tuple) -> None:
    matches = int(np.count_nonzero(np.all(colour == np.asarray(transparent), axis=-1)))
    if matches:
        value = transparent[0] if len(transparent) == 1 else tuple(transparent)
        raise ImageError(f"{shown}: PNG tRNS chunk makes value {value} transparent and "
                         f"{_counted(matches, 'pixel')} have it; {_FLATTEN}")


def _refuse_unequal_rgb(shown: str, colour: np.ndarray, what: str) -> None:
    differ = int(np.count_nonzero(np.any(colour != colour[..., :1], axis=-1)))
    if differ:
        raise ImageError(f"{shown}: {what}: R, G, B differ in {_counted(differ, 'pixel')}; {_MAKE_GREY}")


def _png_palette_grey(shown: str, indices: np.ndarray, palette) -> np.ndarray:
    """Grey values of a palette image; refused unless every used entry is grey and opaque."""
    table = np.asarray(palette, dtype=np.int64)          # (entries, 3 or 4), 8-bit
    used = np.unique(indices)
    if used[-1] >= len(table):
        raise ImageError(f"{shown}: malformed PNG: palette index {used[-1]} beyond its "
                         f"{len(table)} entries")
    entries = table[used]
    colour = [int(index) for index, entry in zip(used, entries) if not entry[0] == entry[1] == entry[2]]
    if colour:
        raise ImageError(f"{shown}: palette PNG (colour type 3) uses "
                         f"{_counted(len(colour), 'colour entry', 'colour entries')} "
                         f"(first: index {colour[0]} = {tuple(int(v) for v in table[colour[0], :3])}); "
                         f"{_MAKE_GREY}")
    if table.shape[1] == 4:
        see_through = int(np.count_nonzero(entries[:, 3] != 255))
        if see_through:
            raise ImageError(f"{shown}: palette PNG uses "
                             f"{_counted(see_through, 'entry', 'entries')} with alpha below 255 "
                             f"(tRNS chunk); {_FLATTEN}")
    return table[indices, 0].astype(np.float64) / 255.0


def _counted(count: int, thing: str, things: str | None = None) -> str:
    """``"1 pixel"``, ``"3 pixels"``."""
    return f"{count} {thing}" if count == 1 else f"{count} {things or thing + 's'}"


def _one_line(error: Exception) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return printable(text)


# --------------------------------------------------------------------------- EXR

def _read_exr(path: Path, shown: str, pixels: int) -> np.ndarray:
    """Channel Y, or equal R, G, B, of a single-part EXR; an A channel must be 1."""
    with open(path, "rb") as stream:
        magic = stream.read(len(_EXR_MAGIC))
    if magic != _EXR_MAGIC:
        raise ImageError(f"{shown}: not an EXR file (it does not start with EXR's magic number)")
    channels = _exr_channels(path, shown, pixels)
    names = set(channels)
    colour = {"R", "G", "B"}
    unused = names - {"Y", "A"} - colour
    found = ", ".join(sorted(names)) or "none"
    fix = "save a Y channel, or R, G, B (and an opaque A)"
    if unused:
        raise ImageError(f"{shown}: EXR channels {', '.join(sorted(unused))} are not a grey reflectance "
                         f"(found {found}); {fix}")
    if "Y" in names and names & colour:
        raise ImageError(f"{shown}: EXR has both Y and R, G, B (found {found}); keep one of them")
    if "Y" not in names and not colour <= names:
        raise ImageError(f"{shown}: EXR has no Y channel nor all of R, G, B (found {found}); {fix}")
    for name, values in channels.items():
        if values.dtype.kind != "f":
            raise ImageError(f"{shown}: EXR channel {name} holds {values.dtype} integers (UINT); "
                             f"write it as HALF or FLOAT")
    if "A" in channels:
        _refuse_exr_alpha(shown, channels["A"])
    if "Y" in channels:
        return channels["Y"].astype(np.float64)
    rgb = np.stack([channels["R"], channels["G"], channels["B"]], axis=-1)
    _refuse_unequal_rgb(shown, rgb, "colour EXR")
    return rgb[..., 0].astype(np.float64)


def _exr_channels(path: Path, shown: str, pixels: int) -> dict[str, np.ndarray]:
    """The channels of a single-part EXR, each ``(height, width)``, its size checked before decoding."""
    import OpenEXR

    with _library_output_captured(path) as library_says:
        try:
            with OpenEXR.File(str(path), header_only=True) as handle:
                parts = len(handle.parts)
                low, high = handle.header()["dataWindow"]
            if parts != 1:
                raise ImageError(f"{shown}: EXR has {parts} parts; save the reflectance as a single-part image")
            _check_size(shown, int(high[0] - low[0]) + 1, int(high[1] - low[1]) + 1, pixels)
            # separate_channels: the binding would otherwise group R, G, B (and A) into one
            # "RGB"/"RGBA" array of shape (h, w, 3|4), and layers "x.R", "x.G", ... into "x"
            with OpenEXR.File(str(path), separate_channels=True) as handle:
                return {name: np.array(channel.pixels)     # copy: the pixels die with the handle
                        for name, channel in handle.channels().items()}
        except ImageError:
            raise
        except Exception as error:  # the binding raises RuntimeError, ValueError and others
            detail = library_says() or _one_line(error)
            raise ImageError(f"{shown}: not a readable EXR ({detail})") from None


def _refuse_exr_alpha(shown: str, alpha: np.ndarray) -> None:
    see_through = int(np.count_nonzero(alpha != 1.0))
    if see_through:
        raise ImageError(f"{shown}: EXR alpha channel A is not 1 (opaque) in "
                         f"{_counted(see_through, 'pixel')}; {_FLATTEN}")


@contextlib.contextmanager
def _library_output_captured(path: Path):
    """Hold what the OpenEXR library prints; yields a getter of its first line.

    On a corrupt file the library prints its diagnosis on file descriptor 2
    and the binding a warning through Python's ``sys.stdout``; either would
    break the command's one-line error, so both are held and the diagnosis
    goes into the message instead. While held, what other threads print goes
    there too: reading a scene's image happens before any worker starts.
    """
    with _CAPTURE_LOCK:
        yield from _output_captured(path)


def _output_captured(path: Path):
    sys.stdout.flush()
    sys.stderr.flush()
    python_output = io.StringIO()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as capture:
        def first_line() -> str:
            capture.seek(0)
            text = capture.read(4096).decode("utf-8", "replace") + "\n" + python_output.getvalue()
            for line in text.splitlines():
                line = " ".join(line.split()).removeprefix(f"{path}: ")
                if line:
                    return printable(line)
            return ""
        try:
            os.dup2(capture.fileno(), 1)
            os.dup2(capture.fileno(), 2)
            with contextlib.redirect_stdout(python_output), contextlib.redirect_stderr(python_output):
                yield first_line
        finally:
            for descriptor, copy in zip((1, 2), saved):
                os.dup2(copy, descriptor)
                os.close(copy)
