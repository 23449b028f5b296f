"""A scene's transient as a tal HDF5 capture, in the layout of the scene's kind.

A plane's rows are its sensors (H_format T_Si, :func:`.capture.write_capture`);
a relay-wall capture's are its (laser point, read point) pairs in the layout
``tal render`` writes (:func:`.relay_wall_capture.write_relay_wall_capture`).
A new scene kind adds its writer to :data:`WRITERS`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analytic.scenes.kinds import for_kind

from .capture import write_capture
from .relay_wall_capture import write_relay_wall_capture

__all__ = ["write_scene_capture", "WRITERS"]


def _plane_capture(path: str | Path, transient, scene, *, scene_info: dict) -> Path:
    """A plane's (K, N) transient with its source and sensors' positions (metres)."""
    sampling = scene.sampling
    return write_capture(path, transient, start_opl=sampling.start_opl, bin_width_opl=sampling.bin_width_opl,
                         source=[float(v) for v in scene.source],
                         sensors=np.asarray(scene.sensors, dtype=np.float64).tolist(), scene_info=scene_info)


#: The capture writer of each scene kind.
WRITERS = {"plane": _plane_capture, "relay_wall": write_relay_wall_capture}


def write_scene_capture(path: str | Path, transient, scene, *, scene_info: dict) -> Path:
    """Write ``transient`` (the scene's rows x bins) as a tal capture of ``scene``, atomically.

    Parameters
    ----------
    path : str or Path
        Destination (``.h5``).
    transient : array_like
        ``(rows, N)``: sensors or pairs by bins, in the scene's order.
    scene : analytic.scenes.kinds.SceneKind
        The scene the transient belongs to.
    scene_info : dict
        Recorded as the capture's ``scene_info``.

    Returns
    -------
    Path
        The file written.
    """
    return for_kind(WRITERS, scene, "tal capture")(path, transient, scene, scene_info=scene_info)
