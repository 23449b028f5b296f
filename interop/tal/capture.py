"""Transients in tal's HDF5 capture layout (``transient.h5``), written and read with h5py.

tal (y-tal, the NLOS toolkit) keeps a capture in one HDF5 file whose
datasets are the attributes of ``tal.io.capture_data.NLOSCaptureData``; its
reader refuses any other key. What we write, for a scene with K sensors and
N bins (docs/design.md section 5):

=================================  ==================================================
``H``                              ``(N, K)`` float64 y_k[n], time first (``H_format`` T_Si)
``H_format``                       tal's ``HFormat`` enum, T_Si (3)
``sensor_grid_xyz``                ``(K, 3)`` sensor positions, metres (N_3 layout)
``sensor_grid_format``             tal's ``GridFormat`` enum, N_3 (1)
``laser_xyz``                      ``(3,)`` the source position, metres
``laser_grid_xyz``                 ``(1, 3)`` the source again: the one "illuminated point"
``laser_grid_format``              N_3 (1)
``delta_t``                        T = ``bin_width_opl``, metres of path length
``t_start``                        t0 = ``start_opl``, metres of path length
``t_accounts_first_and_last_bounces``  False (see below)
``scene_info``                     our metadata as JSON text (JSON is YAML, which tal parses)
``sensor_xyz``                     ``(3,)`` the sensors' centroid: tal's reconstructions
                                   reshape it whatever the flag, and ignore it while
                                   the flag is False (point sensors have no separate
                                   device origin)
``*_grid_normals``, ``volume_format``  empty (``h5py.Empty``), as tal writes an attribute
                                   that is None: omnidirectional points have no normal
=================================  ==================================================

Enums are stored as tal stores them: a ``(1,)`` dataset of an HDF5 enum type
(base int32) carrying every name of tal's enum.

Why ``t_accounts_first_and_last_bounces`` is False: tal's reconstructions
(``tal.reconstruct.bp``, ``pf_dev``) take a sample's path length to be
d_1 + d_2 + d_3 + d_4 with d_1 = |laser_xyz - laser_grid_xyz| and
d_4 = |sensor_grid_xyz - sensor_xyz| counted only when the flag is True.
Our path length is |p_s - x| + |x - p_k|: exactly d_2 + d_3 with the laser
grid point at the source and the sensor grid points at the sensors, and no
first or last leg. With the flag True tal would add |p_k - sensor_xyz|, a
different length per sensor that no single ``sensor_xyz`` can make zero.
The times are still measured from the source's emission (t = 0 when the
pulse leaves p_s), the same ``start_opl`` as every other output. Checked:
``tal.reconstruct.bp`` (DIRECT_LIGHT camera) on our capture of a plane with
one bright pixel focuses on that pixel with the flag False, and elsewhere
with it True (tests/interop/tal/test_capture.py).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analytic.errors import DataError
from analytic.values import exact

from analytic.files.atomic import atomic_write
from analytic.files.formats import json_default

__all__ = ["Capture", "CaptureError", "write_capture", "read_capture", "H_FORMATS", "GRID_FORMATS",
           "VOLUME_FORMATS", "ACCOUNTS_FIRST_AND_LAST_BOUNCES"]

# tal.enums (y-tal 0.20): name -> value, stored whole in each enum dataset's HDF5 type.
H_FORMATS = {"UNKNOWN": 0, "T_Sx_Sy": 1, "T_Lx_Ly_Sx_Sy": 2, "T_Si": 3, "T_Li_Si": 4}
GRID_FORMATS = {"UNKNOWN": 0, "N_3": 1, "X_Y_3": 2}
VOLUME_FORMATS = {"UNKNOWN": 0, "N_3": 1, "X_Y_Z_3": 2, "X_Y_3": 3}

#: Our path lengths run source -> plane -> sensor with the laser grid at the
#: source and the sensor grid at the sensors: no extra legs (module docstring).
ACCOUNTS_FIRST_AND_LAST_BOUNCES = False

# Every key tal's NLOSCaptureData accepts; read_capture refuses others.
_TAL_KEYS = ("H", "H_format", "sensor_xyz", "sensor_grid_xyz", "sensor_grid_normals", "sensor_grid_format",
             "laser_xyz", "laser_grid_xyz", "laser_grid_normals", "laser_grid_format", "volume_format",
             "delta_t", "t_start", "t_accounts_first_and_last_bounces", "scene_info")


class CaptureError(DataError):
    """An HDF5 file that is not a usable tal capture; the message names the file and the problem."""


@dataclass(frozen=True)
class Capture:
    """A transient read from a tal HDF5 capture, one column per (lit point, read point) pair.

    Columns are in the pair order of docs/design.md section 7, whatever the
    layout: laser points first, then read points, each grid with x fastest
    (grid cell (x index i, y index j) of an Sx x Sy grid is column j Sx + i);
    a plane capture (T_Si) keeps its sensors' order.

    Attributes
    ----------
    transient : numpy.ndarray
        ``(K, N)`` float64: column k's samples y_k[n].
    start_opl : float
        ``t_start``: lower edge of bin 0, metres of path length.
    bin_width_opl : float
        ``delta_t``: bin width, metres of path length.
    sensors : numpy.ndarray or None
        ``(K, 3)`` the read (sensor grid) point of each column, metres.
    source : numpy.ndarray or None
        ``(3,)`` ``laser_xyz``, metres.
    accounts_first_and_last_bounces : bool or None
        The file's ``t_accounts_first_and_last_bounces``.
    scene_info : Any
        The file's ``scene_info``: a dict when it is JSON, else its text.
    lasers : numpy.ndarray or None
        ``(K, 3)`` the lit (laser grid) point of each column, metres; None
        when the file has no ``laser_grid_xyz`` (or one that does not match H).
    laser_count : int
        Laser points in H's laser axes (1 for T_Si and for T_Sx_Sy, whose one
        laser axis is the scan itself when it is confocal).
    sensor_position : numpy.ndarray or None
        ``(3,)`` ``sensor_xyz``, metres.
    layout : str
        The ``H_format`` read (UNKNOWN resolved from H's rank).
    grid : tuple
        H's read-point axes: ``(Sx, Sy)`` for the grid layouts, ``(K,)`` else.
    """

    transient: np.ndarray
    start_opl: float
    bin_width_opl: float
    sensors: np.ndarray | None
    source: np.ndarray | None
    accounts_first_and_last_bounces: bool | None
    scene_info: Any
    lasers: np.ndarray | None = None
    laser_count: int = 1
    sensor_position: np.ndarray | None = None
    layout: str = "T_Si"
    grid: tuple = ()


def _enum(handle, key: str, names: dict[str, int], value: str) -> None:
    import h5py

    dataset = handle.create_dataset(key, (1,), dtype=h5py.enum_dtype(dict(names), basetype="i"))
    dataset[0] = names[value]


def write_capture(path: str | Path, transient, *, start_opl: float, bin_width_opl: float, source,
                  sensors, scene_info: dict) -> Path:
    """Write a transient as a tal HDF5 capture, atomically.

    Parameters
    ----------
    path : str or Path
        Destination (``transient.h5``); written to a temporary file in the
        same folder, re-opened and checked, then renamed.
    transient : array_like
        ``(K, N)`` samples y_k[n] (units of y); stored transposed as H (N, K).
    start_opl : float
        Lower edge t0 of bin 0, metres of path length (``t_start``).
    bin_width_opl : float
        Bin width T, metres of path length (``delta_t``).
    source : array_like
        ``(3,)`` source position, metres (``laser_xyz`` and ``laser_grid_xyz``).
    sensors : array_like
        ``(K, 3)`` sensor positions, metres (``sensor_grid_xyz``).
    scene_info : dict
        JSON-serialisable metadata, stored as JSON text (valid YAML, which
        is how tal reads ``scene_info``).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    ValueError
        Naming the argument whose shape or values are wrong.

    Notes
    -----
    Bin n of sensor k holds H[n, k] = y_k[n], the light whose path length
    |p_s - x| + |x - p_k| lies in [t_start + n delta_t, t_start + (n + 1) delta_t).
    """
    import h5py

    transient = np.asarray(transient, dtype=np.float64)
    if transient.ndim != 2:
        raise ValueError(f"transient: expected a (sensors, bins) array, got shape {transient.shape}")
    sensors = np.asarray(sensors, dtype=np.float64)
    if sensors.shape != (transient.shape[0], 3):
        raise ValueError(f"sensors: expected shape ({transient.shape[0]}, 3), got {sensors.shape}")
    source = np.asarray(source, dtype=np.float64)
    if source.shape != (3,):
        raise ValueError(f"source: expected shape (3,), got {source.shape}")
    start_opl, bin_width_opl = float(start_opl), float(bin_width_opl)
    if not np.isfinite(start_opl):
        raise ValueError(f"start_opl: must be finite, got {start_opl}")
    if not (np.isfinite(bin_width_opl) and bin_width_opl > 0):
        raise ValueError(f"bin_width_opl: must be finite and > 0, got {bin_width_opl}")
    info = json.dumps(scene_info, sort_keys=True, default=json_default)
    H = np.ascontiguousarray(transient.T)

    def write(temporary):
        with h5py.File(temporary, "w") as handle:
            handle["H"] = H
            _enum(handle, "H_format", H_FORMATS, "T_Si")
            # tal's reconstructions reshape sensor_xyz whatever the flag: give the
            # array's centroid (unused while t_accounts_first_and_last_bounces is False).
            handle["sensor_xyz"] = sensors.mean(axis=0)
            handle["sensor_grid_xyz"] = sensors
            handle["sensor_grid_normals"] = h5py.Empty("f8")
            _enum(handle, "sensor_grid_format", GRID_FORMATS, "N_3")
            handle["laser_xyz"] = source
            handle["laser_grid_xyz"] = source.reshape(1, 3)
            handle["laser_grid_normals"] = h5py.Empty("f8")
            _enum(handle, "laser_grid_format", GRID_FORMATS, "N_3")
            handle["volume_format"] = h5py.Empty("f8")
            handle["delta_t"] = bin_width_opl
            handle["t_start"] = start_opl
            handle["t_accounts_first_and_last_bounces"] = ACCOUNTS_FIRST_AND_LAST_BOUNCES
            handle["scene_info"] = info
            handle.flush()

    def verify(temporary):
        with h5py.File(temporary, "r") as handle:
            keys = set(handle.keys())
            if keys != set(_TAL_KEYS):
                raise OSError(f"{path}: written keys {sorted(keys)} differ from tal's")
            if handle["H"].shape != H.shape or handle["H"].dtype != np.float64:
                raise OSError(f"{path}: H reads back as {handle['H'].shape} {handle['H'].dtype}")
            if float(handle["t_start"][()]) != start_opl or float(handle["delta_t"][()]) != bin_width_opl:
                raise OSError(f"{path}: the time axis does not read back")
    return atomic_write(path, write, verify)


# What each dataset read_capture uses must hold, for its messages.
_EXPECTED = {
    "H": "a real-valued array, time first, in the layout H_format names",
    "H_format": f"one of tal's HFormat values ({', '.join(f'{v} {k}' for k, v in H_FORMATS.items())})",
    "sensor_grid_format": f"one of tal's GridFormat values "
                          f"({', '.join(f'{v} {k}' for k, v in GRID_FORMATS.items())})",
    "sensor_grid_xyz": "the sensor points in metres, (sensors, 3) in N_3 or (Sx, Sy, 3) in X_Y_3",
    "laser_xyz": "3 numbers, the laser's (the source's) position in metres",
    "sensor_xyz": "3 numbers, the sensor's position in metres",
    "laser_grid_format": f"one of tal's GridFormat values "
                         f"({', '.join(f'{v} {k}' for k, v in GRID_FORMATS.items())})",
    "laser_grid_xyz": "the lit points in metres, (points, 3) in N_3 or (Lx, Ly, 3) in X_Y_3",
    "t_start": "one finite number, the lower edge of bin 0 in metres of path length",
    "delta_t": "one finite number > 0, the bin width in metres of path length",
    "t_accounts_first_and_last_bounces": "true or false",
}

# H's rank in each layout tal names; UNKNOWN is read from the rank.
_H_RANK = {"T_Si": 2, "T_Sx_Sy": 3, "T_Lx_Ly_Sx_Sy": 5, "T_Li_Si": 3}


def _refuse(name: str, key: str, problem: str) -> CaptureError:
    return CaptureError(f"{name}: {key} {problem}; expected {_EXPECTED.get(key, 'what tal writes')}")


def _read(handle, name: str, key: str):
    """A dataset's value as a NumPy array, or None when absent or empty (tal's None)."""
    import h5py

    try:
        if key not in handle:
            return None
        item = handle[key]
    except Exception as error:   # a damaged file: h5py raises KeyError, OSError, RuntimeError for its objects
        raise CaptureError(f"{name}: {key} cannot be opened ({type(error).__name__}: {error}); the file is "
                           f"damaged: copy or write it again") from None
    if not isinstance(item, h5py.Dataset):
        raise _refuse(name, key, f"is a {type(item).__name__.lower()}, not a dataset")
    try:
        value = item[()]
    except Exception as error:   # h5py raises several types for data it cannot convert
        raise _refuse(name, key, f"cannot be read ({type(error).__name__}: {error})") from None
    if isinstance(value, h5py.Empty):
        return None
    return np.asarray(value)


def _kind(dtype: np.dtype) -> str:
    """What a dtype that is no real number holds, in words."""
    return {"S": "text", "U": "text", "O": "text or objects", "b": "true/false values",
            "c": "complex numbers", "V": "compound records"}.get(dtype.kind, f"{dtype} values")


def _real(value: np.ndarray, name: str, key: str) -> np.ndarray:
    """``value`` as finite float64 numbers, refusing text, booleans, complex numbers, NaN and infinity."""
    if value.dtype == bool or not (np.issubdtype(value.dtype, np.floating)
                                   or np.issubdtype(value.dtype, np.integer)):
        raise _refuse(name, key, f"holds {_kind(value.dtype)}, not real numbers")
    if value.size == 0:
        raise _refuse(name, key, f"is empty (shape {value.shape})")
    value = value.astype(np.float64)
    bad = int(np.count_nonzero(~np.isfinite(value)))
    if bad:
        raise _refuse(name, key, f"holds {bad} NaN or infinite value(s)")
    return value


def _number(value: np.ndarray, name: str, key: str) -> float:
    if value.size != 1:
        raise _refuse(name, key, f"holds {value.size} values (shape {value.shape})")
    return float(_real(value, name, key).reshape(-1)[0])


def _enum_name(value: np.ndarray | None, name: str, key: str, names: dict[str, int]) -> str:
    """The name of an enum stored as tal stores it (or as a plain integer); UNKNOWN when absent."""
    if value is None:
        return "UNKNOWN"
    code = _number(value, name, key)
    by_value = {number: label for label, number in names.items()}
    if code != int(code) or int(code) not in by_value:
        raise _refuse(name, key, f"is {exact(code)}, not one of its values")
    return by_value[int(code)]


def _flag(value: np.ndarray | None, name: str, key: str) -> bool | None:
    if value is None:
        return None
    number = _number(value.astype(np.int8) if value.dtype == bool else value, name, key)
    if number not in (0.0, 1.0):
        raise _refuse(name, key, f"is {exact(number)}")
    return bool(number)


def _transient(H: np.ndarray | None, layout: str, name: str) -> tuple[np.ndarray, str]:
    """H as ``(K, N)`` columns in pair order, and its layout (UNKNOWN resolved from H's rank)."""
    if H is None:
        raise CaptureError(f"{name}: no H dataset (not a tal capture)")
    if H.dtype == bool or not (np.issubdtype(H.dtype, np.floating) or np.issubdtype(H.dtype, np.integer)):
        raise CaptureError(f"{name}: H holds {_kind(H.dtype)}, not real numbers; expected {_EXPECTED['H']}")
    if layout == "UNKNOWN":
        layout = {2: "T_Si", 3: "T_Sx_Sy", 5: "T_Lx_Ly_Sx_Sy"}.get(H.ndim, "UNKNOWN")
    if layout not in _H_RANK or H.ndim != _H_RANK[layout]:
        raise CaptureError(f"{name}: H of shape {H.shape} with H_format {layout} is not a time x sensors "
                           f"capture; expected rank {_H_RANK.get(layout, '2 (T_Si), 3 (T_Sx_Sy) or 5 (T_Lx_Ly_Sx_Sy)')}")
    if H.size == 0:
        raise CaptureError(f"{name}: H is empty (shape {H.shape}); expected at least one bin and one sensor")
    H = _real(H, name, "H")
    # grids to x fastest: (T, Sx, Sy) -> (T, Sy, Sx), (T, Lx, Ly, Sx, Sy) -> (T, Ly, Lx, Sy, Sx)
    if layout == "T_Sx_Sy":
        H = H.transpose(0, 2, 1)
    elif layout == "T_Lx_Ly_Sx_Sy":
        H = H.transpose(0, 2, 1, 4, 3)
    return np.ascontiguousarray(H.reshape(H.shape[0], -1).T), layout


def _axes(H_shape: tuple[int, ...], layout: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """H's (laser axes, read-point axes): ((Lx, Ly), (Sx, Sy)), ((L,), (K,)), ((), (Sx, Sy)) or ((), (K,))."""
    if layout == "T_Lx_Ly_Sx_Sy":
        return tuple(H_shape[1:3]), tuple(H_shape[3:])
    if layout == "T_Li_Si":
        return tuple(H_shape[1:2]), tuple(H_shape[2:])
    return (), tuple(H_shape[1:])


def _points(grid: np.ndarray | None, grid_format: str, axes: tuple[int, ...], name: str,
            key: str) -> np.ndarray | None:
    """A grid of points ``(n, 3)`` in pair order (x fastest), checked against the H axes it belongs to."""
    if grid is None:
        return None
    grid = _real(grid, name, key)
    if grid_format == "UNKNOWN":
        grid_format = {2: "N_3", 3: "X_Y_3"}.get(grid.ndim, "UNKNOWN")
    rank = {"N_3": 2, "X_Y_3": 3}.get(grid_format)
    if rank is None or grid.ndim != rank or grid.shape[-1] != 3:
        raise _refuse(name, key, f"has shape {grid.shape} ({key.replace('_xyz', '_format')} {grid_format})")
    count = int(np.prod(axes))
    if grid_format == "X_Y_3" and len(axes) == 2 and grid.shape[:2] != axes:
        what = "sensors" if key.startswith("sensor") else "lit points"
        raise _refuse(name, key, f"is a {grid.shape[0]} x {grid.shape[1]} grid for H's {axes[0]} x {axes[1]} "
                                 f"{what}")
    points = grid.reshape(-1, 3)
    if len(points) != count:
        what = "sensors" if key.startswith("sensor") else "lit points"
        raise _refuse(name, key, f"holds {len(points)} points for {count} {what} in H")
    if len(axes) == 2:      # (Sx, Sy) flattened row-major: x index slowest -> x fastest
        points = points.reshape(axes[0], axes[1], 3).transpose(1, 0, 2).reshape(-1, 3)
    return points


def _lasers(grid: np.ndarray | None, grid_format: str, laser_axes: tuple[int, ...], read: tuple[int, ...],
            name: str) -> np.ndarray | None:
    """The lit point of every column, ``(L R, 3)``, or None when the file states none that fits."""
    if grid is None:
        return None
    key = "laser_grid_xyz"
    if laser_axes:                                        # one lit point per laser axis entry
        points = _points(grid, grid_format, laser_axes, name, key)
        return np.repeat(points, int(np.prod(read)), axis=0)
    values = _real(grid, name, key)
    if values.size == 3:                                  # one lit point (a single scan, or the source)
        return np.repeat(values.reshape(1, 3), int(np.prod(read)), axis=0)
    # a confocal scan: the laser grid lights each read point in turn
    return _points(grid, grid_format, read, name, key)


def _vector3(value: np.ndarray | None, name: str, key: str) -> np.ndarray | None:
    if value is None:
        return None
    vector = _real(value, name, key)
    if vector.size != 3:
        raise _refuse(name, key, f"holds {vector.size} number(s)")
    return vector.reshape(3)


def read_capture(path: str | Path) -> Capture:
    """Read a transient from a tal HDF5 capture (ours or tal's own).

    Parameters
    ----------
    path : str or Path
        The ``.h5`` / ``.hdf5`` file.

    Returns
    -------
    Capture
        H as ``(K, N)`` float64 columns in pair order, with its time axis and
        each column's read and lit points.

    Raises
    ------
    FileNotFoundError
        No such file.
    CaptureError
        One line naming the file, the dataset and what it must hold: not
        HDF5; no H, or H not finite real numbers, empty or of the wrong rank
        for its H_format; an H_format or grid format that is not one of
        tal's values; a missing or non-finite time axis; a sensor_grid_xyz
        or laser_grid_xyz that does not match H's axes; a laser_xyz or
        sensor_xyz that is not 3 finite numbers; a
        t_accounts_first_and_last_bounces that is not true or false.

    Notes
    -----
    Accepted ``H_format``: T_Si ``(N, K)``; T_Li_Si ``(N, L, K)``; T_Sx_Sy
    ``(N, Sx, Sy)`` (a single scan when ``laser_grid_xyz`` is one point, a
    confocal one when it is the sensor grid); T_Lx_Ly_Sx_Sy
    ``(N, Lx, Ly, Sx, Sy)``. Grids are flattened x fastest (cell (i, j) is
    j Sx + i, tal's X_Y_3 grids indexed [i, j]), laser points before read
    points: docs/design.md section 7's pair order. A missing or UNKNOWN
    format is taken from H's rank (2: T_Si, 3: T_Sx_Sy, 5: T_Lx_Ly_Sx_Sy),
    and a missing grid format from the grid's (2: N_3, 3: X_Y_3). Normals
    and the volume format are not read.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no capture file at {path}")
    name = str(path)
    try:
        handle = h5py.File(path, "r")
    except OSError as error:
        raise CaptureError(f"{name}: not a readable HDF5 file ({error})") from None
    with handle:
        values = {key: _read(handle, name, key) for key in _EXPECTED}
        info = _read(handle, name, "scene_info") if "scene_info" in handle else None
    H = values["H"]
    transient, layout = _transient(H, _enum_name(values["H_format"], name, "H_format", H_FORMATS), name)
    start, width = values["t_start"], values["delta_t"]
    if start is None or width is None:
        raise CaptureError(f"{name}: no time axis (t_start and delta_t, one number each, are needed)")
    start, width = _number(start, name, "t_start"), _number(width, name, "delta_t")
    if not width > 0:
        raise _refuse(name, "delta_t", f"is {exact(width)}")
    laser_axes, read_axes = _axes(H.shape, layout)
    grid_format = _enum_name(values["sensor_grid_format"], name, "sensor_grid_format", GRID_FORMATS)
    read = _points(values["sensor_grid_xyz"], grid_format, read_axes, name, "sensor_grid_xyz")
    laser_count = int(np.prod(laser_axes))
    sensors = None if read is None else np.tile(read, (laser_count, 1))
    lasers = _lasers(values["laser_grid_xyz"],
                     _enum_name(values["laser_grid_format"], name, "laser_grid_format", GRID_FORMATS),
                     laser_axes, read_axes, name)
    accounts = _flag(values["t_accounts_first_and_last_bounces"], name, "t_accounts_first_and_last_bounces")
    return Capture(transient=transient, start_opl=start, bin_width_opl=width, sensors=sensors,
                   source=_vector3(values["laser_xyz"], name, "laser_xyz"),
                   accounts_first_and_last_bounces=accounts, scene_info=_scene_info(info), lasers=lasers,
                   laser_count=laser_count, sensor_position=_vector3(values["sensor_xyz"], name, "sensor_xyz"),
                   layout=layout, grid=read_axes)


def _scene_info(info):
    """tal's ``scene_info``: JSON (ours) as a dict, other text (tal's YAML) as text, anything else as is."""
    if info is None:
        return None
    if info.shape == () and info.dtype == object:
        info = info.item()
    elif info.shape == () and info.dtype.kind in "SU":
        info = info.item()
    else:
        return info.tolist()
    if isinstance(info, bytes):
        info = info.decode("utf-8", errors="replace")
    if isinstance(info, str):
        try:
            return json.loads(info)
        except json.JSONDecodeError:
            return info   # tal's own files hold YAML; kept as text
    return info
