"""Write the example scenes' reflectance images: ``pattern.png``, ``hidden.png`` and ``shapes.png``.

``pattern.png`` is the built-in scene's pattern (:func:`analytic.builtin_reflectance`)
at M = 50 as a 16-bit grey PNG, so that ``paper.toml`` is the built-in scene
as a file (to the PNG's rounding, 1/131070 of the reflectance range).
``hidden.png`` is the same pattern at M = 16, the hidden image of ``nlos.toml``.
``shapes.png`` is a 32 x 32 8-bit grey image for ``image.toml``: a bright
ring, a dark square and a ramp, drawn at pixel centres.

Scene files read a PNG's grey value as value/255 (8-bit) or value/65535
(16-bit), with no sRGB decoding, and image row 0 is the top of the plane
(docs/files.md). Run ``python3 examples/make_image.py [FOLDER]`` to write
both (default: this script's folder).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import png

import analytic

#: Image side of ``pattern.png``: the built-in scene's M.
PATTERN_PIXELS = 50

#: Image side of ``hidden.png``: ``nlos.toml``'s hidden M.
HIDDEN_PIXELS = 16

#: Image side of ``shapes.png``: ``image.toml``'s M.
SHAPES_PIXELS = 32


def shapes(pixels: int) -> np.ndarray:
    """A ramp, a bright ring and a dark square, in [0, 1], row 0 at the top.

    Parameters
    ----------
    pixels : int
        Image side M.
    """
    centres = (np.arange(pixels) + 0.5) / pixels
    x = centres[None, :]                      # to the right, fraction of the plane's side
    y = (1.0 - centres)[:, None]              # up: row 0 is the top
    image = np.broadcast_to(0.2 + 0.3 * x, (pixels, pixels))   # a ramp from left to right
    radius = np.hypot(x - 0.62, y - 0.62)
    image = np.where(np.abs(radius - 0.22) < 0.06, 0.95, image)
    square = (np.abs(x - 0.25) < 0.12) & (np.abs(y - 0.27) < 0.12)
    return np.where(square, 0.02, image)


def write_grey_png(path: Path, image: np.ndarray, bit_depth: int) -> None:
    """Write ``image`` (values in [0, 1]) as a grey PNG of ``bit_depth`` bits, rounded to the nearest level."""
    top = 2**bit_depth - 1
    levels = np.rint(np.clip(image, 0.0, 1.0) * top).astype(np.uint16)
    writer = png.Writer(width=levels.shape[1], height=levels.shape[0], greyscale=True, bitdepth=bit_depth)
    with open(path, "wb") as handle:
        writer.write(handle, levels.tolist())


def main(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    write_grey_png(folder / "pattern.png", analytic.builtin_reflectance(PATTERN_PIXELS), 16)
    write_grey_png(folder / "hidden.png", analytic.builtin_reflectance(HIDDEN_PIXELS), 16)
    write_grey_png(folder / "shapes.png", shapes(SHAPES_PIXELS), 8)
    print(f"wrote {folder / 'pattern.png'} ({PATTERN_PIXELS} x {PATTERN_PIXELS}, 16-bit), "
          f"{folder / 'hidden.png'} ({HIDDEN_PIXELS} x {HIDDEN_PIXELS}, 16-bit) and "
          f"{folder / 'shapes.png'} ({SHAPES_PIXELS} x {SHAPES_PIXELS}, 8-bit)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
