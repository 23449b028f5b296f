"""The one command that does not take relay-wall (NLOS) scene files, ``sweep``, refuses them in one line
(tests/cli/test_nlos_commands.py and tests/cli/test_check_relay_wall.py hold the commands that take them)."""

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
