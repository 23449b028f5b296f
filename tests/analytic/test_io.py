"""Output files: atomic and checked, staged together, in a locked folder; one metadata schema."""

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest

from analytic.errors import DataError, ResourceError
from analytic.io import (LOCK_FILE, atomic_write, build_meta, output_folder, read_transient, save_exr,
                         save_json, save_npy, staged_writes, write_transient)
from analytic.scene import Illumination, default_scene

SCHEMA = {"kind", "samples", "seed", "scene", "plane_size", "pixels", "source", "intensity",
          "sensor_positions", "attenuation", "illumination", "illumination_parameters", "tolerance",
          "window_share", "noise", "start_opl", "bin_width_opl", "bins", "sensors", "units"}


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


def test_output_folder_is_locked_cleaned_and_undone_on_failure(tmp_path):
    folder = tmp_path / "out"
    with output_folder(folder):
        assert (folder / LOCK_FILE).read_text() == str(os.getpid())
        with pytest.raises(ResourceError, match=f"process {os.getpid()}"):
            with output_folder(folder):
                pass
    assert not (folder / LOCK_FILE).exists()
    (folder / ".transient.npy.tmp-abc123.npy").write_bytes(b"left by a killed run")
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


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_one_schema_for_model_and_render(waveform):
    scene = default_scene(pixels=8, illumination=Illumination(waveform=waveform))
    model = build_meta(scene, kind="model", window_share=1.0)
    render = build_meta(scene, kind="render", samples=1024, seed=3, variant="llvm_ad_mono")
    assert SCHEMA <= set(model) and SCHEMA <= set(render)
    assert model["illumination"] == render["illumination"] == waveform
    assert model["illumination_parameters"] == render["illumination_parameters"]
    assert render["attenuation"] == "lambertian" and render["tolerance"] is None
    assert model["intensity"] == scene.intensity and model["bin_width_opl"] == scene.sampling.bin_width_opl
    with pytest.raises(ValueError, match="schema"):
        build_meta(scene, kind="model", bins=3)


def test_exr_header_holds_numbers_as_doubles(tmp_path):
    scene = default_scene(pixels=8).replace(sampling=default_scene().sampling.__class__(
        bin_width_opl=1e-4, start_opl=800.123456789, count=4))
    meta = build_meta(scene, kind="model")
    write_transient(tmp_path, np.zeros((16, 4)), meta)
    import OpenEXR
    with OpenEXR.File(str(tmp_path / "transient.exr")) as handle:
        header = {key: value for key, value in handle.header().items()}
    assert float(np.ravel(header["start_opl"])[0]) == 800.123456789    # exact: a double, not float32
    assert float(np.ravel(header["bin_width_opl"])[0]) == 1e-4
    assert header["bins"] == 4 and header["kind"] == "model"
    assert np.allclose(header["source"], scene.source)
    assert json.loads((tmp_path / "meta.json").read_text())["start_opl"] == 800.123456789


def test_read_transient_refuses_what_it_cannot_use(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_transient(tmp_path / "missing.npy")
    (tmp_path / "text.exr").write_text("not an EXR")
    with pytest.raises(DataError, match="cannot read"):
        read_transient(tmp_path / "text.exr")
    save_exr(tmp_path / "image.exr", np.zeros((2, 3)))
    assert read_transient(tmp_path / "image.exr").shape == (2, 3)
    save_npy(tmp_path / "flat.npy", np.zeros(5))
    with pytest.raises(DataError, match="shape"):
        read_transient(tmp_path / "flat.npy")
    np.save(tmp_path / "words.npy", np.array(["a", "b"]))
    with pytest.raises(DataError, match="not numbers"):
        read_transient(tmp_path / "words.npy")
