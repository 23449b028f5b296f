"""The scene's continuous numbers as named parameters (docs/design.md section 9).

A parameter is one number of the scene, named by its scene-file key:
components as ``.x``, ``.y``, ``.z`` and list items by a 0-based index in
the scene's own order (``sensors.positions.3.z``). :func:`parameter` reads a
key (the bracket forms ``source.position[2]`` and
``sensors.positions[3][2]`` are aliases), :func:`value_of` gives its value
in a scene and :func:`with_values` the scene with some values changed,
validated again. Everything that differentiates, fits or bounds the model
(:mod:`.derivatives`, calibration, Cramér-Rao bounds) names its parameters
through here.

Three kinds of key are motions rather than stored numbers; their value in
a scene is 0 (or 1 for a scale) and :func:`with_values` applies them:

- ``plane.translation.*`` / ``plane.rotation.*`` (radians about the world
  axis through the plane's centre): the plane's frame is the scene's, so the
  plane moving is the source and sensors moving the other way (exactly the
  same light: a plane scene's attenuation depends only on positions
  relative to the plane);
- ``hidden.rotation.*``: the hidden rectangle's edge vectors turned about
  the world axis through its centre;
- ``plane.reflectance`` / ``hidden.reflectance``: a uniform scale s of the
  image (∂y/∂s at s = 1 is y).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from ..errors import OptionError, SceneError

__all__ = ["Parameter", "parameter", "parameters", "value_of", "with_values", "parameter_keys", "rotation"]

_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Parameter:
    """One named number of a scene.

    Attributes
    ----------
    key : str
        The canonical key (``sensors.positions.3.z``).
    stem : str
        The key without its indices (``sensors.positions``).
    index : tuple of int
        The list item and/or component (``(3, 2)``).
    unit : str
        ``"m"``, ``"rad"``, ``"W/sr"`` or ``"1"`` (a scale).
    """

    key: str
    stem: str
    index: tuple
    unit: str


def rotation(axis: int, angle: float) -> np.ndarray:
    """The 3 x 3 rotation by ``angle`` radians about world axis ``axis`` (0, 1, 2), right-handed."""
    c, s = np.cos(angle), np.sin(angle)
    matrix = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    matrix[i, i], matrix[i, j], matrix[j, i], matrix[j, j] = c, -s, s, c
    return matrix


# stem -> (scene kind, how many list indices, has a component, unit)
_STEMS = {
    "plane": {
        "source.position": (0, True, "m"), "sensors.positions": (1, True, "m"),
        "plane.size": (0, False, "m"), "plane.translation": (0, True, "m"), "plane.rotation": (0, True, "rad"),
        "plane.reflectance": (0, False, "1"), "source.intensity": (0, False, "W/sr"),
    },
    "relay_wall": {
        "laser.position": (0, True, "m"), "sensor.position": (0, True, "m"), "hidden.center": (0, True, "m"),
        "hidden.u": (0, True, "m"), "hidden.v": (0, True, "m"), "hidden.rotation": (0, True, "rad"),
        "hidden.reflectance": (0, False, "1"), "laser.intensity": (0, False, "W/sr"),
        "scan.laser_point": (0, True, "m"),
    },
}
_SHARED = {"sampling.start": (0, False, "m")}
_ILLUMINATION = ("width", "cutoff", "duration", "fwhm", "tail")


def _stems(scene) -> dict:
    stems = {**_STEMS.get(scene.kind, {}), **_SHARED}
    for name in _ILLUMINATION:
        if getattr(scene.illumination, name, None) is not None:
            stems[f"illumination.{name}"] = (0, False, "m")
    return stems


def parameter_keys(scene) -> list[str]:
    """Every key pattern of this scene (``{k}`` for a list index), for messages and ``--help``."""
    keys = []
    for stem, (lists, component, _unit) in _stems(scene).items():
        tail = ".{k}" * lists + (".x|y|z" if component else "")
        keys.append(stem + tail)
    return keys


def _canonical(key: str) -> str:
    """``a.b[3][2]`` -> ``a.b.3.z`` (the bracket aliases of docs/design.md section 9)."""
    match = re.fullmatch(r"([a-z_.]+?)((?:\[\d+\])+)", key)
    if not match:
        return key
    numbers = [int(n) for n in re.findall(r"\d+", match.group(2))]
    last = numbers.pop()
    if last > 2:
        return key
    return ".".join([match.group(1), *map(str, numbers), _AXES[last]])


def parameter(scene, key: str) -> Parameter:
    """The :class:`Parameter` a key names in this scene, or OptionError naming the keys it has.

    Parameters
    ----------
    scene : SceneKind
        A plane or relay-wall scene.
    key : str
        A key of docs/design.md section 9, or a bracket alias.
    """
    if not isinstance(key, str):
        raise OptionError(f"parameter: expected a key such as 'source.position.x', got {key!r}")
    name = _canonical(key.strip())
    stems = _stems(scene)
    for stem, (lists, component, unit) in stems.items():
        if name != stem and not name.startswith(stem + "."):
            continue
        parts = name[len(stem):].split(".")[1:] if name != stem else []
        if len(parts) != lists + component:
            break
        index = []
        for part in parts[:lists]:
            if not part.isdigit():
                break
            index.append(int(part))
        if len(index) != lists:
            break
        if lists and not index[0] < scene.sensor_count:
            raise OptionError(f"parameter: {key!r}: the scene has {scene.sensor_count} "
                                           f"{scene.row_noun}s (indices 0 to {scene.sensor_count - 1})")
        if component:
            axes = _AXES[:2] if stem == "scan.laser_point" else _AXES
            if parts[-1] not in axes:
                break
            index.append(_AXES.index(parts[-1]))
        if stem == "scan.laser_point" and scene.scan.type != "single":
            raise OptionError(f"parameter: {key!r} applies to a single scan, not {scene.scan.type!r}")
        if stem in ("hidden.u", "hidden.v"):
            _check_edge_component(scene, stem, index[-1])
        canonical = ".".join([stem, *map(str, index[:lists]), *(_AXES[i] for i in index[lists:])])
        return Parameter(canonical, stem, tuple(index), unit)
    raise OptionError(f"parameter: {key!r} is no parameter of this {scene.kind} scene; "
                                   f"expected one of {', '.join(parameter_keys(scene))}")


def parameters(scene, keys) -> list[Parameter]:
    """:func:`parameter` of each key; OptionError on a repeated key (two names of one number included)."""
    found = [parameter(scene, key) for key in keys]
    if not found:
        raise OptionError("parameters: name at least one parameter")
    seen = {}
    for key, item in zip(keys, found):
        if item.key in seen:
            raise OptionError(f"parameters: {key!r} names the same number as {seen[item.key]!r}; give it once")
        seen[item.key] = key
    return found


def _check_edge_component(scene, stem: str, axis: int) -> None:
    """SceneError for a component of an edge vector that cannot move alone: one along which the other
    edge is not 0 (changing it breaks u ⟂ v, which the scene requires)."""
    other, key = (scene.v, "hidden.v") if stem == "hidden.u" else (scene.u, "hidden.u")
    if abs(other[axis]) > 1e-9 * np.linalg.norm(other):
        raise SceneError(f"{stem}.{_AXES[axis]}", f"has no derivative on its own: {key}.{_AXES[axis]} = "
                                                  f"{float(other[axis])!r} is not 0, so changing it breaks u ⟂ v, "
                                                  f"which the scene requires; take the components along which "
                                                  f"{key} is 0, or hidden.rotation.*")


def value_of(scene, item: Parameter | str) -> float:
    """The parameter's value in the scene (0 for a motion, 1 for a scale), in its unit."""
    item = item if isinstance(item, Parameter) else parameter(scene, item)
    stem, index = item.stem, item.index
    if stem.endswith((".translation", ".rotation")):
        return 0.0
    if stem.endswith(".reflectance"):
        return 1.0
    if stem == "sampling.start":
        return float(scene.sampling.start_opl)
    if stem.startswith("illumination."):
        return float(getattr(scene.illumination, stem.split(".")[1]))
    if stem == "scan.laser_point":
        return float(scene.laser_points[0][index[0]])
    return float(np.asarray(getattr(scene, _FIELDS[stem]), dtype=np.float64)[index])


# stem -> the scene's field that stores it
_FIELDS = {"source.position": "source", "sensors.positions": "sensors", "plane.size": "size",
           "source.intensity": "intensity", "laser.position": "laser_position",
           "sensor.position": "sensor_position", "hidden.center": "center", "hidden.u": "u", "hidden.v": "v",
           "laser.intensity": "intensity"}


def with_values(scene, values: dict):
    """The scene with the named parameters set to the given values, validated again.

    Parameters
    ----------
    scene : SceneKind
    values : dict
        ``{key: value}`` in each parameter's unit. Motions (translations,
        rotations) and scales are relative to ``scene``: rotations first,
        then translations, then scales.

    Returns
    -------
    SceneKind
        A new scene; ``scene`` is unchanged. A value the scene refuses
        (a sensor below the plane) raises its SceneError.
    """
    items = [(parameter(scene, key), float(value)) for key, value in values.items()]
    changes: dict = {}

    def array(field):
        if field not in changes:
            changes[field] = np.array(getattr(scene, field), dtype=np.float64)
        return changes[field]

    order = {"rotation": 0, "translation": 1}
    for item, value in sorted(items, key=lambda pair: order.get(pair[0].stem.split(".")[-1], 2)):
        stem, index = item.stem, item.index
        if stem == "plane.rotation":
            # the plane turning by +value about an axis through its centre is the points turning by -value
            centre = np.array([0.5 * scene.size, 0.5 * scene.size, 0.0])
            turn = rotation(index[0], -value)
            array("source")[:] = centre + turn @ (array("source") - centre)
            array("sensors")[:] = centre + (array("sensors") - centre) @ turn.T
        elif stem == "plane.translation":
            array("source")[index[0]] -= value
            array("sensors")[:, index[0]] -= value
        elif stem == "hidden.rotation":
            turn = rotation(index[0], value)
            array("u")[:] = turn @ array("u")
            array("v")[:] = turn @ array("v")
        elif stem.endswith(".reflectance"):
            changes["reflectance"] = np.asarray(changes.get("reflectance", scene.reflectance)) * value
        elif stem == "sampling.start":
            changes["sampling"] = replace(scene.sampling, start_opl=value)
        elif stem.startswith("illumination."):
            light = changes.get("illumination", scene.illumination)
            changes["illumination"] = type(light)(waveform=light.waveform,
                                                  **{**dict(light.values), stem.split(".")[1]: value})
        elif stem == "scan.laser_point":
            point = np.array(scene.laser_points[0] if "scan" not in changes else changes["scan"].laser_point)
            point[index[0]] = value
            changes["scan"] = replace(changes.get("scan", scene.scan), laser_point=point)
        elif item.unit == "W/sr" or stem == "plane.size":
            changes[_FIELDS[stem]] = value
        else:
            array(_FIELDS[stem])[index] = value
    return scene.replace(**changes)
