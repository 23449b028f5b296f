"""The one command that does not take relay-wall (NLOS) scene files, ``sweep``, refuses them in one line
(tests/cli/test_nlos_commands.py and tests/cli/test_check_relay_wall.py hold the commands that take them)."""

import numpy as np
import pytest

from analytic.errors import SceneError
from validation.cli import main

SCENE = """
[relay_wall]
size = [2.0, 2.0]
[hidden]
pixels = 8
[scan]
type = "confocal"
grid = [2, 2]
"""


def test_sweep_refuses_a_relay_wall_base_scene_in_one_line(tmp_path, capsys):
    (tmp_path / "wall.toml").write_text(SCENE)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('scene = "wall.toml"\nsamples = 64\n\n[grid]\n"hidden.pixels" = [4, 8]\n')
    out = tmp_path / "out"
    assert main(["sweep", str(sweep), "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "relay-wall (NLOS)" in lines[0], lines
    assert not out.exists()


# issue 38: the laser at z = 2 behind the default 1 m square at z = 1, right above the lit point (the wall's centre)
BLOCKED = SCENE + "[laser]\nposition = [0.0, 0.0, 2.0]\n"


@pytest.mark.parametrize("command", [
    ["forward"], ["render", "--spp", "4096"], ["run", "--spp", "4096"], ["validate", "--spp", "4096"],
    ["export", "--format", "mitsuba"], ["export", "--format", "mitransient"],
    ["check", "--data", "DATA"], ["reconstruct", "--data", "DATA"],
])
def test_every_command_refuses_a_blocked_laser_line_in_one_line(tmp_path, capsys, command):
    scene = tmp_path / "wall.toml"
    scene.write_text(BLOCKED)
    data = tmp_path / "data.npy"
    np.save(data, np.zeros((4, 40)))
    out = tmp_path / "out"
    args = [command[0], str(scene), *[str(data) if a == "DATA" else a for a in command[1:]], "--out", str(out)]
    assert main(args) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "hidden.center: the hidden rectangle blocks the laser's line" in lines[0], lines
    assert not out.exists()


def test_the_python_api_refuses_the_blocked_scene_file(tmp_path):
    import analytic

    scene = tmp_path / "wall.toml"
    scene.write_text(BLOCKED)
    with pytest.raises(SceneError, match="blocks the laser's line"):
        analytic.load_scene(scene)
