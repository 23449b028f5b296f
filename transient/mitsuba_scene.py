"""Every Mitsuba 3 scene dictionary of the project.

- :func:`scene_dict`: a :class:`analytic.scenes.common.Scene` for our single-plane
  integrator ``transient_opl``. The plane [0, L]² x {0} is a ``rectangle``
  (local [-1, 1]², normal +z) scaled by L/2 and moved by (L/2, L/2, 0); its
  ``diffuse`` BSDF reads the reflectance image through a ``bitmap`` texture
  with nearest-neighbour lookup and no colour conversion (``raw``, float32
  data). A bitmap's row 0 lies at v = 0, the rectangle's -y edge, while the
  image's row 0 is the top of the plane (y = L, docs/design.md section 1), so the
  image is flipped top to bottom.
- :func:`corner_scene_dict`: floor and wall meeting at a corner, for the
  multi-bounce integrator ``transient_opl_path``.
- :func:`mitransient_scene_dict`: either scene for mitransient's
  ``transient_path``, each sensor a tiny sphere carrying an
  ``irradiancemeter`` (see :func:`irradiancemeter_correction`).

Import after :func:`transient.backend.select_variant` (or any
``mitsuba.set_variant``: the mitransient dictionary needs no plugin of ours).
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from analytic.scenes.common import Sampling, Scene
from .constants import RAY_EPSILON
from .intensity import emitter_intensity
from .scene_xml import waveform_entries

__all__ = ["plane_to_world", "scene_dict", "load_scene", "corner_scene_dict", "wall_to_world",
           "mitransient_scene_dict", "mitransient_planes", "irradiancemeter_correction", "METER_RADIUS",
           "RAY_EPSILON"]

#: Radius of mitransient's irradiancemeter spheres, metres. The meter's
#: reading differs from the point value at its centre by a relative
#: (4/3) r / d to first order (1.3e-4 at d = 1 m).
METER_RADIUS = 1e-4

_FILM = {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance"}


def plane_to_world(size: float):
    """Double-precision transform of the local rectangle [-1, 1]² onto [0, L]² x {0}.

    Parameters
    ----------
    size : float
        Plane side L, metres.
    """
    half = 0.5 * float(size)
    return mi.ScalarTransform4d().translate([half, half, 0.0]).scale([half, half, 1.0])


def wall_to_world(size: float):
    """Transform of the local rectangle onto the wall {0} x [0, L]² (normal +x).

    Local x -> world y, local y -> world z, local z (the normal) -> world x.
    """
    half = 0.5 * float(size)
    return mi.ScalarTransform4d(np.array([[0.0, 0.0, 1.0, 0.0], [half, 0.0, 0.0, half],
                                          [0.0, half, 0.0, half], [0.0, 0.0, 0.0, 1.0]]))


def _bitmap_bsdf(reflectance: np.ndarray) -> dict:
    # Image row 0 is the top (y = L); bitmap row 0 is v = 0 (y = 0).
    texture = np.ascontiguousarray(np.flipud(reflectance), dtype=np.float32)[..., None]
    return {"type": "diffuse",
            "reflectance": {"type": "bitmap", "bitmap": mi.Bitmap(texture), "raw": True,
                            "filter_type": "nearest", "wrap_mode": "clamp"}}


def _illumination_entries(scene) -> dict:
    """The integrator's waveform keys: the scene's own fields, defaults left to the plugin."""
    return waveform_entries(scene.illumination, scene.sampling.bin_width_opl)


def _sampling_entries(sampling: Sampling) -> dict:
    return {"bins": int(sampling.count), "start_opl": float(sampling.start_opl),
            "bin_width_opl": float(sampling.bin_width_opl)}


def _sensors(positions) -> dict:
    from .sensor import PLUGIN_NAME as SENSOR

    # Zero-padded keys keep Mitsuba's sensor order equal to the scene's; a
    # distinct sampler seed keeps the parser from merging two sensors at one place.
    return {f"sensor_{k:06d}": {"type": SENSOR, "position": [float(v) for v in position], "film": dict(_FILM),
                                "sampler": {"type": "independent", "seed": k}}
            for k, position in enumerate(np.asarray(positions, dtype=np.float64))}


def scene_dict(scene: Scene, **estimator) -> dict:
    """The Mitsuba scene dictionary of a scene, for ``transient_opl``.

    Parameters
    ----------
    scene : Scene
        Plane, reflectance image, source, sensors, sampling and illumination.
    **estimator
        Further ``transient_opl`` parameters (``strategy``, ``sampler``).

    Returns
    -------
    dict
        For ``mitsuba.load_dict``: integrator ``transient_opl`` (with the
        scene's attenuation, and its source position and intensity in
        float64), shape ``plane``, emitter ``source`` (point; its float32
        intensity is :func:`transient.intensity.emitter_intensity` of the
        scene's) and sensors ``sensor_000000`` ..., in sensor order.

    Notes
    -----
    Every scene field is rendered except ``tolerance`` (the model's
    quadrature accuracy) and ``noise`` (added to the model's y; a render
    is noiseless but for its own Monte Carlo error).
    """
    from .plane import PLUGIN_NAME as INTEGRATOR

    source = [float(v) for v in scene.source]
    integrator = {"type": INTEGRATOR, **_sampling_entries(scene.sampling), **_illumination_entries(scene),
                  "plane_to_world": plane_to_world(scene.size), "source_position": source,
                  "source_intensity": float(scene.intensity), "attenuation": scene.attenuation, **estimator}
    return {"type": "scene", "integrator": integrator,
            "plane": {"type": "rectangle", "to_world": plane_to_world(scene.size),
                      "bsdf": _bitmap_bsdf(scene.reflectance)},
            "source": {"type": "point", "position": source, "intensity": emitter_intensity(scene.intensity)},
            **_sensors(scene.sensors)}


def load_scene(scene: Scene, **estimator):
    """``mitsuba.load_dict(scene_dict(scene, **estimator))``, checking that sensor order survived loading."""
    loaded = mi.load_dict(scene_dict(scene, **estimator))
    positions = np.array([sensor.position for sensor in loaded.sensors()])
    if positions.shape != scene.sensors.shape or not np.array_equal(positions, scene.sensors):
        raise RuntimeError("Mitsuba reordered or dropped the sensors of the scene")
    return loaded


def corner_scene_dict(source, sensors, albedo: float, sampling: Sampling, max_depth: int,
                      size: float = 1.0) -> dict:
    """Floor [0, L]² x {0} (normal +z) and wall {0} x [0, L]² (normal +x), for ``transient_opl_path``.

    Parameters
    ----------
    source : array_like
        Point emitter position (intensity 1 W/sr), metres.
    sensors : array_like
        ``(K, 3)`` omni point sensor positions, metres.
    albedo : float
        Reflectance of both planes.
    sampling : Sampling
        The bins.
    max_depth : int
        Most surface bounces.
    size : float
        L, metres.
    """
    from .path import PLUGIN_NAME as INTEGRATOR

    bsdf = {"type": "diffuse", "reflectance": float(albedo)}
    return {"type": "scene",
            "integrator": {"type": INTEGRATOR, **_sampling_entries(sampling), "max_depth": int(max_depth)},
            "floor": {"type": "rectangle", "to_world": plane_to_world(size), "bsdf": dict(bsdf)},
            "wall": {"type": "rectangle", "to_world": wall_to_world(size), "bsdf": dict(bsdf)},
            "source": {"type": "point", "position": [float(v) for v in source], "intensity": 1.0},
            **_sensors(sensors)}


def irradiancemeter_correction(radius: float = METER_RADIUS) -> tuple[float, float]:
    """(factor, offset_opl) that turn a tiny-sphere irradiancemeter's transient into an omni point's.

    Mitsuba's ``irradiancemeter`` (``src/sensors/irradiancemeter.cpp``)
    starts each ray at a uniform point of its shape, in a cosine-weighted
    direction about the normal, with weight π, from the point moved
    ``math::RayEpsilon`` along the ray; mitransient's ``transient_path``
    counts the path length from that origin. So:

    - factor 4: the mean irradiance over a sphere is a quarter of the
      fluence rate ∫ L dω that an omni point measures;
    - offset 2r/3 + RayEpsilon: a ray toward a point at distance d ≫ r
      starts from sphere points with μ = n·ω distributed as 2μ dμ, r μ
      nearer than the centre (mean 2r/3), plus the epsilon. The meter's
      bins must start that much earlier (``start_opl - offset``).

    Returns
    -------
    factor : float
    offset_opl : float
        Metres of path length.
    """
    return 4.0, 2.0 * float(radius) / 3.0 + RAY_EPSILON


def mitransient_scene_dict(*, planes: list[dict], source, sensors, sampling: Sampling, max_depth: int,
                           samples: int, radius: float = METER_RADIUS, intensity: float = 1.0) -> dict:
    """A scene for mitransient's ``transient_path`` with irradiancemeter spheres as sensors.

    Parameters
    ----------
    planes : list of dict
        ``{"to_world": transform, "bsdf": dict}`` per rectangle.
    source : array_like
        Point emitter position, metres.
    sensors : array_like
        ``(K, 3)`` meter centres, metres.
    sampling : Sampling
        The bins of the omni point sensors; the meters' bins start
        :func:`irradiancemeter_correction`'s offset earlier.
    max_depth : int
        Most surface bounces (mitransient's ``max_depth`` counts segments:
        this + 1).
    samples : int
        Samples per render (the meter's sampler ``sample_count``).
    radius : float
        Meter radius, metres.
    intensity : float
        The point emitter's intensity, W/sr.
    """
    _, offset = irradiancemeter_correction(radius)
    film = {"type": "transient_hdr_film", "width": 1, "height": 1, "temporal_bins": int(sampling.count),
            "start_opl": float(sampling.start_opl) - offset, "bin_width_opl": float(sampling.bin_width_opl),
            "rfilter": {"type": "box"}}
    entries = {"type": "scene", "integrator": {"type": "transient_path", "max_depth": int(max_depth) + 1,
                                               "rr_depth": int(max_depth) + 2},
               "source": {"type": "point", "position": [float(v) for v in source],
                          "intensity": float(intensity)}}
    for i, plane in enumerate(planes):
        entries[f"plane_{i}"] = {"type": "rectangle", "to_world": plane["to_world"], "bsdf": plane["bsdf"]}
    for k, centre in enumerate(np.asarray(sensors, dtype=np.float64)):
        entries[f"meter_{k:06d}"] = {
            "type": "sphere", "center": [float(v) for v in centre], "radius": float(radius),
            "bsdf": {"type": "null"},
            # A distinct sampler seed per meter: Mitsuba's parser merges identical
            # dictionaries into one object, and a sensor can sit on one shape only.
            "sensor": {"type": "irradiancemeter", "film": dict(film),
                       "sampler": {"type": "independent", "sample_count": int(samples), "seed": k}}}
    return entries


def mitransient_planes(scene: Scene | None = None, *, albedo: float | None = None, size: float = 1.0) -> list[dict]:
    """The rectangles of :func:`mitransient_scene_dict`: a Scene's plane, or the corner's floor and wall."""
    if scene is not None:
        return [{"to_world": plane_to_world(scene.size), "bsdf": _bitmap_bsdf(scene.reflectance)}]
    bsdf = {"type": "diffuse", "reflectance": float(albedo)}
    return [{"to_world": plane_to_world(size), "bsdf": dict(bsdf)},
            {"to_world": wall_to_world(size), "bsdf": dict(bsdf)}]


def hidden_to_world(scene) -> "mi.ScalarTransform4d":
    """Double-precision transform of the local rectangle [-1, 1]² onto a relay-wall scene's hidden rectangle.

    Local x runs along u, local y along v, local +z (Mitsuba's normal) along u x v, the lit face.
    """
    from interop.mitransient.export_relay_wall import hidden_to_world_matrix

    return mi.ScalarTransform4d(hidden_to_world_matrix(scene))


def relay_wall_scene_dict(scene, **estimator) -> dict:
    """The Mitsuba scene dictionary of a relay-wall capture, for ``transient_opl_nlos``.

    Parameters
    ----------
    scene : analytic.scenes.relay_wall.RelayWallScene
        The wall, the hidden rectangle and its image, the laser, the sensor, the scan, sampling and
        illumination.
    **estimator
        Further ``transient_opl_nlos`` parameters.

    Returns
    -------
    dict
        For ``mitsuba.load_dict``: integrator ``transient_opl_nlos`` (every geometric value in float64),
        shape ``hidden`` (the image as a float32 texture) and one ``nlos_sensor`` stand-in sensor (the
        integrator reads the scan itself; Mitsuba needs a sensor to load a scene).

    Notes
    -----
    Every scene field is rendered except ``tolerance`` (the model's) and ``noise`` (added to the
    model's y); the laser's intensity multiplies the per-unit-intensity estimate at the end
    (:func:`transient.render.render`).
    """
    from .nlos import PLUGIN_NAME as INTEGRATOR

    scan = scene.scan
    integrator = {"type": INTEGRATOR, **_sampling_entries(scene.sampling), **_illumination_entries(scene),
                  "hidden_to_world": hidden_to_world(scene), "wall_size_x": float(scene.wall_size[0]),
                  "wall_size_y": float(scene.wall_size[1]), "wall_reflectance": float(scene.wall_reflectance),
                  "laser_position": [float(v) for v in scene.laser_position],
                  "sensor_position": [float(v) for v in scene.sensor_position], "scan_type": scan.type,
                  "grid_width": int(scan.grid[0]), "grid_height": int(scan.grid[1]),
                  "account_first_and_last_bounces": bool(scan.account_first_and_last_bounces), **estimator}
    if scan.type == "single" and scan.laser_point is not None:
        integrator["laser_point"] = [float(v) for v in scan.laser_point]
    if scan.type == "exhaustive" and scan.laser_grid is not None:
        integrator["laser_grid_width"], integrator["laser_grid_height"] = (int(g) for g in scan.laser_grid)
    return {"type": "scene", "integrator": integrator,
            "hidden": {"type": "rectangle", "id": "hidden", "to_world": hidden_to_world(scene),
                       "bsdf": _bitmap_bsdf(scene.reflectance)},
            **_sensors([scene.sensor_position])}
