"""Scene files: TOML <-> :class:`analytic.scenes.common.Scene` (docs/design.md section 5), or
:class:`analytic.scenes.relay_wall.RelayWallScene` when the file has a ``[relay_wall]`` table (section 7).

Missing tables and keys take the defaults docs/design.md section 5 lists; an
unknown key is an error, so a typo never falls back to a default. Every bad
value is a :class:`~analytic.errors.SceneError` naming its key.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import re
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from ..measurement.detector import Detector
from ..errors import ImageError, OptionError, SceneError
from .kinds import is_scene
from ..formats import reader_for
from .reflectance import printable, read_reflectance, regular_file_problem
from .common import (MAX_SENSORS, illumination_keys, Illumination, Noise, Sampling, Scene, _integer, _number,
                    _point, sensor_grid)
from ..values import exact

__all__ = ["load_scene", "scene_of", "read_toml", "scene_from_dict", "scene_to_tables", "MAX_FILE_BYTES"]

#: Largest scene or sweep file read, bytes: a TOML scene is a few hundred bytes,
#: and a device such as /dev/zero must not be read until memory runs out.
MAX_FILE_BYTES = 1 << 20

#: The UTF-8 byte-order mark some editors (Windows Notepad) write first: accepted and skipped.
_UTF8_BOM = b"\xef\xbb\xbf"
# other byte-order marks: the file is not UTF-8 (UTF-32 first: its little-endian mark starts as UTF-16's)
_OTHER_BOMS = ((b"\x00\x00\xfe\xff", "UTF-32 (big-endian)"), (b"\xff\xfe\x00\x00", "UTF-32 (little-endian)"),
               (b"\xfe\xff", "UTF-16 (big-endian)"), (b"\xff\xfe", "UTF-16 (little-endian)"))
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_TOML_PLACE = re.compile(r"^(?P<reason>.*) \(at (?:line (?P<line>\d+), column (?P<column>\d+)|end of document)\)$")

# TOML keys of [sampling] -> Sampling fields
_SAMPLING_FIELDS = {"period": "bin_width_opl", "start": "start_opl", "count": "count"}

class _IlluminationKeys:
    """``[illumination]``'s keys, read from the waveform registry when asked (one registered later counts)."""

    def __contains__(self, key) -> bool:
        return key == "waveform" or key in illumination_keys()

    def __iter__(self):
        return iter(("waveform", *illumination_keys()))


_SCHEMA = {
    "name": None,
    "plane": {"size", "pixels", "reflectance"},
    "source": {"position", "intensity"},
    "illumination": _IlluminationKeys(),
    "sensors": {"positions", "grid", "extent", "center"},
    "sampling": {"period", "start", "count"},
    "model": {"attenuation", "tolerance"},
    "noise": {"kind", "sigma", "photons", "seed"},
    "detector": {"photons", "background", "cycles", "dead_time", "seed"},
}


def _table(data: dict, name: str, schema: dict = _SCHEMA) -> dict:
    table = data.get(name, {})
    if isinstance(table, list):
        raise SceneError(name, f"expected one table [{name}], got an array of tables [[{name}]]; "
                               f"write [{name}] once")
    if not isinstance(table, dict):
        raise SceneError(name, f"expected a table [{name}], got {table!r}")
    for key in table:
        if key not in schema[name]:
            raise SceneError(f"{name}.{_key_name(key)}", _unknown_key(key, schema[name]))
    return table


def _key_name(key: str) -> str:
    """A key as TOML spells it: bare when it can be, else quoted (an empty key, one with a dot or space)."""
    return key if _BARE_KEY.fullmatch(key) else printable(json.dumps(key, ensure_ascii=False))


def _unknown_key(key: str, known) -> str:
    problem = f"unknown key (known: {', '.join(sorted(known))})"
    if "." in key:
        problem += (f"; the quotes make {_key_name(key)} one key with a dot in its name: "
                    f"write it without quotes for a dotted key")
    return problem


def _refuse_dates(value: Any, key: str) -> None:
    """Refuse a TOML date or time anywhere: no scene key takes one, and its repr would be the message."""
    if isinstance(value, (datetime.date, datetime.time)):      # datetime is a date
        raise SceneError(key, f"got the TOML date/time {value.isoformat()}; no scene key takes a date "
                              f"(a number or a string in quotes was meant?)")
    if isinstance(value, dict):
        for inner, item in value.items():
            _refuse_dates(item, f"{key}.{_key_name(inner)}" if key else _key_name(inner))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _refuse_dates(item, f"{key}[{index}]")


#: The tables of a relay-wall (NLOS) scene file (docs/design.md section 7).
_RELAY_WALL_SCHEMA = {
    "name": None,
    "relay_wall": {"size", "reflectance"},
    "hidden": {"center", "u", "v", "pixels", "reflectance"},
    "laser": {"position", "intensity"},
    "sensor": {"position"},
    "scan": {"type", "grid", "laser_point", "laser_grid", "account_first_and_last_bounces"},
    "illumination": _SCHEMA["illumination"],
    "sampling": _SCHEMA["sampling"],
    "model": {"tolerance"},
    "noise": _SCHEMA["noise"],
    "detector": _SCHEMA["detector"],
}


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
    """Build a scene from the TOML tables of docs/design.md section 5.

    Parameters
    ----------
    data : dict
        Parsed TOML. Missing tables and keys take the defaults of docs/design.md
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
    _refuse_dates(data, "")
    if "relay_wall" in data:
        return _relay_wall_scene(data, base_dir, name)
    for key in data:
        if key not in _SCHEMA:
            raise SceneError(_key_name(key), _unknown_key(key, _SCHEMA))
    plane = _table(data, "plane")
    source = _table(data, "source")
    illumination = _table(data, "illumination")
    sampling = _table(data, "sampling")
    model = _table(data, "model")
    pixels = _integer("plane.pixels", plane.get("pixels", 50))
    reflectance = _image(plane, "plane.reflectance", pixels, base_dir)
    noise = Noise(**_table(data, "noise")) if "noise" in data else None
    return Scene(
        detector=_detector(data),
        name=_label(data, name),
        size=plane.get("size", 1.0),
        pixels=pixels,
        reflectance=reflectance,
        source=source.get("position", (0.5, 0.5, 1.0)),
        intensity=source.get("intensity", 1.0),
        sensors=_sensors(_table(data, "sensors")),
        illumination=_illumination(illumination, base_dir),
        sampling=Sampling(**{_SAMPLING_FIELDS[key]: value for key, value in sampling.items()}),
        attenuation=model.get("attenuation", "lambertian"),
        tolerance=model.get("tolerance", 1e-6),
        noise=noise,
    )


def _illumination(table: dict, base_dir) -> Illumination:
    """``[illumination]``, a sampled response's ``file`` read relative to the scene file."""
    table = dict(table)
    if "file" in table:
        if "samples" in table:
            raise SceneError("illumination.samples", "give the samples in a file or inline, not both")
        name = table["file"]
        if not isinstance(name, str) or not name:
            raise SceneError("illumination.file", f"expected a file name (.npy or .csv, relative to the scene "
                                                  f"file), got {name!r}")
        from ..waveforms.measured import histogram_axis, is_histogram, read_samples

        path = Path(base_dir) / name
        table["samples"] = read_samples(path)
        if is_histogram(path):
            _histogram_spacing(table, *histogram_axis(path))
    return Illumination(**table)


def _histogram_spacing(table: dict, width: float, start: float) -> None:
    """A tal histogram's own spacing (the scene's must equal it) and, unless the scene sets one, its start."""
    from ..waveforms.measured import sample_width_metres

    given = [key for key in ("sample_width", "sample_width_ps") if table.get(key) is not None]
    if not given:
        table["sample_width"] = width
    elif len(given) == 1:
        try:
            stated = sample_width_metres(table.get("sample_width"), table.get("sample_width_ps"))
        except (TypeError, ValueError):
            stated = None     # not a number: Illumination names the key
        if stated is not None and not math.isclose(stated, width, rel_tol=1e-9):
            raise SceneError(f"illumination.{given[0]}", f"{exact(stated)} m differs from the file's delta_t, "
                                                         f"{exact(width)} m; "
                                                         f"leave it out to use the file's")
    table.setdefault("start", start)


def _detector(data: dict, schema: dict = _SCHEMA) -> Detector | None:
    """``[detector]`` (docs/design.md section 8), or None when absent."""
    if "detector" not in data:
        return None
    table = _table(data, "detector", schema)
    if "photons" not in table:
        raise SceneError("detector.photons", "required: expected signal photons per laser cycle per unit of y")
    return Detector(**table)


def _label(data: dict, name: str) -> str:
    label = data.get("name", name)
    if not isinstance(label, str):
        raise SceneError("name", f"expected a string, got {label!r}")
    return printable(label)


def _image(table: dict, key: str, pixels: int, base_dir) -> Any:
    """A reflectance key: a number, an array, or an image file relative to the scene file."""
    reflectance = table.get("reflectance", 0.5)
    if isinstance(reflectance, str) and not reflectance:
        raise SceneError(key, "empty string; give a number in [0, 1] or an image file "
                              "(.png or .exr, relative to the scene file)")
    if isinstance(reflectance, str):
        try:
            return read_reflectance(Path(base_dir) / reflectance, pixels)
        except ImageError as error:
            raise SceneError(key, str(error)) from None
    return reflectance


def _relay_wall_scene(data: dict, base_dir, name: str):
    """A capture through a relay wall from the tables of docs/design.md section 7."""
    from .relay_wall import RelayWallScene, Scan

    for key in data:
        if key not in _RELAY_WALL_SCHEMA:
            problem = _unknown_key(key, _RELAY_WALL_SCHEMA)
            if key in ("plane", "source", "sensors"):
                problem = (f"not used with [relay_wall] (the hidden rectangle is [hidden], the laser [laser], "
                           f"the sensor [sensor], the read points [scan]); remove [{key}]")
            raise SceneError(_key_name(key), problem)
    tables = {key: _table(data, key, _RELAY_WALL_SCHEMA) for key in _RELAY_WALL_SCHEMA if key != "name"}
    wall, hidden, laser, scan = tables["relay_wall"], tables["hidden"], tables["laser"], tables["scan"]
    pixels = _integer("hidden.pixels", hidden.get("pixels", 32))
    defaults = RelayWallScene.__dataclass_fields__
    noise = Noise(**tables["noise"]) if "noise" in data else None
    return RelayWallScene(
        name=_label(data, name),
        wall_size=wall.get("size", defaults["wall_size"].default),
        wall_reflectance=wall.get("reflectance", defaults["wall_reflectance"].default),
        center=hidden.get("center", defaults["center"].default), u=hidden.get("u", defaults["u"].default),
        v=hidden.get("v", defaults["v"].default), pixels=pixels,
        reflectance=_image(hidden, "hidden.reflectance", pixels, base_dir),
        laser_position=laser.get("position", defaults["laser_position"].default),
        intensity=laser.get("intensity", defaults["intensity"].default),
        sensor_position=tables["sensor"].get("position", defaults["sensor_position"].default),
        scan=Scan(**scan),
        illumination=_illumination(tables["illumination"], base_dir),
        sampling=Sampling(**{_SAMPLING_FIELDS[key]: value for key, value in tables["sampling"].items()}),
        tolerance=tables["model"].get("tolerance", 1e-6),
        noise=noise,
        detector=_detector(data, _RELAY_WALL_SCHEMA),
    )


def scene_to_tables(scene: Scene) -> dict:
    """The scene as TOML tables that :func:`scene_from_dict` reads back to an equal scene.

    The reflectance is the image array itself (or its constant value when
    uniform); write it to a PNG or EXR to put it in a file.
    """
    # a sampled response's samples inline (the file they came from is a label; the tables stand alone)
    illumination = {key: list(value) if key == "samples" else value
                    for key in illumination_keys() if key != "file"
                    for value in [getattr(scene.illumination, key)] if value is not None}
    common = {"illumination": {"waveform": scene.illumination.waveform, **illumination},
              "sampling": {"period": scene.sampling.bin_width_opl, "start": scene.sampling.start_opl,
                           "count": scene.sampling.count}}
    tables = {"name": scene.name, **scene.to_tables(common)}
    if scene.noise is not None:
        noise = scene.noise
        own = {"sigma": noise.sigma} if noise.kind == "gaussian" else {"photons": noise.photons}
        tables["noise"] = {"kind": noise.kind, **own, "seed": noise.seed}
    if scene.detector is not None:
        tables["detector"] = scene.detector.as_dict()
    return tables


def load_scene(path: str | Path) -> Scene:
    """Read a scene TOML file, or another tool's scene file that :mod:`analytic.formats` has a reader for.

    A tal render configuration (``.yaml``/``.yml``) is read by :mod:`interop.tal.config` (registered by
    :mod:`interop.tal.formats`); a file of any other suffix is read as TOML.

    Parameters
    ----------
    path : str or Path
        The file; image paths inside it are relative to its folder.

    Raises
    ------
    SceneError
        Unreadable file, bad TOML, unknown key or bad value.
    """
    if isinstance(path, (str, Path)) and str(path) and Path(path).suffix.lower() not in ("", ".toml"):
        reader = reader_for("scene", Path(path).suffix)
        if reader is not None:
            return reader.read(path)           # another tool's scene file (a tal configuration: docs/tal.md)
    data = read_toml(path, "scene")
    path = Path(path)
    return scene_from_dict(data, path.parent, name=path.stem)


def read_text(path: str | Path, what: str = "scene", *, language: str = "TOML") -> tuple[str, str]:
    """The UTF-8 text of a scene file of at most :data:`MAX_FILE_BYTES`, and its printable name.

    Raises
    ------
    SceneError
        Naming the file: empty path, missing, not a regular file, too large, not UTF-8 (as :func:`read_toml`).
    """
    if isinstance(path, str) and not path:
        raise SceneError(f"{what} file", f"empty path; give a {language} {what} file")
    if not isinstance(path, (str, os.PathLike)):
        raise SceneError(f"{what} file", f"expected a path (str or pathlib.Path), got {type(path).__name__} "
                                         f"{printable(repr(path))[:60]}")
    path = Path(path)
    shown = printable(str(path))
    problem = regular_file_problem(path)
    if problem is not None:
        raise SceneError(shown, f"cannot read {what} file: {problem}")
    try:
        with open(path, "rb") as stream:
            raw = stream.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise SceneError(shown, f"cannot read {what} file ({error.strerror})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise SceneError(shown, f"{what} file larger than {MAX_FILE_BYTES // 1024} KiB; "
                                f"is it really a {language} {what} file?")
    return _decode(raw, shown, what), shown


def read_toml(path: str | Path, what: str = "scene") -> dict:
    """Parse a TOML file of at most :data:`MAX_FILE_BYTES`, UTF-8.

    A UTF-8 byte-order mark at the start is accepted and skipped (editors
    such as Windows Notepad write one; TOML's own parser would refuse it).

    Raises
    ------
    SceneError
        Naming the file: empty path, missing, not a regular file (a folder, a
        FIFO, a device, a broken or looping link), too large, not UTF-8
        (UTF-16 or UTF-32, NUL bytes, Latin-1), not valid TOML (naming the
        line and, for a key or table given twice, saying so), or without any
        key.
    """
    text, shown = read_text(path, what)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(shown, _toml_problem(error, text)) from None
    except ValueError:          # int() past Python's digit limit, raised by tomllib as it is
        raise SceneError(shown, f"{what} file holds a whole number of more than {sys.get_int_max_str_digits()} "
                                f"digits, which no key takes; shorten it") from None
    if not data:
        raise SceneError(shown, f"{what} file has no keys (is it empty?); write its tables as in the "
                                f"README's examples")
    return data


def _decode(raw: bytes, shown: str, what: str) -> str:
    """UTF-8 text of a TOML file, a leading UTF-8 byte-order mark dropped; other encodings refused by name."""
    raw = raw.removeprefix(_UTF8_BOM)
    for mark, encoding in _OTHER_BOMS:
        if raw.startswith(mark):
            raise SceneError(shown, f"{what} file is {encoding} text, not UTF-8 (it starts with that "
                                    f"byte-order mark); save it as UTF-8")
    if b"\0" in raw:
        line = raw[:raw.index(b"\0")].count(b"\n") + 1
        raise SceneError(shown, f"{what} file is not UTF-8 text: NUL byte on line {line} (UTF-16 "
                                f"without a byte-order mark, or not a text file?); save it as UTF-8")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as error:
        line = raw[:error.start].count(b"\n") + 1
        raise SceneError(shown, f"{what} file is not UTF-8 text: byte 0x{raw[error.start]:02X} on line "
                                f"{line} (Latin-1 or Windows-1252?); save it as UTF-8") from None


def _toml_problem(error: tomllib.TOMLDecodeError, text: str) -> str:
    """One line from tomllib's error: where, the line's text, what is wrong, how to fix it."""
    match = _TOML_PLACE.match(" ".join(str(error).split()))
    if match is None:
        return f"invalid TOML ({printable(str(error))})"
    reason = match["reason"]
    if match["line"] is None:
        return f"invalid TOML at the end of the file: {reason}; is the last line complete?"
    line, column = int(match["line"]), int(match["column"])
    source = text.split("\n")[line - 1].rstrip("\r") if line <= text.count("\n") + 1 else ""
    quoted = printable(source.strip()[:80])
    place = f"invalid TOML at line {line}, column {column} ({quoted})"
    declared = re.fullmatch(r"Cannot declare \((.*)\) twice", reason)
    if reason == "Cannot overwrite a value":
        return (f"{place}: sets a value that is already set (a key given twice, or a key set again "
                f"as a table); give each key once")
    if declared:
        table = ".".join(part.strip().strip("'\"") for part in declared[1].split(",") if part.strip())
        return (f"{place}: table [{printable(table)}] is declared twice (or was already made by a dotted "
                f"key or an inline table); merge its keys into one [{printable(table)}] table")
    if reason.startswith("Cannot mutate immutable namespace"):
        return (f"{place}: adds to a table or array given inline (key = {{...}} or [...]), which "
                f"cannot be extended; write all its keys in one place")
    if "\r" in source.rstrip("\r"):
        return (f"{place}: a carriage return without a line feed (old Mac line endings); save the "
                f"file with LF or CRLF line endings")
    return f"{place}: {printable(reason)}; fix the TOML syntax there"


def scene_of(scene):
    """A scene object, loaded when given as a path (TOML or tal YAML, as ``check``'s SCENE).

    Raises
    ------
    SceneError
        A bad scene file.
    OptionError
        Neither a scene nor a path.
    """
    if is_scene(scene):
        return scene
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene)
    raise OptionError(f"scene: expected a Scene, a RelayWallScene or a scene file's path (TOML or tal YAML), "
                      f"got {type(scene).__name__}")
