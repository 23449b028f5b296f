"""Relay-wall scene files (docs/design.md section 7): every key read, written back, and refused when wrong."""

import numpy as np
import pytest

from analytic.errors import SceneError
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Illumination, Sampling
from analytic.scenes.scene_file import load_scene, scene_from_dict, scene_to_tables

EVERY_KEY = """
name = "around the corner"
[relay_wall]
size = [2.5, 1.5]
reflectance = 0.8
[hidden]
center = [0.1, -0.2, 1.1]
u = [0.9, 0.0, 0.1]
v = [0.0, -0.7, 0.0]
pixels = 12
reflectance = 0.4
[laser]
position = [-0.5, 0.1, 0.3]
intensity = 2.5
[sensor]
position = [0.4, -0.1, 0.2]
[scan]
type = "exhaustive"
grid = [3, 2]
laser_grid = [2, 2]
account_first_and_last_bounces = true
[illumination]
waveform = "square"
width = 0.05
[sampling]
period = 0.02
start = 1.5
count = 150
[model]
tolerance = 1e-7
"""


def _write(tmp_path, text):
    path = tmp_path / "wall.toml"
    path.write_text(text)
    return path


def test_every_key_reaches_the_scene(tmp_path):
    scene = load_scene(_write(tmp_path, EVERY_KEY))
    expected = RelayWallScene(
        name="around the corner", wall_size=(2.5, 1.5), wall_reflectance=0.8, center=(0.1, -0.2, 1.1),
        u=(0.9, 0.0, 0.1), v=(0.0, -0.7, 0.0), pixels=12, reflectance=0.4, laser_position=(-0.5, 0.1, 0.3),
        intensity=2.5, sensor_position=(0.4, -0.1, 0.2),
        scan=Scan(type="exhaustive", grid=(3, 2), laser_grid=(2, 2), account_first_and_last_bounces=True),
        illumination=Illumination(waveform="square", width=0.05),
        sampling=Sampling(bin_width_opl=0.02, start_opl=1.5, count=150), tolerance=1e-7)
    assert isinstance(scene, RelayWallScene) and scene.sensor_count == 24
    for name in ("wall_size", "wall_reflectance", "pixels", "intensity", "scan", "illumination", "sampling",
                 "tolerance", "name"):
        assert getattr(scene, name) == getattr(expected, name), name
    for name in ("center", "u", "v", "laser_position", "sensor_position", "reflectance"):
        assert np.array_equal(getattr(scene, name), getattr(expected, name)), name


def test_tables_read_back_to_the_same_scene(tmp_path):
    scene = load_scene(_write(tmp_path, EVERY_KEY))
    again = scene_from_dict(scene_to_tables(scene))
    first, second = scene.geometry()[1], again.geometry()[1]
    for name in ("sources", "sensors", "offsets", "scales"):
        assert np.array_equal(getattr(first, name), getattr(second, name)), name
    assert again.scan == scene.scan and again.sampling == scene.sampling and again.name == scene.name


@pytest.mark.parametrize("extra, key", [
    ("[plane]\nsize = 1\n", "plane"),
    ("[sensors]\npositions = [[0, 0, 1]]\n", "sensors"),
    ("[hidden]\nnormal = [0, 0, -1]\n", "hidden.normal"),
    ("[model]\nattenuation = \"paper\"\n", "model.attenuation"),
])
def test_keys_that_do_not_belong_are_refused_by_name(tmp_path, extra, key):
    text = "[relay_wall]\nsize = [2.0, 2.0]\n" + extra
    with pytest.raises(SceneError) as raised:
        load_scene(_write(tmp_path, text))
    assert str(raised.value).startswith(key)


def test_a_bare_relay_wall_table_is_the_default_capture(tmp_path):
    scene = load_scene(_write(tmp_path, "[relay_wall]\n"))
    default = RelayWallScene()
    assert scene.scan == default.scan and scene.sensor_count == default.sensor_count


def test_tables_left_out_take_the_defaults_docs_nlos_states(tmp_path):
    """docs/nlos.md lists what a missing [hidden], [laser], [sensor], [scan] or [sampling] (or key) takes."""
    scene = load_scene(_write(tmp_path, "[relay_wall]\n"))
    assert scene.wall_size == (2.0, 2.0) and scene.wall_reflectance == 1.0
    for name, value in (("center", [0, 0, 1]), ("u", [1, 0, 0]), ("v", [0, -1, 0]),
                        ("laser_position", [-0.5, 0, 0.25]), ("sensor_position", [-0.5, 0, 0.25])):
        np.testing.assert_array_equal(getattr(scene, name), value, err_msg=name)
    assert scene.pixels == 32 and np.all(scene.reflectance == 0.5) and scene.intensity == 1.0
    assert (scene.scan.type, scene.scan.grid, scene.scan.account_first_and_last_bounces) == ("single", (4, 4), False)
    np.testing.assert_array_equal(scene.laser_points, [[0, 0, 0]])           # the wall's centre
    sampling = scene.sampling
    assert (sampling.bin_width_opl, sampling.start_opl, sampling.count) == (0.1, 0.0, 40)
    assert scene.illumination.waveform == "impulse" and scene.noise is None and scene.tolerance == 1e-6
    exhaustive = load_scene(_write(tmp_path, "[relay_wall]\n[scan]\ntype = \"exhaustive\"\ngrid = [3, 2]\n"))
    assert exhaustive.scan.laser_grid in (None, (3, 2)) and exhaustive.sensor_count == 36     # the grid's points



def test_an_oversized_scan_is_refused_before_its_points_are_built(tmp_path):
    """A 10^5 x 10^5 confocal grid needed 75 GiB for its points before the pair count was checked."""
    with pytest.raises(SceneError) as raised:
        load_scene(_write(tmp_path, "[relay_wall]\n[scan]\ntype = \"confocal\"\ngrid = [100000, 100000]\n"))
    assert str(raised.value).startswith("scan.grid")
