"""The commands that do not take relay-wall (NLOS) scene files yet refuse them in one line
(tests/cli/test_nlos_commands.py holds those that take them)."""

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


def _write(folder, text):
    path = folder / "wall.toml"
    path.write_text(text)
    return path


def test_the_commands_refuse_a_relay_wall_scene_in_one_line(tmp_path, capsys):
    """Until check takes NLOS captures, it refuses one by name before writing anything."""
    from validation.cli import main

    path = _write(tmp_path, SCENE)
    for command in (["check", str(path), "--data", str(path)],):
        out = tmp_path / "out"
        assert main([*command, "--out", str(out)]) == 2, command
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and "relay-wall (NLOS)" in lines[0], (command, lines)
        assert not out.exists()
