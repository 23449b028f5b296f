"""Reflectance images: every PNG colour type and bit depth at full precision, EXR Y or equal R, G, B,
transparency and colour refused, every unreadable path named by its cause."""

import os
import re
import socket
import threading

import numpy as np
import png
import pytest
from PIL import Image

from analytic import forward
from analytic.errors import ImageError, SceneError
from analytic.files import save_exr
from analytic.scenes.reflectance import builtin_reflectance, read_reflectance
from analytic.scenes.scene_file import load_scene
from scene_files import GOOD, write_scene

SIDE = 8

# (colour type, bit depth): every combination the PNG specification allows
LEGAL_PNG = [(0, 1), (0, 2), (0, 4), (0, 8), (0, 16), (2, 8), (2, 16), (3, 1), (3, 2), (3, 4), (3, 8),
             (4, 8), (4, 16), (6, 8), (6, 16)]


def write_png(path, samples, **options):
    """Write ``samples`` ((rows, columns x planes) integers) with pypng's Writer; returns the path."""
    samples = np.asarray(samples)
    with open(path, "wb") as stream:
        png.Writer(SIDE, samples.shape[0], **options).write(stream, samples.tolist())
    return path


def known_samples(rng, depth):
    """An image of stored samples with both ends of the range and, at 16 bits, 200 and 32768 in it."""
    maximum = 2**depth - 1
    samples = rng.integers(0, maximum + 1, (SIDE, SIDE))
    samples[0, :2] = (0, maximum)
    if depth == 16:
        samples[1, :2] = (200, 32768)
    return samples


def interleave(*planes):
    """(rows, columns) planes -> (rows, columns x planes) as PNG rows hold them."""
    return np.stack(planes, axis=-1).reshape(SIDE, -1)


def png_of_type(path, colour_type, depth, grey):
    """A PNG of ``colour_type`` whose every pixel is grey sample ``grey`` and fully opaque."""
    opaque = np.full_like(grey, 2**depth - 1)
    if colour_type == 0:
        return write_png(path, grey, greyscale=True, bitdepth=depth)
    if colour_type == 2:
        return write_png(path, interleave(grey, grey, grey), greyscale=False, bitdepth=depth)
    if colour_type == 4:
        return write_png(path, interleave(grey, opaque), greyscale=True, alpha=True, bitdepth=depth)
    return write_png(path, interleave(grey, grey, grey, opaque), greyscale=False, alpha=True, bitdepth=depth)


@pytest.mark.parametrize("colour_type, depth", [case for case in LEGAL_PNG if case[0] != 3])
def test_every_png_type_reads_stored_sample_over_full_scale(tmp_path, rng, colour_type, depth):
    samples = known_samples(rng, depth)
    path = png_of_type(tmp_path / "image.png", colour_type, depth, samples)
    image = read_reflectance(path, SIDE)
    assert image.dtype == np.float64
    assert np.array_equal(image, samples / (2**depth - 1))      # exactly, row 0 at the top


@pytest.mark.parametrize("depth", [1, 2, 4, 8])
@pytest.mark.parametrize("alpha", [False, True], ids=["plain", "opaque-trns"])
def test_palette_png_reads_its_grey_entries_over_255(tmp_path, rng, depth, alpha):
    entries = min(2**depth, 256)
    greys = rng.permutation(256)[:entries]                       # palette entries are always 8-bit
    palette = [(int(v), int(v), int(v)) + ((255,) if alpha else ()) for v in greys]
    indices = rng.integers(0, entries, (SIDE, SIDE))
    path = write_png(tmp_path / "palette.png", indices, palette=palette, bitdepth=depth)
    assert np.array_equal(read_reflectance(path, SIDE), greys[indices] / 255)


def test_png_colour_entries_that_no_pixel_uses_are_ignored(tmp_path):
    palette = [(10, 10, 10), (255, 0, 0), (90, 90, 90)]
    indices = np.tile([0, 2], (SIDE, SIDE // 2))
    path = write_png(tmp_path / "palette.png", indices, palette=palette, bitdepth=8)
    assert np.array_equal(read_reflectance(path, SIDE), np.where(indices == 0, 10, 90) / 255)


def test_png_gamma_and_interlace_do_not_change_the_values(tmp_path, rng):
    samples = known_samples(rng, 16)
    for name, options in (("gamma.png", {"gamma": 0.45455}), ("interlaced.png", {"interlace": True})):
        path = write_png(tmp_path / name, samples, greyscale=True, bitdepth=16, **options)
        assert np.array_equal(read_reflectance(path, SIDE), samples / 65535)


def test_png_transparent_colour_that_no_pixel_has_is_accepted(tmp_path):
    samples = np.full((SIDE, SIDE), 7)
    path = write_png(tmp_path / "trns.png", samples, greyscale=True, bitdepth=4, transparent=3)
    assert np.array_equal(read_reflectance(path, SIDE), samples / 15)


def test_pillow_8_and_16_bit_grey_read_as_before(tmp_path, rng):
    eight = rng.integers(0, 256, (SIDE, SIDE)).astype(np.uint8)
    sixteen = rng.integers(0, 65536, (SIDE, SIDE)).astype(np.uint16)
    Image.fromarray(eight).save(tmp_path / "eight.png")
    Image.fromarray(sixteen).save(tmp_path / "sixteen.png")
    assert np.array_equal(read_reflectance(tmp_path / "eight.png", SIDE), eight / 255)
    assert np.array_equal(read_reflectance(tmp_path / "sixteen.png", SIDE), sixteen / 65535)


def test_16_bit_colour_and_grey_alpha_pngs_reach_the_forward_model_unrounded(tmp_path):
    # Pillow read these as 8 bits: 200/65535 became 0 (y all zeros), 32768/65535 became 128/255
    for name, colour_type, sample in (("rgb.png", 2, 200), ("grey_alpha.png", 4, 32768)):
        png_of_type(tmp_path / name, colour_type, 16, np.full((SIDE, SIDE), sample))
        from_image = load_scene(write_scene(tmp_path, GOOD.replace("reflectance = 0.5",
                                                                   f'reflectance = "{name}"')))
        uniform = load_scene(write_scene(tmp_path, GOOD.replace("reflectance = 0.5", "reflectance = 1.0"),
                                         name="uniform.toml"))
        y_image, y_uniform = forward(from_image), forward(uniform)
        assert y_uniform.max() > 0.0
        # y is linear in f: a uniform f = s/65535 gives exactly that share of f = 1's y
        np.testing.assert_allclose(y_image, y_uniform * (sample / 65535), rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("case, match", [
    ("rgb-unequal", "colour PNG"),
    ("palette-colour", "palette PNG"),
    ("palette-transparent", "no transparency"),
    ("grey-alpha", "alpha channel is below 65535"),
    ("rgba", "alpha channel is below 255"),
    ("grey-trns", "tRNS"),
    ("rgb-trns", "tRNS"),
])
def test_colour_and_transparent_pngs_are_refused_naming_why(tmp_path, case, match):
    grey = np.full((SIDE, SIDE), 100)
    see_through = grey.copy()
    see_through[3, 4] = 0
    path = tmp_path / f"{case}.png"
    if case == "rgb-unequal":
        red = grey.copy()
        red[5, 5] = 101
        write_png(path, interleave(red, grey, grey), greyscale=False, bitdepth=16)
    elif case == "palette-colour":
        write_png(path, np.eye(SIDE, dtype=int), palette=[(100, 100, 100), (0, 0, 255)], bitdepth=2)
    elif case == "palette-transparent":
        write_png(path, np.eye(SIDE, dtype=int), palette=[(9, 9, 9, 255), (100, 100, 100, 254)], bitdepth=1)
    elif case == "grey-alpha":
        write_png(path, interleave(grey, see_through + 65435), greyscale=True, alpha=True, bitdepth=16)
    elif case == "rgba":
        write_png(path, interleave(grey, grey, grey, see_through + 155), greyscale=False, alpha=True, bitdepth=8)
    elif case == "grey-trns":
        write_png(path, see_through, greyscale=True, bitdepth=8, transparent=0)
    else:
        write_png(path, interleave(see_through, see_through, see_through), greyscale=False, bitdepth=8,
                  transparent=(0, 0, 0))
    with pytest.raises(ImageError, match=match) as error:
        read_reflectance(path, SIDE)
    assert "\n" not in str(error.value)
    assert "flatten" in str(error.value) or "grey" in str(error.value)


def test_exr_y_equal_rgb_grouped_rgba_and_half_read_as_stored(tmp_path, rng):
    import OpenEXR

    values = rng.random((SIDE, SIDE)).astype(np.float32)
    opaque = np.ones_like(values)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    files = {
        "y.exr": {"Y": values},
        "y_alpha.exr": {"Y": values, "A": opaque},
        "rgb.exr": {"R": values, "G": values, "B": values},
        # the binding's grouped form: one channel "RGB" / "RGBA" of shape (h, w, 3 | 4)
        "grouped_rgb.exr": {"RGB": np.stack([values] * 3, axis=-1)},
        "grouped_rgba.exr": {"RGBA": np.stack([values] * 3 + [opaque], axis=-1)},
    }
    for name, channels in files.items():
        with OpenEXR.File(header, channels) as handle:
            handle.write(str(tmp_path / name))
        assert np.array_equal(read_reflectance(tmp_path / name, SIDE), values.astype(np.float64)), name
    half = values.astype(np.float16)
    with OpenEXR.File(header, {"Y": half}) as handle:
        handle.write(str(tmp_path / "half.exr"))
    assert np.array_equal(read_reflectance(tmp_path / "half.exr", SIDE), half.astype(np.float64))


@pytest.mark.parametrize("channels, match", [
    ({"RGBA": "grey-rgba-transparent"}, "alpha channel A is not 1"),
    ({"Y": "grey", "A": "transparent"}, "alpha channel A is not 1"),
    ({"R": "grey", "G": "red", "B": "grey"}, "colour EXR"),
    ({"diffuse.R": "grey", "diffuse.G": "grey", "diffuse.B": "grey"}, "diffuse.B, diffuse.G, diffuse.R"),
    ({"Y": "grey", "Z": "grey"}, "channels Z"),
    ({"Y": "grey", "R": "grey", "G": "grey", "B": "grey"}, "both Y and R, G, B"),
    ({"R": "grey", "G": "grey"}, r"found G, R"),
    ({"Y": "integer"}, "UINT"),
])
def test_exr_that_is_not_one_opaque_grey_is_refused_naming_what_it_found(tmp_path, channels, match):
    import OpenEXR

    grey = np.full((SIDE, SIDE), 0.25, np.float32)
    red = grey.copy()
    red[2, 2] = 0.5
    transparent = np.ones_like(grey)
    transparent[1, 1] = 0.5
    planes = {"grey": grey, "red": red, "transparent": transparent,
              "grey-rgba-transparent": np.stack([grey] * 3 + [transparent], axis=-1),
              "integer": np.zeros((SIDE, SIDE), np.uint32)}
    built = {name: planes[kind] for name, kind in channels.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, built) as handle:
        handle.write(str(tmp_path / "image.exr"))
    with pytest.raises(ImageError, match=match) as error:
        read_reflectance(tmp_path / "image.exr", SIDE)
    assert "\n" not in str(error.value)


def test_corrupt_exr_is_one_line_and_the_library_prints_nothing(tmp_path, capfd):
    save_exr(tmp_path / "whole.exr", np.full((SIDE, SIDE), 0.5))
    whole = (tmp_path / "whole.exr").read_bytes()
    (tmp_path / "cut.exr").write_bytes(whole[:-10])
    (tmp_path / "png.exr").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(40))
    for name, match in (("cut.exr", "not a readable EXR"), ("png.exr", "not an EXR file")):
        with pytest.raises(ImageError, match=match) as error:
            read_reflectance(tmp_path / name, SIDE)
        assert "\n" not in str(error.value)
    captured = capfd.readouterr()
    assert captured.out == "" and captured.err == ""


def _make_problem(tmp_path, case):
    """A path with one problem; returns it."""
    path = tmp_path / f"{case}.png"
    if case == "folder":
        path.mkdir()
    elif case == "fifo":
        os.mkfifo(path)
    elif case == "loop":
        path.symlink_to(path.name)
    elif case == "broken-link":
        path.symlink_to("nowhere.png")
    elif case == "empty-file":
        path.write_bytes(b"")
    elif case == "file-as-folder":
        (tmp_path / "plain.png").write_bytes(b"x")
        path = tmp_path / "plain.png" / "inside.png"
    elif case == "nul":
        path = tmp_path / "a\x00b.png"
    elif case == "device":
        path = "/dev/null"
    elif case == "empty":
        path = ""
    return path


@pytest.mark.parametrize("case, match", [
    ("empty", "empty image path"),
    ("missing", "no such file"),
    ("folder", "a folder, not a regular file"),
    ("fifo", r"a named pipe \(FIFO\), not a regular file"),
    ("device", "a character device, not a regular file"),
    ("loop", "a symbolic link loop"),
    ("broken-link", r"a broken symbolic link \(its target nowhere.png does not exist\)"),
    ("empty-file", r"the file is empty \(0 bytes\)"),
    ("file-as-folder", "is a file, not a folder"),
    ("nul", "NUL character"),
])
def test_an_unreadable_image_path_names_its_real_cause(tmp_path, case, match):
    path = _make_problem(tmp_path, case)
    outcome = {}

    def attempt():                 # in a thread: a FIFO opened by mistake would block for ever
        try:
            read_reflectance(path, SIDE)
        except ImageError as error:
            outcome["message"] = str(error)
    worker = threading.Thread(target=attempt, daemon=True)
    worker.start()
    worker.join(timeout=20)
    assert not worker.is_alive(), "read_reflectance blocked"
    assert "message" in outcome
    assert "\n" not in outcome["message"] and "\x00" not in outcome["message"]
    assert re.search(match, outcome["message"])


def test_a_socket_is_not_an_image(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)            # a socket's path must be short
    with socket.socket(socket.AF_UNIX) as server:
        server.bind("s.png")
        with pytest.raises(ImageError, match="a socket, not a regular file"):
            read_reflectance("s.png", SIDE)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file")
def test_an_unreadable_image_says_permission_denied(tmp_path):
    path = write_png(tmp_path / "locked.png", np.zeros((SIDE, SIDE), int), greyscale=True, bitdepth=8)
    path.chmod(0)
    with pytest.raises(ImageError, match="permission denied"):
        read_reflectance(path, SIDE)


def test_a_missing_image_in_a_scene_names_the_key_and_the_path(tmp_path):
    scene = write_scene(tmp_path, GOOD.replace("reflectance = 0.5", 'reflectance = "images/missing.png"'))
    with pytest.raises(SceneError, match="no such file") as error:
        load_scene(scene)
    assert error.value.key == "plane.reflectance" and "images/missing.png" in str(error.value)


def test_png_8_and_16_bit_and_exr_images_load_linear(tmp_path):
    values = np.linspace(0, 1, 64).reshape(8, 8)
    Image.fromarray(np.round(values * 255).astype(np.uint8)).save(tmp_path / "a.png")
    Image.fromarray(np.round(values * 65535).astype(np.uint16)).save(tmp_path / "b.png")
    save_exr(tmp_path / "c.exr", values)
    for name, tolerance in (("a.png", 0.5 / 255), ("b.png", 0.5 / 65535), ("c.exr", 1e-7)):
        scene = load_scene(write_scene(tmp_path, GOOD.replace("reflectance = 0.5", f'reflectance = "{name}"')))
        np.testing.assert_allclose(scene.reflectance, values, atol=tolerance)


def test_wrong_size_and_colour_images_are_rejected(tmp_path):
    Image.fromarray(np.zeros((9, 8), np.uint8)).save(tmp_path / "small.png")
    rgb = np.zeros((8, 8, 3), np.uint8)
    rgb[..., 0] = 200
    Image.fromarray(rgb).save(tmp_path / "red.png")
    (tmp_path / "broken.png").write_bytes(b"not a png")
    for name in ("small.png", "red.png", "broken.png"):
        with pytest.raises(SceneError, match="plane.reflectance"):
            load_scene(write_scene(tmp_path, GOOD.replace("reflectance = 0.5", f'reflectance = "{name}"')))


def test_builtin_pattern_looks_the_same_at_any_resolution():
    coarse, fine = builtin_reflectance(10), builtin_reflectance(40)
    # each coarse pixel's centre is a fine pixel's corner region: compare block means
    blocks = fine.reshape(10, 4, 10, 4).mean(axis=(1, 3))
    assert np.mean(np.abs(blocks - coarse)) < 0.05
    assert 0.0 <= fine.min() and fine.max() <= 1.0
