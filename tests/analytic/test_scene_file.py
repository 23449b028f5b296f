"""Scene files: keys, defaults, every bad value named by its key, files that are not scene files."""

import os
import re
import textwrap
import threading

import numpy as np
import pytest

from analytic.errors import SceneError
from analytic.scenes.common import default_scene
from analytic.scenes.scene_file import load_scene, scene_from_dict, scene_to_tables
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


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    plain = load_scene(write_scene(tmp_path, GOOD))
    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + textwrap.dedent(GOOD).encode("utf-8"))
    marked = load_scene(tmp_path / "bom.toml")
    assert marked.sampling == plain.sampling and np.array_equal(marked.sensors, plain.sensors)
    assert np.array_equal(marked.reflectance, plain.reflectance) and marked.size == plain.size


@pytest.mark.parametrize("encode, match", [
    (lambda text: text.encode("utf-16"), r"UTF-16 \(little-endian\) text, not UTF-8"),
    (lambda text: b"\xfe\xff" + text.encode("utf-16-be"), r"UTF-16 \(big-endian\) text, not UTF-8"),
    (lambda text: text.encode("utf-32"), r"UTF-32 \(little-endian\) text, not UTF-8"),
    (lambda text: text.encode("utf-16-le"), "NUL byte on line 2 .*save it as UTF-8"),
    (lambda text: ("name = \"sc\xe8ne\"\n" + text).encode("latin-1"), "byte 0xE8 on line 1 .*Latin-1"),
], ids=["utf-16", "utf-16-be", "utf-32", "utf-16-without-mark", "latin-1"])
def test_a_scene_file_in_another_encoding_is_refused_naming_it(tmp_path, encode, match):
    (tmp_path / "encoded.toml").write_bytes(encode(textwrap.dedent(GOOD)))
    with pytest.raises(SceneError, match=match) as error:
        load_scene(tmp_path / "encoded.toml")
    assert "\n" not in str(error.value)


def _last_line_holding(text, fragment):
    """1-based number of the last line of ``text`` that holds ``fragment`` (where TOML finds the clash)."""
    return max(number for number, line in enumerate(text.split("\n"), 1) if fragment in line)


@pytest.mark.parametrize("change, fragment, match", [
    (("size = 1.0", "size = 1.0\nsize = 2.0"), "size = 2.0", "already set .*give each key once"),
    (("[model]", "[plane]\npixels = 4\n[model]"), "[plane]", r"table \[plane\] is declared twice"),
    (("[plane]", "plane.size = 2.0\n[plane]"), "[plane]", r"table \[plane\] is declared twice"),
    (("[plane]", "plane = { size = 2.0 }\n[plane]"), "[plane]", r"table \[plane\] is declared twice"),
    (("[plane]", "sensors = { grid = [2, 2] }\nsensors.extent = 1\n[plane]"), "sensors.extent",
     "given inline .* cannot be extended"),
    (("size = 1.0", "size = 1.0.0"), "size = 1.0.0", "fix the TOML syntax there"),
    (("size = 1.0", "size = 1.0\rpixels = 2"), "size = 1.0\r", "carriage return without a line feed"),
])
def test_toml_syntax_problems_name_the_line_and_the_fix(tmp_path, change, fragment, match):
    text = textwrap.dedent(GOOD.replace(*change))
    with pytest.raises(SceneError, match=match) as error:
        load_scene(write_scene(tmp_path, text))
    assert f"invalid TOML at line {_last_line_holding(text, fragment)}," in str(error.value)
    assert "\n" not in str(error.value)


def test_toml_cut_short_says_the_end_of_the_file(tmp_path):
    with pytest.raises(SceneError, match="at the end of the file.*is the last line complete"):
        load_scene(write_scene(tmp_path, GOOD + "\n[sampl"))


@pytest.mark.parametrize("change, key, match", [
    (("[plane]", '"plane.size" = 2.0\n[plane]'), '"plane.size"', "without quotes for a dotted key"),
    (("size = 1.0", '"source.position" = 1.0'), 'plane."source.position"', "without quotes"),
    (("size = 1.0", '"" = 1.0'), 'plane.""', "unknown key"),
    (("size = 1.0", '"si ze" = 1.0'), 'plane."si ze"', "unknown key"),
    (("[model]", "[noise]\nsigma = 0.1\nseed = 18446744073709551617\n[model]"), "noise.seed", "<= 4294967295"),
    (("count = 40", "count = 18446744073709551617"), "sampling.count", "beyond"),
    (("size = 1.0", "size = 1" + "0" * 400), "plane.size", "float64"),     # an integer beyond 2^1024
    (("size = 1.0", "size = nan"), "plane.size", "finite"),
    (("size = 1.0", "size = -inf"), "plane.size", "finite"),
    (("count = 40", "count = inf"), "sampling.count", "whole number"),
    (("size = 1.0", "size = 1979-05-27"), "plane.size", "TOML date/time 1979-05-27"),
    (("period = 0.1", "period = 07:32:00"), "sampling.period", "TOML date/time 07:32:00"),
    (("position = [0.5, 0.5, 1.0]", "position = [0.5, 1979-05-27T07:32:00Z, 1.0]"), "source.position[1]",
     "date"),
    (('attenuation = "lambertian"', "attenuation = 1979-05-27"), "model.attenuation", "date"),
    (("position = [0.5, 0.5, 1.0]", "position = [0.5, 'half', 1.0]"), "source.position[1]", "number"),
    (("positions = [[0.2, 0.7, 1.0]]", "positions = [[0.2, 0.7, 1.0], 5, 'x']"), "sensors.positions[1]",
     r"\[x, y, z\]"),
    (("[plane]", "[[plane]]"), "plane", r"array of tables \[\[plane\]\]"),
    (("reflectance = 0.5", 'reflectance = ""'), "plane.reflectance", "empty string"),
    (("reflectance = 0.5", 'reflectance = "."'), "plane.reflectance", "a folder, not a regular file"),
    (("reflectance = 0.5", 'reflectance = "a\\u0000b.png"'), "plane.reflectance", "NUL character"),
])
def test_toml_oddities_end_in_one_line_naming_the_key(tmp_path, change, key, match):
    path = write_scene(tmp_path, GOOD.replace(*change))
    with pytest.raises(SceneError, match=match) as error:
        load_scene(path)
    assert error.value.key == key
    assert "\n" not in str(error.value) and "\x00" not in str(error.value)


def _scene_path_problem(tmp_path, case):
    path = tmp_path / f"{case}.toml"
    if case == "folder":
        path.mkdir()
    elif case == "fifo":
        os.mkfifo(path)
    elif case == "loop":
        path.symlink_to(path.name)
    elif case == "broken-link":
        path.symlink_to("nowhere.toml")
    elif case == "empty-file":
        path.write_bytes(b"")
    elif case == "only-comments":
        path.write_text("# a scene, one day\n\n")
    elif case == "huge":
        path.write_bytes(b"#" * (2 << 20))
    elif case == "empty-path":
        path = ""
    return path


@pytest.mark.parametrize("case, match", [
    ("missing", "cannot read scene file: no such file"),
    ("folder", "a folder, not a regular file"),
    ("fifo", r"a named pipe \(FIFO\), not a regular file"),
    ("loop", "a symbolic link loop"),
    ("broken-link", r"a broken symbolic link \(its target nowhere.toml does not exist\)"),
    ("empty-file", r"has no keys \(is it empty\?\)"),
    ("only-comments", r"has no keys \(is it empty\?\)"),
    ("huge", "larger than 1024 KiB"),
    ("empty-path", "empty path"),
])
def test_a_scene_path_that_is_not_a_scene_file_names_its_cause(tmp_path, case, match):
    path = _scene_path_problem(tmp_path, case)
    outcome = {}

    def attempt():                 # in a thread: a FIFO opened by mistake would block for ever
        try:
            load_scene(path)
        except SceneError as error:
            outcome["message"] = str(error)
    worker = threading.Thread(target=attempt, daemon=True)
    worker.start()
    worker.join(timeout=20)
    assert not worker.is_alive(), "load_scene blocked"
    assert re.search(match, outcome["message"]) and "\n" not in outcome["message"]


def test_a_whole_number_past_pythons_digit_limit_is_one_line(tmp_path):
    path = tmp_path / "big.toml"
    path.write_text(GOOD.replace("pixels = 8", "pixels = 1" + "0" * 5000))
    with pytest.raises(SceneError, match="whole number of more than 4300 digits"):
        load_scene(path)


@pytest.mark.parametrize("image", [np.full((8, 8), "0.5"), np.full((8, 8), True), np.full((8, 8), None)])
def test_a_reflectance_array_of_anything_but_numbers_is_refused(image):
    from analytic.scenes.relay_wall import RelayWallScene
    from analytic.scenes.common import Scene

    with pytest.raises(SceneError, match="plane.reflectance: expected an image of numbers"):
        Scene(pixels=8, reflectance=image)
    with pytest.raises(SceneError, match="hidden.reflectance: expected an image of numbers"):
        RelayWallScene(pixels=8, reflectance=image)
