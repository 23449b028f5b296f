"""Transients in tal's HDF5 capture layout (``transient.h5``), written and read with h5py.

tal (y-tal, the NLOS toolkit) keeps a capture in one HDF5 file whose
datasets are the attributes of ``tal.io.capture_data.NLOSCaptureData``; its
reader refuses any other key. What we write, for a scene with K sensors and
N bins (DESIGN.md section 5):

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
with it True (tests/test_capture.py).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import DataError
from .io import _json_default, atomic_write

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
    """A transient read from a tal HDF5 capture.

    Attributes
    ----------
    transient : numpy.ndarray
        ``(K, N)`` float64 y_k[n], sensors in the file's order (T_Sx_Sy
        grids flattened row-major, as ``sensor_grid_xyz.reshape(-1, 3)``).
    start_opl : float
        ``t_start``: lower edge of bin 0, metres of path length.
    bin_width_opl : float
        ``delta_t``: bin width, metres of path length.
    sensors : numpy.ndarray or None
        ``(K, 3)`` sensor grid positions, metres, in the order of ``transient``.
    source : numpy.ndarray or None
        ``(3,)`` ``laser_xyz``, metres.
    accounts_first_and_last_bounces : bool or None
        The file's ``t_accounts_first_and_last_bounces``.
    scene_info : Any
        The file's ``scene_info``: a dict when it is JSON, else its text.
    """

    transient: np.ndarray
    start_opl: float
    bin_width_opl: float
    sensors: np.ndarray | None
    source: np.ndarray | None
    accounts_first_and_last_bounces: bool | None
    scene_info: Any


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
    info = json.dumps(scene_info, sort_keys=True, default=_json_default)
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


def _value(handle, key: str):
    """A dataset's value, None when absent or empty (tal's None)."""
    import h5py

    if key not in handle:
        return None
    value = handle[key][()]
    if isinstance(value, h5py.Empty):
        return None
    return value


def _scalar(value):
    """A real number stored as a scalar or a one-element array; None when absent or anything else."""
    if value is None:
        return None
    array = np.asarray(value)
    if array.size != 1 or not (np.issubdtype(array.dtype, np.number) or array.dtype == bool) \
            or np.iscomplexobj(array):
        return None
    return array.reshape(-1)[0].item()


def read_capture(path: str | Path) -> Capture:
    """Read a transient from a tal HDF5 capture (ours or tal's own).

    Parameters
    ----------
    path : str or Path
        The ``.h5`` / ``.hdf5`` file.

    Returns
    -------
    Capture
        H as ``(K, N)`` float64 with its time axis and sensor positions.

    Raises
    ------
    FileNotFoundError
        No such file.
    CaptureError
        Not HDF5, no H, an H layout with several laser points, or a missing
        time axis; the message names the file and the problem.

    Notes
    -----
    Accepted ``H_format``: T_Si ``(N, K)``; T_Sx_Sy ``(N, Sx, Sy)``,
    flattened to K = Sx Sy sensors in row-major order; T_Lx_Ly_Sx_Sy and
    T_Li_Si when the laser dimensions hold one point. A missing or UNKNOWN
    format is taken from H's rank (2: T_Si, 3: T_Sx_Sy).
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
        H = _value(handle, "H")
        if H is None:
            raise CaptureError(f"{name}: no H dataset (not a tal capture)")
        H = np.asarray(H)
        if not (np.issubdtype(H.dtype, np.floating) or np.issubdtype(H.dtype, np.integer)):
            raise CaptureError(f"{name}: H holds {H.dtype} values, not real numbers")
        H = H.astype(np.float64)
        code = _scalar(_value(handle, "H_format"))
        names = {value: key for key, value in H_FORMATS.items()}
        layout = names.get(int(code), "UNKNOWN") if code is not None else "UNKNOWN"
        if layout == "UNKNOWN":
            layout = {2: "T_Si", 3: "T_Sx_Sy"}.get(H.ndim, "UNKNOWN")
        expected_rank = {"T_Si": 2, "T_Sx_Sy": 3, "T_Lx_Ly_Sx_Sy": 5, "T_Li_Si": 3}
        if layout not in expected_rank or H.ndim != expected_rank[layout]:
            raise CaptureError(f"{name}: H of shape {H.shape} with H_format {layout} is not a "
                               f"time x sensors capture")
        if layout == "T_Lx_Ly_Sx_Sy":
            if H.shape[1] * H.shape[2] != 1:
                raise CaptureError(f"{name}: H holds {H.shape[1]} x {H.shape[2]} laser points; "
                                   f"one source is needed")
            H = H[:, 0, 0]
        elif layout == "T_Li_Si":
            if H.shape[1] != 1:
                raise CaptureError(f"{name}: H holds {H.shape[1]} laser points; one source is needed")
            H = H[:, 0]
        transient = np.ascontiguousarray(H.reshape(H.shape[0], -1).T)
        start = _value(handle, "t_start")
        width = _value(handle, "delta_t")
        start, width = _scalar(start), _scalar(width)
        if start is None or width is None:
            raise CaptureError(f"{name}: no time axis (t_start and delta_t, one number each, are needed)")
        if not (math.isfinite(start) and math.isfinite(width) and width > 0):
            raise CaptureError(f"{name}: time axis t_start = {start}, delta_t = {width}: "
                               f"both must be finite and delta_t > 0")
        grid = _value(handle, "sensor_grid_xyz")
        sensors = None
        if grid is not None:
            sensors = np.asarray(grid, dtype=np.float64).reshape(-1, 3)
            if len(sensors) != transient.shape[0]:
                raise CaptureError(f"{name}: sensor_grid_xyz holds {len(sensors)} points for "
                                   f"{transient.shape[0]} sensors in H")
        laser = _value(handle, "laser_xyz")
        source = None if laser is None else np.asarray(laser, dtype=np.float64).reshape(3)
        accounts = _scalar(_value(handle, "t_accounts_first_and_last_bounces"))
        info = _value(handle, "scene_info")
    if isinstance(info, bytes):
        info = info.decode("utf-8", errors="replace")
    if isinstance(info, str):
        try:
            info = json.loads(info)
        except json.JSONDecodeError:
            pass   # tal's own files hold YAML; kept as text
    return Capture(transient=transient, start_opl=float(start), bin_width_opl=float(width),
                   sensors=sensors, source=source,
                   accounts_first_and_last_bounces=None if accounts is None else bool(accounts),
                   scene_info=info)
