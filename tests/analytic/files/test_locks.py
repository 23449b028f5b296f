"""Folder locks and temporaries (analytic.files.locks): one writer at a time without a window, readers kept
apart from writers, the lock file gone on every way out, only our dead processes' temporaries removed.

The references are the operating system's own: several processes racing for a folder, a marker file
created exclusively inside the critical section (two holders at once would find it there), process ids
of processes that have ended.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from analytic.errors import ResourceError
from analytic.files import (LOCK_FILE, TEMPORARY_PREFIX, output_folder, reading_folder, remove_temporaries,
                            save_npy, staged_writes)
from analytic.files import atomic as atomic_module
from analytic.files import locks as locks_module

ROOT = Path(__file__).resolve().parents[3]

# Each process enters the folder as often as it can; inside, it creates a marker exclusively: a
# second holder at the same time finds the marker there.
_HAMMER = textwrap.dedent(r"""
    import json, os, sys, time
    from analytic.errors import ResourceError
    from analytic.files import output_folder
    folder, inside, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    held = overlaps = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            with output_folder(folder):
                try:
                    marker = os.open(inside, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
                except FileExistsError:
                    overlaps += 1
                    continue
                held += 1
                time.sleep(0.0002)
                os.close(marker)
                os.unlink(inside)
        except ResourceError:
            pass
    print(json.dumps({"held": held, "overlaps": overlaps}))
    """)


def _python(code: str, *args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *map(str, args)], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


def test_no_two_processes_hold_a_folder_at_once(tmp_path):
    folder, inside = tmp_path / "out", tmp_path / "inside"
    folder.mkdir()
    processes = [_python(_HAMMER, folder, inside, 2.5) for _ in range(6)]
    results = []
    for process in processes:
        out, err = process.communicate(timeout=120)
        assert process.returncode == 0, err[-2000:]
        results.append(json.loads(out.strip().splitlines()[-1]))
    assert sum(r["held"] for r in results) > 20            # they did take turns
    assert sum(r["overlaps"] for r in results) == 0
    assert not (folder / LOCK_FILE).exists()


def _holder(code: str, *args) -> subprocess.Popen:
    """A process that runs ``code``, prints "ready" and waits for a line on its stdin."""
    process = subprocess.Popen([sys.executable, "-c", textwrap.dedent(code), *map(str, args)], cwd=ROOT,
                               text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    line = process.stdout.readline().strip()
    assert line == "ready", process.stderr.read()[-2000:]
    return process


def _finish(process: subprocess.Popen) -> None:
    out, err = process.communicate("go\n", timeout=60)
    assert process.returncode == 0, err[-2000:]


def _ended_process_id() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def _temporary_name(pid: int, name: str, host: str | None = None) -> str:
    return f"{TEMPORARY_PREFIX}{host or atomic_module._host_tag()}-{pid}-abcd1234-{name}"


def test_the_lock_file_goes_on_every_way_out(tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "kept.txt").write_text("the user's")

    def full_disk(temporary):
        raise OSError(28, "No space left on device")
    with output_folder(folder):
        save_npy(folder / "a.npy", np.zeros(2))
    assert not (folder / LOCK_FILE).exists()
    with pytest.raises(ResourceError, match="free some space"):
        with output_folder(folder):
            atomic_module.atomic_write(folder / "b.npy", full_disk)
    assert not (folder / LOCK_FILE).exists()
    with pytest.raises(KeyboardInterrupt):
        with output_folder(folder):
            raise KeyboardInterrupt
    assert sorted(p.name for p in folder.iterdir()) == ["a.npy", "kept.txt"]


def test_a_lock_file_left_by_a_killed_command_is_no_obstacle(tmp_path):
    folder = tmp_path / "out"
    holder = _holder("""
        import sys
        from analytic.files import output_folder
        with output_folder(sys.argv[1]):
            print("ready", flush=True)
            sys.stdin.readline()
        """, folder)
    holder.kill()
    holder.communicate(timeout=60)
    assert (folder / LOCK_FILE).read_text() == str(holder.pid)          # left behind by kill -9
    with output_folder(folder):
        assert (folder / LOCK_FILE).read_text() == str(os.getpid())
    assert list(folder.iterdir()) == []


def test_only_our_dead_processes_temporaries_in_the_written_folder_go(tmp_path):
    folder = tmp_path / "userdir"
    deep = folder / "notes" / "deep"
    deep.mkdir(parents=True)
    users = [folder / ".thesis.tmp-draft.tex", deep / ".thesis.tmp-draft.tex", folder / ".x.tmp-1.npy"]
    for path in users:
        path.write_text("the user's")
    dead = _ended_process_id()
    abandoned = folder / _temporary_name(dead, "transient.npy")
    below = deep / _temporary_name(dead, "transient.npy")
    elsewhere = folder / _temporary_name(dead, "transient.npy", host="0badc0de")   # another host's ids
    alive = folder / _temporary_name(os.getppid(), "transient.npy")
    for path in (abandoned, below, elsewhere, alive):
        path.write_text("a temporary")
    with output_folder(folder):
        save_npy(folder / "transient.npy", np.zeros(3))
    assert all(path.read_text() == "the user's" for path in users)
    assert not abandoned.exists()
    assert below.exists() and elsewhere.exists() and alive.exists()
    save_npy(deep / "written.npy", np.zeros(3))            # writing in a folder sweeps it, once
    assert not below.exists()
    assert remove_temporaries(folder) == 0                 # a live process's and another host's stay
    assert alive.exists() and elsewhere.exists()


def test_a_command_writing_a_parent_folder_leaves_a_nested_commands_files_alone(tmp_path):
    parent, nested = tmp_path / "p", tmp_path / "p" / "sub"
    writer = _holder("""
        import sys
        import numpy as np
        from pathlib import Path
        from analytic.files import output_folder, save_npy, staged_writes
        with output_folder(sys.argv[1]) as out:
            with staged_writes():
                save_npy(Path(out) / "model" / "transient.npy", np.arange(4.0))
                print("ready", flush=True)      # its temporary waits in sub/model for the rename
                sys.stdin.readline()
        """, nested)
    temporaries = [p.name for p in (nested / "model").iterdir()]
    assert len(temporaries) == 1 and temporaries[0].startswith(TEMPORARY_PREFIX)
    with output_folder(parent):                            # e.g. `export --out p` during `run --out p/sub`
        save_npy(parent / "scene.npy", np.zeros(1))
    _finish(writer)
    assert np.array_equal(np.load(nested / "model" / "transient.npy"), np.arange(4.0))


def test_a_reader_waits_for_the_writer_then_refuses_naming_it(tmp_path):
    folder = tmp_path / "p"
    (folder / "model").mkdir(parents=True)
    save_npy(folder / "model" / "transient.npy", np.zeros(2))
    writer = _holder("""
        import sys
        from analytic.files import output_folder
        with output_folder(sys.argv[1]):
            print("ready", flush=True)
            sys.stdin.readline()
        """, folder)
    try:
        for path in (folder / "model" / "transient.npy", folder):   # the folder itself, or a file below it
            started = time.monotonic()
            with pytest.raises(ResourceError, match=f"process {writer.pid}.* is writing"):
                with reading_folder(path, wait_seconds=0.3):
                    pass
            assert time.monotonic() - started >= 0.3
    finally:
        _finish(writer)
    with reading_folder(folder / "model" / "transient.npy", wait_seconds=0.3):
        assert np.array_equal(np.load(folder / "model" / "transient.npy"), np.zeros(2))
    assert sorted(p.name for p in folder.rglob("*")) == ["model", "transient.npy"]   # it created nothing


def test_a_writer_waits_for_readers_then_refuses(tmp_path, monkeypatch):
    folder = tmp_path / "p"
    folder.mkdir()
    save_npy(folder / "transient.npy", np.zeros(2))
    monkeypatch.setattr(locks_module, "LOCK_WAIT_SECONDS", 0.3)
    reader = _holder("""
        import sys
        from analytic.files import reading_folder
        with reading_folder(sys.argv[1]):
            print("ready", flush=True)
            sys.stdin.readline()
        """, folder / "transient.npy")
    try:
        with pytest.raises(ResourceError, match="is reading this folder"):
            with output_folder(folder):
                pass
        assert sorted(p.name for p in folder.iterdir()) == ["transient.npy"]   # and the lock file went
    finally:
        _finish(reader)
    with output_folder(folder):
        with reading_folder(folder / "transient.npy", wait_seconds=0):   # its own folder: no wait
            pass


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads and writes any folder")
def test_a_read_only_folder_is_read_without_a_lock_file(tmp_path):
    folder = tmp_path / "data"
    folder.mkdir()
    save_npy(folder / "transient.npy", np.ones(2))
    folder.chmod(0o555)
    try:
        with reading_folder(folder / "transient.npy"):
            assert np.array_equal(np.load(folder / "transient.npy"), np.ones(2))
        assert [p.name for p in folder.iterdir()] == ["transient.npy"]
    finally:
        folder.chmod(0o755)


# A writer commits pairs of files with the same number, over and over; a reader reads both.
_PAIR_WRITER = textwrap.dedent(r"""
    import sys, time
    import numpy as np
    from pathlib import Path
    from analytic.errors import ResourceError
    from analytic.files import output_folder, save_npy, staged_writes
    folder, seconds = Path(sys.argv[1]), float(sys.argv[2])
    end, commits = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        try:
            with output_folder(folder):
                with staged_writes():
                    save_npy(folder / "transient.npy", np.full(4, float(commits)))
                    save_npy(folder / "stderr.npy", np.full(4, float(commits)))
                commits += 1
        except ResourceError:
            pass
        time.sleep(0.002)
    print(commits)
    """)


def test_a_reader_under_the_lock_never_pairs_two_commits(tmp_path):
    folder = tmp_path / "p"
    folder.mkdir()
    with staged_writes():
        save_npy(folder / "transient.npy", np.full(4, -1.0))
        save_npy(folder / "stderr.npy", np.full(4, -1.0))
    writer = _python(_PAIR_WRITER, folder, 2.0)
    reads = mismatches = 0
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        try:
            with reading_folder(folder / "transient.npy"):
                first = np.load(folder / "transient.npy")
                second = np.load(folder / "stderr.npy")
        except ResourceError:
            continue
        reads += 1
        mismatches += int(not np.array_equal(first, second))
    out, err = writer.communicate(timeout=60)
    assert writer.returncode == 0, err[-2000:]
    assert int(out.split()[-1]) > 10 and reads > 10       # both got their turns
    assert mismatches == 0


def test_writing_a_folder_this_process_is_reading_is_a_bug_said_at_once(tmp_path):
    save_npy(tmp_path / "transient.npy", np.zeros(2))
    with reading_folder(tmp_path / "transient.npy"):
        started = time.monotonic()
        with pytest.raises(RuntimeError, match="end the reading block before writing"):
            with output_folder(tmp_path):
                pass
        assert time.monotonic() - started < 1.0
    assert not (tmp_path / LOCK_FILE).exists()
    with output_folder(tmp_path):          # once the reading is over
        pass


def test_output_folder_is_locked_cleaned_and_undone_on_failure(tmp_path):
    folder = tmp_path / "out"
    with output_folder(folder):
        assert (folder / LOCK_FILE).read_text() == str(os.getpid())
        with pytest.raises(ResourceError, match=f"process {os.getpid()}"):
            with output_folder(folder):
                pass
    assert not (folder / LOCK_FILE).exists()
    killed = subprocess.Popen([sys.executable, "-c", "pass"])
    killed.wait()
    (folder / f"{TEMPORARY_PREFIX}{atomic_module._host_tag()}-{killed.pid}-abc123-transient.npy").write_bytes(
        b"left by a killed run")
    with output_folder(folder):
        pass
    assert list(folder.iterdir()) == []                   # the killed run's temporary is gone
    fresh = tmp_path / "fresh"
    with pytest.raises(RuntimeError):
        with output_folder(fresh):
            raise RuntimeError("failed before writing")
    assert not fresh.exists()                             # a failed command leaves no folder behind


def test_output_folder_refuses_files_in_the_way(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(ResourceError, match="is a file"):
        with output_folder(tmp_path / "file"):
            pass
    with pytest.raises(ResourceError, match="a parent of it is a file"):
        with output_folder(tmp_path / "file" / "under"):
            pass


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders anyway")
def test_a_read_only_folder_is_one_line(tmp_path):
    tmp_path.chmod(0o555)
    try:
        with pytest.raises(ResourceError, match="permission"):
            with output_folder(tmp_path / "out"):
                pass
    finally:
        tmp_path.chmod(0o755)


def test_a_failed_command_removes_the_empty_parents_it_made(tmp_path):
    """`export --radius 5 --out new/a/b` was refused after output_folder had made new/a/b: b went, new/a
    stayed. Now the parents it made go too, and a folder that was there before (or holds a file) stays."""
    (tmp_path / "kept").mkdir()
    for out in (tmp_path / "new" / "a" / "b", tmp_path / "kept" / "a" / "b"):
        with pytest.raises(ValueError):
            with output_folder(out):
                raise ValueError("refused")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"] and not any((tmp_path / "kept").iterdir())
    with output_folder(tmp_path / "new" / "a"):
        (tmp_path / "new" / "a" / "mine.txt").write_text("x")
    with pytest.raises(ValueError):
        with output_folder(tmp_path / "new" / "a" / "b" / "c"):
            raise ValueError("refused")
    assert sorted(p.name for p in (tmp_path / "new" / "a").iterdir()) == ["mine.txt"]
