"""Output files: atomic and checked, staged together, in a locked folder; one metadata schema."""

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analytic import io as io_module
from analytic.errors import DataError, ResourceError
from analytic.io import (LOCK_FILE, TEMPORARY_PREFIX, PrecisionWarning, atomic_write, build_meta,
                         float32_problem, output_folder, read_exr, read_transient, save_exr, save_json,
                         save_npy, staged_writes, write_transient)
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
    killed = subprocess.Popen([sys.executable, "-c", "pass"])
    killed.wait()
    (folder / f"{TEMPORARY_PREFIX}{io_module._host_tag()}-{killed.pid}-abc123-transient.npy").write_bytes(
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


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_one_schema_for_model_and_render(waveform):
    scene = default_scene(pixels=8, illumination=Illumination(waveform=waveform))
    model = build_meta(scene, kind="model", window_share=1.0)
    render = build_meta(scene, kind="render", samples=1024, seed=3, variant="llvm_ad_mono")
    assert SCHEMA <= set(model) and SCHEMA <= set(render)
    assert model["illumination"] == render["illumination"] == waveform
    assert model["illumination_parameters"] == render["illumination_parameters"]
    assert render["attenuation"] == "lambertian" and render["tolerance"] is None
    # the renderer renders the paper's attenuation too, and the metadata says which it rendered
    assert build_meta(scene.replace(attenuation="paper"), kind="render")["attenuation"] == "paper"
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


def _model_meta():
    scene = default_scene(pixels=8)
    return scene, build_meta(scene, kind="model")


@pytest.mark.parametrize("peak", [3.3e40, 1e-300])
def test_values_float32_cannot_hold_leave_the_exr_unwritten_and_say_so(tmp_path, peak):
    """y = 3.3e40 is legal (lengths x 1e-6, I = 1e30) and overflows float32; y = 1e-300 underflows it."""
    scene, meta = _model_meta()
    shape = (scene.sensor_count, scene.sampling.count)
    write_transient(tmp_path, np.ones(shape), meta)               # an earlier command's files
    transient = peak * np.linspace(0.5, 1.0, shape[0] * shape[1]).reshape(shape)
    with pytest.warns(PrecisionWarning, match="transient.exr: not written.*float32.*exact record"):
        write_transient(tmp_path, transient, meta)
    assert not (tmp_path / "transient.exr").exists()              # neither inf, nor zeros, nor the old one
    assert np.array_equal(np.load(tmp_path / "transient.npy"), transient)
    record = json.loads((tmp_path / "meta.json").read_text())["exr"]
    assert record.startswith("not written") and "float32" in record
    assert read_transient(tmp_path).max() == transient.max()      # the folder reads as its exact record


def test_the_exr_holds_every_value_float32_can(tmp_path):
    scene, meta = _model_meta()
    shape = (scene.sensor_count, scene.sampling.count)
    # normal values, and subnormal ones beside a normal peak (their error is below 2^-24 of it)
    transient = np.geomspace(1e-44, 3e38, shape[0] * shape[1]).reshape(shape)
    write_transient(tmp_path, transient, meta)
    back, _ = read_exr(tmp_path / "transient.exr")
    assert np.array_equal(back, transient.astype(np.float32).astype(np.float64))
    assert np.max(np.abs(back - transient)) <= 2.0**-24 * transient.max()
    assert json.loads((tmp_path / "meta.json").read_text())["exr"].startswith("written")


def test_float32_problem_measures_the_rounding(tmp_path):
    assert float32_problem(np.array([1.0, 1e-45, 0.0])) is None           # 1e-45 errs by < 2^-24 of 1
    assert float32_problem(np.array([np.finfo(np.float32).max])) is None
    assert "exceeds" in float32_problem(np.array([1.0, 3.5e38]))
    assert "below float32's smallest normal" in float32_problem(np.array([1e-300, 0.0]))
    assert "below float32's smallest normal" in float32_problem(np.array([1e-39]))
    assert "NaN" in float32_problem(np.array([np.nan]))
    with pytest.raises(ValueError, match="float32"):                   # save_exr never writes inf
        save_exr(tmp_path / "never.exr", np.array([[1e40]]))
    assert not (tmp_path / "never.exr").exists()
