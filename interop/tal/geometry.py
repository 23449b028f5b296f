"""The geometries of a tal configuration: the relay wall, the hidden surface's pose, and their checks.

tal (y-tal 0.20.0) places every geometry by its ``to_world``: scale, then
rotate about x, y, z (degrees), then translate, each value through Python's
``or`` (a scale of 0 is 1). The relay wall must be an unmoved, unrotated
rectangle facing +z; the hidden surface is a rectangle or a planar OBJ
(:mod:`interop.tal.mesh`), which must lie in front of the wall, within the
lengths float64 resolves, and face every scanned point
(:mod:`interop.tal.config` reads the rest of the configuration).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from analytic.errors import SceneError
from analytic.scenes.relay_wall import Scan, grid_points
from analytic.scenes.common import MAX_LENGTH, MIN_LENGTH, _number
from analytic.values import exact

__all__ = ["GEOMETRY_KEYS", "tal_or", "to_world", "hidden_rectangle", "geometries", "wall_halves", "check_extent",
           "check_facing"]

GEOMETRY_KEYS = {"name", "description", "mesh", "material", "displacement_x", "displacement_y", "displacement_z",
                  "rot_degrees_x", "rot_degrees_y", "rot_degrees_z", "scale_x", "scale_y", "scale_z"}


def tal_or(value, default):
    """tal's ``value or default`` (0, None, False and "" take the default)."""
    return value if value else default


def to_world(geometry: dict, key: str) -> tuple[np.ndarray, np.ndarray]:
    """tal's to_world of a geometry: the 3 x 3 part Rz Ry Rx S and the translation."""
    values = {}
    for name in ("scale_x", "scale_y", "scale_z", "rot_degrees_x", "rot_degrees_y", "rot_degrees_z",
                 "displacement_x", "displacement_y", "displacement_z"):
        raw = geometry.get(name)
        if raw is not None:
            _number(f"{key}.{name}", raw)
        values[name] = float(tal_or(raw, 1.0 if name.startswith("scale") else 0.0))
        if name.startswith("scale") and values[name] < 0:
            raise SceneError(f"{key}.{name}", f"{raw}: a mirroring scale is not supported; rotate instead")
    matrix = np.diag([values["scale_x"], values["scale_y"], values["scale_z"]])
    for axis in "xyz":
        angle = math.radians(values[f"rot_degrees_{axis}"])
        c, s = math.cos(angle), math.sin(angle)
        i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
        rotation = np.eye(3)
        rotation[i, i], rotation[i, j], rotation[j, i], rotation[j, j] = c, -s, s, c
        matrix = rotation @ matrix
    translation = np.array([values["displacement_x"], values["displacement_y"], values["displacement_z"]])
    return matrix, translation


def hidden_rectangle(geometry: dict, key: str, cwd: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """The hidden geometry's (corner, u, v), u x v along its lit normal, in world metres, and an OBJ's
    outline (``(E, 2, 3)`` directed sides, for :func:`interop.tal.mesh.indicator_image`; None for a rectangle)."""
    from .mesh import planar_polygon, read_obj

    mesh = geometry.get("mesh")
    kind = mesh.get("type") if isinstance(mesh, dict) else None
    matrix, translation = to_world(geometry, key)
    if kind == "rectangle":
        with np.errstate(over="ignore", invalid="ignore"):       # beyond float64: check_extent refuses it
            return (matrix @ [-1.0, -1.0, 0.0] + translation, matrix @ [2.0, 0.0, 0.0], matrix @ [0.0, 2.0, 0.0],
                    None)
    if kind != "obj":
        raise SceneError(f"{key}.mesh.type", f"{kind!r}: the model holds one planar Lambertian polygon (a "
                                             f"rectangle, or a planar OBJ whose sides follow a pixel grid); "
                                             f"refused")
    filename = mesh.get("filename")
    if not isinstance(filename, str) or not filename:
        raise SceneError(f"{key}.mesh.filename", "an OBJ mesh needs its filename")
    path = Path(cwd) / filename
    if not path.is_file():
        raise SceneError(f"{key}.mesh.filename", f"{filename} is not a file in the working directory {cwd} "
                                                 f"(tal resolves it there, not beside the YAML); run from "
                                                 f"the folder tal render runs in")
    vertices, faces, normals = read_obj(path, f"{key}.mesh.filename")
    with np.errstate(over="ignore", invalid="ignore"):        # beyond float64: planar_polygon refuses it
        world = vertices @ matrix.T + translation
    if normals is not None:
        # normals go by the inverse transpose; only their directions count, so scale them to at most 1 first
        normals = normals / np.maximum(np.max(np.abs(normals), axis=1, keepdims=True), 1e-300)
        with np.errstate(over="ignore", invalid="ignore"):
            normals = normals @ np.linalg.inv(matrix)
    corner, u, v, outline = planar_polygon(world, faces, normals, f"{key}.mesh.filename", filename)
    # start at the corner whose u runs most nearly along +x (the image's columns), v along -y if it can
    for _ in range(4):
        if u[0] >= max(abs(u[1]), abs(v[0])) - 1e-12 * np.linalg.norm(u):
            break
        corner, u, v = corner + u, v, -u
    return corner, u, v, outline


def geometries(config: dict) -> tuple[dict, dict, str]:
    """The relay wall's and the one hidden geometry's mappings, and the hidden one's key."""
    geometry = config["geometry"]
    if not isinstance(geometry, list) or not all(isinstance(g, dict) for g in geometry):
        raise SceneError("geometry", "expected a list of geometry mappings")
    names = [g.get("name") for g in geometry]
    if len(set(map(str, names))) != len(names):
        raise SceneError("geometry", f"duplicated names {names} (tal refuses them)")
    wall_name = config["relay_wall"]
    if wall_name not in names:
        raise SceneError("relay_wall", f"{wall_name!r} is not a geometry's name ({names})")
    hidden = [g for g in geometry if g.get("name") != wall_name]
    if len(hidden) != 1:
        raise SceneError("geometry", f"{len(hidden)} hidden geometries; the model holds one planar hidden "
                                     f"polygon")
    for g in geometry:
        unknown = sorted(set(g) - GEOMETRY_KEYS)
        if unknown:
            raise SceneError(f"geometry[{g.get('name')}].{unknown[0]}",
                             f"unknown key (known: {', '.join(sorted(GEOMETRY_KEYS))})")
    return geometry[names.index(wall_name)], hidden[0], f"geometry[{hidden[0].get('name')}]"


def wall_halves(wall: dict, key: str) -> tuple[float, float]:
    """The relay wall's half sides; anything but an unmoved, unrotated rectangle facing +z refused."""
    kind = wall.get("mesh", {}).get("type") if isinstance(wall.get("mesh"), dict) else None
    if kind != "rectangle":
        raise SceneError(f"{key}.mesh.type", f"{kind!r}: the relay wall is a rectangle (tal warns that other "
                                             f"meshes get a wrong UV mapping)")
    missing = [name for name in ("displacement_x", "displacement_y", "displacement_z", "scale_x", "scale_y")
               if name not in wall]
    if missing:
        raise SceneError(f"{key}.{missing[0]}", "missing: tal reads the relay wall's displacement_x/y/z and "
                                                "scale_x/y itself (without a default) and fails without them")
    for axis in "xyz":
        if f"rot_degrees_{axis}" in wall:
            raise SceneError(f"{key}.rot_degrees_{axis}", "tal refuses a relay wall rotation (not yet implemented "
                                                         "there); rotate the rest of the scene instead")
        # a number first: tal reads it without a default, and a string or NaN is no position ("moved" would mislead)
        if _number(f"{key}.displacement_{axis}", wall[f"displacement_{axis}"]) != 0.0:
            raise SceneError(f"{key}.displacement_{axis}", "a moved relay wall is not modelled (the wall is z = 0 "
                                                           "at the origin); move the rest of the scene instead")
    if wall.get("scale_z") is not None:         # through tal's `or` in to_world: unset or 0 is 1
        _number(f"{key}.scale_z", wall["scale_z"])
    if float(tal_or(wall.get("scale_z"), 1.0)) <= 0:
        raise SceneError(f"{key}.scale_z", "the relay wall must face +z (scale_z = 1)")
    halves = []
    for axis in "xy":
        halves.append(_number(f"{key}.scale_{axis}", wall[f"scale_{axis}"], positive=True, length=True))
    return halves[0], halves[1]


def check_extent(corner, u, v, key: str) -> None:
    """Before any area or normal is formed: corners within ±MAX_LENGTH, sides of at least MIN_LENGTH."""
    with np.errstate(over="ignore", invalid="ignore"):
        corners = corner + np.array([[0, 0], [1, 0], [0, 1], [1, 1]]) @ np.array([u, v])
    far = float(np.max(np.abs(corners)))
    if not far <= MAX_LENGTH:
        raise SceneError(key, f"a corner at {exact(far)} m is beyond the ±{MAX_LENGTH:g} m this tool resolves in "
                              f"float64; scale it down")
    sides = [math.hypot(*map(float, edge)) for edge in (u, v)]       # hypot: no underflow (the scene's rule)
    if not min(sides) >= MIN_LENGTH:
        raise SceneError(key, f"its sides are {sides[0]!r} m and {sides[1]!r} m; the smallest length supported is "
                              f"{MIN_LENGTH:g} m: scale it up")


def check_facing(corner, u, v, halves, scan: Scan, laser: np.ndarray, key: str) -> None:
    """The hidden rectangle in front of the wall, its lit face toward every scanned point (the scene checks the
    laser's and the sensor's lines: :meth:`analytic.scenes.relay_wall.RelayWallScene.blocked`)."""
    corners = corner + np.array([[0, 0], [1, 0], [0, 1], [1, 1]]) @ np.array([u, v])
    if not np.all(corners[:, 2] > 0):
        raise SceneError(key, f"the hidden surface crosses or lies behind the relay wall (a corner at z = "
                              f"{corners[:, 2].min():.4g} m; tal's wall is z = 0, facing +z): move it to z > 0")
    normal = np.cross(u, v)
    size = (2 * halves[0], 2 * halves[1])
    points = [grid_points(scan.grid, size)]
    if scan.laser_point is not None:
        points.append(np.asarray(scan.laser_point)[None, :])
    elif scan.laser_grid is not None:
        points.append(grid_points(scan.laser_grid, size))
    points = np.vstack(points)
    if not np.all((points[:, None, :] - corners[None, :, :]) @ normal > 0):
        raise SceneError(key, f"its lit face (normal {np.round(normal / np.linalg.norm(normal), 6).tolist()}) does "
                              f"not face every scanned point of the wall; Mitsuba's diffuse BSDF is one-sided, so "
                              f"tal renders its back black: turn it to face the wall (a rectangle faces +z: "
                              f"rot_degrees_x: 180)")
