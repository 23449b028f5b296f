"""A relay-wall (NLOS) transient as a tal capture: ``transient.h5`` in the layout ``tal render`` writes.

tal keeps an NLOS capture in one HDF5 file (:mod:`interop.tal.capture`
reads it). For a relay-wall scene with a W x H scan grid (docs/design.md
section 7) we write what ``tal render`` writes for the same scan
(y-tal 0.20, ``tal/render/render.py`` and ``util.get_grid_xyz``):

==================================  ===============================================================
``H``                               float64 y; ``(N, W, H)`` for single and confocal scans
                                    (H_format T_Sx_Sy), ``(N, Lx, Ly, W, H)`` for exhaustive ones
                                    (T_Lx_Ly_Sx_Sy): time first, then x index, then y index
``sensor_grid_xyz``                 ``(W, H, 3)`` the read points s, ``[i, j]`` the cell centre
                                    ((2i+1)/W - 1, (2j+1)/H - 1, 0) x the wall's half sizes (X_Y_3)
``laser_grid_xyz``                  the lit points l: ``(1, 1, 3)`` for a single scan, the sensor
                                    grid for a confocal one, ``(Lx, Ly, 3)`` for an exhaustive one
``*_grid_normals``                  the wall's normal (0, 0, 1) at every grid point
``sensor_xyz``, ``laser_xyz``       o_s and o_l, metres
``delta_t``, ``t_start``            ``bin_width_opl`` and ``start_opl``, metres of path length
``t_accounts_first_and_last_bounces``  the scan's ``account_first_and_last_bounces``: path lengths
                                    count |o_l - l| + |s - o_s| exactly when it is true, as tal's
                                    reconstructions expect
``scene_info``                      our metadata as JSON text (JSON is YAML, which tal parses)
``volume_format``                   empty (tal's None)
==================================  ===============================================================

Pair p of our ``(P, N)`` transient (laser-major, each grid row-major with
x fastest: p = j W + i) is ``H[:, i, j]`` (single, confocal) or
``H[:, li, lj, i, j]`` for lit point lj Lx + li (exhaustive).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from analytic.scenes.relay_wall import WALL_NORMAL, RelayWallScene

from analytic.files.atomic import atomic_write
from .capture import GRID_FORMATS, H_FORMATS, _TAL_KEYS, _enum, read_capture
from analytic.files.formats import json_default

__all__ = ["write_relay_wall_capture", "relay_wall_layout"]


def _x_y_3(points: np.ndarray, grid) -> np.ndarray:
    """``(W H, 3)`` points in pair order (x fastest) as tal's X_Y_3 grid ``(W, H, 3)``."""
    width, height = int(grid[0]), int(grid[1])
    return np.ascontiguousarray(points.reshape(height, width, 3).transpose(1, 0, 2))


def relay_wall_layout(transient, scene: RelayWallScene) -> dict:
    """tal's datasets (but ``scene_info``) for a relay-wall scene's ``(P, N)`` transient.

    Parameters
    ----------
    transient : array_like
        ``(P, N)`` y in the scene's pair order (docs/design.md section 7).
    scene : RelayWallScene
        The capture's scene: its scan, wall, laser and sensor.

    Returns
    -------
    dict
        Dataset name -> value (enum datasets by name: ``H_format``,
        ``sensor_grid_format``, ``laser_grid_format``).

    Raises
    ------
    ValueError
        A transient whose shape is not the scene's pairs x bins.
    """
    transient = np.asarray(transient, dtype=np.float64)
    pairs, bins = scene.sensor_count, scene.sampling.count
    if transient.shape != (pairs, bins):
        raise ValueError(f"transient: expected the scene's ({pairs}, {bins}) pairs x bins, got shape "
                         f"{transient.shape}")
    scan = scene.scan
    width, height = scan.grid
    read = _x_y_3(scene.read_points, scan.grid)
    if scan.type == "exhaustive":
        lasers = scan.laser_grid or scan.grid
        # (Ly, Lx, H, W, N) -> (N, Lx, Ly, W, H)
        H = transient.reshape(lasers[1], lasers[0], height, width, bins).transpose(4, 1, 0, 3, 2)
        lit, layout = _x_y_3(scene.laser_points, lasers), "T_Lx_Ly_Sx_Sy"
    else:
        H = transient.reshape(height, width, bins).transpose(2, 1, 0)          # (N, W, H)
        lit = read.copy() if scan.type == "confocal" else scene.laser_points.reshape(1, 1, 3)
        layout = "T_Sx_Sy"
    return {"H": np.ascontiguousarray(H), "H_format": layout, "sensor_xyz": np.array(scene.sensor_position),
            "sensor_grid_xyz": read, "sensor_grid_normals": np.broadcast_to(WALL_NORMAL, read.shape).copy(),
            "sensor_grid_format": "X_Y_3", "laser_xyz": np.array(scene.laser_position), "laser_grid_xyz": lit,
            "laser_grid_normals": np.broadcast_to(WALL_NORMAL, lit.shape).copy(), "laser_grid_format": "X_Y_3",
            "delta_t": float(scene.sampling.bin_width_opl), "t_start": float(scene.sampling.start_opl),
            "t_accounts_first_and_last_bounces": bool(scan.account_first_and_last_bounces)}


def write_relay_wall_capture(path: str | Path, transient, scene: RelayWallScene, *, scene_info: dict) -> Path:
    """Write a relay-wall transient as a tal NLOS capture, atomically; checked by reading it back.

    Parameters
    ----------
    path : str or Path
        Destination (``transient.h5``); written to a temporary file in the
        same folder, read back with :func:`interop.tal.read_capture` and
        compared (every sample, every read and lit point, the time axis and
        the flag), then renamed.
    transient : array_like
        ``(P, N)`` y in the scene's pair order, units of y (the radiance
        leaving s toward the sensor, integrated over each bin).
    scene : RelayWallScene
        The capture's scene.
    scene_info : dict
        JSON-serialisable metadata (``meta.json``'s record), stored as JSON text.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    ValueError
        A transient that is not the scene's pairs x bins, or not finite.

    Notes
    -----
    Bin n of pair (l, s) holds the light whose path length
    |l - x| + |x - s| (+ |o_l - l| + |s - o_s| when
    ``t_accounts_first_and_last_bounces``) lies in
    [t_start + n delta_t, t_start + (n + 1) delta_t): the same numbers
    as ``transient.npy``, in the layout of the module docstring.
    """
    import h5py

    datasets = relay_wall_layout(transient, scene)
    if not np.all(np.isfinite(datasets["H"])):
        raise ValueError("transient: holds NaN or infinite values")
    info = json.dumps(scene_info, sort_keys=True, default=json_default)
    expected = np.asarray(transient, dtype=np.float64)
    lit, read = scene.pair_points

    def write(temporary):
        with h5py.File(temporary, "w") as handle:
            for key, value in datasets.items():
                if key == "H_format":
                    _enum(handle, key, H_FORMATS, value)
                elif key.endswith("_format"):
                    _enum(handle, key, GRID_FORMATS, value)
                else:
                    handle[key] = value
            handle["volume_format"] = h5py.Empty("f8")
            handle["scene_info"] = info
            handle.flush()

    def verify(temporary):
        with h5py.File(temporary, "r") as handle:
            if set(handle.keys()) != set(_TAL_KEYS):
                raise OSError(f"{path}: written keys {sorted(handle.keys())} differ from tal's")
        back = read_capture(temporary)
        if not (np.array_equal(back.transient, expected) and np.array_equal(back.sensors, read)
                and np.array_equal(back.lasers, lit)):
            raise OSError(f"{path}: the capture does not read back as the transient and scan written")
        if (back.start_opl, back.bin_width_opl) != (datasets["t_start"], datasets["delta_t"]) or \
                back.accounts_first_and_last_bounces != datasets["t_accounts_first_and_last_bounces"]:
            raise OSError(f"{path}: the time axis does not read back")
    return atomic_write(path, write, verify)
