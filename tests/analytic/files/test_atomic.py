"""analytic.files.atomic: a file is renamed into place only once written and checked; staged files together."""

import errno
import json
from pathlib import Path

import numpy as np
import pytest

from analytic.errors import ResourceError
from analytic.files import atomic_write, save_json, save_npy, staged_writes


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    save_npy(tmp_path / "a.npy", np.arange(3.0))

    def broken(temporary):
        with open(temporary, "wb") as stream:
            stream.write(b"half")
        raise OSError(errno.ENOSPC, "No space left on device")
    with pytest.raises(ResourceError, match="free some space"):
        atomic_write(tmp_path / "a.npy", broken)
    assert np.array_equal(np.load(tmp_path / "a.npy"), np.arange(3.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npy"]


def test_a_file_that_does_not_read_back_is_not_renamed(tmp_path):
    def empty(temporary):
        open(temporary, "wb").close()
    with pytest.raises(ResourceError, match="empty"):
        atomic_write(tmp_path / "b.npy", empty)

    def garbage(temporary):
        with open(temporary, "wb") as stream:
            stream.write(b"not json")
    with pytest.raises(ResourceError, match="does not read back"):
        atomic_write(tmp_path / "c.json", garbage, lambda temporary: json.loads(Path(temporary).read_text()))
    assert list(tmp_path.iterdir()) == []


def test_staged_writes_commit_together_or_not_at_all(tmp_path):
    with pytest.raises(RuntimeError):
        with staged_writes():
            save_npy(tmp_path / "first.npy", np.zeros(2))
            raise RuntimeError("the command failed half-way")
    assert list(tmp_path.iterdir()) == []
    with staged_writes():
        save_npy(tmp_path / "first.npy", np.zeros(2))
        assert not (tmp_path / "first.npy").exists()       # not yet: renamed at the end
        save_json(tmp_path / "second.json", {"a": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["first.npy", "second.json"]
