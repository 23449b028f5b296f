"""``run`` and ``validate`` refuse a scene that sends no light into the window (a black plane or hidden
rectangle, a black relay wall, a window before the first arrival) in one line, before any file: the model
and the render would both be exactly zero, with every standard error zero and nothing to judge."""

import pytest
from scene_files import write_relay_wall_file, write_scene_file

from analytic.relay_wall import default_relay_wall_scene
from analytic.scene import Sampling, default_scene
from validation.cli import main
from validation.harness import refuse_dark

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
