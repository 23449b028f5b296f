"""interop.mitransient.export_relay_wall: a relay-wall capture as Mitsuba 3 XML, rendered by our plugin and by mitransient.

References: for ``--format mitsuba``, the same scene built in memory
(``transient.mitsuba_scene.relay_wall_scene_dict``) and rendered by the same
plugin with the same samples; for ``--format mitransient``, mitransient
itself (the exported README's script, run as written in a subprocess),
judged against the exact model and against mitransient's estimator in
closed form (interop.mitransient.nlos, held to an emulation of its
code in tests/interop/mitransient/test_nlos.py).
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import OpenEXR
import pytest
from scene_files import write_relay_wall_file

from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Illumination, Sampling, SceneError
from interop.mitransient.export import export_scene
from validation.cli import main

needs_mitransient = pytest.mark.skipif(importlib.util.find_spec("mitransient") is None,
                                       reason="mitransient is not installed (pip install -e .[bench])")


def scene_of(**changes) -> RelayWallScene:
    image = np.arange(16, dtype=np.float64).reshape(4, 4) / 20.0 + 0.1           # asymmetric: catches flips
    values = dict(name="nlos", pixels=4, reflectance=image, center=(0.1, 0.05, 0.7), u=(0.6, 0.0, 0.1),
                  v=(0.0, -0.5, 0.0), intensity=3.0, laser_position=(-0.5, 0.1, 0.3),
                  sensor_position=(-0.4, -0.1, 0.35),
                  scan=Scan(type="single", grid=(3, 3), laser_point=(0.3, -0.2, 0.0)),
                  sampling=Sampling(bin_width_opl=0.02, start_opl=1.2, count=60))
    return RelayWallScene(**(values | changes))


def values_of(element) -> dict:
    return {child.get("name"): child.get("value") for child in element if child.get("name")}


def floats(text: str) -> np.ndarray:
    return np.array([float(v) for v in re.split(r"[,\s]+", text.strip())])


def test_mitransient_xml_states_the_capture(tmp_path):
    scene = scene_of()
    written = export_scene(scene, tmp_path, "mitransient")
    assert sorted(written) == ["README.md", "reflectance.exr", "scene.xml"]
    root = ET.parse(tmp_path / "scene.xml").getroot()
    integrator = root.find("integrator")
    assert integrator.get("type") == "transient_nlos_path"
    assert values_of(integrator) == {
        "filter_bounces": "2", "max_depth": "4", "capture_type": "single", "nlos_laser_sampling": "true",
        "nlos_hidden_geometry_sampling": "true", "nlos_hidden_geometry_sampling_includes_relay_wall": "false",
        "account_first_and_last_bounces": "false", "temporal_filter": "box"}
    wall, hidden = root.find("shape[@id='relay_wall']"), root.find("shape[@id='hidden']")
    assert np.array_equal(floats(wall.find("transform/matrix").get("value")).reshape(4, 4), np.diag([1, 1, 1, 1.0]))
    sensor = wall.find("sensor")
    assert sensor.get("type") == "nlos_capture_meter"
    assert np.array_equal(floats(values_of(sensor)["sensor_origin"]), scene.sensor_position)
    film = values_of(sensor.find("film"))
    assert (film["width"], film["height"], film["temporal_bins"]) == ("3", "3", "60")
    assert (float(film["start_opl"]), float(film["bin_width_opl"])) == (1.2, 0.02)
    laser = root.find("emitter")
    assert laser.get("type") == "projector"
    aim = laser.find("transform/lookat")
    assert np.array_equal(floats(aim.get("origin")), scene.laser_position)
    assert np.array_equal(floats(aim.get("target")), [0.3, -0.2, 0.0])
    assert float(values_of(laser)["irradiance"]) * math.pi * float(values_of(laser)["scale"]) == pytest.approx(3.0)
    # the hidden rectangle: local [-1, 1]² onto centre ± u/2 ± v/2, normal u x v (toward the wall)
    matrix = floats(hidden.find("transform/matrix").get("value")).reshape(4, 4)
    normal = np.cross([0.6, 0.0, 0.1], [0.0, -0.5, 0.0])
    for local, world in (((1, 1, 0), [0.4, -0.2, 0.75]), ((-1, 1, 0), [-0.2, -0.2, 0.65]), ((0, 0, 1), None)):
        mapped = matrix[:3, :3] @ local + (matrix[:3, 3] if local[2] == 0 else 0)
        expected = world if world is not None else normal / np.linalg.norm(normal)
        assert np.allclose(mapped, expected, atol=1e-15)
    with OpenEXR.File(str(tmp_path / "reflectance.exr")) as handle:
        texture = np.array(handle.channels()["Y"].pixels)
    assert np.array_equal(texture, np.flipud(scene.reflectance).astype(np.float32))       # row 0 at v = 0


def test_a_confocal_capture_is_one_render_per_point(tmp_path):
    scene = scene_of(scan=Scan(type="confocal", grid=(3, 2)))
    export_scene(scene, tmp_path, "mitransient")
    sensor = ET.parse(tmp_path / "scene.xml").getroot().find("shape/sensor")
    assert values_of(sensor)["original_film_width"] == "3" and values_of(sensor)["original_film_height"] == "2"
    film = values_of(sensor.find("film"))
    assert (film["width"], film["height"]) == ("1", "1")
    readme = (tmp_path / "README.md").read_text()
    assert "focus_emitter_at_relay_wall_pixel(mi.Point2f(i + 0.5, j + 0.5)" in readme   # the cell's centre


@pytest.mark.parametrize("changes, key", [
    (dict(scan=Scan(type="exhaustive", grid=(2, 2))), "scan.type"),
    (dict(illumination=Illumination(waveform="square")), "illumination.waveform"),
    (dict(laser_position=(0.1, 0.0, 1.0)), "hidden.center"),   # behind the hidden rectangle: the scene refuses it
    (dict(sensor_position=(0.1, 0.0, 1.0)), "hidden.center"),
    (dict(reflectance=np.full((4, 4), 1e-39)), "hidden.reflectance"),
])
def test_what_mitransient_cannot_render_is_refused(tmp_path, changes, key):
    with pytest.raises(SceneError, match=re.escape(key)):
        export_scene(scene_of(**changes), tmp_path, "mitransient")
    assert not any(tmp_path.iterdir())


def test_export_command_refuses_in_one_line(tmp_path, capsys):
    scene_file = write_relay_wall_file(tmp_path, scene_of(scan=Scan(type="exhaustive", grid=(2, 2))))
    assert main(["export", str(scene_file), "--format", "mitransient", "--out", str(tmp_path / "x"), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "scan.type" in lines[0] and "single and confocal" in lines[0]
    scene_file = write_relay_wall_file(tmp_path, scene_of())
    assert main(["export", str(scene_file), "--format", "mitransient", "--radius", "0.01",
                 "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert "--radius" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_our_plugin_renders_the_exported_xml_as_the_scene_dictionary(tmp_path):
    from transient.backend import select_variant

    scene = scene_of(scan=Scan(type="exhaustive", grid=(2, 2), laser_grid=(2, 1), account_first_and_last_bounces=True),
                     illumination=Illumination(waveform="butterworth", order=2),
                     sensor_position=(0.1 + 0.2, -0.1, 0.35))                  # doubles float32 would round
    export_scene(scene, tmp_path, "mitsuba")
    select_variant()
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import relay_wall_scene_dict

    exported, built = mi.load_file(str(tmp_path / "scene.xml")), mi.load_dict(relay_wall_scene_dict(scene))
    ours, theirs = exported.integrator(), built.integrator()
    for name in ("lit", "read", "leg", "offsets", "hidden_matrix", "laser_position", "sensor_position"):
        assert np.array_equal(getattr(ours, name), getattr(theirs, name)), name
    assert ours.waveform.description == theirs.waveform.description
    layout = ReplicaLayout.for_samples(2**14)
    sums = [integrator.render_chunk_per_unit_intensity(loaded, seed=3, layout=layout, first=0, count=layout.samples)
            for integrator, loaded in ((ours, exported), (theirs, built))]
    assert np.allclose(sums[0], sums[1], rtol=1e-12, atol=1e-15 * np.abs(sums[1]).max())
    # the README's script, as written, in the exported folder
    block = re.search(r"```python\n(.*?)```", (tmp_path / "README.md").read_text(), re.S).group(1)
    here = os.getcwd()
    try:
        os.chdir(tmp_path)
        namespace = {}
        exec(block.replace("2**20", "2**12"), namespace)
    finally:
        os.chdir(here)
    assert namespace["y"].shape == (scene.sensor_count, 60)


# Runs the exported README's script as written (fewer samples) in a fresh process: mitransient's plugins never
# load into this one.
def run_readme(folder, spp: int) -> None:
    from transient.backend import choose_libllvm, find_llvm_libraries

    block = re.search(r"```python\n(.*?)```", (folder / "README.md").read_text(), re.S).group(1)
    block = block.replace("spp=2**18", f"spp={spp}")
    environment = os.environ | {"DRJIT_LIBLLVM_PATH": choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"),
                                                                     find_llvm_libraries())}
    done = subprocess.run([sys.executable, "-c", block], cwd=folder, capture_output=True, text=True, timeout=1800,
                          env=environment)
    assert done.returncode == 0, done.stderr[-3000:]


@needs_mitransient
@pytest.mark.slow
@pytest.mark.parametrize("scan", [Scan(type="single", grid=(3, 3), laser_point=(0.3, -0.2, 0.0)),
                                  Scan(type="confocal", grid=(2, 2))], ids=["single", "confocal"])
def test_mitransient_renders_of_the_export_agree_once_its_ray_offsets_are_stated(tmp_path, scan):
    """The README's round trip: export, render with mitransient, check.

    As given, mitransient's paths are short by its float32 ray offset (~1e-4 m, resolved); stating its
    estimator in closed form (``--expect transient_nlos_path``, no fitted parameter) it agrees, and a fit
    against that expectation finds scale 1 and offset 0 within their errors.
    """
    from analytic.operator.matrix_free import forward
    from validation.check import check_transient, read_data
    from interop.mitransient import offset_model

    scene = scene_of(scan=scan)
    scene_file = write_relay_wall_file(tmp_path, scene)
    assert main(["export", str(scene_file), "--format", "mitransient", "--out", str(tmp_path / "xml"), "--quiet"]) == 0
    run_readme(tmp_path / "xml", 2**18)
    films = sorted((tmp_path / "xml").glob("render_*.npy"))
    assert len(films) == 16 and np.load(films[0]).shape == (scan.grid[1], scan.grid[0], 60, 1)
    status = main(["check", str(scene_file), "--data", *map(str, films), "--expect", "transient_nlos_path",
                   "--out", str(tmp_path / "check"), "--quiet"])
    metrics = json.loads((tmp_path / "check" / "metrics.json").read_text())
    assert status == 0 and metrics["expected"]["agrees"] is True, metrics["expected"]
    fit = metrics["fit"]                                                    # against the model as given
    assert 5e-5 < fit["offset_opl"] < 3e-4 and fit["offset_opl"] > 3 * fit["offset_stderr"]
    replicas = np.stack([read_data(path, scene) for path in films])
    stated = check_transient(scene, replicas, evaluate=offset_model)     # judged and fitted against it
    assert abs(stated.fit.scale - 1) < 3 * stated.fit.scale_stderr
    assert abs(stated.fit.offset_opl) < 3 * stated.fit.offset_stderr
    assert stated.agrees
    assert np.abs(forward(scene) - offset_model(scene)).max() > 0                # the statement is not the model
