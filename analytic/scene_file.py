"""Scene files: TOML <-> :class:`analytic.scene.Scene` (DESIGN.md section 5).

Missing tables and keys take the defaults DESIGN.md section 5 lists; an
unknown key is an error, so a typo never falls back to a default. Every bad
value is a :class:`~analytic.errors.SceneError` naming its key.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ImageError, SceneError
from .reflectance import read_reflectance
from .scene import (MAX_SENSORS, Illumination, Noise, Sampling, Scene, _integer, _number, _point,
                    sensor_grid)

__all__ = ["load_scene", "read_toml", "scene_from_dict", "scene_to_tables", "MAX_FILE_BYTES"]

#: Largest scene or sweep file read, bytes: a TOML scene is a few hundred bytes,
#: and a device such as /dev/zero must not be read until memory runs out.
MAX_FILE_BYTES = 1 << 20

# TOML keys of [sampling] -> Sampling fields
_SAMPLING_FIELDS = {"period": "bin_width_opl", "start": "start_opl", "count": "count"}

_SCHEMA = {
    "name": None,
    "plane": {"size", "pixels", "reflectance"},
    "source": {"position", "intensity"},
    "illumination": {"waveform", "width", "cutoff", "duration", "order"},
    "sensors": {"positions", "grid", "extent", "center"},
    "sampling": {"period", "start", "count"},
    "model": {"attenuation", "tolerance"},
    "noise": {"kind", "sigma", "photons", "seed"},
}


def _table(data: dict, name: str) -> dict:
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise SceneError(name, "expected a table")
    for key in table:
        if key not in _SCHEMA[name]:
            raise SceneError(f"{name}.{key}", f"unknown key (known: {', '.join(sorted(_SCHEMA[name]))})")
    return table


def _label(text: str) -> str:
    """A printable label: file names that are not UTF-8 keep their readable part."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def _sensors(table: dict) -> Any:
    if "positions" in table:
        extra = {"grid", "extent", "center"} & table.keys()
        if extra:
            raise SceneError(f"sensors.{sorted(extra)[0]}", "give either positions or grid, not both")
        positions = table["positions"]
        if not isinstance(positions, list) or not positions:
            raise SceneError("sensors.positions", "expected a non-empty list of [x, y, z]")
        return positions
    if "grid" in table:
        grid = table["grid"]
        if not isinstance(grid, list) or len(grid) != 2:
            raise SceneError("sensors.grid", f"expected [nx, ny], got {grid!r}")
        shape = tuple(_integer(f"sensors.grid[{i}]", g, maximum=MAX_SENSORS) for i, g in enumerate(grid))
        if shape[0] * shape[1] > MAX_SENSORS:
            raise SceneError("sensors.grid", f"{shape[0]} x {shape[1]} sensors; at most {MAX_SENSORS} "
                                             f"are supported")
        extent = _number("sensors.extent", table.get("extent", 1.0), positive=True, length=True)
        if "center" not in table:
            raise SceneError("sensors.center", "required with sensors.grid")
        return sensor_grid(shape, extent, _point("sensors.center", table["center"]))
    raise SceneError("sensors", "give positions = [[x, y, z], ...] or grid = [nx, ny]")


def scene_from_dict(data: dict, base_dir: str | Path = ".", *, name: str = "scene") -> Scene:
    """Build a scene from the TOML tables of DESIGN.md section 5.

    Parameters
    ----------
    data : dict
        Parsed TOML. Missing tables and keys take the defaults of DESIGN.md
        section 5; unknown ones are errors. ``plane.reflectance`` may also be
        an ``(M, M)`` array (as :func:`scene_to_tables` gives).
    base_dir : str or Path
        Folder that relative image paths are resolved against.
    name : str
        Scene label when the file has no ``name`` key.

    Raises
    ------
    SceneError
        Naming the key and the problem.
    """
    for key in data:
        if key not in _SCHEMA:
            raise SceneError(key, f"unknown key (known: {', '.join(sorted(_SCHEMA))})")
    plane = _table(data, "plane")
    source = _table(data, "source")
    illumination = _table(data, "illumination")
    sampling = _table(data, "sampling")
    model = _table(data, "model")
    pixels = _integer("plane.pixels", plane.get("pixels", 50))
    reflectance = plane.get("reflectance", 0.5)
    if isinstance(reflectance, str):
        try:
            reflectance = read_reflectance(Path(base_dir) / reflectance, pixels)
        except ImageError as error:
            raise SceneError("plane.reflectance", str(error)) from None
    noise = Noise(**_table(data, "noise")) if "noise" in data else None
    label = data.get("name", name)
    if not isinstance(label, str):
        raise SceneError("name", f"expected a string, got {label!r}")
    return Scene(
        name=_label(label),
        size=plane.get("size", 1.0),
        pixels=pixels,
        reflectance=reflectance,
        source=source.get("position", (0.5, 0.5, 1.0)),
        intensity=source.get("intensity", 1.0),
        sensors=_sensors(_table(data, "sensors")),
        illumination=Illumination(**illumination),
        sampling=Sampling(**{_SAMPLING_FIELDS[key]: value for key, value in sampling.items()}),
        attenuation=model.get("attenuation", "lambertian"),
        tolerance=model.get("tolerance", 1e-6),
        noise=noise,
    )


def scene_to_tables(scene: Scene) -> dict:
    """The scene as TOML tables that :func:`scene_from_dict` reads back to an equal scene.

    The reflectance is the image array itself (or its constant value when
    uniform); write it to a PNG or EXR to put it in a file.
    """
    image = scene.reflectance
    uniform = bool(np.all(image == image.flat[0]))
    illumination = {key: getattr(scene.illumination, key)
                    for key in ("width", "cutoff", "duration", "order")
                    if getattr(scene.illumination, key) is not None}
    tables = {
        "name": scene.name,
        "plane": {"size": scene.size, "pixels": scene.pixels,
                  "reflectance": float(image.flat[0]) if uniform else np.array(image)},
        "source": {"position": scene.source.tolist(), "intensity": scene.intensity},
        "illumination": {"waveform": scene.illumination.waveform, **illumination},
        "sensors": {"positions": scene.sensors.tolist()},
        "sampling": {"period": scene.sampling.bin_width_opl, "start": scene.sampling.start_opl,
                     "count": scene.sampling.count},
        "model": {"attenuation": scene.attenuation, "tolerance": scene.tolerance},
    }
    if scene.noise is not None:
        noise = scene.noise
        own = {"sigma": noise.sigma} if noise.kind == "gaussian" else {"photons": noise.photons}
        tables["noise"] = {"kind": noise.kind, **own, "seed": noise.seed}
    return tables


def load_scene(path: str | Path) -> Scene:
    """Read a scene TOML file.

    Parameters
    ----------
    path : str or Path
        The file; image paths inside it are relative to its folder.

    Raises
    ------
    SceneError
        Unreadable file, bad TOML, unknown key or bad value.
    """
    path = Path(path)
    return scene_from_dict(read_toml(path, "scene"), path.parent, name=path.stem)


def read_toml(path: str | Path, what: str = "scene") -> dict:
    """Parse a TOML file of at most :data:`MAX_FILE_BYTES`, UTF-8.

    Raises
    ------
    SceneError
        Naming the file: missing, not a regular file, too large, not UTF-8,
        or not valid TOML.
    """
    path = Path(path)
    shown = _label(str(path))
    try:
        if not path.is_file():
            problem = "no such file" if not path.exists() else "not a regular file"
            raise SceneError(shown, f"cannot read {what} file ({problem})")
        with open(path, "rb") as stream:
            raw = stream.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise SceneError(shown, f"cannot read {what} file ({error.strerror})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise SceneError(shown, f"{what} file larger than {MAX_FILE_BYTES // 1024} KiB; "
                                f"is it really a TOML {what} file?")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError(shown, f"{what} file is not UTF-8 text (byte {error.start}); save it as UTF-8") \
            from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(shown, f"invalid TOML ({error})") from None
