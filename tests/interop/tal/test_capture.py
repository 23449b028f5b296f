"""transient.h5 in tal's HDF5 capture layout (interop.tal.capture), read back by tal itself.

tal (y-tal) pins numpy < 2 and Pillow 10.3.0, so it lives in its own virtual
environment, ``.venv-tal`` (``scripts/setup_interop.sh``); the tests that need
it run ``.venv-tal/bin/python`` in a subprocess and are skipped when it is
absent. The independent reference for our writer is tal's own reader
(``tal.io.read_capture``) and tal's own backprojection, and for our reader a
file written by tal's own writer (``tal.io.write_capture``).
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from interop.tal import capture as capture_module
from interop.tal import CaptureError, read_capture, write_capture
from analytic.scenes.common import Sampling, Scene, sensor_grid
from analytic.operator.matrix_free import forward
from analytic.errors import DataError
from tal_env import TAL_READ, needs_tal, run_tal
from validation.check import read_data



def small_capture(tmp_path, rng):
    transient = rng.random((3, 7))
    sensors = np.array([[0.2, 0.7, 1.0], [0.8, 0.15, 0.5], [0.1 + 0.2, 0.4, 0.9]])
    path = write_capture(tmp_path / "transient.h5", transient, start_opl=1.2345678901234567,
                         bin_width_opl=0.1, source=[0.5, 0.5, 1.0], sensors=sensors,
                         scene_info={"scene": "small", "start_opl": 1.2345678901234567})
    return path, transient, sensors


def test_round_trip_is_exact(tmp_path, rng):
    path, transient, sensors = small_capture(tmp_path, rng)
    read = read_capture(path)
    assert np.array_equal(read.transient, transient)
    assert read.start_opl == 1.2345678901234567 and read.bin_width_opl == 0.1
    assert np.array_equal(read.sensors, sensors)
    assert np.array_equal(read.source, [0.5, 0.5, 1.0])
    assert read.accounts_first_and_last_bounces is False
    assert read.scene_info == {"scene": "small", "start_opl": 1.2345678901234567}
    with h5py.File(path, "r") as handle:
        assert handle["H"].shape == (7, 3)            # time first: T_Si
        assert handle["H"].dtype == np.float64
        assert h5py.check_enum_dtype(handle["H_format"].dtype)["T_Si"] == handle["H_format"][0] == 3


def test_interrupted_write_keeps_the_previous_file(tmp_path, rng, monkeypatch):
    path, transient, _ = small_capture(tmp_path, rng)
    before = path.read_bytes()

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")
    monkeypatch.setattr(capture_module, "_enum", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        write_capture(path, 2 * transient, start_opl=0.0, bin_width_opl=0.1, source=[0.5, 0.5, 1.0],
                      sensors=np.ones((3, 3)), scene_info={})
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["transient.h5"]   # no temporary left


@pytest.mark.parametrize("arguments, name", [
    (dict(sensors=np.ones((2, 3))), "sensors"),
    (dict(source=[0.5, 0.5]), "source"),
    (dict(bin_width_opl=0.0), "bin_width_opl"),
])
def test_bad_arguments_are_named(tmp_path, arguments, name):
    values = dict(start_opl=0.0, bin_width_opl=0.1, source=[0.5, 0.5, 1.0], sensors=np.ones((3, 3)),
                  scene_info={}) | arguments
    with pytest.raises(ValueError, match=name):
        write_capture(tmp_path / "t.h5", np.ones((3, 4)), **values)
    assert not (tmp_path / "t.h5").exists()


def test_files_that_are_not_captures_are_refused(tmp_path):
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(CaptureError, match="not a readable HDF5"):
        read_capture(tmp_path / "text.h5")
    with h5py.File(tmp_path / "empty.h5", "w") as handle:
        handle["t_start"] = 0.0
    with pytest.raises(CaptureError, match="no H"):
        read_capture(tmp_path / "empty.h5")
    with h5py.File(tmp_path / "lasers.h5", "w") as handle:
        handle["H"] = np.ones((5, 2, 3))
        handle.create_dataset("H_format", (1,), dtype=h5py.enum_dtype(capture_module.H_FORMATS, basetype="i"))
        handle["H_format"][0] = capture_module.H_FORMATS["T_Li_Si"]
        handle["t_start"], handle["delta_t"] = 0.0, 0.1
    assert read_capture(tmp_path / "lasers.h5").laser_count == 2      # read (a relay wall's layout) ...
    plane = Scene(size=1.0, pixels=4, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=[(0.2, 0.7, 1.0), (0.8, 0.15, 0.5), (0.3, 0.4, 0.9)],
                  sampling=Sampling(bin_width_opl=0.1, start_opl=0.0, count=5))
    with pytest.raises(DataError, match="H holds 2 laser points .* a plane scene has one source"):
        read_data(tmp_path / "lasers.h5", plane)                          # ... and refused for a plane

    with pytest.raises(FileNotFoundError):
        read_capture(tmp_path / "missing.h5")


@pytest.mark.parametrize("datasets, words", [
    ({"H": np.ones((40, 1))}, "no time axis"),                                    # no t_start, delta_t
    ({"H": np.ones((40, 1)), "t_start": 0.0, "delta_t": np.nan}, "finite"),
    ({"H": np.ones((40, 1)), "t_start": np.inf, "delta_t": 0.1}, "finite"),
    ({"H": np.ones((40, 1)), "t_start": 0.0, "delta_t": -0.1},
     "delta_t is -0.1; expected one finite number > 0"),
    ({"H": np.ones((40, 1)), "t_start": 0.0, "delta_t": np.array([0.1, 0.2])}, "delta_t holds 2 values"),
    ({"H": np.ones((40, 1)), "t_start": "zero", "delta_t": 0.1}, "t_start holds text, not real numbers"),
    ({"H": np.array([b"hello"] * 40).reshape(40, 1), "t_start": 0.0, "delta_t": 0.1}, "not real numbers"),
    ({"H": np.ones((40, 1)) * (1 + 1j), "t_start": 0.0, "delta_t": 0.1}, "not real numbers"),
])
def test_captures_with_a_bad_time_axis_or_h_are_refused(tmp_path, datasets, words):
    with h5py.File(tmp_path / "bad.h5", "w") as handle:
        for key, value in datasets.items():
            handle[key] = value
    with pytest.raises(CaptureError, match=words):
        read_capture(tmp_path / "bad.h5")



def _enum_dataset(handle, key, names, code):
    dataset = handle.create_dataset(key, (1,), dtype=h5py.enum_dtype(dict(names), basetype="i"))
    dataset[0] = code


def _grid_capture(handle):
    """A valid T_Sx_Sy capture of 2 x 3 sensors with its X_Y_3 grid."""
    handle["H"] = np.ones((7, 2, 3))
    _enum_dataset(handle, "H_format", capture_module.H_FORMATS, capture_module.H_FORMATS["T_Sx_Sy"])
    handle["sensor_grid_xyz"] = np.ones((2, 3, 3))
    _enum_dataset(handle, "sensor_grid_format", capture_module.GRID_FORMATS,
                  capture_module.GRID_FORMATS["X_Y_3"])


# (dataset, what to store there: a value, None to delete it, or a function of the open file), words
_MALFORMED = [
    ("laser_xyz", np.array([0.5, 0.5]), "laser_xyz holds 2 number"),
    ("laser_xyz", np.array([np.nan, 0.5, 1.0]), "laser_xyz holds 1 NaN or infinite"),
    ("laser_xyz", "over there", "laser_xyz holds text, not real numbers"),
    ("laser_xyz", np.array([True, False, True]), "laser_xyz holds true/false values"),
    ("sensor_grid_xyz", np.arange(19.0), r"sensor_grid_xyz has shape \(19,\)"),
    ("sensor_grid_xyz", np.ones((3, 2)), r"sensor_grid_xyz has shape \(3, 2\)"),
    ("sensor_grid_xyz", np.ones((4, 3)), "sensor_grid_xyz holds 4 points for 3 sensors in H"),
    ("sensor_grid_xyz", np.full((3, 3), np.inf), "sensor_grid_xyz holds 9 NaN or infinite"),
    ("sensor_grid_xyz", np.zeros((0, 3)), "sensor_grid_xyz is empty"),
    ("sensor_grid_xyz", np.ones((3, 3), dtype=complex), "sensor_grid_xyz holds complex numbers"),
    ("sensor_grid_format", 5, "sensor_grid_format is 5, not one of its values"),
    ("sensor_grid_format", 2, r"sensor_grid_xyz has shape \(3, 3\) \(sensor_grid_format X_Y_3\)"),
    ("H_format", np.nan, "H_format holds 1 NaN or infinite"),
    ("H_format", 7, "H_format is 7, not one of its values"),
    ("H_format", 2.5, "H_format is 2.5, not one of its values"),
    ("H_format", "T_Si", "H_format holds text"),
    ("H_format", np.array([3, 3]), "H_format holds 2 values"),
    ("H_format", lambda h: _enum_dataset(h, "H_format", capture_module.H_FORMATS, 9), "H_format is 9"),
    ("H_format", lambda h: _enum_dataset(h, "H_format", capture_module.H_FORMATS, 1),
     r"H of shape \(7, 3\) with H_format T_Sx_Sy is not a time x sensors capture"),
    ("H", np.ones(7), r"H of shape \(7,\) with H_format T_Si"),
    ("H", np.ones((0, 3)), r"H is empty \(shape \(0, 3\)\)"),
    ("H", np.where(np.eye(7, 3) > 0, np.nan, 1.0), "H holds 3 NaN or infinite"),
    ("H", np.ones((7, 3), dtype=bool), "H holds true/false values, not real numbers"),
    ("H", np.ones((7, 3), dtype=complex), "H holds complex numbers"),
    ("H", None, "no H dataset"),
    ("H", lambda h: h.create_group("H"), "H is a group, not a dataset"),
    ("H", h5py.Empty("f8"), "no H dataset"),
    ("t_start", None, "no time axis"),
    ("t_start", np.array([0.0, 1.0]), "t_start holds 2 values"),
    ("delta_t", 0.0, "delta_t is 0; expected one finite number > 0"),
    ("delta_t", np.nan, "delta_t holds 1 NaN or infinite"),
    ("delta_t", np.array([]), "delta_t holds 0 values"),
    ("t_accounts_first_and_last_bounces", 2,
     "t_accounts_first_and_last_bounces is 2; expected true or false"),
    ("t_accounts_first_and_last_bounces", "yes", "t_accounts_first_and_last_bounces holds text"),
    ("grid", _grid_capture, None),                                         # valid: the reference
    ("grid", lambda h: (_grid_capture(h), h.__delitem__("sensor_grid_xyz"),
                        h.__setitem__("sensor_grid_xyz", np.ones((3, 2, 3)))),
     "sensor_grid_xyz is a 3 x 2 grid for H's 2 x 3 sensors"),
]


@pytest.mark.parametrize("key, stored, words", _MALFORMED, ids=[f"{case[0]}-{i}" for i, case in
                                                                enumerate(_MALFORMED)])
def test_every_malformed_dataset_is_one_line_naming_it(tmp_path, rng, key, stored, words):
    path, _, _ = small_capture(tmp_path, rng)
    with h5py.File(path, "a") as handle:
        if key in handle:
            del handle[key]
        if callable(stored):
            if key == "grid":
                for name in ("H", "H_format", "sensor_grid_xyz", "sensor_grid_format"):
                    del handle[name]
            stored(handle)
        elif stored is not None:
            handle[key] = stored
    if words is None:
        assert read_capture(path).transient.shape == (6, 7)
        return
    with pytest.raises(CaptureError, match=words) as refused:
        read_capture(path)
    message = str(refused.value)
    assert "\n" not in message and message.startswith(str(path))




@needs_tal
def test_tal_reads_our_capture_back(tmp_path, rng):
    path, transient, sensors = small_capture(tmp_path, rng)
    seen = json.loads(run_tal(TAL_READ, path, tmp_path / "H.npy").splitlines()[-1])
    H = np.load(tmp_path / "H.npy")
    assert H.dtype == np.float64 and np.array_equal(H, transient.T)
    assert seen["t_start"] == 1.2345678901234567 and seen["delta_t"] == 0.1
    assert (seen["H_format"], seen["sensor_grid_format"], seen["laser_grid_format"]) == ("T_Si", "N_3", "N_3")
    assert np.array_equal(seen["sensor_grid_xyz"], sensors)
    assert seen["laser_xyz"] == [0.5, 0.5, 1.0] and seen["laser_grid_xyz"] == [[0.5, 0.5, 1.0]]
    assert seen["accounts"] is False and seen["confocal"] is False
    assert seen["scene_info"] == {"scene": "small", "start_opl": 1.2345678901234567}


_TAL_BACKPROJECT = r"""
import sys
import numpy as np, tal
from tal.enums import CameraSystem, VolumeFormat
data = tal.io.read_capture(sys.argv[1])
data.t_accounts_first_and_last_bounces = sys.argv[2] == "True"
pixels = int(sys.argv[3])
centres = (np.arange(pixels) + 0.5) / pixels
x, y = np.meshgrid(centres, 1.0 - centres)         # image row r lies at y = 1 - (r + 1/2) / M
volume = np.stack([x, y, np.zeros_like(x)], axis=-1)
image = tal.reconstruct.bp.solve(data, volume_xyz=volume, volume_format=VolumeFormat.X_Y_3,
                                 camera_system=CameraSystem.DIRECT_LIGHT, progress=False)
print(int(np.argmax(np.abs(np.asarray(image)))))
"""


@needs_tal
def test_tal_backprojection_focuses_on_the_bright_pixel(tmp_path):
    """Our path lengths are tal's d_2 + d_3 with the flag False (interop.tal.capture's docstring).

    A plane dark but for one pixel: tal's backprojection of our capture
    peaks on that pixel as written (flag False), and elsewhere when the
    flag is forced True (tal then adds |sensor - sensor_xyz| to every path).
    """
    pixels, bright = 16, (4, 11)
    image = np.zeros((pixels, pixels))
    image[bright] = 1.0
    scene = Scene(size=1.0, pixels=pixels, reflectance=image, source=(0.5, 0.5, 0.6),
                  sensors=sensor_grid((6, 6), 1.0, (0.5, 0.5, 0.4)),
                  sampling=Sampling(bin_width_opl=0.005, start_opl=0.7, count=200))
    path = write_capture(tmp_path / "transient.h5", forward(scene), start_opl=0.7, bin_width_opl=0.005,
                         source=scene.source, sensors=scene.sensors, scene_info={})
    peak = int(run_tal(_TAL_BACKPROJECT, path, False, pixels).split()[-1])
    assert np.unravel_index(peak, image.shape) == bright
    wrong = int(run_tal(_TAL_BACKPROJECT, path, True, pixels).split()[-1])
    assert np.unravel_index(wrong, image.shape) != bright


_TAL_WRITE = r"""
import sys
import numpy as np, tal
from tal.enums import GridFormat, HFormat
from tal.io.capture_data import NLOSCaptureData
H = np.load(sys.argv[2])
grid = np.load(sys.argv[3])
data = NLOSCaptureData()
data.H, data.H_format = H, HFormat.T_Sx_Sy
data.sensor_grid_xyz, data.sensor_grid_format = grid, GridFormat.X_Y_3
data.sensor_xyz = np.array([0.5, 0.5, 1.0])
data.laser_xyz = np.array([0.5, 0.5, 1.0])
data.laser_grid_xyz, data.laser_grid_format = np.array([[[0.5, 0.5, 1.0]]]), GridFormat.X_Y_3
data.delta_t, data.t_start, data.t_accounts_first_and_last_bounces = 0.05, 1.5, False
data.scene_info = {"written_by": "tal"}
tal.io.write_capture(sys.argv[1], data)
"""


@needs_tal
def test_a_capture_written_by_tal_is_read_with_sensors_matched_by_position(tmp_path):
    """tal's T_Sx_Sy grid is indexed [x index, y index]; read_capture lists x fastest, as the scene does."""
    scene = Scene(size=1.0, pixels=8, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=sensor_grid((3, 2), 0.6, (0.5, 0.5, 1.0)),
                  sampling=Sampling(bin_width_opl=0.05, start_opl=1.5, count=30))
    y = forward(scene)                                  # (6, 30), sensor k = j * 3 + i (x fastest)
    grid = scene.sensors.reshape(2, 3, 3).transpose(1, 0, 2)   # (Sx, Sy, 3)
    H = y.reshape(2, 3, 30).transpose(2, 1, 0)                 # (T, Sx, Sy)
    np.save(tmp_path / "H.npy", H)
    np.save(tmp_path / "grid.npy", grid)
    run_tal(_TAL_WRITE, tmp_path / "tal.hdf5", tmp_path / "H.npy", tmp_path / "grid.npy")
    read = read_capture(tmp_path / "tal.hdf5")
    assert read.transient.shape == (6, 30) and read.start_opl == 1.5 and read.bin_width_opl == 0.05
    assert read.scene_info == "written_by: tal\n"                 # tal's YAML, kept as text
    assert np.array_equal(read.sensors, scene.sensors)            # x fastest, as the scene lists them
    assert np.array_equal(read_data(tmp_path / "tal.hdf5", scene), y)


def test_data_reader_refuses_captures_of_another_scene(tmp_path, rng):
    scene = Scene(size=1.0, pixels=4, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=[(0.2, 0.7, 1.0), (0.8, 0.15, 0.5)],
                  sampling=Sampling(bin_width_opl=0.1, start_opl=1.0, count=7))
    y = rng.random((2, 7))
    kwargs = dict(bin_width_opl=0.1, source=scene.source, sensors=scene.sensors, scene_info={})
    write_capture(tmp_path / "ok.h5", y, start_opl=1.0, **kwargs)
    assert np.array_equal(read_data(tmp_path / "ok.h5", scene), y)
    write_capture(tmp_path / "late.h5", y, start_opl=1.05, **kwargs)
    with pytest.raises(DataError, match="time axis"):
        read_data(tmp_path / "late.h5", scene)
    write_capture(tmp_path / "moved.h5", y, start_opl=1.0, **(kwargs | {"sensors": scene.sensors + 0.01}))
    with pytest.raises(DataError, match="no sensor of sensor_grid_xyz"):
        read_data(tmp_path / "moved.h5", scene)
    write_capture(tmp_path / "source.h5", y, start_opl=1.0, **(kwargs | {"source": [0.4, 0.5, 1.0]}))
    with pytest.raises(DataError, match="laser_xyz"):
        read_data(tmp_path / "source.h5", scene)


@pytest.mark.parametrize("start, step", [(800, 97), (1000, 61), (3000, 211)])
def test_a_damaged_capture_is_one_capture_error(tmp_path, rng, start, step):
    """Bytes flipped inside the HDF5 objects: h5py's KeyError/RuntimeError on opening a dataset becomes
    one CaptureError naming the file, not a traceback."""
    path, _, _ = small_capture(tmp_path, rng)
    damaged = bytearray(path.read_bytes())
    for i in range(start, len(damaged), step):
        damaged[i] ^= 0xFF
    path.write_bytes(bytes(damaged))
    with pytest.raises(CaptureError, match=f"{path}: .*(damaged|cannot be read)"):
        read_capture(path)
