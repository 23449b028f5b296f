"""Resource problems end in one line and exit 2, leaving the folder as it was:
a full disk (whichever writer meets it), a read-only file system, --out naming a file, a FIFO, a
device, a dangling link, a name too long, a loop of links or a NUL byte, a folder another command
holds, a scheduler nobody runs; and a command removes none of the user's files."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from analytic.errors import ResourceError
from analytic.files import save_exr, save_npy

from scene_files import GOOD, write_scene
from validation.cli import main

# a window that holds the light and little else: no window warning (an error under pytest's filters)
FITTED = GOOD.replace("start = 0.0\ncount = 40", "start = 1.9\ncount = 10")


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
    assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(out), "--quiet"]) == 2
    error = _one_error(capsys)
    assert "free some space" in error and str(out) in error
    assert not out.exists() and os.listdir(small_disk) == []


def test_a_read_only_file_system_is_one_line(tmp_path, small_disk, capsys):
    subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], check=True)
    out = small_disk / "out"
    assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(out), "--quiet"]) == 2
    assert "read-only" in _one_error(capsys)
    assert not out.exists()


def test_out_naming_a_file_or_a_path_under_one(tmp_path, capsys):
    scene = str(write_scene(tmp_path, FITTED))
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
        from analytic.files import output_folder
        with output_folder({str(out)!r}):
            print("holding", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        with holder.stdout:
            assert holder.stdout.readline().strip() == "holding"
        assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(out), "--quiet"]) == 2
        assert f"process {holder.pid}" in _one_error(capsys)
        assert sorted(os.listdir(out)) == [".diffuse-imaging.lock"]     # nothing written by the second
    finally:
        holder.kill()
        holder.wait()
    # once the first is gone (even killed), the folder is free again
    assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(out), "--quiet"]) == 0


def test_a_scheduler_nobody_runs_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("validation.sweep.driver.CONNECT_SECONDS", 1)       # nobody answers: do not wait 10 s
    (tmp_path / "base.toml").write_text(GOOD)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('scene = "base.toml"\nsamples = 1000\n[grid]\n"sampling.period" = [0.1]\n')
    assert main(["sweep", str(sweep), "--scheduler", "tcp://127.0.0.1:9", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    assert "--scheduler" in _one_error(capsys)
    assert not (tmp_path / "out").exists()


def _fill(disk, leave: int):
    """Fill a small disk, then free ``leave`` bytes: a file larger than that fails half-way."""
    with open(disk / "filler", "wb", buffering=0) as stream:
        try:
            while True:
                stream.write(b"\0" * 512)
        except OSError as error:
            assert error.errno == errno.ENOSPC
    os.truncate(disk / "filler", os.path.getsize(disk / "filler") - leave)


_NOISE = np.random.default_rng(0).random((64, 64))     # 16 kB as float32, and it does not compress


@pytest.mark.parametrize("save", [
    lambda path: save_exr(path.with_suffix(".exr"), _NOISE),   # OpenEXR: RuntimeError quoting the C library
    lambda path: save_npy(path.with_suffix(".npy"), _NOISE),   # NumPy: a short write, OSError without errno
], ids=["exr", "npy"])
def test_every_writer_meeting_a_full_disk_is_one_resource_line(small_disk, save):
    (small_disk / "out").mkdir()
    _fill(small_disk, leave=4096)
    with pytest.raises(ResourceError, match="free some space"):
        save(small_disk / "out" / "transient")
    assert os.listdir(small_disk / "out") == []                 # and no temporary left


def test_out_paths_that_are_no_folder_are_one_line(tmp_path, capsys):
    scene = str(write_scene(tmp_path, FITTED))
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "loop_a").symlink_to(tmp_path / "loop_b")
    (tmp_path / "loop_b").symlink_to(tmp_path / "loop_a")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    cases = {str(tmp_path / ("x" * 256) / "out"): "longer than the file system allows",
             str(tmp_path / "loop_a" / "out"): "symbolic links loop",
             str(tmp_path / "dangling"): "symbolic link to .*nowhere, which does not exist",
             str(fifo): "is a named pipe",
             "/dev/null": "is a device",
             str(tmp_path / "nul\0byte"): "NUL byte"}
    for out, words in cases.items():
        assert main(["forward", scene, "--out", out, "--quiet"]) == 2, out
        line = _one_error(capsys)
        assert __import__("re").search(words, line), line
    assert not (tmp_path / "nowhere").exists() and fifo.exists()


def test_out_as_a_link_to_a_folder_is_that_folder(tmp_path, capsys):
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(tmp_path / "link"), "--quiet"]) == 0
    assert (tmp_path / "real" / "transient.npy").is_file() and (tmp_path / "link").is_symlink()


def test_a_command_removes_none_of_the_users_files(tmp_path):
    userdir = tmp_path / "userdir"
    deep = userdir / "notes" / "deep"
    deep.mkdir(parents=True)
    drafts = [userdir / ".thesis.tmp-draft.tex", deep / ".thesis.tmp-draft.tex"]
    for draft in drafts:
        draft.write_text("chapter 1")
    assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(userdir), "--quiet"]) == 0
    assert all(draft.read_text() == "chapter 1" for draft in drafts)
    assert not (userdir / ".diffuse-imaging.lock").exists()
