"""Where part of ``run``'s job would measure nothing.

``run`` and ``validate`` refuse a scene that sends no light into the window (a black plane or hidden
rectangle, a black relay wall, a window before the first arrival) in one line, before any file: the model
and the render would both be exactly zero, with every standard error zero and nothing to judge. ``run``
skips the reconstruction, saying why, where no image can be recovered (one sensor or pair)."""

import json

import numpy as np
import pytest
from scene_files import write_relay_wall_file, write_scene_file

from analytic.scenes.relay_wall import Scan, default_relay_wall_scene
from analytic.scenes.common import Sampling, default_scene
from validation.cli import main
from validation.runs.harness import imaging_problem, refuse_dark

DARK = {
    "black plane": (default_scene(pixels=8, reflectance=0.0, noise=None), "plane.reflectance: the plane is black"),
    "window before the light": (default_scene(pixels=8, noise=None).replace(
        sampling=Sampling(bin_width_opl=0.1, start_opl=0.5, count=10)), "sampling: the window holds none"),
    "black hidden rectangle": (default_relay_wall_scene(pixels=8).replace(reflectance=0.0),
                               "hidden.reflectance: the hidden rectangle is black"),
    "black relay wall": (default_relay_wall_scene(pixels=8).replace(wall_reflectance=0.0),
                         "relay_wall.reflectance: the relay wall is black"),
}


def _write(folder, scene):
    write = write_relay_wall_file if hasattr(scene, "wall_reflectance") else write_scene_file
    return write(folder, scene, name="dark.toml")


@pytest.mark.parametrize("command", ["run", "validate"])
@pytest.mark.parametrize("case", list(DARK))
def test_a_dark_scene_is_refused_in_one_line_before_any_file(tmp_path, capsys, command, case):
    scene, start = DARK[case]
    path = _write(tmp_path, scene)
    out = tmp_path / "out"
    assert main([command, str(path), "--out", str(out), "--spp", "4096", "--quiet"]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and start in lines[0] and "nothing to judge" in lines[0], lines
    assert not out.exists()


def test_a_lit_scene_is_not_refused():
    assert refuse_dark(default_scene(pixels=8), 1.0) is None
    assert refuse_dark(default_relay_wall_scene(pixels=8), 0.3) is None


def test_imaging_problem_names_one_sensor_or_pair():
    textured = default_scene(pixels=8)
    assert imaging_problem(textured) is None
    assert imaging_problem(textured.replace(reflectance=0.5)) is None      # a uniform truth: PSNR still measures
    assert imaging_problem(default_relay_wall_scene(pixels=8)) is None
    one = textured.replace(sensors=np.asarray(textured.sensors)[:1])
    assert imaging_problem(one).startswith("one sensor sees only path lengths")
    assert imaging_problem(default_relay_wall_scene(pixels=8, scan=Scan(type="single", grid=(1, 1)))).startswith(
        "one pair sees only path lengths")


def test_run_on_one_sensor_judges_the_render_and_says_why_it_does_not_reconstruct(tmp_path, capsys):
    scene = default_scene(pixels=8, noise=None)
    scene = scene.replace(sensors=np.asarray(scene.sensors)[:1])
    path = write_scene_file(tmp_path, scene, name="one.toml")
    status = main(["run", str(path), "--out", str(tmp_path / "out"), "--spp", "65536"])
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert status == (0 if metrics["agreement"]["agrees"] else 1) and "agrees" in metrics["agreement"]
    assert metrics["reconstruction"] == {"skipped": imaging_problem(scene)}
    assert f"No reconstruction: {imaging_problem(scene)}." in (tmp_path / "out" / "report.md").read_text()
    assert f"no reconstruction: {imaging_problem(scene)}" in capsys.readouterr().out
    assert not (tmp_path / "out" / "reconstructions.png").exists()


def test_run_refuses_lambda_options_for_a_scene_it_does_not_reconstruct(tmp_path, capsys):
    scene = default_scene(pixels=8, noise=None)
    path = write_scene_file(tmp_path, scene.replace(sensors=np.asarray(scene.sensors)[:1]), name="one.toml")
    for options in (["--lambda", "gcv"], ["--lambda-range", "1e-3", "1"]):
        assert main(["run", str(path), "--out", str(tmp_path / "out"), "--spp", "4096", *options]) == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 1 and "run does not reconstruct this scene (one sensor" in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_validate_refuses_a_dark_scene_before_rendering_the_others(tmp_path, capsys, monkeypatch):
    import validation.runs.harness

    lit = write_scene_file(tmp_path, default_scene(pixels=8, noise=None), name="lit.toml")
    dark = write_scene_file(tmp_path, default_scene(pixels=8, noise=None, reflectance=0.0), name="dark.toml")
    monkeypatch.setattr(validation.runs.harness, "check_scene", lambda *a, **k: pytest.fail("rendered first"))
    assert main(["validate", str(lit), str(dark), "--out", str(tmp_path / "out"), "--spp", "4096"]) == 2
    assert "plane.reflectance: the plane is black" in capsys.readouterr().err
