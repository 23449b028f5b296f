"""A scene as a Mitsuba 3 XML file, for our plugins or for mitransient.

``export_scene(scene, out_dir, format)`` writes into ``out_dir``:

- ``reflectance.exr``: the reflectance image as one float32 channel ``Y``,
  flipped top to bottom (a bitmap's row 0 lies at v = 0, the plane's
  y = 0 edge; the image's row 0 is its top, docs/design.md section 1), read by
  a ``bitmap`` texture with ``filter_type = nearest`` and ``raw = true``
  (no colour conversion), exactly as :func:`transient.mitsuba_scene.scene_dict`
  builds it in memory;
- ``scene.xml``: the plane (``rectangle`` scaled by L/2 and moved to
  (L/2, L/2, 0), ``diffuse`` BSDF), the point source (the scene's intensity, W/sr) and

  * ``format="mitsuba"``: our ``transient_opl`` integrator (bins,
    start_opl, bin_width_opl, waveform and its parameters, the plane's
    transform and the source position in double precision) and one
    ``omni_point`` sensor per scene sensor, in order: loaded after
    :func:`transient.backend.select_variant`, it renders the same y as
    :func:`transient.render.render`;
  * ``format="mitransient"``: mitransient's ``transient_path`` integrator
    (``max_depth`` 2: one bounce) and, per scene sensor, a small
    ``sphere`` (``null`` BSDF) carrying an ``irradiancemeter`` with a 1 x 1
    ``transient_hdr_film`` (temporal_bins, start_opl, bin_width_opl of the
    scene) and an ``independent`` sampler of ``$spp`` samples;
- ``README.md``: how to render it and ``check`` the result.

What mitransient's irradiancemeter reads (Mitsuba 3's
``src/sensors/irradiancemeter.cpp``): the irradiance averaged over the
sphere's surface, which for a small sphere is a quarter of the fluence rate
our point sensors read; its rays start on the sphere's surface, moved a
further ``math::RayEpsilon`` (1500 x 2⁻²⁴ m = 8.94e-5 m in float variants)
along the ray, so path lengths come out short by 2r/3 (the mean of r cos θ
over cosine-distributed directions) + 8.94e-5 m. ``diffuse-imaging check``
finds exactly these as scale 1/4 and a positive offset.

A relay-wall (NLOS) scene is written by :mod:`interop.mitransient.export_relay_wall`
(our ``transient_opl_nlos``, or mitransient's ``transient_nlos_path``).

No Mitsuba import is needed to write the files.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from analytic.files import float32_problem
from analytic.scenes.common import Scene, SceneError
from analytic.scenes.kinds import for_kind
from analytic.values import exact

from transient.intensity import emitter_intensity
from transient.scene_xml import add as _add, add_entries, number as _number, point as _point, scene_text, \
    textured_diffuse, transform as _transform, waveform_entries, write_scene_files
from .export_relay_wall import MITRANSIENT_IMPULSE_ONLY, export_relay_wall

__all__ = ["export_scene", "FORMATS", "RADIUS", "SPP", "SPP_RELAY_WALL", "plane_to_world_matrix",
           "MITRANSIENT_IMPULSE_ONLY"]

FORMATS = ("mitsuba", "mitransient")

#: Default irradiancemeter sphere radius, metres (as validation/runs/bench.py uses).
RADIUS = 1e-3

#: Default samples per irradiancemeter for mitransient (``$spp`` in the XML).
SPP = 2**20

#: Default samples per film pixel of a relay-wall capture for mitransient (``$spp`` in the XML).
SPP_RELAY_WALL = 2**18

# Plugin names of this package (transient/plane.py, transient/sensor.py); kept
# here as strings so that exporting never imports Mitsuba.
_INTEGRATOR = "transient_opl"
_SENSOR = "omni_point"


def plane_to_world_matrix(size: float) -> np.ndarray:
    """4 x 4 transform of the local rectangle [-1, 1]² onto [0, L]² x {0}, float64.

    Parameters
    ----------
    size : float
        Plane side L, metres.

    Notes
    -----
    translate(L/2, L/2, 0) · scale(L/2, L/2, 1), the matrix of
    :func:`transient.mitsuba_scene.plane_to_world`.
    """
    half = 0.5 * float(size)
    return np.array([[half, 0.0, 0.0, half], [0.0, half, 0.0, half], [0.0, 0.0, 1.0, 0.0],
                     [0.0, 0.0, 0.0, 1.0]])


def _plane(root, scene: Scene) -> None:
    shape = _add(root, "shape", type="rectangle", id="plane")
    _transform(shape, "to_world", plane_to_world_matrix(scene.size))
    textured_diffuse(shape)


def _source(root, scene: Scene, format: str) -> None:
    emitter = _add(root, "emitter", type="point", id="source")
    _point(emitter, "position", scene.source)
    # The source's peak radiant intensity, W/sr: y scales with it exactly. Our integrator reads it in
    # float64 (source_intensity) and checks the emitter's float32 stand-in against it.
    intensity = emitter_intensity(scene.intensity) if format == "mitsuba" else float(scene.intensity)
    _add(emitter, "float", "intensity", value=repr(intensity))


def _our_integrator(root, scene: Scene) -> None:
    sampling, illumination = scene.sampling, scene.illumination
    integrator = _add(root, "integrator", type=_INTEGRATOR)
    _add(integrator, "integer", "bins", value=int(sampling.count))
    _add(integrator, "float", "start_opl", value=_number(sampling.start_opl))
    _add(integrator, "float", "bin_width_opl", value=_number(sampling.bin_width_opl))
    add_entries(integrator, waveform_entries(illumination, sampling.bin_width_opl))
    _transform(integrator, "plane_to_world", plane_to_world_matrix(scene.size))
    _point(integrator, "source_position", scene.source)
    _add(integrator, "float", "source_intensity", value=repr(float(scene.intensity)))
    _add(integrator, "string", "attenuation", value=scene.attenuation)


def _our_sensors(root, scene: Scene) -> None:
    for k, position in enumerate(scene.sensors):
        sensor = _add(root, "sensor", type=_SENSOR, id=f"sensor_{k:06d}")
        _point(sensor, "position", position)
        film = _add(sensor, "film", type="hdrfilm")
        _add(film, "integer", "width", value=1)
        _add(film, "integer", "height", value=1)
        _add(film, "string", "pixel_format", value="luminance")


def _mitransient(root, scene: Scene, radius: float) -> None:
    integrator = _add(root, "integrator", type="transient_path")
    _add(integrator, "integer", "max_depth", value=2)   # emitter -> plane -> sensor: one bounce
    sampling = scene.sampling
    for k, position in enumerate(scene.sensors):
        sphere = _add(root, "shape", type="sphere", id=f"sensor_{k:06d}")
        _point(sphere, "center", position)
        _add(sphere, "float", "radius", value=_number(radius))
        _add(sphere, "bsdf", type="null")
        sensor = _add(sphere, "sensor", type="irradiancemeter")
        sampler = _add(sensor, "sampler", type="independent")
        _add(sampler, "integer", "sample_count", value="$spp")
        # Mitsuba (3.7+) merges identical objects when loading, and an irradiancemeter
        # belongs to one shape only: a seed per sensor keeps them distinct.
        _add(sampler, "integer", "seed", value=k)
        film = _add(sensor, "film", type="transient_hdr_film")
        _add(film, "integer", "width", value=1)
        _add(film, "integer", "height", value=1)
        _add(film, "integer", "temporal_bins", value=int(sampling.count))
        _add(film, "float", "start_opl", value=_number(sampling.start_opl))
        _add(film, "float", "bin_width_opl", value=_number(sampling.bin_width_opl))
        _add(film, "rfilter", type="box")


def _check_float32(scene: Scene, format: str) -> None:
    """Mitsuba reads the texture as float32, and mitransient the intensity too: refuse what it cannot hold.

    Our integrator takes the intensity in float64 (``source_intensity``).
    """
    problem = float32_problem(scene.reflectance)
    if problem is not None:
        raise SceneError("plane.reflectance", f"the exported texture is float32, as Mitsuba reads it, and "
                                              f"{problem}; scale the reflectance up (and the intensity down)")
    problem = float32_problem([scene.intensity]) if format == "mitransient" else None
    if problem is not None:
        raise SceneError("source.intensity", f"Mitsuba's float variants read it as float32, and {problem}; "
                                             f"scale the intensity into float32's range")


_README = {
    "mitsuba": """# {name}: Mitsuba 3 scene for diffuse-imaging's plugins

`scene.xml` + `reflectance.exr`: {sensors} `omni_point` sensor(s), {bins} bins of {width} m from
start_opl = {start} m (path length, c = 1), `transient_opl` integrator. Render it with the plugins
registered (the variant chosen by diffuse-imaging):

```python
from transient.backend import select_variant
select_variant()
import mitsuba as mi
from transient.render import render_loaded
result = render_loaded(mi.load_file("scene.xml"), spp=2**22, seed=0)
y, stderr = result.mean, result.stderr    # (K, N), the same estimate as `diffuse-imaging render`
```
""",
    "mitransient": """# {name}: Mitsuba 3 scene for mitransient

`scene.xml` + `reflectance.exr`: {sensors} irradiancemeter sphere(s) of radius {radius} m, one per
sensor in the scene's order, each with a 1 x 1 `transient_hdr_film` of {bins} bins of {width} m from
start_opl = {start} m; `transient_path` integrator, impulse illumination. Render every sensor with
16 seeds and save them stacked, one file per seed: independent replicas, whose spread is each bin's
error and whose sign flips (16 or more) give the check's limits whatever the correlation between bins:

```python
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_mono")
import mitransient
scene = mi.load_file("scene.xml", spp=2**20)
for seed in range(16):
    films = [np.array(mi.render(scene, sensor=k, seed=seed)[1]) for k in range(len(scene.sensors()))]
    np.save(f"render_{{seed:02d}}.npy", np.stack(films))      # (K, 1, 1, N, 1)
```

then judge them against the exact model, stating what the irradiancemeter reads:

    diffuse-imaging check SCENE.toml --data render_*.npy --expect irradiancemeter --out check

or, in a test, `validation.assert_agrees("SCENE.toml", sorted(glob.glob("render_*.npy")),
expect="irradiancemeter")` (docs/testing-your-renderer.md). The irradiancemeter reads the mean
irradiance over its sphere, exactly a quarter of the fluence, with path lengths short by
{offset:.4g} m (rays start on the sphere's surface, 2r/3 = {two_thirds:.4g} m closer on average,
plus Mitsuba's ray epsilon 8.94e-5 m): as given the renders disagree, as stated they agree, and
their fitted scale and offset are tested against 1/4 and {offset:.4g} m. `check` states what the
renders can detect (`detectable`: the smallest scale error and time shift flagged half the time);
it falls as 1/sqrt(spp): 16 renders of 2^16 samples see about 0.5 % on examples/paper.toml.
""",
}


def export_scene(scene: Scene, out_dir: str | Path, format: str, *, radius: float | None = None,
                 spp: int | None = None) -> dict[str, Path]:
    """Write ``scene.xml``, ``reflectance.exr`` and ``README.md`` for Mitsuba 3, atomically.

    Parameters
    ----------
    scene : Scene or RelayWallScene
        The scene. Our integrator renders either attenuation (written as its
        ``attenuation``); mitransient renders physical (``lambertian``)
        transport only, so ``paper`` is refused for it. A relay-wall scene
        goes to :func:`interop.mitransient.export_relay_wall.export_relay_wall`.
    out_dir : str or Path
        Output folder (created).
    format : {"mitsuba", "mitransient"}
        Our ``transient_opl`` and ``omni_point`` plugins, or mitransient's
        ``transient_path`` with an irradiancemeter sphere per sensor.
    radius : float, optional
        ``mitransient`` only (refused otherwise): irradiancemeter sphere
        radius, metres, below every sensor's height. Default :data:`RADIUS`.
    spp : int, optional
        ``mitransient`` only (refused otherwise): default samples per
        sensor (``$spp``, overridden by ``mi.load_file(path, spp=...)``).
        Default :data:`SPP` (:data:`SPP_RELAY_WALL` per film pixel of a
        relay-wall capture).

    Returns
    -------
    dict
        File name -> path written.

    Raises
    ------
    ValueError
        Unknown format, a bad radius or spp, or either given for ``mitsuba``.
    SceneError
        ``mitransient`` with a waveform other than the impulse
        (``illumination.waveform``, :data:`MITRANSIENT_IMPULSE_ONLY`): its
        point emitter emits a Dirac pulse and its film has no temporal filter;
        a reflectance or an intensity that float32 (the texture's EXR,
        Mitsuba's float variants) cannot hold
        (:func:`analytic.files.float32_problem`).

    Notes
    -----
    A sample of bin n holds the light whose path length
    |p_s - x| + |x - p_k| lies in [start_opl + n T, start_opl + (n + 1) T).
    The scene's name goes into an XML comment, made safe there (any
    character XML cannot hold as ``\\uXXXX``, "--" split), and
    ``scene.xml`` is parsed back before it is renamed into place.
    """
    check_export_options(scene, format, radius=radius, spp=spp)
    return for_kind(_EXPORTERS, scene, "export")(scene, out_dir, format, radius=radius, spp=spp)


def check_export_options(scene, format: str, *, radius: float | None = None, spp: int | None = None) -> None:
    """Refuse a format or an option that ``scene``'s kind does not take (ValueError naming it), before
    anything is written; the values are checked further by the kind's exporter."""
    if format not in FORMATS:
        raise ValueError(f"format: must be one of {', '.join(FORMATS)}, got {format!r}")
    for_kind(_OPTION_CHECKS, scene, "export")(format, radius, spp)


def _plane_options(format: str, radius, spp) -> None:
    if format == "mitsuba" and (radius is not None or spp is not None):
        raise ValueError("radius, spp: apply to format 'mitransient' only (our omni_point sensors are "
                         "points; render_loaded takes the sample count)")


def _relay_wall_options(format: str, radius, spp) -> None:
    if radius is not None:
        raise ValueError("radius: applies to a plane scene's irradiancemeter spheres; a relay-wall scene's "
                         "nlos_capture_meter reads wall points")
    if format == "mitsuba" and spp is not None:
        raise ValueError("spp: applies to format 'mitransient' only (render_chunk_per_unit_intensity takes "
                         "the sample count)")


def _export_relay_wall(scene, out_dir: str | Path, format: str, *, radius, spp) -> dict[str, Path]:

    spp = SPP_RELAY_WALL if spp is None else int(spp)
    if spp < 1:
        raise ValueError(f"spp: must be >= 1, got {spp}")
    return export_relay_wall(scene, out_dir, format, spp=spp)


def _export_plane(scene: Scene, out_dir: str | Path, format: str, *, radius, spp) -> dict[str, Path]:
    """A plane scene's files (see :func:`export_scene`)."""
    radius = RADIUS if radius is None else float(radius)
    spp = SPP if spp is None else int(spp)
    if format == "mitransient":
        if scene.illumination.waveform != "impulse":
            raise SceneError("illumination.waveform", MITRANSIENT_IMPULSE_ONLY)
        lowest = float(np.min(scene.sensors[:, 2]))
        if not (0.0 < radius < lowest):
            raise ValueError(f"radius: must lie in (0, {exact(lowest)}) m (below the lowest sensor's height), "
                             f"got {exact(radius)}")
        if spp < 1:
            raise ValueError(f"spp: must be >= 1, got {spp}")
    if format == "mitransient" and scene.attenuation != "lambertian":
        raise SceneError("model.attenuation", f"mitransient renders physical transport only, not the paper's "
                                              f"eq. (1) ({scene.attenuation!r}); export with format 'mitsuba' "
                                              f"(our plugins render both)")
    _check_float32(scene, format)
    out_dir = Path(out_dir)
    root = ET.Element("scene", version="3.0.0")
    if format == "mitransient":
        _add(root, "default", "spp", value=spp)
        _mitransient(root, scene, radius)
    else:
        _our_integrator(root, scene)
    _plane(root, scene)
    _source(root, scene, format)
    if format == "mitsuba":
        _our_sensors(root, scene)
    text = scene_text(root, scene.name, format)
    sampling = scene.sampling
    readme = _README[format].format(name=scene.name, sensors=scene.sensor_count, bins=sampling.count,
                                    width=sampling.bin_width_opl, start=sampling.start_opl, radius=radius,
                                    offset=2 * radius / 3 + 1500 * 2.0**-24, two_thirds=2 * radius / 3)
    # Image row 0 is the top (y = L); a bitmap's row 0 is v = 0 (y = 0): write_scene_files flips it.
    return write_scene_files(out_dir, scene.reflectance, text, readme)


#: Each scene kind's option check and exporter.
_OPTION_CHECKS = {"plane": _plane_options, "relay_wall": _relay_wall_options}
_EXPORTERS = {"plane": _export_plane, "relay_wall": _export_relay_wall}
