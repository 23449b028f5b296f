"""Scene files: keys, defaults, validation, images; the CLI's one-line errors."""

import json
import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from PIL import Image

from analytic.io import read_transient, save_exr
from analytic.scene import SceneError, default_scene, load_scene

GOOD = """
[plane]
size = 1.0
pixels = 8
reflectance = 0.5

[source]
position = [0.5, 0.5, 1.0]

[illumination]
waveform = "impulse"

[sensors]
positions = [[0.2, 0.7, 1.0]]

[sampling]
period = 0.1
start = 0.0
count = 40

[model]
attenuation = "lambertian"
"""


def _write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_design_example_loads(tmp_path):
    scene = load_scene(_write(tmp_path, GOOD))
    assert scene.pixels == 8 and scene.sensor_count == 1 and scene.noise is None
    assert scene.reflectance.shape == (8, 8) and np.all(scene.reflectance == 0.5)


def test_sensor_grid_matches_extent_and_centre(tmp_path):
    text = GOOD.replace("positions = [[0.2, 0.7, 1.0]]", "grid = [4, 4]\nextent = 2.0\ncenter = [0.5, 0.5, 1.0]")
    scene = load_scene(_write(tmp_path, text))
    assert scene.sensor_count == 16
    assert scene.sensors[:, 0].min() == pytest.approx(-0.5) and scene.sensors[:, 0].max() == pytest.approx(1.5)
    assert np.all(scene.sensors[:, 2] == 1.0)


def test_default_scene_is_the_papers_set_up():
    scene = default_scene()
    assert scene.pixels == 50 and scene.sensor_count == 16 and scene.noise.sigma == 0.1
    assert np.allclose(scene.sensors[:, :2].mean(axis=0), scene.source[:2])
    image = scene.reflectance
    assert image.min() < 0.1 and image.max() > 0.85       # hard edges ...
    assert len(np.unique(np.round(image, 3))) > 50        # ... beside smooth regions


@pytest.mark.parametrize("change, key", [
    (("size = 1.0", "size = 1.0\nsise = 2"), "plane.sise"),
    (("[model]", "[modle]"), "modle"),
    (("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, 0.0]"), "source.position"),
    (("positions = [[0.2, 0.7, 1.0]]", "positions = [[0.2, 0.7, -1.0]]"), "sensors.positions[0]"),
    (("size = 1.0", "size = -1.0"), "plane.size"),
    (("pixels = 8", "pixels = 0"), "plane.pixels"),
    (("period = 0.1", "period = 0.0"), "sampling.period"),
    (("count = 40", "count = -3"), "sampling.count"),
    (("start = 0.0", "start = nan"), "sampling.start"),
    (("period = 0.1", "period = inf"), "sampling.period"),
    (('waveform = "impulse"', 'waveform = "laser"'), "illumination.waveform"),
    (('waveform = "impulse"', 'waveform = "impulse"\nwidth = 0.1'), "illumination.width"),
    (('attenuation = "lambertian"', 'attenuation = "phong"'), "model.attenuation"),
    (("reflectance = 0.5", 'reflectance = "missing.png"'), "plane.reflectance"),
    (("reflectance = 0.5", "reflectance = 1.5"), "plane.reflectance"),
])
def test_bad_values_name_their_key(tmp_path, change, key):
    path = _write(tmp_path, GOOD.replace(*change))
    with pytest.raises(SceneError) as error:
        load_scene(path)
    assert error.value.key == key


def test_png_8_and_16_bit_and_exr_images_load_linear(tmp_path):
    values = np.linspace(0, 1, 64).reshape(8, 8)
    Image.fromarray(np.round(values * 255).astype(np.uint8)).save(tmp_path / "a.png")
    Image.fromarray(np.round(values * 65535).astype(np.uint16)).save(tmp_path / "b.png")
    save_exr(tmp_path / "c.exr", values)
    for name, tolerance in (("a.png", 0.5 / 255), ("b.png", 0.5 / 65535), ("c.exr", 1e-7)):
        scene = load_scene(_write(tmp_path, GOOD.replace("reflectance = 0.5", f'reflectance = "{name}"')))
        np.testing.assert_allclose(scene.reflectance, values, atol=tolerance)


def test_wrong_size_and_colour_images_are_rejected(tmp_path):
    Image.fromarray(np.zeros((9, 8), np.uint8)).save(tmp_path / "small.png")
    rgb = np.zeros((8, 8, 3), np.uint8)
    rgb[..., 0] = 200
    Image.fromarray(rgb).save(tmp_path / "red.png")
    (tmp_path / "broken.png").write_bytes(b"not a png")
    for name in ("small.png", "red.png", "broken.png"):
        with pytest.raises(SceneError, match="plane.reflectance"):
            load_scene(_write(tmp_path, GOOD.replace("reflectance = 0.5", f'reflectance = "{name}"')))


def test_window_too_large_for_memory_is_refused_before_allocation():
    from analytic.system import system_matrix
    from analytic.scene import Sampling
    scene = default_scene(pixels=20).replace(sampling=Sampling(bin_width_opl=0.001, start_opl=0.0, count=5000))
    with pytest.raises(SceneError, match="sampling"):
        system_matrix(scene, memory_limit=1_000_000)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "validation.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


@pytest.mark.parametrize("change", [
    ("size = 1.0", "size = 1.0\ncolour = 3"),
    ("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, -0.1]"),
    ("count = 40", "count = 0"),
])
def test_cli_bad_scene_exits_2_with_one_line_and_no_files(tmp_path, change):
    path = _write(tmp_path, GOOD.replace(*change))
    out = tmp_path / "out"
    result = _cli("forward", path, "--out", out)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert not out.exists()


def test_cli_missing_scene_file_exits_2(tmp_path):
    result = _cli("forward", tmp_path / "nope.toml", "--out", tmp_path / "out")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1


def test_cli_forward_writes_the_contract_files(tmp_path):
    text = GOOD + "\n[noise]\nsigma = 0.1\nseed = 3\n"
    path = _write(tmp_path, text)
    out = tmp_path / "out"
    result = _cli("forward", path, "--out", out, "--quiet")
    assert result.returncode == 0, result.stderr
    names = {p.name for p in out.iterdir()}
    assert {"transient.exr", "transient.npy", "meta.json", "transient_noisy.npy", "transient.png"} <= names
    y = np.load(out / "transient.npy")
    assert y.shape == (1, 40) and y.dtype == np.float64 and y.max() > 0
    np.testing.assert_allclose(read_transient(out / "transient.exr"), y, rtol=1e-6, atol=1e-12)
    meta = json.loads((out / "meta.json").read_text())
    assert meta["start_opl"] == 0.0 and meta["period_opl"] == 0.1 and meta["attenuation"] == "lambertian"
    import OpenEXR
    with OpenEXR.File(str(out / "transient.exr")) as handle:
        header = dict(handle.header())   # the header is a view that closes with the file
    assert float(header["t0"]) == 0.0 and float(header["T"]) == 0.1 and header["illumination"] == "impulse"
    noisy = np.load(out / "transient_noisy.npy")
    # σ = 0.1 noise: the residual's standard deviation within 4 standard errors of σ
    residual = noisy - y
    assert abs(residual.std() - 0.1) < 4 * 0.1 / math.sqrt(2 * residual.size)
