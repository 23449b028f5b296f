"""tal's render configuration (a YAML file for ``tal render``) as the relay-wall scene tal renders.

tal (y-tal 0.20.0, ``tal/render/render.py`` and
``tal/render/mitsuba3_transient_nlos.py``) reads the YAML with
``yaml.safe_load``, merges it shallowly over its ``scene_defaults.yaml``
(a ``geometry:`` list replaces the default list whole), writes a Mitsuba 3
scene for mitransient's ``transient_nlos_path`` and an ``nlos_capture_meter``
on the relay wall, and stores the capture as HDF5. What each key used here
means there, and so here (docs/tal.md has the table):

- every geometry's ``to_world`` (:mod:`interop.tal.geometry`) is scale,
  then rotate about x, y, z (degrees, right-handed), then translate:
  T Rz Ry Rx S, each value through Python's
  ``or`` (a scale of 0 is 1); a ``rectangle`` is [-1, 1]² at z = 0 with normal
  +z; an OBJ ``filename`` is resolved against the working directory, and a
  planar OBJ polygon is its bounding rectangle with the polygon's indicator
  image as the reflectance, exact when its sides lie on the pixel grid
  (:mod:`interop.tal.mesh`; refused otherwise);
- the relay wall is a ``rectangle`` of ``scale_x`` x ``scale_y`` half sides at
  the origin facing +z; read points are the cell centres of a
  ``sensor_width`` x ``sensor_height`` grid over it; confocal and exhaustive
  scans light cell centres of the ``laser_width`` x ``laser_height`` grid; a
  single scan lights ``laser_lookat_x/y`` / W (a cell corner for whole
  numbers; 0 counts as unset, which is the wall's centre);
- the laser is a ``projector`` of irradiance E (``laser_emission``) and
  scale 1: its on-axis intensity is π E per channel; materials ``white``
  (diffuse 1) and ``custom`` diffuse reflectances; an RGB variant's three
  channels are summed into H, so the scene's I ρ_w² ρ_h is Σ_c π E_c ρ_w,c² ρ_h,c;
- bins: ``num_bins`` of ``bin_width_opl`` from ``start_opl``, a box filter
  (the impulse response, binned).

Where tal's files say otherwise than what it renders, the scene is what it
renders and one line says so (:class:`TalConfigWarning`):
``account_first_and_last_bounces: true`` reaches only the capture meter,
which ignores it, so the path lengths never include the first and last legs
while the HDF5 says they do (:attr:`TalScene.stated_accounts_first_and_last_bounces`
keeps the file's flag for ``check``). Everything the exact model cannot
hold is refused in one line naming the key: another hidden shape or
material, a partial laser aperture, a moved or rotated relay wall,
spectral or polarized variants, the frequency histogram.

The keys tal does not read are refused (a typo never falls back to a
default), except the ``diffuse_imaging`` table, ours, which tal ignores:
``pixels`` (M of the hidden image, default 32), ``tolerance`` and ``noise``
(as in a TOML scene).
"""

from __future__ import annotations

import math
import os
import re
import sys
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analytic.errors import SceneError
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.resources import require_memory
from analytic.scenes.common import MAX_INTENSITY, Noise, Sampling, _integer, _number
from .geometry import check_extent, check_facing, geometries, hidden_rectangle, tal_or, wall_halves

__all__ = ["TalScene", "TalConfigWarning", "load_tal_config", "tal_config_scene", "is_tal_config",
           "TAL_DEFAULTS", "TAL_VERSION"]

#: The tal release whose behaviour is modelled.
TAL_VERSION = "0.20.0"

#: The defaults this reader relies on: the values of y-tal 0.20.0's ``tal/render/scene_defaults.yaml``
#: (GPL-3.0; reproduced as facts, the file is not vendored). ``mitsuba_variant`` is the mitsuba3
#: backend's ``get_default_variant()``, which tal puts in place of the file's placeholder.
TAL_DEFAULTS: dict[str, Any] = {
    "mitsuba_variant": "llvm_ad_rgb", "integrator_max_depth": -1, "integrator_filter_bounces": -1,
    "integrator_discard_direct_paths": False, "integrator_nlos_laser_sampling": True,
    "integrator_nlos_hidden_geometry_sampling": False,
    "integrator_nlos_hidden_geometry_sampling_do_rroulette": False,
    "integrator_nlos_hidden_geometry_sampling_includes_relay_wall": True, "sample_count": 1_000_000,
    "account_first_and_last_bounces": False, "num_bins": 4096, "bin_width_opl": 0.003, "start_opl": 0.0,
    "auto_detect_bins": False, "histogram_mode": "time", "wl_mean": None, "wl_sigma": None,
    "scan_type": "single", "sensor_x": -0.5, "sensor_y": 0.0, "sensor_z": 0.25, "laser_x": -0.5,
    "laser_y": 0.0, "laser_z": 0.25, "sensor_width": 256, "sensor_height": 256, "laser_lookat_x": None,
    "laser_lookat_y": None, "laser_width": 32, "laser_height": 32, "laser_aperture_start_x": 0,
    "laser_aperture_start_y": 0, "laser_aperture_end_x": 1, "laser_aperture_end_y": 1,
    "laser_emission_mode": "rgb", "laser_emission": "1.0, 1.0, 1.0",
    "geometry": [
        {"name": "Z", "mesh": {"type": "obj", "filename": "./Z.obj"}, "displacement_x": 0.0,
         "displacement_y": 0.0, "displacement_z": 0.0, "rot_degrees_x": 0.0, "rot_degrees_y": 0.0,
         "rot_degrees_z": 0.0, "scale_x": 1, "scale_y": 1, "scale_z": 1, "material": {"id": "white"}},
        {"name": "relay_wall", "mesh": {"type": "rectangle"}, "displacement_x": 0.0, "displacement_y": 0.0,
         "displacement_z": 0.0, "scale_x": 1, "scale_y": 1, "scale_z": 1, "material": {"id": "white"}},
    ],
    "relay_wall": "relay_wall",
}

#: Keys of later tal releases that 0.20 does not read (its examples carry them): accepted, said in one line.
_LATER_KEYS = ("simultaneous_scan", "integrator_force_equal_illumination_scanning",
               "integrator_illumination_scan_fov")
_OURS = "diffuse_imaging"
_OUR_KEYS = {"pixels", "tolerance", "noise"}


class TalConfigWarning(UserWarning):
    """A tal configuration whose files state something other than what tal renders (one line each)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class TalScene(RelayWallScene):
    """A relay-wall scene read from a tal configuration: the capture ``tal render`` makes of it.

    Parameters
    ----------
    stated_accounts_first_and_last_bounces : bool
        The ``t_accounts_first_and_last_bounces`` that tal writes into the
        capture (the YAML's flag), which its render does not honour; the
        scene's own ``scan.account_first_and_last_bounces`` is what it renders
        (false). ``check`` takes a capture stating this flag.
    config : str
        The configuration file read.
    """

    stated_accounts_first_and_last_bounces: bool = False
    config: str = ""

    @property
    def capture_accounts_flag(self) -> bool:
        """The flag a tal capture of this scene states (not what its path lengths hold)."""
        return bool(self.stated_accounts_first_and_last_bounces)


def is_tal_config(path: str | Path) -> bool:
    """Whether a scene path names a tal configuration (``.yaml`` / ``.yml``)."""
    return Path(path).suffix.lower() in (".yaml", ".yml")


def load_tal_config(path: str | Path, *, cwd: str | Path | None = None) -> TalScene:
    """Read a tal render configuration as the scene tal renders.

    Parameters
    ----------
    path : str or Path
        The YAML file.
    cwd : str or Path, optional
        The folder OBJ file names are resolved against (tal's working
        directory; default: this process's).

    Raises
    ------
    SceneError
        Naming the key: unreadable file, bad YAML, an unknown key, a value
        tal would refuse, or a scene the exact model cannot hold.
    """
    import yaml

    from analytic.scenes.scene_file import read_text

    text, shown = read_text(path, "tal configuration", language="YAML")
    try:
        config = yaml.safe_load(text) or {}
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        reason = getattr(error, "problem", None) or type(error).__name__
        raise SceneError(shown, f"invalid YAML{where}: {reason}; fix the YAML syntax there") from None
    except ValueError:          # int() past Python's digit limit, raised by PyYAML as it is
        raise SceneError(shown, f"holds a whole number of more than {sys.get_int_max_str_digits()} digits, "
                                f"which no key takes; shorten it") from None
    if not isinstance(config, dict):
        raise SceneError(shown, f"a tal configuration is a mapping of keys, got {type(config).__name__}")
    return tal_config_scene(config, name=Path(path).stem, config=str(path), cwd=cwd)


def _flag(config: dict, key: str) -> bool:
    value = config[key]
    if not isinstance(value, bool):
        raise SceneError(key, f"expected true or false, got {value!r}")
    return value


def _channels(key: str, value: Any, count: int, *, unit: bool) -> np.ndarray:
    """A Mitsuba ``rgb``/``float`` value ("r, g, b", "x" or a number) as ``count`` channels."""
    if isinstance(value, bool):
        raise SceneError(key, f"expected a number or \"r, g, b\", got {value!r}")
    if isinstance(value, (int, float)):
        parts = [float(value)]
    elif isinstance(value, str):
        try:
            parts = [float(part) for part in re.split(r"[,\s]+", value.strip()) if part]
        except ValueError:
            raise SceneError(key, f"expected a number or \"r, g, b\", got {value!r}") from None
    else:
        raise SceneError(key, f"expected a number or \"r, g, b\", got {value!r}")
    if len(parts) not in (1, 3) or not all(math.isfinite(p) and p >= 0 for p in parts):
        raise SceneError(key, f"expected one or three finite values >= 0, got {value!r}")
    channels = np.array(parts * 3 if len(parts) == 1 else parts)
    if unit and channels.max() > 1.0:
        raise SceneError(key, f"a reflectance above 1 ({value!r}) is not Lambertian; give values in [0, 1]")
    if count == 1:
        if np.ptp(channels) != 0.0:
            raise SceneError(key, f"{value!r} is coloured, and a mono variant renders its luminance; give equal "
                                  f"channels (or use an rgb variant, whose channels tal sums)")
        return channels[:1]
    return channels


def _material(geometry: dict, key: str, count: int) -> np.ndarray:
    """A geometry's diffuse reflectance per channel: ``white`` or a ``custom`` diffuse BSDF."""
    material = geometry.get("material")
    if not isinstance(material, dict) or "id" not in material:
        raise SceneError(f"{key}.material", "expected a mapping with an id (white or custom)")
    if material["id"] == "white":
        return np.ones(count)
    if material["id"] != "custom":
        raise SceneError(f"{key}.material.id", f"{material['id']!r} is not Lambertian (tal's copper is a rough "
                                               f"conductor); the model holds white or a custom diffuse BSDF")
    text = material.get("text")
    if not isinstance(text, str):
        raise SceneError(f"{key}.material.text", "a custom material needs its BSDF as XML text")
    try:
        elements = list(ET.fromstring(f"<root>{text}</root>"))
    except ET.ParseError as error:
        raise SceneError(f"{key}.material.text", f"not valid XML ({error})") from None
    if len(elements) != 1 or elements[0].tag != "bsdf" or elements[0].get("type") != "diffuse":
        found = ", ".join(f"<{e.tag} type={e.get('type')!r}>" for e in elements) or "nothing"
        raise SceneError(f"{key}.material.text", f"holds {found}; the model holds one <bsdf type=\"diffuse\"> "
                                                 f"(Lambertian, one-sided)")
    reflectance = 0.5                                  # Mitsuba's diffuse default
    for child in elements[0]:
        if child.get("name") != "reflectance" or child.tag not in ("rgb", "float", "spectrum") or \
                (child.tag == "spectrum" and ":" in child.get("value", "")):
            raise SceneError(f"{key}.material.text", f"<{child.tag} name={child.get('name')!r}> in the diffuse "
                                                     f"BSDF: the model holds a constant reflectance (rgb, float "
                                                     f"or a one-value spectrum)")
        reflectance = child.get("value", "")
    return _channels(f"{key}.material.text", reflectance, count, unit=True)


def _variant_channels(config: dict) -> int:
    variant = config["mitsuba_variant"]
    if not isinstance(variant, str) or not re.fullmatch(r"(llvm|cuda)_(ad_)?(rgb|mono)(_double)?", variant):
        raise SceneError("mitsuba_variant", f"{variant!r}: the model holds tal's llvm_/cuda_ rgb and mono "
                                            f"variants (spectral and polarized ones are refused)")
    return 3 if "rgb" in variant else 1


def _check_integrator(config: dict) -> list[str]:
    """Refuse what the model cannot hold; the notes (:class:`TalConfigWarning`) on what tal renders otherwise."""
    for key in ("integrator_discard_direct_paths", "integrator_nlos_laser_sampling",
                "integrator_nlos_hidden_geometry_sampling", "integrator_nlos_hidden_geometry_sampling_do_rroulette",
                "integrator_nlos_hidden_geometry_sampling_includes_relay_wall", "auto_detect_bins"):
        _flag(config, key)
    depth = config["integrator_max_depth"]
    bounces = config["integrator_filter_bounces"]
    for key, value in (("integrator_max_depth", depth), ("integrator_filter_bounces", bounces)):
        if isinstance(value, bool) or not isinstance(value, int) or value < -1:
            raise SceneError(key, f"expected a whole number >= -1, got {value!r}")
    if depth != -1 and depth < 4:
        raise SceneError("integrator_max_depth", f"{depth}: the third bounce (laser -> l -> x -> s, path depth 3) "
                                                 f"needs a max_depth of at least 4 (or -1)")
    if bounces not in (-1, 2):
        raise SceneError("integrator_filter_bounces", f"{bounces}: tal renders only the paths of {bounces + 1} "
                                                      f"vertices; the model is the third bounce "
                                                      f"(integrator_filter_bounces: 2)")
    if tal_or(config["histogram_mode"], "time") != "time":
        raise SceneError("histogram_mode", f"{config['histogram_mode']!r}: the model writes time histograms "
                                           f"(histogram_mode: time)")
    notes = []
    if bounces == -1:
        notes.append("integrator_filter_bounces: -1 makes tal render every bounce; the model is the third "
                     "bounce (laser -> l -> x -> s) only, so the interreflections of the hidden rectangle and "
                     "the wall are missing from it; set integrator_filter_bounces: 2 to render what it models")
    if config["auto_detect_bins"]:
        notes.append("auto_detect_bins: tal 0.20 leaves it out of the film (commented out of its XML); the bins "
                     "are num_bins from start_opl")
    return notes


def _scan(config: dict, halves: tuple[float, float]) -> Scan:
    """The scan tal renders (the aperture, lookat and confocal rules of its render.py)."""
    kind = config["scan_type"]
    if kind not in ("single", "confocal", "exhaustive"):
        raise SceneError("scan_type", f"{kind!r}: tal's scans are single, confocal or exhaustive")
    width = _integer("sensor_width", config["sensor_width"])
    height = _integer("sensor_height", config["sensor_height"])
    if kind == "single":
        lookat = []
        for axis, size in (("x", width), ("y", height)):
            raw = config[f"laser_lookat_{axis}"]
            if raw is not None:
                _number(f"laser_lookat_{axis}", raw)
            pixel = float(tal_or(raw, size / 2))
            if not 0.0 <= pixel <= size:
                raise SceneError(f"laser_lookat_{axis}", f"{raw} lies off the wall's {size} pixels; give a "
                                                         f"pixel coordinate in [0, {size}]")
            lookat.append(pixel / size)
        point = [halves[0] * (2 * lookat[0] - 1), halves[1] * (2 * lookat[1] - 1), 0.0]
        return Scan(type="single", grid=(width, height), laser_point=point)
    laser = (_integer("laser_width", config["laser_width"]), _integer("laser_height", config["laser_height"]))
    aperture, partial = [], []
    for end, default in (("start", 0), ("end", 1)):
        for axis in "xy":
            key = f"laser_aperture_{end}_{axis}"
            if config[key] is not None:             # a string or a list is no fraction of the wall (nor NaN)
                _number(key, config[key])
            aperture.append(float(tal_or(config[key], default)))
            if aperture[-1] != default:
                partial.append(key)
    if partial:
        raise SceneError(partial[0], f"a partial laser aperture {aperture} is not modelled (and tal 0.20 writes "
                                     f"the whole wall's sensor_grid_xyz for a confocal scan while it reads the "
                                     f"aperture's points); scan the whole wall (0, 0, 1, 1)")
    if kind == "confocal":
        if laser != (width, height):
            raise SceneError("laser_width", f"{laser[0]} x {laser[1]} differs from sensor_width x sensor_height "
                                            f"{width} x {height}; tal refuses a confocal scan unless they match")
        return Scan(type="confocal", grid=(width, height))
    return Scan(type="exhaustive", grid=(width, height), laser_grid=laser)


def _emission(config: dict, count: int) -> np.ndarray:
    mode = tal_or(config["laser_emission_mode"], "rgb")
    value = tal_or(config["laser_emission"], "1.0, 1.0, 1.0")
    if mode == "mono":
        if isinstance(value, str) and re.search(r"[,\s:]", value.strip()):
            raise SceneError("laser_emission", f"{value!r}: laser_emission_mode mono takes one value")
    elif mode != "rgb":
        raise SceneError("laser_emission_mode", f"{mode!r}: the model holds rgb or mono emission (a spectrum "
                                                f"of wavelengths is refused)")
    emission = _channels("laser_emission", value, count, unit=False)
    if emission.max() > MAX_INTENSITY:            # before Σ E, π Σ E and the reflectances' weights overflow
        raise SceneError("laser_emission", f"{value!r}: an irradiance beyond {MAX_INTENSITY:g} (the laser's "
                                           f"intensity π Σ E is at most {MAX_INTENSITY:g} W/sr)")
    if not emission.sum() > 0:
        raise SceneError("laser_emission", "the laser emits nothing; give an irradiance > 0")
    return emission


_KEY_NAMES = {"relay_wall.size": "geometry[relay_wall].scale_x", "laser.position": "laser_z",
              "sensor.position": "sensor_z", "laser.intensity": "laser_emission", "scan.grid": "sensor_width",
              "scan.laser_point": "laser_lookat_x", "scan.laser_grid": "laser_width", "sampling.count": "num_bins",
              "sampling.period": "bin_width_opl", "sampling.start": "start_opl",
              "model.tolerance": f"{_OURS}.tolerance", "hidden.pixels": f"{_OURS}.pixels"}


def tal_config_scene(data: dict, *, name: str = "tal", config: str = "",
                     cwd: str | Path | None = None) -> TalScene:
    """The scene tal renders from a parsed configuration (merged here over :data:`TAL_DEFAULTS`).

    Parameters
    ----------
    data : dict
        The YAML's mapping, as ``yaml.safe_load`` gives it.
    name : str
        The scene's name when the configuration has no ``name``.
    config : str
        The file it came from (recorded on the scene).
    cwd : str or Path, optional
        Where OBJ file names are resolved (tal's working directory; default: this process's).

    Raises
    ------
    SceneError
        Naming tal's key (module docstring).
    """
    for key in data:
        if not isinstance(key, str) or (key not in TAL_DEFAULTS and key not in ("name", _OURS) + _LATER_KEYS):
            raise SceneError(str(key), f"unknown key for tal {TAL_VERSION} (tal would ignore it; a typo?)")
    # the notes (TalConfigWarning) are said once the whole configuration is accepted: a refusal is one line
    notes = []
    later = [key for key in _LATER_KEYS if key in data]
    if later:
        notes.append(f"{', '.join(later)}: keys of later tal releases that tal {TAL_VERSION} does not read; "
                     f"the scene is what {TAL_VERSION} renders")
    merged = {**TAL_DEFAULTS, **data}                                  # tal's shallow merge
    ours = merged.get(_OURS) or {}
    if not isinstance(ours, dict):
        raise SceneError(_OURS, f"expected a mapping of {', '.join(sorted(_OUR_KEYS))}, got {ours!r}")
    if set(ours) - _OUR_KEYS:
        raise SceneError(f"{_OURS}.{sorted(map(str, set(ours) - _OUR_KEYS))[0]}",
                         f"not a key of ours here; the keys are {', '.join(sorted(_OUR_KEYS))}")
    label = merged.get("name", name)
    if not isinstance(label, str):
        raise SceneError("name", f"expected a string, got {label!r}")
    count = _variant_channels(merged)
    notes += _check_integrator(merged)
    wall, hidden, hidden_key = geometries(merged)
    halves = wall_halves(wall, f"geometry[{merged['relay_wall']}]")
    scan = _scan(merged, halves)
    try:
        scan.check_pairs()              # before check_facing builds the grids' points
    except SceneError as error:
        raise SceneError(_KEY_NAMES[error.key], error.problem) from None
    corner, u, v, outline = hidden_rectangle(hidden, hidden_key, Path(os.getcwd() if cwd is None else cwd))
    check_extent(corner, u, v, hidden_key)
    emission = _emission(merged, count)
    wall_channels = _material(wall, f"geometry[{merged['relay_wall']}]", count)
    hidden_channels = _material(hidden, hidden_key, count)
    rho_w, rho_h = _reflectances(emission, wall_channels, hidden_channels)
    stated = _flag(merged, "account_first_and_last_bounces")
    if stated:
        notes.append("account_first_and_last_bounces: true reaches only tal 0.20's capture meter, which ignores "
                     "it: the path lengths tal renders never include |o_l - l| + |s - o_s|, while its HDF5 says "
                     "they do (t_accounts_first_and_last_bounces); the scene is what it renders")
    position = {what: [merged[f"{what}_{axis}"] for axis in "xyz"] for what in ("laser", "sensor")}
    for what, values in position.items():
        for axis, value in zip("xyz", values):
            _number(f"{what}_{axis}", value, length=True)
    noise = ours.get("noise")
    if noise is not None and not isinstance(noise, dict):
        raise SceneError(f"{_OURS}.noise", "expected a mapping (kind, sigma or photons, seed)")
    pixels = _integer(f"{_OURS}.pixels", ours.get("pixels", 32))
    require_memory(8 * 8 * pixels**2, f"{_OURS}.pixels = {pixels}", "use fewer pixels")
    if outline is not None:
        from .mesh import indicator_image

        covered = indicator_image(outline, corner, u, v, pixels, f"{hidden_key}.mesh.filename",
                                  hidden["mesh"]["filename"], f"{_OURS}.pixels")
        if covered is not None:
            rho_h = rho_h * covered
    check_facing(corner, u, v, halves, scan, np.array(position["laser"], dtype=float), hidden_key)
    try:
        scene = TalScene(
            name=label, wall_size=(2 * halves[0], 2 * halves[1]), wall_reflectance=rho_w,
            center=corner + 0.5 * (u + v), u=u, v=v, pixels=pixels, reflectance=rho_h,
            laser_position=position["laser"], sensor_position=position["sensor"],
            intensity=math.pi * float(emission.sum()), scan=scan,
            sampling=Sampling(bin_width_opl=merged["bin_width_opl"], start_opl=merged["start_opl"],
                              count=merged["num_bins"]),
            tolerance=ours.get("tolerance", 1e-6), noise=None if noise is None else Noise(**noise),
            stated_accounts_first_and_last_bounces=stated, config=config)
    except SceneError as error:
        key = error.key
        mapped = _KEY_NAMES.get(key) or (f"{_OURS}.{key}" if key.startswith("noise") else
                                         hidden_key if key.startswith("hidden") else key)
        raise SceneError(mapped, error.problem) from None
    except TypeError as error:                        # Noise(**mapping) with a key it does not take
        raise SceneError(f"{_OURS}.noise", f"{error}; its keys are kind, sigma or photons, seed") from None
    for note in notes:
        warnings.warn(note, TalConfigWarning, stacklevel=3)
    return scene


def _reflectances(emission: np.ndarray, wall: np.ndarray, hidden: np.ndarray) -> tuple[float, float]:
    """ρ_w and ρ_h with I ρ_w² ρ_h = Σ_c π E_c ρ_w,c² ρ_h,c for I = π Σ_c E_c (the channels tal sums)."""
    if np.ptp(wall) == 0.0:
        return float(wall[0]), float(emission @ hidden / emission.sum())
    return 1.0, float(emission @ (wall**2 * hidden) / emission.sum())
