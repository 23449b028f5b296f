"""Reflectance images: PNG (8/16-bit, no sRGB) and EXR read linearly; bad images refused by key."""

import numpy as np
import pytest
from PIL import Image

from analytic.errors import SceneError
from analytic.io import save_exr
from analytic.reflectance import builtin_reflectance
from analytic.scene_file import load_scene
from scene_files import GOOD, write_scene


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
