"""A relay-wall transient as tal's NLOS capture (interop.tal.relay_wall_capture), read back by tal itself.

The independent references: tal's own reader (``tal.io.read_capture``, in
``.venv-tal``: tal pins numpy < 2) for our files, tal's own writer and grid
(``tal.io.write_capture``, ``tal.render.util.get_grid_xyz``) for our
reader, and the grid formula of docs/design.md section 7 written out here.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from tal_env import TAL_READ, needs_tal, run_tal

from analytic.errors import DataError
from interop.tal import read_capture, write_relay_wall_capture
from interop.tal import relay_wall_capture as module
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Sampling
from validation.check import read_data

SCANS = {
    "single": Scan(type="single", grid=(3, 2), laser_point=(0.3, -0.2, 0.0)),
    "confocal": Scan(type="confocal", grid=(3, 2)),
    "exhaustive": Scan(type="exhaustive", grid=(3, 2), laser_grid=(2, 4), account_first_and_last_bounces=True),
}


def scene_of(scan: Scan) -> RelayWallScene:
    return RelayWallScene(wall_size=(2.0, 1.5), pixels=4, scan=scan, laser_position=(-0.5, 0.1, 0.25),
                          sensor_position=(-0.4, 0.0, 0.3),
                          sampling=Sampling(bin_width_opl=0.01, start_opl=1.9, count=7))


def cell(i: int, j: int, grid, size) -> list[float]:
    """Grid cell (i, j)'s centre, written out from docs/design.md section 7."""
    return [((2 * i + 1) / grid[0] - 1) * size[0] / 2, ((2 * j + 1) / grid[1] - 1) * size[1] / 2, 0.0]


@pytest.mark.parametrize("kind", list(SCANS))
def test_round_trip_and_layout(tmp_path, rng, kind):
    scene = scene_of(SCANS[kind])
    y = rng.random((scene.sensor_count, 7))
    path = write_relay_wall_capture(tmp_path / "transient.h5", y, scene, scene_info={"scene": kind})
    capture = read_capture(path)
    lit, read = scene.pair_points
    assert np.array_equal(capture.transient, y) and np.array_equal(capture.sensors, read)
    assert np.array_equal(capture.lasers, lit)
    assert capture.accounts_first_and_last_bounces is (kind == "exhaustive")
    assert np.array_equal(capture.source, scene.laser_position)
    assert np.array_equal(capture.sensor_position, scene.sensor_position)
    with h5py.File(path, "r") as handle:
        H, grid = handle["H"][()], handle["sensor_grid_xyz"][()]
        layout = h5py.check_enum_dtype(handle["H_format"].dtype)
        code = int(handle["H_format"][0])
    assert grid.shape == (3, 2, 3)
    for i in range(3):
        for j in range(2):
            assert np.array_equal(grid[i, j], cell(i, j, (3, 2), (2.0, 1.5)))
    if kind == "exhaustive":
        assert code == layout["T_Lx_Ly_Sx_Sy"] and H.shape == (7, 2, 4, 3, 2)
        # pair p = (lit index lj Lx + li) (W H) + (j W + i)
        assert np.array_equal(H[:, 1, 3, 2, 0], y[(3 * 2 + 1) * 6 + 0 * 3 + 2])
    else:
        assert code == layout["T_Sx_Sy"] and H.shape == (7, 3, 2)
        assert np.array_equal(H[:, 2, 1], y[1 * 3 + 2]) and np.array_equal(H[:, 0, 1], y[3])


def test_wrong_transient_is_refused_before_writing(tmp_path):
    scene = scene_of(SCANS["single"])
    with pytest.raises(ValueError, match=r"transient: expected the scene's \(6, 7\)"):
        write_relay_wall_capture(tmp_path / "t.h5", np.ones((7, 6)), scene, scene_info={})
    with pytest.raises(ValueError, match="NaN"):
        write_relay_wall_capture(tmp_path / "t.h5", np.full((6, 7), np.nan), scene, scene_info={})
    assert not any(tmp_path.iterdir())


def test_a_file_that_does_not_read_back_is_not_renamed(tmp_path, monkeypatch, rng):
    scene = scene_of(SCANS["confocal"])
    original = module.read_capture

    def shuffled(path):
        capture = original(path)
        return type(capture)(**(capture.__dict__ | {"transient": capture.transient[::-1]}))
    monkeypatch.setattr(module, "read_capture", shuffled)
    with pytest.raises(Exception, match="does not read back"):
        write_relay_wall_capture(tmp_path / "t.h5", rng.random((6, 7)), scene, scene_info={})
    assert not any(tmp_path.iterdir())




@needs_tal
@pytest.mark.parametrize("kind", list(SCANS))
def test_tal_reads_our_capture_of_each_scan(tmp_path, rng, kind):
    scene = scene_of(SCANS[kind])
    y = rng.random((scene.sensor_count, 7))
    path = write_relay_wall_capture(tmp_path / "transient.h5", y, scene, scene_info={"scene": kind})
    seen = json.loads(run_tal(TAL_READ, path, tmp_path / "H.npy").splitlines()[-1])
    H = np.load(tmp_path / "H.npy")
    grid = np.array(seen["sensor_grid_xyz"])
    assert grid.shape == (3, 2, 3) and seen["sensor_grid_format"] == "X_Y_3"
    assert all(np.array_equal(grid[i, j], cell(i, j, (3, 2), (2.0, 1.5))) for i in range(3) for j in range(2))
    assert np.array_equal(seen["sensor_grid_normals"], np.broadcast_to([0.0, 0.0, 1.0], (3, 2, 3)))
    assert seen["laser_xyz"] == [-0.5, 0.1, 0.25] and seen["sensor_xyz"] == [-0.4, 0.0, 0.3]
    assert seen["t_start"] == 1.9 and seen["delta_t"] == 0.01 and seen["scene_info"] == {"scene": kind}
    assert seen["accounts"] is (kind == "exhaustive")
    lasers = np.array(seen["laser_grid_xyz"])
    if kind == "exhaustive":
        assert seen["H_format"] == "T_Lx_Ly_Sx_Sy" and H.shape == (7, 2, 4, 3, 2) and not seen["confocal"]
        assert all(np.array_equal(lasers[i, j], cell(i, j, (2, 4), (2.0, 1.5))) for i in range(2) for j in range(4))
        for li, lj, i, j in [(0, 0, 0, 0), (1, 2, 2, 1), (0, 3, 1, 0)]:
            assert np.array_equal(H[:, li, lj, i, j], y[(lj * 2 + li) * 6 + j * 3 + i])
    else:
        assert seen["H_format"] == "T_Sx_Sy" and H.shape == (7, 3, 2)
        assert seen["confocal"] is (kind == "confocal")
        expected = grid if kind == "confocal" else [[[0.3, -0.2, 0.0]]]
        assert np.array_equal(lasers, expected)
        for i in range(3):
            for j in range(2):
                assert np.array_equal(H[:, i, j], y[j * 3 + i])


_TAL_WRITE = r"""
import sys
import numpy as np, tal
from tal.enums import GridFormat, HFormat
from tal.io.capture_data import NLOSCaptureData
from tal.render.util import get_grid_xyz
H = np.load(sys.argv[2]).astype(np.float32)
data = NLOSCaptureData()
data.H = H
data.H_format = HFormat.T_Sx_Sy if H.ndim == 3 else HFormat.T_Lx_Ly_Sx_Sy
data.sensor_grid_xyz, data.sensor_grid_format = get_grid_xyz(H.shape[-2], H.shape[-1], 1.0, 0.75), GridFormat.X_Y_3
if H.ndim == 3:
    data.laser_grid_xyz = np.array([[[0.3, -0.2, 0.0]]], dtype=np.float32)
else:
    data.laser_grid_xyz = get_grid_xyz(H.shape[1], H.shape[2], 1.0, 0.75)
data.laser_grid_format = GridFormat.X_Y_3
data.sensor_xyz = np.array([-0.4, 0.0, 0.3], dtype=np.float32)
data.laser_xyz = np.array([-0.5, 0.1, 0.25], dtype=np.float32)
data.delta_t, data.t_start = 0.01, 1.9
data.t_accounts_first_and_last_bounces = H.ndim == 5
data.scene_info = {"written_by": "tal"}
tal.io.write_capture(sys.argv[1], data)
"""


@needs_tal
@pytest.mark.parametrize("kind", ["single", "exhaustive"])
def test_a_capture_written_by_tal_is_read_in_the_scenes_pair_order(tmp_path, rng, kind):
    """tal's own writer and grid (float32, as ``tal render`` writes); columns matched to pairs by their points."""
    scene = scene_of(SCANS[kind])
    y = rng.random((scene.sensor_count, 7)).astype(np.float32).astype(np.float64)
    if kind == "single":
        H = np.stack([[y[j * 3 + i] for j in range(2)] for i in range(3)]).transpose(2, 0, 1)
    else:
        H = np.empty((7, 2, 4, 3, 2))
        for li in range(2):
            for lj in range(4):
                for i in range(3):
                    for j in range(2):
                        H[:, li, lj, i, j] = y[(lj * 2 + li) * 6 + j * 3 + i]
    np.save(tmp_path / "H.npy", H)
    run_tal(_TAL_WRITE, tmp_path / "tal.hdf5", tmp_path / "H.npy")
    assert np.array_equal(read_data(tmp_path / "tal.hdf5", scene), y)
    # the same file against scenes it does not belong to: one line naming what differs
    other = scene.replace(scan=Scan(**(SCANS[kind].__dict__ | {"grid": (2, 3)})))
    with pytest.raises(DataError, match="its grids differ from the scene's"):
        read_data(tmp_path / "tal.hdf5", other)
    flipped = scene.replace(scan=Scan(**(SCANS[kind].__dict__ | {
        "account_first_and_last_bounces": not SCANS[kind].account_first_and_last_bounces})))
    with pytest.raises(DataError, match="t_accounts_first_and_last_bounces is"):
        read_data(tmp_path / "tal.hdf5", flipped)
    moved = scene.replace(laser_position=(-0.5, 0.2, 0.25))
    with pytest.raises(DataError, match="laser_xyz .* is not the scene's laser.position"):
        read_data(tmp_path / "tal.hdf5", moved)
