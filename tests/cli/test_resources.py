"""Resource problems end in one line and exit 2, leaving the folder as it was:
a full disk, a read-only file system, --out naming a file, a folder another command holds,
a scheduler nobody runs."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from scene_files import GOOD, write_scene
from validation.cli import main


def _mount_tmpfs(where, size: str):
    where.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                          capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {done.stderr.decode().strip()}")


@pytest.fixture
def small_disk(tmp_path):
    disk = tmp_path / "disk"
    _mount_tmpfs(disk, "12k")
    yield disk
    subprocess.run(["umount", str(disk)], check=True)


def _one_error(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: error:"), lines
    return lines[0]


def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, small_disk, capsys):
    out = small_disk / "out"
    # the figure alone is larger than the disk
    assert main(["forward", str(write_scene(tmp_path)), "--out", str(out), "--quiet"]) == 2
    error = _one_error(capsys)
    assert "free some space" in error and str(out) in error
    assert not out.exists() and os.listdir(small_disk) == []


def test_a_read_only_file_system_is_one_line(tmp_path, small_disk, capsys):
    subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], check=True)
    out = small_disk / "out"
    assert main(["forward", str(write_scene(tmp_path)), "--out", str(out), "--quiet"]) == 2
    assert "read-only" in _one_error(capsys)
    assert not out.exists()


def test_out_naming_a_file_or_a_path_under_one(tmp_path, capsys):
    scene = str(write_scene(tmp_path))
    (tmp_path / "taken").write_text("a file")
    assert main(["forward", scene, "--out", str(tmp_path / "taken"), "--quiet"]) == 2
    assert "is a file" in _one_error(capsys)
    assert main(["forward", scene, "--out", str(tmp_path / "taken" / "below"), "--quiet"]) == 2
    assert "parent of it is a file" in _one_error(capsys)
    assert (tmp_path / "taken").read_text() == "a file"


def test_a_second_command_on_a_busy_folder_names_the_first(tmp_path, capsys):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        from analytic.io import output_folder
        with output_folder({str(out)!r}):
            print("holding", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        with holder.stdout:
            assert holder.stdout.readline().strip() == "holding"
        assert main(["forward", str(write_scene(tmp_path)), "--out", str(out), "--quiet"]) == 2
        assert f"process {holder.pid}" in _one_error(capsys)
        assert sorted(os.listdir(out)) == [".diffuse-imaging.lock"]     # nothing written by the second
    finally:
        holder.kill()
        holder.wait()
    # once the first is gone (even killed), the folder is free again
    assert main(["forward", str(write_scene(tmp_path)), "--out", str(out), "--quiet"]) == 0


def test_a_scheduler_nobody_runs_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("validation.sweep.driver.CONNECT_SECONDS", 1)       # nobody answers: do not wait 10 s
    (tmp_path / "base.toml").write_text(GOOD)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('scene = "base.toml"\nsamples = 1000\n[grid]\n"sampling.period" = [0.1]\n')
    assert main(["sweep", str(sweep), "--scheduler", "tcp://127.0.0.1:9", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    assert "--scheduler" in _one_error(capsys)
    assert not (tmp_path / "out").exists()
