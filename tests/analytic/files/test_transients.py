"""analytic.files.transients: one metadata schema, a transient's files written together, read back by format."""

import json

import numpy as np
import pytest

from analytic.errors import DataError
from analytic.files import (PrecisionWarning, build_meta, read_exr, read_transient, save_exr, save_npy,
                            write_transient)
from analytic.scenes.common import Illumination, default_scene

SCHEMA = {"kind", "samples", "seed", "scene", "plane_size", "pixels", "source", "intensity",
          "sensor_positions", "attenuation", "illumination", "illumination_parameters", "tolerance",
          "window_share", "noise", "start_opl", "bin_width_opl", "bins", "sensors", "units"}


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


def test_a_relay_wall_capture_has_the_same_keys_and_its_own_tables(tmp_path):
    """One schema: a capture's record has every key a plane's has (those of the other geometry None), and a
    capture's transient is written without a tal file (tal's NLOS layout is wired apart)."""
    from analytic.scenes.relay_wall import RelayWallScene, Scan

    plane = build_meta(default_scene(pixels=8), kind="model", window_share=1.0)
    capture = RelayWallScene(pixels=4, scan=Scan(type="single", grid=(3, 2), laser_point=(0.2, -0.1, 0.0)),
                             laser_position=(-0.5, 0.1, 0.3), wall_reflectance=0.7)
    meta = build_meta(capture, kind="render", samples=64, seed=1)
    assert set(meta) == set(plane) and SCHEMA <= set(meta)
    assert plane["geometry"] == "plane" and all(plane[key] is None for key in
                                                 ("relay_wall", "hidden", "laser", "sensor", "scan"))
    assert meta["geometry"] == "relay_wall" and meta["plane_size"] is meta["source"] is None
    assert meta["sensors"] == 6 and meta["pixels"] == 4 and meta["attenuation"] == "lambertian"
    assert meta["relay_wall"] == {"size": [2.0, 2.0], "reflectance": 0.7}
    assert meta["laser"]["position"] == [-0.5, 0.1, 0.3]
    assert meta["scan"] == {"type": "single", "grid": [3, 2], "laser_point": [0.2, -0.1, 0.0], "laser_grid": None,
                            "account_first_and_last_bounces": False, "pairs": 6}
    (tmp_path / "transient.h5").write_bytes(b"an earlier command's")
    y = np.arange(6 * meta["bins"], dtype=np.float64).reshape(6, meta["bins"])
    with pytest.raises(ValueError, match="needs its scene"):
        write_transient(tmp_path, y, meta)
    written = write_transient(tmp_path, y, meta, scene=capture)
    assert set(written) == {"transient.npy", "transient.exr", "transient.h5", "meta.json"}
    np.testing.assert_array_equal(read_transient(tmp_path / "transient.h5"), y)     # tal's layout, our pair order
    assert json.loads((tmp_path / "meta.json").read_text())["scan"]["laser_point"] == [0.2, -0.1, 0.0]


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
    with pytest.raises(DataError, match="not real numbers"):
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
