"""Scene files: keys, defaults, every bad value named by its key, files that are not scene files."""

import os

import numpy as np
import pytest

from analytic.errors import SceneError
from analytic.scene import default_scene
from analytic.scene_file import load_scene, scene_from_dict, scene_to_tables
from scene_files import GOOD, write_scene


def test_design_example_loads(tmp_path):
    scene = load_scene(write_scene(tmp_path))
    assert scene.pixels == 8 and scene.sensor_count == 1 and scene.noise is None
    assert scene.reflectance.shape == (8, 8) and np.all(scene.reflectance == 0.5)
    assert scene.intensity == 1.0 and scene.name == "scene"


def test_source_intensity_key(tmp_path):
    scene = load_scene(write_scene(tmp_path, GOOD.replace("position = [0.5, 0.5, 1.0]",
                                                          "position = [0.5, 0.5, 1.0]\nintensity = 250.0")))
    assert scene.intensity == 250.0


def test_sensor_grid_matches_extent_and_centre(tmp_path):
    text = GOOD.replace("positions = [[0.2, 0.7, 1.0]]", "grid = [4, 4]\nextent = 2.0\ncenter = [0.5, 0.5, 1.0]")
    scene = load_scene(write_scene(tmp_path, text))
    assert scene.sensor_count == 16
    assert scene.sensors[:, 0].min() == pytest.approx(-0.5) and scene.sensors[:, 0].max() == pytest.approx(1.5)
    assert np.all(scene.sensors[:, 2] == 1.0)


@pytest.mark.parametrize("change, key", [
    (("size = 1.0", "size = 1.0\nsise = 2"), "plane.sise"),
    (("[model]", "[modle]"), "modle"),
    (("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, 0.0]"), "source.position"),
    (("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, 1.0]\nintensity = 0"), "source.intensity"),
    (("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, 1.0]\nintensity = \"bright\""), "source.intensity"),
    (("positions = [[0.2, 0.7, 1.0]]", "positions = [[0.2, 0.7, -1.0]]"), "sensors.positions[0]"),
    (("positions = [[0.2, 0.7, 1.0]]", "grid = [100000, 100000]\ncenter = [0.5, 0.5, 1.0]"), "sensors.grid[0]"),
    (("positions = [[0.2, 0.7, 1.0]]", "grid = [40, 40]\ncenter = [0.5, 0.5, 1.0]"), "sensors.grid"),
    (("size = 1.0", "size = -1.0"), "plane.size"),
    (("size = 1.0", "size = 5e-324"), "plane.size"),
    (("pixels = 8", "pixels = 0"), "plane.pixels"),
    (("period = 0.1", "period = 0.0"), "sampling.period"),
    (("period = 0.1", "period = 1e307"), "sampling.period"),
    (("start = 0.0", "start = -1e308"), "sampling.start"),
    (("count = 40", "count = -3"), "sampling.count"),
    (("start = 0.0", "start = nan"), "sampling.start"),
    (("period = 0.1", "period = inf"), "sampling.period"),
    (("period = 0.1\nstart = 0.0", "period = 1e-9\nstart = 1e6"), "sampling.period"),
    (('waveform = "impulse"', 'waveform = "laser"'), "illumination.waveform"),
    (('waveform = "impulse"', 'waveform = "impulse"\nwidth = 0.1'), "illumination.width"),
    (('attenuation = "lambertian"', 'attenuation = "phong"'), "model.attenuation"),
    (("reflectance = 0.5", 'reflectance = "missing.png"'), "plane.reflectance"),
    (("reflectance = 0.5", "reflectance = 1.5"), "plane.reflectance"),
])
def test_bad_values_name_their_key(tmp_path, change, key):
    path = write_scene(tmp_path, GOOD.replace(*change))
    with pytest.raises(SceneError) as error:
        load_scene(path)
    assert error.value.key == key


def test_files_that_are_not_scene_files_are_refused_by_name(tmp_path):
    (tmp_path / "latin1.toml").write_bytes("name = \"sc\xe8ne\"\n".encode("latin-1"))
    with pytest.raises(SceneError, match="not UTF-8"):
        load_scene(tmp_path / "latin1.toml")
    with pytest.raises(SceneError, match="not a regular file"):
        load_scene("/dev/zero")
    with pytest.raises(SceneError, match="not a regular file"):
        load_scene(tmp_path)
    (tmp_path / "big.toml").write_bytes(b"#" * (2 << 20))
    with pytest.raises(SceneError, match="larger than"):
        load_scene(tmp_path / "big.toml")
    (tmp_path / "bad.toml").write_text("[plane\n")
    with pytest.raises(SceneError, match="invalid TOML"):
        load_scene(tmp_path / "bad.toml")


def test_a_file_name_that_is_not_utf8_gives_a_readable_label(tmp_path):
    name = os.fsdecode(b"sc\xe8ne.toml")
    path = write_scene(tmp_path, GOOD, name=name)
    label = load_scene(path).name
    label.encode("utf-8")          # printable and JSON-safe
    assert label.startswith("sc") and label.endswith("ne")


def test_tables_round_trip_to_an_equal_scene():
    scene = default_scene(pixels=12)
    back = scene_from_dict(scene_to_tables(scene))
    for field in ("size", "pixels", "intensity", "attenuation", "tolerance", "name"):
        assert getattr(back, field) == getattr(scene, field)
    assert np.array_equal(back.reflectance, scene.reflectance)
    assert np.array_equal(back.sensors, scene.sensors) and np.array_equal(back.source, scene.source)
    assert back.sampling == scene.sampling and back.illumination == scene.illumination
    assert back.noise == scene.noise
