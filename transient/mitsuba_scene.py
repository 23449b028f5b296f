"""Scene (analytic.scene.Scene) -> Mitsuba 3 scene dictionary.

The plane [0, L]² x {0} is a ``rectangle`` (local [-1, 1]², normal +z)
scaled by L/2 and moved by (L/2, L/2, 0); its ``diffuse`` BSDF reads the
reflectance image through a ``bitmap`` texture with nearest-neighbour lookup
and no colour conversion (``raw``, float32 data). A bitmap's row 0 lies at
v = 0, the rectangle's -y edge, while the image's row 0 is the top of the
plane (y = L, DESIGN.md section 1), so the image is flipped top to bottom.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from analytic.scene import Scene
from analytic.waveforms import make_waveform

from .integrator import PLUGIN_NAME as INTEGRATOR
from .sensor import PLUGIN_NAME as SENSOR

__all__ = ["plane_to_world", "scene_dict", "load_scene"]


def plane_to_world(size: float):
    """Double-precision transform of the local rectangle [-1, 1]² onto [0, L]² x {0}.

    Parameters
    ----------
    size : float
        Plane side L, metres.
    """
    half = 0.5 * float(size)
    return mi.ScalarTransform4d().translate([half, half, 0.0]).scale([half, half, 1.0])


def _integrator_dict(scene: Scene) -> dict:
    illumination = scene.illumination
    sampling = scene.sampling
    entry = {"type": INTEGRATOR, "bins": int(sampling.count), "start_opl": float(sampling.start_opl),
             "bin_width_opl": float(sampling.bin_width_opl), "waveform": illumination.waveform,
             "plane_to_world": plane_to_world(scene.size),
             "source_position": [float(v) for v in scene.source]}
    # The plugin builds its waveform with the same make_waveform and period, so
    # passing the scene's own fields (defaults left unset) gives the same pulse.
    if illumination.waveform == "square":
        entry["pulse_width"] = float(make_waveform(illumination, sampling.bin_width_opl).duration)
    elif illumination.waveform == "butterworth":
        for name in ("cutoff", "duration", "order"):
            value = getattr(illumination, name)
            if value is not None:
                entry[name] = int(value) if name == "order" else float(value)
    return entry


def scene_dict(scene: Scene) -> dict:
    """The Mitsuba scene dictionary of a scene.

    Parameters
    ----------
    scene : Scene
        Plane, reflectance image, source, sensors, sampling and illumination.

    Returns
    -------
    dict
        For ``mitsuba.load_dict``: integrator ``transient_opl``, shape
        ``plane``, emitter ``source`` (point, intensity 1 W/sr) and sensors
        ``sensor_000`` ... (``omni_point``), in sensor order.
    """
    # Image row 0 is the top (y = L); bitmap row 0 is v = 0 (y = 0).
    texture = np.ascontiguousarray(np.flipud(scene.reflectance), dtype=np.float32)[..., None]
    result = {
        "type": "scene",
        "integrator": _integrator_dict(scene),
        "plane": {
            "type": "rectangle",
            "to_world": plane_to_world(scene.size),
            "bsdf": {"type": "diffuse",
                     "reflectance": {"type": "bitmap", "bitmap": mi.Bitmap(texture), "raw": True,
                                     "filter_type": "nearest", "wrap_mode": "clamp"}},
        },
        "source": {"type": "point", "position": [float(v) for v in scene.source], "intensity": 1.0},
    }
    for k, position in enumerate(scene.sensors):
        # Zero-padded keys keep Mitsuba's sensor order equal to the scene's.
        result[f"sensor_{k:06d}"] = {
            "type": SENSOR, "position": [float(v) for v in position],
            "film": {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance"}}
    return result


def load_scene(scene: Scene):
    """``mitsuba.load_dict(scene_dict(scene))``, checking that sensor order survived loading."""
    loaded = mi.load_dict(scene_dict(scene))
    positions = np.array([sensor.position for sensor in loaded.sensors()])
    if positions.shape != scene.sensors.shape or not np.array_equal(positions, scene.sensors):
        raise RuntimeError("Mitsuba reordered or dropped the sensors of the scene")
    return loaded
