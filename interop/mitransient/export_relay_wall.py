"""A relay-wall (NLOS) capture as Mitsuba 3 XML: for our ``transient_opl_nlos``, or for mitransient.

``export_relay_wall(scene, out_dir, format)`` writes ``reflectance.exr``
(the hidden image, flipped top to bottom as for the plane: a bitmap's row 0
lies at v = 0, the image's row 0 at v's far end), ``scene.xml`` and
``README.md`` with a script that renders it:

- ``format="mitsuba"``: our ``transient_opl_nlos`` integrator with every
  geometric value in double precision (the hidden rectangle's transform,
  the wall, the laser and sensor positions, the scan), the hidden
  ``rectangle`` (id ``hidden``, ``diffuse`` BSDF reading the texture) and one
  ``omni_point`` stand-in sensor at o_s (Mitsuba loads no scene without a
  sensor; the integrator reads the scan itself).
- ``format="mitransient"``: mitransient's ``transient_nlos_path`` with
  ``filter_bounces = 2`` (the three-vertex paths laser -> l -> x -> s, the
  third bounce; mitransient's documentation says 3, which keeps four),
  laser sampling and hidden-geometry sampling without the relay wall,
  ``account_first_and_last_bounces`` as the scan's, ``max_depth = 4``; the
  relay wall a ``rectangle`` scaled to the wall's sides with a ``diffuse``
  BSDF of reflectance ρ_w and an ``nlos_capture_meter`` at o_s whose
  ``transient_hdr_film`` is the scan grid (W x H; confocal: 1 x 1 with
  ``original_film_width/height`` W x H, one render per point) with the
  scene's bins; the laser a ``projector`` at o_l aimed at the centre of the
  lit cell, of ``irradiance`` E = I / π and ``scale`` k = 1.

The intensity mapping: Mitsuba's projector returns, toward a point at
distance d seen at angle θ off its axis, π E k / (d² cos³ θ)
(``src/emitters/projector.cpp``: irradiance E on its image plane at unit
distance); on its axis that is a point source of intensity π E k, so
E = I / π gives the scene's I. mitransient's confocal and exhaustive
captures evaluate it on the axis; a single scan's laser point is on it.

Only single and confocal scans are exported for mitransient (an exhaustive
scan is refused in one line); a pulse other than the impulse, a value
float32 cannot hold, or a laser or sensor line that the hidden rectangle
blocks (mitransient traces them; the model assumes them clear) are refused.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from analytic.files import float32_problem
from analytic.scenes.relay_wall import RelayWallScene
from analytic.scenes.common import SceneError

from transient.scene_xml import (add, add_entries, number, point, scene_text, textured_diffuse, transform, waveform_entries,
                        write_scene_files)

__all__ = ["export_relay_wall", "hidden_to_world_matrix", "wall_to_world_matrix", "MITRANSIENT_SCANS",
           "PROJECTOR_FOV"]

#: Scans mitransient's export writes (an exhaustive one needs its laser grid equal to the read grid and an
#: exhaustive film; not written yet).
MITRANSIENT_SCANS = ("single", "confocal")

#: The projector's field of view, degrees: wide enough to hold the lit point as mitransient's rays find it
#: (moved off the axis by its ray offsets), narrow enough that 1/cos³ θ stays 1 there.
PROJECTOR_FOV = 2.0

_INTEGRATOR = "transient_opl_nlos"
_SENSOR = "omni_point"

#: Why a pulse (square, Butterworth, ...) is not exported for mitransient (the README quotes it). Its
#: point emitter emits a Dirac pulse and its film bins each path by floor((length - start_opl) /
#: bin_width_opl), a box; its integrators read ``temporal_filter`` and discard it. A pulse's bin is
#: ∫_bin (g * s) = ∫ g(τ) κ_n(τ) dτ, with κ_n a ramp wherever the pulse straddles a bin edge: box-binned
#: samples of g (sums of g over bins) give it only in the limit of ever finer bins, so no export is exact.
MITRANSIENT_IMPULSE_ONLY = ('mitransient renders the impulse response only; export the scene with '
                            'waveform = "impulse" and convolve, or use our render')


def hidden_to_world_matrix(scene: RelayWallScene) -> np.ndarray:
    """4 x 4 transform of the local rectangle [-1, 1]² onto the hidden rectangle, float64.

    Local x along u, local y along v, local +z (the normal Mitsuba's BSDF lights) along u x v, the
    lit face; the matrix of :func:`transient.mitsuba_scene.hidden_to_world`.
    """
    rectangle = scene.rectangle()
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2] = 0.5 * rectangle.u, 0.5 * rectangle.v, rectangle.normal
    matrix[:3, 3] = rectangle.corner + 0.5 * (rectangle.u + rectangle.v)
    return matrix


def wall_to_world_matrix(scene: RelayWallScene) -> np.ndarray:
    """4 x 4 transform of the local rectangle onto the relay wall (z = 0, normal +z, centred at the origin)."""
    return np.diag([0.5 * scene.wall_size[0], 0.5 * scene.wall_size[1], 1.0, 1.0])


def _moved(matrix: np.ndarray, shift: np.ndarray) -> np.ndarray:
    moved = matrix.copy()
    moved[:3, 3] += shift
    return moved


def _hidden(root, scene: RelayWallScene, shift: np.ndarray) -> None:
    shape = add(root, "shape", type="rectangle", id="hidden")
    transform(shape, "to_world", _moved(hidden_to_world_matrix(scene), shift))
    textured_diffuse(shape)


def _our_integrator(root, scene: RelayWallScene) -> None:
    sampling, scan = scene.sampling, scene.scan
    integrator = add(root, "integrator", type=_INTEGRATOR)
    add(integrator, "integer", "bins", value=int(sampling.count))
    add(integrator, "float", "start_opl", value=number(sampling.start_opl))
    add(integrator, "float", "bin_width_opl", value=number(sampling.bin_width_opl))
    add_entries(integrator, waveform_entries(scene.illumination, sampling.bin_width_opl))
    transform(integrator, "hidden_to_world", hidden_to_world_matrix(scene))
    add(integrator, "float", "wall_size_x", value=number(scene.wall_size[0]))
    add(integrator, "float", "wall_size_y", value=number(scene.wall_size[1]))
    add(integrator, "float", "wall_reflectance", value=number(scene.wall_reflectance))
    point(integrator, "laser_position", scene.laser_position)
    point(integrator, "sensor_position", scene.sensor_position)
    add(integrator, "string", "scan_type", value=scan.type)
    add(integrator, "integer", "grid_width", value=int(scan.grid[0]))
    add(integrator, "integer", "grid_height", value=int(scan.grid[1]))
    add(integrator, "boolean", "account_first_and_last_bounces",
        value=str(bool(scan.account_first_and_last_bounces)).lower())
    if scan.type == "single" and scan.laser_point is not None:
        point(integrator, "laser_point", scan.laser_point)
    if scan.type == "exhaustive" and scan.laser_grid is not None:
        add(integrator, "integer", "laser_grid_width", value=int(scan.laser_grid[0]))
        add(integrator, "integer", "laser_grid_height", value=int(scan.laser_grid[1]))
    sensor = add(root, "sensor", type=_SENSOR, id="sensor_000000")
    point(sensor, "position", scene.sensor_position)
    film = add(sensor, "film", type="hdrfilm")
    add(film, "integer", "width", value=1)
    add(film, "integer", "height", value=1)
    add(film, "string", "pixel_format", value="luminance")


def _mitransient(root, scene: RelayWallScene, shift: np.ndarray) -> None:
    sampling, scan = scene.sampling, scene.scan
    integrator = add(root, "integrator", type="transient_nlos_path")
    add(integrator, "integer", "filter_bounces", value=2)       # laser -> l -> x -> s: three scattering vertices
    add(integrator, "integer", "max_depth", value=4)            # above filter_bounces + 1 (mitransient warns at =)
    add(integrator, "string", "capture_type", value=scan.type)
    add(integrator, "boolean", "nlos_laser_sampling", value="true")
    add(integrator, "boolean", "nlos_hidden_geometry_sampling", value="true")
    add(integrator, "boolean", "nlos_hidden_geometry_sampling_includes_relay_wall", value="false")
    add(integrator, "boolean", "account_first_and_last_bounces",
        value=str(bool(scan.account_first_and_last_bounces)).lower())
    add(integrator, "string", "temporal_filter", value="box")
    wall = add(root, "shape", type="rectangle", id="relay_wall")
    transform(wall, "to_world", _moved(wall_to_world_matrix(scene), shift))
    bsdf = add(wall, "bsdf", type="diffuse")
    add(bsdf, "float", "reflectance", value=number(scene.wall_reflectance))
    sensor = add(wall, "sensor", type="nlos_capture_meter")
    point(sensor, "sensor_origin", scene.sensor_position + shift)
    confocal = scan.type == "confocal"
    if confocal:
        add(sensor, "integer", "original_film_width", value=int(scan.grid[0]))
        add(sensor, "integer", "original_film_height", value=int(scan.grid[1]))
    sampler = add(sensor, "sampler", type="independent")
    add(sampler, "integer", "sample_count", value="$spp")
    film = add(sensor, "film", type="transient_hdr_film")
    add(film, "integer", "width", value=1 if confocal else int(scan.grid[0]))
    add(film, "integer", "height", value=1 if confocal else int(scan.grid[1]))
    add(film, "integer", "temporal_bins", value=int(sampling.count))
    add(film, "float", "start_opl", value=number(sampling.start_opl))
    add(film, "float", "bin_width_opl", value=number(sampling.bin_width_opl))
    add(film, "rfilter", type="box")
    laser = add(root, "emitter", type="projector", id="laser")
    aim = add(laser, "transform", "to_world")
    add(aim, "lookat", origin=", ".join(number(v) for v in scene.laser_position + shift),
        target=", ".join(number(v) for v in scene.laser_points[0] + shift), up="0, 1, 0")
    add(laser, "float", "irradiance", value=number(scene.intensity / math.pi))      # I = π E k
    add(laser, "float", "scale", value="1.0")
    add(laser, "float", "fov", value=number(PROJECTOR_FOV))


def _check_mitransient(scene: RelayWallScene) -> None:
    if scene.scan.type not in MITRANSIENT_SCANS:
        raise SceneError("scan.type", f"export --format mitransient writes {' and '.join(MITRANSIENT_SCANS)} scans, "
                                      f"not {scene.scan.type!r}; export one laser point at a time as a single "
                                      f"scan, or use --format mitsuba (our plugins render every scan)")
    if scene.illumination.waveform != "impulse":
        raise SceneError("illumination.waveform", MITRANSIENT_IMPULSE_ONLY)
    problem = float32_problem([scene.intensity / math.pi])
    if problem is not None:
        raise SceneError("laser.intensity", f"mitransient reads the projector's irradiance I/π as float32, and "
                                            f"{problem}; scale the intensity into float32's range")


_README = {
    "mitsuba": """# {name}: a relay-wall capture for diffuse-imaging's plugins

`scene.xml` + `reflectance.exr`: the `transient_opl_nlos` integrator ({scan} scan, {pairs} (l, s)
pairs, {bins} bins of {width} m from start_opl = {start} m of path length, c = 1), the hidden
rectangle (id `hidden`) and a stand-in sensor. The integrator renders per unit laser intensity;
multiply by the scene's I = {intensity!r} W/sr:

```python
from transient.backend import select_variant
select_variant()
import mitsuba as mi
from transient.chunks import ReplicaLayout
scene = mi.load_file("scene.xml")
layout = ReplicaLayout.for_samples(2**20)
sums = scene.integrator().render_chunk_per_unit_intensity(scene, seed=0, layout=layout, first=0,
                                                          count=layout.samples)
replicas = sums / layout.size * {intensity!r}      # (R, P, N): R independent estimates of y
y = replicas.mean(axis=0)                        # (P, N) in the pair order of docs/design.md section 7
```
""",
    "mitransient": """# {name}: a relay-wall capture for mitransient

`scene.xml` + `reflectance.exr`: `transient_nlos_path` (filter_bounces = 2: the third bounce
laser -> l -> x -> s only), the relay wall with an `nlos_capture_meter` at o_s, the hidden
rectangle, and a `projector` laser of irradiance I/π (its on-axis intensity is π E k = I =
{intensity!r} W/sr). The film is the {grid_w} x {grid_h} scan grid, {bins} bins of {width} m from
start_opl = {start} m. Render it with 16 seeds (one file per seed: independent replicas, whose
sign flips, 16 or more, give the check's limits whatever the correlation between bins) in a mono variant:

```python
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_mono")
import mitransient
scene = mi.load_file("scene.xml", spp=2**18)
{render}
```

then judge the films against the exact model:

    diffuse-imaging check SCENE.toml --data render_*.npy --out check

Expect a small disagreement as given: mitransient's float32 ray offsets make its path lengths short
by about 1.5e-4 m near the origin (more far from it). Stating what mitransient computes, with no
fitted parameter, it agrees:

    diffuse-imaging check SCENE.toml --data render_*.npy --expect transient_nlos_path --out stated

or, in a test, `validation.assert_agrees("SCENE.toml", sorted(glob.glob("render_*.npy")),
expect="transient_nlos_path")` (docs/testing-your-renderer.md); `detectable` says the smallest scale
error and time shift the renders would flag half the time (docs/interop.md, "What mitransient does
differently, and by how much").
""",
}

_SINGLE = """for seed in range(16):
    film = np.array(mi.render(scene, seed=seed)[1])          # (H, W, T, C): row j, column i reads cell (i, j)
    np.save(f"render_{seed:02d}.npy", film)"""

# mitransient's confocal capture: a 1 x 1 film per lit point, the laser moved between renders. Aim at the
# cell's centre (pixel + 0.5): focus_emitter_at_relay_wall_pixel takes uv = pixel / size, a corner for whole pixels.
_CONFOCAL = """wall = next(shape for shape in scene.shapes() if shape.id() == "relay_wall")
laser = scene.emitters()[0]
width, height = {grid_w}, {grid_h}
for seed in range(16):
    film = np.zeros((height, width, {bins}, 1))
    for j in range(height):
        for i in range(width):
            mitransient.nlos.focus_emitter_at_relay_wall_pixel(mi.Point2f(i + 0.5, j + 0.5), wall, laser)
            image = np.array(mi.render(scene, seed=(seed * height + j) * width + i)[1])   # (1, 1, T, C)
            film[j, i] = image[0, 0, :, :1]
    np.save(f"render_{{seed:02d}}.npy", film)               # (H, W, T, 1), as a single scan's film"""


def export_relay_wall(scene: RelayWallScene, out_dir: str | Path, format: str, *, spp: int,
                      world_offset=None) -> dict[str, Path]:
    """Write ``scene.xml``, ``reflectance.exr`` and ``README.md`` of a relay-wall capture, atomically.

    Parameters
    ----------
    scene : RelayWallScene
        The capture.
    out_dir : str or Path
        Output folder (created).
    format : {"mitsuba", "mitransient"}
        Our ``transient_opl_nlos`` or mitransient's ``transient_nlos_path`` (module docstring).
    spp : int
        ``mitransient``: samples per film pixel (``$spp`` in the XML, overridden by
        ``mi.load_file(path, spp=...)``).
    world_offset : array_like, optional
        ``mitransient`` only: move the whole capture (wall, hidden rectangle, laser, sensor) by this vector,
        metres. The transient is unchanged in exact arithmetic; mitransient's float32 ray offsets grow with
        the coordinates' magnitude (docs/interop.md measures it). Not offered by the command line.

    Returns
    -------
    dict
        File name -> path written.

    Raises
    ------
    SceneError
        For mitransient: an exhaustive scan, a pulse other than the impulse, a laser or sensor line the
        hidden rectangle blocks, an intensity float32 cannot hold; for both: a hidden image float32
        cannot hold (Mitsuba's texture).
    """
    problem = float32_problem(scene.reflectance)
    if problem is not None:
        raise SceneError("hidden.reflectance", f"the exported texture is float32, as Mitsuba reads it, and "
                                               f"{problem}; scale the reflectance up (and the intensity down)")
    if format == "mitransient":
        _check_mitransient(scene)
    elif world_offset is not None:
        raise ValueError("world_offset: applies to format 'mitransient' only (our integrator's wall is at the origin)")
    shift = np.zeros(3) if world_offset is None else np.asarray(world_offset, dtype=np.float64).reshape(3)
    root = ET.Element("scene", version="3.0.0")
    if format == "mitransient":
        add(root, "default", "spp", value=int(spp))
        _mitransient(root, scene, shift)
    else:
        _our_integrator(root, scene)
    _hidden(root, scene, shift)
    text = scene_text(root, scene.name, format)
    sampling, (grid_w, grid_h) = scene.sampling, scene.scan.grid
    fields = dict(name=scene.name, scan=scene.scan.type, pairs=scene.sensor_count, bins=sampling.count,
                  width=sampling.bin_width_opl, start=sampling.start_opl, intensity=float(scene.intensity),
                  grid_w=grid_w, grid_h=grid_h)
    render = (_CONFOCAL.format(**fields) if scene.scan.type == "confocal" else _SINGLE)
    readme = _README[format].format(render=render, **fields)
    return write_scene_files(out_dir, scene.reflectance, text, readme)
