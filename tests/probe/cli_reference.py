"""The command-line probe's plane scenes as plain numbers, their midpoint-rule reference (docs/design.md
section 2's formula integrated by brute force) and image files written byte by byte (tests/cli/probe).
"""

from __future__ import annotations

import dataclasses
import math
import struct
import zlib
from pathlib import Path

import numpy as np


@dataclasses.dataclass
class Geometry:
    """A plane scene as plain numbers: written to TOML here, and integrated here by brute force."""

    size: float = 1.0
    pixels: int = 8
    reflectance: object = 0.5                  # a number, or an (M, M) array written to an image file
    source: tuple = (0.5, 0.5, 1.0)
    intensity: float = 1.0
    sensors: tuple = ((0.2, 0.7, 1.0),)
    period: float = 0.1
    start: float = 1.9
    count: int = 12
    attenuation: str = "lambertian"
    waveform: str = "impulse"
    width: float | None = None

    def toml(self, image: str | None = None, extra: str = "") -> str:
        """The scene file; ``image`` replaces the reflectance by that file name."""
        reflectance = f'"{image}"' if image is not None else _number(self.reflectance)
        sensors = ", ".join(_point(p) for p in self.sensors)
        width = "" if self.width is None else f"width = {_number(self.width)}\n"
        return (f"[plane]\nsize = {_number(self.size)}\npixels = {self.pixels}\nreflectance = {reflectance}\n"
                f"[source]\nposition = {_point(self.source)}\nintensity = {_number(self.intensity)}\n"
                f'[illumination]\nwaveform = "{self.waveform}"\n{width}'
                f"[sensors]\npositions = [{sensors}]\n"
                f"[sampling]\nperiod = {_number(self.period)}\nstart = {_number(self.start)}\n"
                f"count = {self.count}\n"
                f'[model]\nattenuation = "{self.attenuation}"\n{extra}')

    def scaled(self, factor: float) -> "Geometry":
        """Every length times ``factor`` (positions, size, period, start)."""
        return dataclasses.replace(
            self, size=self.size * factor, source=tuple(v * factor for v in self.source),
            sensors=tuple(tuple(v * factor for v in p) for p in self.sensors),
            period=self.period * factor, start=self.start * factor)

    def image(self) -> np.ndarray:
        if np.ndim(self.reflectance) == 0:
            return np.full((self.pixels, self.pixels), float(self.reflectance))
        return np.asarray(self.reflectance, dtype=np.float64)


def _number(value) -> str:
    return repr(float(value)) if not isinstance(value, int) else str(value)


def _point(point) -> str:
    return "[" + ", ".join(_number(v) for v in point) + "]"


def _samples(geometry: Geometry, grid: int):
    """Midpoints of a grid x grid partition of the plane (grid a multiple of M), their ρ and cell area."""
    assert grid % geometry.pixels == 0
    size = geometry.size
    step = size / grid
    centres = (np.arange(grid) + 0.5) * step
    x, y = np.meshgrid(centres, centres)
    # docs/design.md section 1: image[r, c] covers x in [cΔ, (c+1)Δ), y in [L-(r+1)Δ, L-rΔ)
    per_pixel = grid // geometry.pixels
    column = np.arange(grid) // per_pixel
    row = (grid - 1 - np.arange(grid)) // per_pixel            # y index counted from the bottom
    rho = geometry.image()[row[:, None], column[None, :]]
    return x.ravel(), y.ravel(), rho.ravel(), step


def _attenuation(geometry: Geometry, x, y, sensor):
    """docs/design.md section 2's a_k(x) and d(x), written out again."""
    sx, sy, sz = geometry.source
    kx, ky, kz = sensor
    ds = np.sqrt((x - sx) ** 2 + (y - sy) ** 2 + sz**2)
    dk = np.sqrt((x - kx) ** 2 + (y - ky) ** 2 + kz**2)
    cos_s, cos_k = sz / ds, kz / dk
    if geometry.attenuation == "lambertian":
        return cos_s * cos_k / (math.pi * ds**2 * dk**2), ds + dk
    return cos_s / (ds**2 * dk**2), ds + dk


def _edge_distance(length, geometry: Geometry):
    """Distance from each path length to the nearest bin edge, metres."""
    index = np.clip(np.rint((length - geometry.start) / geometry.period), 0, geometry.count)
    return np.abs(length - (geometry.start + index * geometry.period))


_REFERENCES: dict = {}


def reference(geometry: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """:func:`binned_reference`, computed once per geometry."""
    key = repr(dataclasses.replace(geometry, reflectance=geometry.image().tobytes()))
    if key not in _REFERENCES:
        _REFERENCES[key] = binned_reference(geometry)
    y, bound = _REFERENCES[key]
    return y.copy(), bound.copy()


def binned_reference(geometry: Geometry, grid: int = 256, levels: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(y, bound): the binned transient by midpoint samples, and a bound on each bin's error.

    The impulse puts each cell's f a ΔA in the bin of its midpoint's path
    length; a cell whose path lengths may cross a bin edge (|∇d| <= 2 and a
    half-diagonal of h/√2: its midpoint within √2 h of an edge) is cut into
    4 x 4 and looked at again, ``levels`` times; the weight of the cells
    still straddling an edge at the end bounds the binning error (added to
    the bins on both sides). A square pulse of width w spreads a cell's
    weight over [d, d + w], a continuous function of d. 2e-5 of the peak
    covers the midpoint rule's smooth error (h²/24 of the integrand's
    curvature, h = L/256).
    """
    edges = geometry.start + geometry.period * np.arange(geometry.count + 1)
    width = geometry.width if geometry.width is not None else geometry.period / 5.0
    out = np.zeros((len(geometry.sensors), geometry.count))
    bound = np.zeros_like(out)
    x0, y0, rho0, step0 = _samples(geometry, grid)

    def deposit(k, length, weight, into):
        index = np.floor((length - geometry.start) / geometry.period).astype(np.int64)
        inside = (index >= 0) & (index < geometry.count)
        into[k] += np.bincount(index[inside], weights=weight[inside], minlength=geometry.count)

    for k, sensor in enumerate(geometry.sensors):
        if geometry.waveform != "impulse":           # square: twice as fine, for the overlap's kinks
            x, y, rho, step = _samples(geometry, 2 * grid)
            weight, length = _attenuation(geometry, x, y, sensor)
            weight = rho * weight * step**2
            out[k] = np.maximum(0.0, np.minimum(edges[1:, None], length[None, :] + width)
                                - np.maximum(edges[:-1, None], length[None, :])) @ weight
            continue
        x, y, rho, step = x0, y0, rho0, step0
        for level in range(levels + 1):
            weight, length = _attenuation(geometry, x, y, sensor)
            weight = rho * weight * step**2
            near = _edge_distance(length, geometry) <= math.sqrt(2.0) * step
            if level == levels:
                deposit(k, length, weight, out)
                for shift in (-1.0, 0.0, 1.0):      # a straddling cell may belong to either side
                    deposit(k, length[near] + shift * geometry.period, weight[near], bound)
                break
            deposit(k, length[~near], weight[~near], out)
            offsets = ((np.arange(4) + 0.5) / 4 - 0.5) * step
            x = (x[near][:, None, None] + offsets[None, :, None] + 0 * offsets[None, None, :]).ravel()
            y = (y[near][:, None, None] + 0 * offsets[None, :, None] + offsets[None, None, :]).ravel()
            rho = np.repeat(rho[near], 16)
            step = step / 4
    y = geometry.intensity * out
    bound = geometry.intensity * bound + 2e-5 * np.abs(y).max()
    return y, bound


def reference_total(geometry: Geometry, grid: int = 2048) -> np.ndarray:
    """I ∫ f a_k dx per sensor (the impulse's whole response), ``(K,)``."""
    x, y, rho, step = _samples(geometry, grid)
    return geometry.intensity * np.array(
        [np.sum(rho * _attenuation(geometry, x, y, s)[0]) * step**2 for s in geometry.sensors])


# ======================================================================== image files, written here

def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(samples: np.ndarray, bitdepth: int, colour_type: int, *, palette=None, trns: bytes | None = None,
              chunks=(), declared: tuple[int, int] | None = None) -> bytes:
    """A PNG, byte by byte: samples ``(H, W, planes)`` of unsigned integers, filter 0, no interlace."""
    samples = np.asarray(samples)
    height, width, planes = samples.shape
    rows = []
    for row in samples:
        flat = row.reshape(-1).astype(np.uint64)
        if bitdepth < 8:
            bits = ((flat[:, None] >> np.arange(bitdepth - 1, -1, -1, dtype=np.uint64)) & 1).astype(np.uint8)
            packed = np.packbits(bits.reshape(-1)).tobytes()
        elif bitdepth == 8:
            packed = flat.astype(np.uint8).tobytes()
        else:
            packed = flat.astype(">u2").tobytes()
        rows.append(b"\0" + packed)
    w, h = declared or (width, height)
    header = struct.pack(">IIBBBBB", w, h, bitdepth, colour_type, 0, 0, 0)
    body = [_chunk(b"IHDR", header)]
    body += [_chunk(kind, data) for kind, data in chunks]
    if palette is not None:
        body.append(_chunk(b"PLTE", bytes(np.asarray(palette, np.uint8)[:, :3].reshape(-1))))
    if trns is not None:
        body.append(_chunk(b"tRNS", trns))
    body.append(_chunk(b"IDAT", zlib.compress(b"".join(rows))))
    body.append(_chunk(b"IEND", b""))
    return b"\x89PNG\r\n\x1a\n" + b"".join(body)


def write_exr(path: Path, channels: dict, compression: str = "ZIP", tiled: bool = False) -> Path:
    import OpenEXR

    header = {"compression": getattr(OpenEXR, f"{compression}_COMPRESSION"),
              "type": OpenEXR.tiledimage if tiled else OpenEXR.scanlineimage}
    if tiled:
        tiles = OpenEXR.TileDescription()
        tiles.xSize, tiles.ySize, tiles.mode = 4, 4, OpenEXR.ONE_LEVEL
        header["tiles"] = tiles
    OpenEXR.File(header, channels).write(str(path))
    return path


def pattern(pixels: int, levels: int, seed: int = 7) -> np.ndarray:
    """A random image of integer levels 0 .. levels - 1 that uses the extremes."""
    values = np.random.default_rng(seed).integers(0, levels, size=(pixels, pixels))
    values.flat[0], values.flat[-1] = 0, levels - 1
    return values


#: An 8 x 8 image of 8-bit grey levels, 0 and 255 among them (PNG cases).
GREY_LEVELS = pattern(8, 256, seed=4)
