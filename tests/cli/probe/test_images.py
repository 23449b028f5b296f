"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): reflectance images: PNG files of every
colour type and depth (written byte by byte) and EXR pixel types.
"""

from __future__ import annotations

import dataclasses
import struct

import numpy as np

from probe.cli_reference import pattern, png_bytes, write_exr
from probe.cli_probe import GOOD, case_table, case_test, forward


CASES, case = case_table()


def image_case(name: str, samples, bitdepth: int, colour_type: int, values, slow: bool = False, **png):
    """A legal PNG: y must equal the reference of the image ``values`` (exact fractions of the levels)."""
    @case("images", name, "exit 0; y equal to the reference of value/(2^d - 1)", slow=slow)
    def _(probe):
        probe.file("image.png", png_bytes(samples, bitdepth, colour_type, **png))
        geometry = dataclasses.replace(GOOD, reflectance=values)
        if forward(probe, probe.scene(geometry.toml(image="image.png"))).answered():
            probe.matches_reference(geometry)


def image_refusal(name: str, data: bytes, *words: str, file: str = "image.png", pixels: int = 8):
    @case("images", name, f"exit 2, one line naming {', '.join(words)}, no --out")
    def _(probe):
        probe.file(file, data)
        geometry = dataclasses.replace(GOOD, pixels=pixels)
        forward(probe, probe.scene(geometry.toml(image=file))).refused(*words)


# 2 and 4 bits are slow: 1 bit keeps sub-byte unpacking, 8 and 16 bits whole bytes, in the default suite
for _depth in (1, 2, 4, 8, 16):
    _levels = pattern(8, 2**_depth, seed=_depth)
    image_case(f"grey PNG, {_depth}-bit", _levels[..., None], _depth, 0, _levels / (2**_depth - 1),
               slow=_depth in (2, 4))
for _depth in (1, 2, 4, 8):
    _indices = pattern(8, 2**_depth, seed=10 + _depth)
    _greys = np.random.default_rng(_depth).integers(0, 256, 2**_depth)
    _palette = np.stack([_greys] * 3, axis=1)
    image_case(f"grey palette PNG, {_depth}-bit", _indices[..., None], _depth, 3, _greys[_indices] / 255.0,
               palette=_palette, slow=_depth in (2, 4))
_indices = pattern(8, 4, seed=3)
image_case("palette PNG with an unused colour entry", _indices[..., None], 8, 3, (_indices * 60) / 255.0,
           palette=np.array([[0, 0, 0], [60, 60, 60], [120, 120, 120], [180, 180, 180], [255, 0, 0]]))
_levels = pattern(8, 256, seed=4)
image_case("grey + alpha PNG, 8-bit, opaque", np.stack([_levels, np.full_like(_levels, 255)], -1), 8, 4,
           _levels / 255.0)
_levels16 = pattern(8, 65536, seed=5)
_levels16.flat[3] = 200
image_case("RGB PNG, 16-bit, equal channels (holds 200/65535)", np.stack([_levels16] * 3, -1), 16, 2,
           _levels16 / 65535.0)
image_case("RGBA PNG, 16-bit, opaque", np.stack([_levels16] * 3 + [np.full_like(_levels16, 65535)], -1), 16, 6,
           _levels16 / 65535.0)
image_case("grey PNG with a tRNS value no pixel has", np.minimum(_levels, 254)[..., None], 8, 0,
           np.minimum(_levels, 254) / 255.0, trns=struct.pack(">H", 255))
image_case("grey PNG with gAMA, cHRM, sRGB, sBIT chunks (applied to nothing)", _levels[..., None], 8, 0,
           _levels / 255.0, chunks=[(b"gAMA", struct.pack(">I", 45455)), (b"sRGB", b"\0"),
                                    (b"cHRM", struct.pack(">8I", 31270, 32900, 64000, 33000, 30000, 60000,
                                                          15000, 6000)), (b"sBIT", b"\x05")])


@case("images", "interlaced (Adam7) grey PNG, 16-bit", "exit 0; y equal to the reference of value/65535")
def _(probe):
    import png

    with open(probe.tmp / "image.png", "wb") as stream:
        png.Writer(8, 8, greyscale=True, bitdepth=16, interlace=True).write(stream, _levels16.tolist())
    geometry = dataclasses.replace(GOOD, reflectance=_levels16 / 65535.0)
    if forward(probe, probe.scene(geometry.toml(image="image.png"))).answered():
        probe.matches_reference(geometry)


@case("images", "image named .PNG (capitals), absolute path", "exit 0; y equal to the reference")
def _(probe):
    path = probe.file("pictures/Image.PNG", png_bytes(_levels[..., None], 8, 0))
    geometry = dataclasses.replace(GOOD, reflectance=_levels / 255.0)
    if forward(probe, probe.scene(geometry.toml(image=str(path)))).answered():
        probe.matches_reference(geometry)


@case("images", "image path through '..' above the scene's folder", "exit 0; y equal to the reference")
def _(probe):
    probe.file("image.png", png_bytes(_levels[..., None], 8, 0))
    geometry = dataclasses.replace(GOOD, reflectance=_levels / 255.0)
    if forward(probe, probe.scene(geometry.toml(image="../image.png"), name="scenes/scene.toml")).answered():
        probe.matches_reference(geometry)


_palette_colour = np.array([[0, 0, 0], [10, 20, 30]])
image_refusal("palette PNG using a colour entry", png_bytes(pattern(8, 2)[..., None], 1, 3, palette=_palette_colour),
              "palette", "grey")
image_refusal("grey + alpha PNG, 16-bit, one pixel at 65534",
              png_bytes(np.stack([_levels16, np.where(np.arange(64).reshape(8, 8) == 9, 65534, 65535)], -1), 16, 4),
              "alpha", "1 pixel")
image_refusal("RGB PNG, 16-bit, G one level off in one pixel",
              png_bytes(np.stack([_levels16, _levels16 + (np.arange(64).reshape(8, 8) == 5), _levels16], -1)
                        .clip(0, 65535), 16, 2), "differ")
image_refusal("grey PNG whose tRNS value a pixel has", png_bytes(_levels[..., None], 8, 0, trns=struct.pack(">H", 255)),
              "tRNS")
_broken = bytearray(png_bytes(_levels[..., None], 8, 0))
_broken[29] ^= 0xFF                        # the IHDR checksum
image_refusal("PNG with a wrong IHDR checksum", bytes(_broken), "image.png")
_whole = png_bytes(_levels[..., None], 8, 0)
image_refusal("PNG cut inside its IDAT", _whole[:_whole.index(b"IDAT") + 20], "image.png")
image_refusal("PNG header of 2^31 - 1 x 2^31 - 1 pixels", png_bytes(_levels[..., None], 8, 0,
                                                                    declared=(2**31 - 1, 2**31 - 1)), "pixels")
image_refusal("PNG of 8 x 9 pixels for M = 8", png_bytes(pattern(9, 256)[:, :8, None], 8, 0), "8 x 9")
image_refusal("a PNG named .exr", _whole, "EXR", file="image.exr")
image_refusal("16-bit grey PNG for M = 4 (size first)", png_bytes(_levels16[..., None], 16, 0), "plane.pixels",
              pixels=4)


@case("images", "image path /dev/zero", "exit 2, one line naming the device")
def _(probe):
    forward(probe, probe.scene(GOOD.toml(image="/dev/zero"))).refused("/dev/zero")


@case("images", "an EXR named .png", "exit 2, one line naming the file")
def _(probe):
    write_exr(probe.tmp / "real.exr", {"Y": np.full((8, 8), 0.5, np.float32)})
    (probe.tmp / "image.png").write_bytes((probe.tmp / "real.exr").read_bytes())
    forward(probe, probe.scene(GOOD.toml(image="image.png"))).refused("image.png")


def exr_case(name: str, channels_of, values, compression="ZIP", tiled=False):
    @case("images", name, "exit 0; y equal to the reference of the stored values")
    def _(probe):
        write_exr(probe.tmp / "image.exr", channels_of(), compression, tiled)
        geometry = dataclasses.replace(GOOD, reflectance=values)
        if forward(probe, probe.scene(geometry.toml(image="image.exr"))).answered():
            probe.matches_reference(geometry)


def exr_refusal(name: str, channels_of, *words):
    @case("images", name, f"exit 2, one line naming {', '.join(words)}")
    def _(probe):
        write_exr(probe.tmp / "image.exr", channels_of())
        forward(probe, probe.scene(GOOD.toml(image="image.exr"))).refused(*words)


_values = np.random.default_rng(11).uniform(0, 1, (8, 8))
_half = _values.astype(np.float16)
_single = _values.astype(np.float32)
exr_case("EXR Y HALF", lambda: {"Y": _half}, _half.astype(np.float64))
exr_case("EXR Y FLOAT, PIZ", lambda: {"Y": _single}, _single.astype(np.float64), "PIZ")
exr_case("EXR Y FLOAT, tiled 4 x 4", lambda: {"Y": _single}, _single.astype(np.float64), tiled=True)
exr_case("EXR R, G, B HALF equal, NO_COMPRESSION", lambda: {"R": _half, "G": _half, "B": _half},
         _half.astype(np.float64), "NO")
exr_case("EXR R, G, B, A FLOAT with A = 1", lambda: {c: _single for c in "RGB"} | {"A": np.ones((8, 8), np.float32)},
         _single.astype(np.float64))
_tiny = np.full((8, 8), np.float16(2.0**-24))
exr_case("EXR Y of the smallest half subnormal (2^-24)", lambda: {"Y": _tiny}, np.full((8, 8), 2.0**-24))
exr_case("EXR Y of -0.0", lambda: {"Y": np.full((8, 8), -0.0, np.float32)}, np.zeros((8, 8)))
exr_refusal("EXR Y UINT", lambda: {"Y": np.ones((8, 8), np.uint32)}, "UINT")
exr_refusal("EXR R, G, B FLOAT unequal", lambda: {"R": _single, "G": _single, "B": _single * 0.5}, "differ")
exr_refusal("EXR A = 0.5 in one pixel", lambda: {"Y": _single, "A": np.where(np.arange(64).reshape(8, 8) == 0,
                                                                              np.float32(0.5), np.float32(1))},
            "alpha")
exr_refusal("EXR Y = 1.0000001 (float32 above 1)", lambda: {"Y": np.full((8, 8), np.nextafter(np.float32(1),
                                                                                            np.float32(2)))}, "[0, 1]")
exr_refusal("EXR Y with a NaN", lambda: {"Y": np.where(np.arange(64).reshape(8, 8) == 3, np.float32(np.nan), _single)},
            "NaN")
exr_refusal("EXR lowercase channel y", lambda: {"y": _single}, "y")
exr_refusal("EXR layer diffuse.Y", lambda: {"diffuse.Y": _single}, "diffuse.Y")
exr_refusal("EXR of 4 x 4 for M = 8", lambda: {"Y": _single[:4, :4]}, "4 x 4")


@case("images", "EXR cut to half its bytes", "exit 2, one line naming the file")
def _(probe):
    data = write_exr(probe.tmp / "full.exr", {"Y": np.random.default_rng(1).uniform(0, 1, (8, 8)).astype(np.float32)},
                     "NO").read_bytes()
    probe.file("image.exr", data[: len(data) // 2])
    forward(probe, probe.scene(GOOD.toml(image="image.exr"))).refused("image.exr")


test_case = case_test(CASES)
