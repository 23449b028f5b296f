"""What the model integrates over: a Lambertian rectangle in any pose and a list of point pairs.

Every measurement the project models is one bounce off a Lambertian
rectangle between two points: light leaves a *source* point, reaches x on
the rectangle, and goes on to a *sensor* point. The plane of the letter is
one instance (the rectangle [0, L]² at z = 0; the source and each sensor a
pair); a relay-wall (NLOS) capture is another (the hidden rectangle; a lit
wall point and a read wall point a pair, with the wall's cosines at both
ends and the laser's and sensor's legs added to the path). The model's
kernels see only

- a :class:`Rectangle`: its corner, two orthogonal edge vectors and its
  M x M pixels, and
- :class:`PointPairs`: for each pair p the two points, a path length added
  to every path (metres), an optional normal at each end (then the
  cosine between it and the direction to x multiplies the attenuation),
  a factor on the pair's row of A, and the attenuation kind,

and work in the rectangle's local frame (:func:`pair_table`): x and y along
its edges from its corner, heights along its normal.

Pixel p = r M + c (image row r from the top) covers the u-fraction
[c/M, (c+1)/M) and the v-fraction [1 - (r+1)/M, 1 - r/M): for the plane,
x ∈ [cΔ, (c+1)Δ), y ∈ [L - (r+1)Δ, L - rΔ) (docs/design.md section 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SceneError

__all__ = ["Rectangle", "PointPairs", "PAIR_DTYPE", "ATTENUATIONS", "pair_table", "plane_geometry"]

#: The attenuation kinds a pair may carry (the scene's ``[model] attenuation``; :mod:`analytic.attenuation`).
ATTENUATIONS = ("lambertian", "paper")

#: One pair in the rectangle's frame, as the compiled kernels read it (metres): the two points'
#: coordinates and heights, the path length added to every path of the pair, and for each end
#: whether a cosine multiplies the attenuation and its affine form n·(x - point) = c0 + cu x + cv y.
PAIR_DTYPE = np.dtype([
    ("source_x", np.float64), ("source_y", np.float64), ("source_height", np.float64),
    ("sensor_x", np.float64), ("sensor_y", np.float64), ("sensor_height", np.float64),
    ("offset", np.float64),
    ("source_cosine", np.bool_), ("source_cosine_0", np.float64), ("source_cosine_u", np.float64),
    ("source_cosine_v", np.float64),
    ("sensor_cosine", np.bool_), ("sensor_cosine_0", np.float64), ("sensor_cosine_u", np.float64),
    ("sensor_cosine_v", np.float64),
])


def _vector(name: str, value) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected 3 finite numbers, got {value!r}")
    return array


@dataclass(frozen=True, eq=False)
class Rectangle:
    """A Lambertian rectangle imaged as M x M pixels.

    Parameters
    ----------
    corner : array_like
        World position of the image's bottom-left corner (u- and
        v-fractions 0), metres.
    u : array_like
        Edge vector along the image's columns (left to right), metres.
    v : array_like
        Edge vector along the image's rows, bottom to top, metres;
        orthogonal to ``u``. The lit face's normal is u x v / |u x v|.
    pixels : int
        M.
    """

    corner: np.ndarray
    u: np.ndarray
    v: np.ndarray
    pixels: int

    def __post_init__(self):
        corner, u, v = (_vector(name, getattr(self, name)) for name in ("corner", "u", "v"))
        width, height = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        if not (width > 0 and height > 0):
            raise ValueError("u, v: the rectangle's edges must have positive length")
        if abs(float(u @ v)) > 1e-9 * width * height:
            raise ValueError("u, v: the rectangle's edges must be orthogonal")
        for name, array in (("corner", corner), ("u", u), ("v", v)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        if not (isinstance(self.pixels, (int, np.integer)) and self.pixels >= 1):
            raise ValueError(f"pixels: a whole number >= 1, got {self.pixels!r}")
        object.__setattr__(self, "pixels", int(self.pixels))

    @property
    def width(self) -> float:
        """|u|, metres."""
        return float(np.linalg.norm(self.u))

    @property
    def height(self) -> float:
        """|v|, metres."""
        return float(np.linalg.norm(self.v))

    @property
    def axes(self) -> np.ndarray:
        """``(3, 3)``: the unit vectors along u, along v, and the lit face's normal (rows)."""
        x_axis = self.u / self.width
        y_axis = self.v / self.height
        return np.array([x_axis, y_axis, np.cross(x_axis, y_axis)])

    @property
    def normal(self) -> np.ndarray:
        """The lit face's unit normal, u x v / |u x v|."""
        return self.axes[2]

    def local(self, points) -> np.ndarray:
        """World points ``(..., 3)`` in the rectangle's frame: (x along u, y along v, height along the normal)."""
        return (np.asarray(points, dtype=np.float64) - self.corner) @ self.axes.T

    def world(self, local) -> np.ndarray:
        """Points ``(..., 3)`` of the rectangle's frame in world coordinates (inverse of :meth:`local`)."""
        return np.asarray(local, dtype=np.float64) @ self.axes + self.corner

    def corners(self) -> np.ndarray:
        """``(4, 3)`` world corners."""
        return self.corner + np.array([np.zeros(3), self.u, self.v, self.u + self.v])


@dataclass(frozen=True, eq=False)
class PointPairs:
    """P (source, sensor) pairs: each is one row block (its N bins) of A.

    Parameters
    ----------
    sources, sensors : array_like
        ``(P, 3)`` world points, metres, in front of the rectangle's lit face.
    offsets : array_like, optional
        ``(P,)`` path length added to every path of the pair, metres
        (a laser's and a sensor's legs to the wall). Default 0.
    source_normals, sensor_normals : array_like, optional
        ``(P, 3)`` unit normals at the ends: the cosine between it and the
        direction from the end to x multiplies the attenuation (a wall
        point's Lambertian cosine). None: no cosine (omnidirectional).
    scales : array_like, optional
        ``(P,)`` factor on the pair's entries (the source's intensity and
        anything constant along the pair). Default 1.
    attenuation : {"lambertian", "paper"}
        The attenuation kind (:mod:`analytic.attenuation`).
    """

    sources: np.ndarray
    sensors: np.ndarray
    offsets: np.ndarray | None = None
    source_normals: np.ndarray | None = None
    sensor_normals: np.ndarray | None = None
    scales: np.ndarray | None = None
    attenuation: str = "lambertian"

    def __post_init__(self):
        sources = np.asarray(self.sources, dtype=np.float64).reshape(-1, 3)
        sensors = np.asarray(self.sensors, dtype=np.float64).reshape(-1, 3)
        if sources.shape != sensors.shape:
            raise ValueError(f"sources {sources.shape} and sensors {sensors.shape} must pair up")
        count = len(sources)
        fields = {"sources": sources, "sensors": sensors,
                  "offsets": np.zeros(count) if self.offsets is None else np.asarray(self.offsets, np.float64),
                  "scales": np.ones(count) if self.scales is None else np.asarray(self.scales, np.float64)}
        for name in ("source_normals", "sensor_normals"):
            value = getattr(self, name)
            fields[name] = None if value is None else np.asarray(value, dtype=np.float64).reshape(count, 3)
        for name, value in fields.items():
            if value is None:
                continue
            expected = (count,) if name in ("offsets", "scales") else (count, 3)
            if value.shape != expected or not np.all(np.isfinite(value)):
                raise ValueError(f"{name}: expected {expected} finite values, got shape {value.shape}")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.attenuation not in ATTENUATIONS:
            raise ValueError(f"attenuation: one of {ATTENUATIONS}, got {self.attenuation!r}")

    def __len__(self) -> int:
        return len(self.sources)

    def block(self, start: int, stop: int) -> "PointPairs":
        """Pairs start ... stop - 1: their rows of A are exactly the whole set's (pairs are independent)."""
        def part(value):
            return None if value is None else value[start:stop]

        return PointPairs(self.sources[start:stop], self.sensors[start:stop], part(self.offsets),
                          part(self.source_normals), part(self.sensor_normals), part(self.scales), self.attenuation)


def _cosine_form(rectangle: Rectangle, points: np.ndarray, normals: np.ndarray | None):
    """(flag, c0, cu, cv) per pair: n·(x - point) = c0 + cu x + cv y for x = corner + x û + y v̂."""
    count = len(points)
    if normals is None:
        return np.zeros(count, np.bool_), np.ones(count), np.zeros(count), np.zeros(count)
    lengths = np.linalg.norm(normals, axis=1)
    if not np.all(lengths > 0):
        raise ValueError("normals: every end normal must be non-zero")
    unit = normals / lengths[:, None]
    x_axis, y_axis, _ = rectangle.axes
    return (np.ones(count, np.bool_), np.einsum("ij,ij->i", rectangle.corner - points, unit), unit @ x_axis,
            unit @ y_axis)


def pair_table(rectangle: Rectangle, pairs: PointPairs) -> np.ndarray:
    """The pairs in the rectangle's frame, as the compiled kernels read them.

    Parameters
    ----------
    rectangle : Rectangle
    pairs : PointPairs

    Returns
    -------
    numpy.ndarray
        ``(P,)`` records of :data:`PAIR_DTYPE`.

    Raises
    ------
    SceneError
        A point not strictly in front of the lit face (key ``geometry``), or
        an end whose cosine is negative somewhere on the rectangle (the
        rectangle behind that end's surface).
    """
    table = np.zeros(len(pairs), dtype=PAIR_DTYPE)
    for end, points in (("source", pairs.sources), ("sensor", pairs.sensors)):
        local = rectangle.local(points)
        if not np.all(local[:, 2] > 0):
            index = int(np.argmin(local[:, 2]))
            raise SceneError("geometry", f"pair {index}: its {end} {points[index].tolist()} is not in front "
                                         f"of the rectangle's lit face (height {local[index, 2]:.3g} m)")
        table[f"{end}_x"], table[f"{end}_y"], table[f"{end}_height"] = local.T
        normals = pairs.source_normals if end == "source" else pairs.sensor_normals
        flag, c0, cu, cv = _cosine_form(rectangle, points, normals)
        if flag.any():
            corners = np.array([[0, 0], [rectangle.width, 0], [0, rectangle.height],
                                [rectangle.width, rectangle.height]])
            # the cosine is affine on the rectangle: its smallest value is at a corner
            lowest = np.min(c0[:, None] + cu[:, None] * corners[None, :, 0] + cv[:, None] * corners[None, :, 1],
                            axis=1)
            if np.any(lowest[flag] < 0):
                index = int(np.argmin(np.where(flag, lowest, np.inf)))
                raise SceneError("geometry", f"pair {index}: part of the rectangle lies behind its {end}'s "
                                             f"surface (the {end} cannot see it); move the rectangle in front")
        table[f"{end}_cosine"], table[f"{end}_cosine_0"] = flag, c0
        table[f"{end}_cosine_u"], table[f"{end}_cosine_v"] = cu, cv
    table["offset"] = pairs.offsets
    return table


def plane_geometry(scene) -> tuple[Rectangle, PointPairs]:
    """The letter's plane scene as a rectangle and point pairs.

    Parameters
    ----------
    scene : analytic.Scene

    Returns
    -------
    (Rectangle, PointPairs)
        The plane [0, L]² at z = 0 (normal +z) and one pair per sensor
        (the source, sensor k), each scaled by the source's intensity I
        (W/sr), with no added path and no end cosines.
    """
    size = float(scene.size)
    rectangle = Rectangle(np.zeros(3), np.array([size, 0.0, 0.0]), np.array([0.0, size, 0.0]), scene.pixels)
    count = scene.sensor_count
    pairs = PointPairs(np.repeat(np.asarray(scene.source, dtype=np.float64)[None, :], count, axis=0),
                       np.asarray(scene.sensors, dtype=np.float64), scales=np.full(count, float(scene.intensity)),
                       attenuation=scene.attenuation)
    return rectangle, pairs
