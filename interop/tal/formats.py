"""tal's files in the model's format registry (:mod:`analytic.formats`), by suffix.

:func:`register` is the package's entry point of the group
``diffuse_imaging.formats`` (``pyproject.toml``): the model calls it the first
time it meets a suffix it does not know, so that ``analytic.load_scene``
reads a tal YAML configuration, the ``sampled`` waveform a tal histogram and
``read_transient`` a tal capture, and ``write_transient`` writes
``transient.h5``, without the model importing this package. Each function
imports its module on first use (h5py and PyYAML load only when needed).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["register", "CAPTURE_SUFFIXES", "CONFIG_SUFFIXES"]

#: tal's HDF5 captures.
CAPTURE_SUFFIXES = (".h5", ".hdf5")
#: tal's render configurations.
CONFIG_SUFFIXES = (".yaml", ".yml")


def _scene(path):
    """A tal render configuration as the relay-wall scene tal renders (:func:`.config.load_tal_config`)."""
    from .config import load_tal_config

    return load_tal_config(path)


def _transient(path):
    """A tal capture's ``(K, N)`` transient (:func:`.capture.read_capture`)."""
    from .capture import read_capture

    return read_capture(path).transient


def _histogram(path):
    """A tal capture, read as a measured histogram (its ``transient``, ``bin_width_opl`` and ``start_opl``)."""
    from .capture import read_capture

    return read_capture(path)


def _write_transient(path: Path, transient, meta: dict, scene) -> Path:
    """``transient.h5``: a plane's capture in the layout of :mod:`.capture` (from ``meta`` alone), a relay-wall
    capture's in tal's NLOS layout (:mod:`.relay_wall_capture`, which needs ``scene``)."""
    from analytic.files.formats import json_ready

    if meta.get("geometry") == "relay_wall":
        if scene is None:
            raise ValueError("write_transient: a relay-wall capture's transient.h5 needs its scene")
        from .relay_wall_capture import write_relay_wall_capture

        return write_relay_wall_capture(path, transient, scene, scene_info=json_ready(meta))
    from .capture import write_capture

    return write_capture(path, transient, start_opl=meta["start_opl"], bin_width_opl=meta["bin_width_opl"],
                         source=meta["source"], sensors=meta["sensor_positions"], scene_info=json_ready(meta))


def register() -> None:
    """Register tal's readers and the ``transient.h5`` writer with :mod:`analytic.formats`."""
    from analytic.formats import register_reader, register_writer

    register_reader("scene", "tal configuration", CONFIG_SUFFIXES, _scene)
    register_reader("transient", "capture", CAPTURE_SUFFIXES, _transient)
    register_reader("response", "tal capture", CAPTURE_SUFFIXES, _histogram)
    register_writer("transient.h5", _write_transient)
