"""A transient's files and metadata (docs/design.md section 5): one schema, one writer, one reader.

Metadata has one schema for every command, built by :func:`build_meta`
(docs/design.md section 5 names its keys), written to ``meta.json`` and, as
numbers, into the EXR header. :func:`write_transient` writes
``transient.npy`` (float64, the exact record), ``transient.exr`` (float32,
where float32 holds the values), tal's ``transient.h5`` and ``meta.json``
together; :func:`read_transient` reads any of them back, through the one
reader per format that ``check`` and ``reconstruct`` use too.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from analytic.errors import DataError
from analytic.formats import reader_for, writers
from analytic.scenes.common import Scene
from analytic.scenes.relay_wall import RelayWallScene

from .atomic import discard, staged_writes
from .formats import PrecisionWarning, float32_problem, read_exr, read_npy, save_exr, save_json, save_npy

__all__ = ["build_meta", "write_transient", "read_transient", "transient_format",
           "transient_in_folder", "UNITS", "RELAY_WALL_UNITS", "RELAY_WALL_KEYS", "KIND_KEYS",
           "TRANSIENT_FILES"]

#: How y's units follow from each kind's intensity (docs/design.md sections 1 and 7), as meta.json states them.
UNITS, RELAY_WALL_UNITS = Scene.units, RelayWallScene.units

#: meta.json's keys that a scene kind fills (:meth:`analytic.scenes.kinds.SceneKind.meta_fields`); None where
#: a kind has not the key (a plane has no relay wall, a relay-wall capture no plane, point source or sensor array).
RELAY_WALL_KEYS = ("relay_wall", "hidden", "laser", "sensor", "scan")
KIND_KEYS = ("geometry", "plane_size", "source", "sensor_positions", "attenuation", "units", *RELAY_WALL_KEYS)


def build_meta(scene, *, kind: str, samples: int = 0, seed: int | None = None,
               window_share: float | None = None, **extra) -> dict:
    """The one metadata record of every command (docs/design.md sections 5 and 7).

    Parameters
    ----------
    scene : analytic.Scene or analytic.scenes.relay_wall.RelayWallScene
        The scene the transient belongs to: a plane, or a capture through a relay wall.
    kind : {"model", "render"}
        Who computed it.
    samples : int
        Monte Carlo samples (0 for the model).
    seed : int, optional
        The render's seed, or the noise seed of a model with noise.
    window_share : float, optional
        Share of the light the window holds (:func:`analytic.window_share`).
    **extra
        Further keys (a command's own: variant, timings, ...); they may not
        redefine the schema's keys.

    Returns
    -------
    dict
        Every record has the same keys: ``kind``, ``samples``, ``seed``,
        ``scene``, ``geometry`` (``"plane"`` or ``"relay_wall"``),
        ``plane_size``, ``pixels``, ``source``, ``intensity``,
        ``sensor_positions``, ``attenuation``, ``illumination`` (the
        waveform's name) and ``illumination_parameters``, ``tolerance``
        (the model's; None for a render), ``window_share``, ``noise`` (the
        scene's, None when noiseless), ``detector`` (the scene's
        ``[detector]`` table, None without one: docs/design.md section 8), ``start_opl``, ``bin_width_opl``,
        ``bins``, ``sensors`` (the transient's rows: sensors, or the
        capture's (laser point, read point) pairs), ``units``, and the
        relay-wall tables ``relay_wall``, ``hidden``, ``laser``, ``sensor``
        and ``scan`` (:meth:`analytic.scenes.relay_wall.RelayWallScene.meta_fields`). The keys of the other
        geometry are None: a plane has no relay wall, and a relay-wall
        capture has no plane, point source or sensor array (its hidden
        image's M is ``pixels``, its laser's I ``intensity``, and its
        third bounce is Lambertian at every vertex: ``attenuation`` is
        ``lambertian``).
    """
    from analytic.waveforms import make_waveform   # here: the waveforms load Numba, files need not

    if kind not in ("model", "render"):
        raise ValueError(f"kind: 'model' or 'render', got {kind!r}")
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    noise = scene.noise
    own = scene.meta_fields()
    fields = {key: own.pop(key, None) for key in KIND_KEYS}
    meta = {
        "kind": kind,
        "samples": int(samples),
        "seed": None if seed is None else int(seed),
        "scene": scene.name,
        "geometry": fields["geometry"],
        "plane_size": fields["plane_size"],
        "pixels": int(scene.pixels),
        "source": fields["source"],
        "intensity": float(scene.intensity),
        "sensor_positions": fields["sensor_positions"],
        "attenuation": fields["attenuation"],
        "illumination": waveform.name,
        "illumination_parameters": dict(waveform.parameters),
        "tolerance": float(scene.tolerance) if kind == "model" else None,
        "window_share": None if window_share is None else float(window_share),
        "noise": None if noise is None else {"kind": noise.kind, "sigma": noise.sigma,
                                             "photons": noise.photons, "seed": noise.seed},
        "detector": None if scene.detector is None else scene.detector.as_dict(),
        "start_opl": float(scene.sampling.start_opl),
        "bin_width_opl": float(scene.sampling.bin_width_opl),
        "bins": int(scene.sampling.count),
        "sensors": int(scene.sensor_count),
        "units": fields["units"],
        **{key: fields[key] for key in RELAY_WALL_KEYS},
        **own,                     # a kind's keys beyond the schema's
    }
    clash = sorted(set(extra) & set(meta))
    if clash:
        raise ValueError(f"extra: {', '.join(clash)} are schema keys")
    meta.update(extra)
    return meta


#: meta.json's ``exr`` when transient.exr is written.
_EXR_WRITTEN = ("written: float32, every value within float32's rounding (2^-24 of the largest) "
                "of transient.npy")


def write_transient(out_dir: str | Path, transient: np.ndarray, meta: dict[str, Any], *, scene=None,
                    stderr: np.ndarray | None = None, noisy: np.ndarray | None = None) -> dict[str, Path]:
    """Write ``transient.{npy,exr,h5}``, ``meta.json`` (+ ``stderr.npy``, ``transient_noisy.npy``), together.

    ``transient.h5`` is tal's HDF5 capture, readable by ``tal.io.read_capture``,
    with the metadata as its ``scene_info``: a plane's in the layout of
    :mod:`interop.tal.capture`, a relay-wall capture's in tal's NLOS layout
    (:mod:`interop.tal.relay_wall_capture`); it is written by the writer
    :mod:`analytic.formats` has for it (every registered writer's file is written).

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    transient : numpy.ndarray
        ``(K, N)`` samples y_k[n]; saved as float64 ``.npy``, float32 EXR
        (width N = time, height K = sensors; only where float32 holds them,
        :func:`float32_problem`) and tal's HDF5 capture (float64).
    meta : dict
        From :func:`build_meta`; all of it goes to meta.json, its numbers and
        strings to the EXR header, with ``exr`` added: whether
        ``transient.exr`` was written, and why not (float32 cannot hold the
        values: then a :class:`PrecisionWarning` says so, and an earlier
        ``transient.exr`` in the folder is removed).
    scene : RelayWallScene, optional
        The scene of a relay-wall capture (``meta["geometry"] == "relay_wall"``,
        where it is required): its scan's points and grids lay out
        ``transient.h5``. A plane's file needs only ``meta``.
    stderr : numpy.ndarray, optional
        ``(K, N)`` per-bin standard error (renders).
    noisy : numpy.ndarray, optional
        ``(K, N)`` noisy samples (model with noise).

    Returns
    -------
    dict
        Name -> path of every file written. The files are renamed into place
        together (see :func:`staged_writes`).
    """
    out_dir = Path(out_dir)
    transient = np.asarray(transient, dtype=np.float64)
    if transient.shape != (meta["sensors"], meta["bins"]):
        raise ValueError(f"transient: shape {transient.shape}, meta says "
                         f"({meta['sensors']}, {meta['bins']})")
    problem = float32_problem(transient)
    meta = dict(meta)
    meta["exr"] = (_EXR_WRITTEN if problem is None
                   else f"not written: {problem}; transient.npy is the exact record")
    written = {}
    with staged_writes():
        written["transient.npy"] = save_npy(out_dir / "transient.npy", transient)
        if stderr is not None:
            written["stderr.npy"] = save_npy(out_dir / "stderr.npy", np.asarray(stderr, dtype=np.float64))
        if noisy is not None:
            written["transient_noisy.npy"] = save_npy(out_dir / "transient_noisy.npy",
                                                      np.asarray(noisy, dtype=np.float64))
        if problem is None:
            written["transient.exr"] = save_exr(out_dir / "transient.exr", transient, meta)
        else:
            discard(out_dir / "transient.exr")   # an earlier command's: it is not this transient
        for name, write in writers().items():   # other tools' files (tal's transient.h5: analytic.formats)
            written[name] = write(out_dir / name, transient, meta, scene)
        written["meta.json"] = save_json(out_dir / "meta.json", meta)
    if problem is not None:
        warnings.warn(f"{out_dir / 'transient.exr'}: not written, {problem}; transient.npy (float64) is "
                      f"the exact record", PrecisionWarning, stacklevel=2)
    return written


#: Our transient files, in the order a reader takes them from a folder.
TRANSIENT_FILES = ("transient.npy", "transient.exr")

# File suffix (any case) -> the format of our own transient files; others' come from analytic.formats.
_FORMATS = {".npy": "npy", ".exr": "exr"}


def transient_format(path: str | Path) -> str | None:
    """The format of a transient file by its suffix, in any case: "npy", "exr", "capture" (tal's HDF5) or None."""
    suffix = Path(path).suffix.lower()
    if suffix in _FORMATS:
        return _FORMATS[suffix]
    reader = reader_for("transient", suffix)
    return None if reader is None else reader.name


def transient_in_folder(folder: str | Path) -> Path | None:
    """Our transient file in ``folder`` (the first of :data:`TRANSIENT_FILES` there), or None."""
    return next((Path(folder) / name for name in TRANSIENT_FILES if (Path(folder) / name).is_file()), None)


def read_transient(path: str | Path) -> np.ndarray:
    """Read a transient from ``.npy``, ``.exr`` (channel ``Y``) or tal's ``.h5``, or from a folder holding ours.

    Each format is read by its one reader (:func:`~analytic.files.read_npy`,
    :func:`~analytic.files.read_exr`, and for tal's ``.h5`` the transient reader of
    :mod:`analytic.formats`: :func:`~interop.tal.read_capture`),
    the same that ``check`` and ``reconstruct`` use; the suffix may be in
    any case.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64.

    Raises
    ------
    DataError
        Missing, unreadable, of an unknown format or not a (K, N) array of real numbers.
    """
    path = Path(path)
    if path.is_dir():
        found = transient_in_folder(path)
        if found is None:
            raise DataError(f"{path}: a folder without {' or '.join(TRANSIENT_FILES)}; give the data file itself")
        path = found
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    kind = transient_format(path)
    if kind == "npy":
        data = read_npy(path)
    elif kind == "exr":
        data, _ = read_exr(path)
    elif kind is not None:
        data = reader_for("transient", path.suffix).read(path)
    else:
        raise DataError(f"{path}: expected a .npy, .exr or .h5 (tal capture) transient")
    if data.ndim != 2:
        raise DataError(f"{path}: expected a (sensors, bins) array, got shape {data.shape}")
    return data
