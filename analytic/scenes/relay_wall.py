"""Seeing around a corner: a capture through a relay wall (NLOS), as a rectangle and point pairs.

A laser at o_l lights a point l of a visible Lambertian wall (the relay
wall: z = 0, normal +z, centred at the origin), light reaches a hidden
Lambertian rectangle, returns to the wall, and a time-resolved sensor at o_s
reads points s of the wall. The third bounce laser -> l -> x -> s is the
letter's isochronal-ellipse integral (:mod:`analytic.geometry`) with l in the
source's place and s in the sensor's, the hidden rectangle as the plane, and
the wall's cosines at both ends (docs/design.md section 7):

    H(l, s)[n] = I cos θ_l^las / |o_l - l|² · (ρ_w / π)²
                 · ∫ ρ_h(x) / π · cos θ_s^x cos θ_x^s cos θ_x^l cos θ_l^x / (|s - x|² |x - l|²)
                   · κ_n(|s - x| + |x - l| [+ |o_l - l| + |s - o_s|]) dA(x),

in mitusba/mitransient's units: the radiance leaving s toward the sensor,
integrated over the bin. Each (l, s) is a pair of :class:`analytic.geometry.PointPairs`
whose scale is the laser leg I cos θ_l^las / |o_l - l|² (ρ_w / π)², whose
ends carry the wall's normal, and whose added path is the laser's and the
sensor's legs when the scan counts them; the hidden image's pixels are the
columns of A and the pairs its row blocks, so the inversion, the noise and
the metrics work unchanged.

Scan types (docs/design.md section 7): ``single`` (one laser point, every
grid point read), ``confocal`` (each grid point lit and read) and
``exhaustive`` (every laser grid point x every read grid point). Grid cell
(row j, column i) of a W x H grid is ((2i+1)/W - 1, (2j+1)/H - 1, 0) times
the wall's half sizes; pairs are laser-major, each grid row-major.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..measurement.detector import Detector
from ..errors import SceneError
from ..geometry import PointPairs, Rectangle
from ..resources import require_memory
from .kinds import register_scene_kind
from .reflectance import reflectance_image
from .common import (MAX_LENGTH, MIN_LENGTH, Illumination, Noise, Sampling, _choice, _integer, _number,
                    check_tolerance)
from ..values import exact
from .limits import check_intensity

__all__ = ["RelayWallScene", "Scan", "SCAN_TYPES", "MAX_PAIRS", "grid_points", "check_edges",
           "default_relay_wall_scene"]

SCAN_TYPES = ("single", "confocal", "exhaustive")

#: Most (laser point, read point) pairs a capture may have (an exhaustive 16 x 16 grid has 65,536).
MAX_PAIRS = 2**20

#: The relay wall's normal: it is the plane z = 0 and faces +z.
WALL_NORMAL = np.array([0.0, 0.0, 1.0])


def grid_points(grid, size) -> np.ndarray:
    """Cell centres of a W x H grid over the wall, row-major (row j along y), metres.

    Parameters
    ----------
    grid : (int, int)
        W cells along x, H along y.
    size : (float, float)
        The wall's sides along x and y, metres.

    Returns
    -------
    numpy.ndarray
        ``(W H, 3)``: point j W + i is ((2i+1)/W - 1, (2j+1)/H - 1, 0) x the half sizes.
    """
    width, height = int(grid[0]), int(grid[1])
    i, j = np.meshgrid(np.arange(width), np.arange(height))
    x = ((2 * i + 1) / width - 1.0) * 0.5 * size[0]
    y = ((2 * j + 1) / height - 1.0) * 0.5 * size[1]
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def _vector(key: str, value: Any, *, front: bool = False) -> np.ndarray:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise SceneError(key, f"expected [x, y, z] in metres, got {value!r}")
    vector = np.array([_number(f"{key}[{i}]", v, length=True) for i, v in enumerate(value)])
    if front and not vector[2] > 0.0:
        raise SceneError(key, f"z = {vector[2]} must be > 0 (in front of the relay wall, which faces +z)")
    return vector


def _pair(key: str, value: Any, *, whole: bool) -> tuple:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SceneError(key, f"expected [x, y], got {value!r}")
    if whole:
        return tuple(_integer(f"{key}[{i}]", v) for i, v in enumerate(value))
    return tuple(_number(f"{key}[{i}]", v, positive=True, length=True) for i, v in enumerate(value))


def check_edges(u, v) -> tuple[float, float]:
    """The hidden rectangle's sides |u| and |v|, metres, or SceneError naming ``hidden.u`` or ``hidden.v``.

    Each side is at least :data:`MIN_LENGTH` (below it the rectangle's area, |u| |v|, and its normal
    u x v underflow toward 0) and u ⟂ v. The lengths are taken by ``math.hypot``, which neither
    underflows nor overflows (``numpy.linalg.norm`` of [1e-300, 0, 0] is 0).
    """
    lengths = []
    for key, edge in (("hidden.u", u), ("hidden.v", v)):
        length = math.hypot(*(float(x) for x in edge))
        if not length >= MIN_LENGTH:
            shown = "0 (the edge vector must be non-zero)" if length == 0.0 else f"{length!r} m"
            raise SceneError(key, f"the rectangle's side along it is {shown}; the smallest length supported is "
                                  f"{MIN_LENGTH:g} m")
        lengths.append(length)
    dot = float(np.dot(u, v))
    if abs(dot) > 1e-9 * lengths[0] * lengths[1]:
        raise SceneError("hidden.v", f"must be orthogonal to hidden.u (u·v = {exact(dot)}, over 1e-9 |u| |v| = "
                                     f"{exact(1e-9 * lengths[0] * lengths[1])})")
    return lengths[0], lengths[1]


@dataclass(frozen=True, kw_only=True)
class Scan:
    """Which wall points are lit and read (docs/design.md section 7).

    Parameters
    ----------
    type : {"single", "confocal", "exhaustive"}
        One laser point and every grid point read; each grid point lit and
        read; every laser grid point with every read grid point.
    grid : (int, int)
        W x H read points (cell centres over the wall).
    laser_point : array_like, optional
        ``single`` only: l on the wall, metres (default: the wall's centre).
    laser_grid : (int, int), optional
        ``exhaustive`` only: the lit points' grid (default: ``grid``).
    account_first_and_last_bounces : bool
        Path lengths add |o_l - l| + |s - o_s| (tal's and mitransient's flag).
    """

    type: str = "single"
    grid: tuple = (4, 4)
    laser_point: Any = None
    laser_grid: tuple | None = None
    account_first_and_last_bounces: bool = False

    def __post_init__(self):
        _choice("scan.type", self.type, SCAN_TYPES)
        object.__setattr__(self, "grid", _pair("scan.grid", self.grid, whole=True))
        if self.laser_point is not None:
            if self.type != "single":
                raise SceneError("scan.laser_point", f"applies to type = 'single' only, not {self.type!r}")
            point = _vector("scan.laser_point", self.laser_point)
            if point[2] != 0.0:
                raise SceneError("scan.laser_point", f"z = {exact(point[2])}: the laser point lies on the wall (z = 0)")
            point.setflags(write=False)
            object.__setattr__(self, "laser_point", point)
        if self.laser_grid is not None:
            if self.type != "exhaustive":
                raise SceneError("scan.laser_grid", f"applies to type = 'exhaustive' only, not {self.type!r}")
            object.__setattr__(self, "laser_grid", _pair("scan.laser_grid", self.laser_grid, whole=True))
        if not isinstance(self.account_first_and_last_bounces, (bool, np.bool_)):
            raise SceneError("scan.account_first_and_last_bounces",
                             f"expected true or false, got {self.account_first_and_last_bounces!r}")

    @property
    def pairs(self) -> int:
        """P, the (laser point, read point) pairs, from the grids alone (no point is built)."""
        width, height = self.grid
        if self.type == "exhaustive":
            lasers = self.laser_grid or self.grid
            return width * height * lasers[0] * lasers[1]
        return width * height

    def check_pairs(self) -> int:
        """P, or SceneError("scan.grid") beyond :data:`MAX_PAIRS`: called before any grid of points is built."""
        pairs = self.pairs
        if pairs > MAX_PAIRS:
            raise SceneError("scan.grid", f"{pairs:,} (laser point, read point) pairs; at most {MAX_PAIRS:,} "
                                          f"are supported")
        return pairs


@register_scene_kind
@dataclass(frozen=True, kw_only=True, eq=False)
class RelayWallScene:
    """A capture through a relay wall (the scene kind ``relay_wall``): the scene file's ``[relay_wall]``, ``[hidden]``, ``[laser]``,
    ``[sensor]`` and ``[scan]`` tables (docs/design.md section 7), with the plane scene's
    ``[illumination]``, ``[sampling]``, ``[model] tolerance``, ``[noise]`` and ``[detector]``.

    Parameters
    ----------
    wall_size : (float, float)
        The wall's sides along x and y, metres; centred at the origin in z = 0, normal +z.
    wall_reflectance : float
        ρ_w in [0, 1].
    center, u, v : array_like
        The hidden rectangle: its centre (z > 0) and edge vectors along the
        image's columns and rows (bottom to top), metres; u ⟂ v, and the lit
        face's normal u x v / |u x v| faces the wall.
    pixels : int
        M.
    reflectance : float or numpy.ndarray
        ρ_h: a number or an M x M image (row 0 at the top, v's far end).
    laser_position, sensor_position : array_like
        o_l and o_s, metres, z > 0.
    intensity : float
        I, the laser's radiant intensity toward the wall, W/sr.
    scan : Scan
    illumination, sampling, tolerance, noise, detector, name
        As for :class:`analytic.scenes.common.Scene`.
    """

    wall_size: tuple = (2.0, 2.0)
    wall_reflectance: float = 1.0
    center: Any = (0.0, 0.0, 1.0)
    u: Any = (1.0, 0.0, 0.0)
    v: Any = (0.0, -1.0, 0.0)
    pixels: int = 32
    reflectance: Any = 0.5
    laser_position: Any = (-0.5, 0.0, 0.25)
    sensor_position: Any = (-0.5, 0.0, 0.25)
    intensity: float = 1.0
    scan: Scan = field(default_factory=Scan)
    illumination: Illumination = field(default_factory=Illumination)
    sampling: Sampling = field(default_factory=Sampling)
    tolerance: float = 1e-6
    noise: Noise | None = None
    detector: Detector | None = None
    name: str = "relay-wall"

    #: The scene kind's name, its rows and its image's key (:class:`analytic.scenes.kinds.SceneKind`).
    kind: ClassVar[str] = "relay_wall"
    row_noun: ClassVar[str] = "pair"
    image_key: ClassVar[str] = "hidden.reflectance"
    #: mitransient's units (docs/design.md section 7), as meta.json states them.
    units: ClassVar[str] = (
        "lengths in metres; time as optical path length in metres (c = 1); each row a (laser point, "
        "read point) pair; H(l, s)[n] is the radiance leaving the read point s toward the sensor "
        "(W sr^-1 m^-2) integrated over the bin (m of path length), for the laser's radiant "
        "intensity I (W/sr) toward the wall: W sr^-1 m^-1, mitransient's nlos_capture_meter units; "
        "noise sigma in the units of H")

    def __post_init__(self):
        object.__setattr__(self, "wall_size", _pair("relay_wall.size", self.wall_size, whole=False))
        reflectance = _number("relay_wall.reflectance", self.wall_reflectance)
        if not 0.0 <= reflectance <= 1.0:
            raise SceneError("relay_wall.reflectance", f"must lie in [0, 1], got {reflectance}")
        object.__setattr__(self, "wall_reflectance", reflectance)
        pixels = _integer("hidden.pixels", self.pixels)
        require_memory(4 * 8 * pixels**2, f"hidden.pixels = {pixels}", "use fewer pixels")
        object.__setattr__(self, "pixels", pixels)
        object.__setattr__(self, "reflectance", reflectance_image("hidden.reflectance", self.reflectance, pixels))
        for name, key, front in (("center", "hidden.center", True), ("u", "hidden.u", False), ("v", "hidden.v", False),
                                 ("laser_position", "laser.position", True),
                                 ("sensor_position", "sensor.position", True)):
            vector = _vector(key, getattr(self, name), front=front)
            vector.setflags(write=False)
            object.__setattr__(self, name, vector)
        object.__setattr__(self, "intensity", check_intensity("laser.intensity", self.intensity))
        for name, kind in (("scan", Scan), ("illumination", Illumination), ("sampling", Sampling)):
            if not isinstance(getattr(self, name), kind):
                raise SceneError(name, f"expected a {kind.__name__}")
        if self.noise is not None and not isinstance(self.noise, Noise):
            raise SceneError("noise", "expected a Noise or None")
        if self.detector is not None and not isinstance(self.detector, Detector):
            raise SceneError("detector", "expected an analytic.measurement.detector.Detector or None")
        object.__setattr__(self, "tolerance", check_tolerance(self.tolerance))
        if not isinstance(self.name, str):
            raise SceneError("name", f"expected a string, got {self.name!r}")
        pairs = self.scan.check_pairs()    # from the grids alone: before any array of points is built
        self._check_hidden()
        self._check_points()
        self._check_lines()
        # y, its noisy copy, the render's mean, error and replicas: P N doubles each
        require_memory(8 * 8 * pairs * self.sampling.count,
                       f"{pairs:,} pairs x sampling.count = {self.sampling.count} bins",
                       "use a smaller scan grid or fewer bins")

    def _check_hidden(self) -> None:
        """u ⟂ v, each at least MIN_LENGTH; the rectangle wholly in front of the wall and its lit face toward it."""
        check_edges(self.u, self.v)
        u, v = self.u, self.v
        corners = self.rectangle().corners()
        if not np.all(corners[:, 2] > 0.0):
            raise SceneError("hidden.center", f"the hidden rectangle crosses or touches the relay wall (a corner "
                                              f"at z = {corners[:, 2].min():.3g} m); move it in front (z > 0)")
        normal = np.cross(u, v)
        points = np.vstack([self.read_points, self.laser_points])
        # every wall point must see the lit face: (point - corner)·n > 0 over the rectangle (n points at them)
        facing = (points[:, None, :] - corners[None, :, :]) @ normal
        if not np.all(facing > 0.0):
            raise SceneError("hidden.u", "the hidden rectangle's lit face (normal u x v) does not face the relay "
                                         "wall's scanned points; swap u and v (or flip one) so that it faces the wall")

    def _check_points(self) -> None:
        """The laser point on the wall, inside it; the scan's points inside the wall."""
        if self.scan.type == "single" and self.scan.laser_point is not None:
            x, y, _ = self.scan.laser_point
            if abs(x) > 0.5 * self.wall_size[0] or abs(y) > 0.5 * self.wall_size[1]:
                raise SceneError("scan.laser_point", f"({exact(x)}, {exact(y)}) lies outside the "
                                                     f"{exact(self.wall_size[0])} x {exact(self.wall_size[1])} m wall")

    # -- the scan -----------------------------------------------------------------

    @property
    def read_points(self) -> np.ndarray:
        """``(W H, 3)`` the read points s (cell centres), row-major, metres."""
        return grid_points(self.scan.grid, self.wall_size)

    @property
    def laser_points(self) -> np.ndarray:
        """``(L, 3)`` the lit points l, metres: one (single), the grid (confocal), the laser grid (exhaustive)."""
        if self.scan.type == "single":
            point = np.zeros(3) if self.scan.laser_point is None else np.asarray(self.scan.laser_point)
            return point[None, :].copy()
        if self.scan.type == "confocal":
            return self.read_points
        return grid_points(self.scan.laser_grid or self.scan.grid, self.wall_size)

    @property
    def pair_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(l, s) of every pair in the pair order: ``(P, 3)`` each, metres."""
        lit, read = self.laser_points, self.read_points
        if self.scan.type == "single":
            return np.repeat(lit, len(read), axis=0), read
        if self.scan.type == "confocal":
            return read, read.copy()
        return np.repeat(lit, len(read), axis=0), np.tile(read, (len(lit), 1))

    @property
    def sensor_count(self) -> int:
        """P, the transient's rows: the (laser point, read point) pairs."""
        return self.scan.pairs

    @property
    def pixel_size(self) -> tuple[float, float]:
        """The hidden image's pixel sides (du, dv) along u and v, metres."""
        return float(np.linalg.norm(self.u)) / self.pixels, float(np.linalg.norm(self.v)) / self.pixels

    # -- the model's geometry -----------------------------------------------------

    def rectangle(self) -> Rectangle:
        """The hidden rectangle: corner at centre - (u + v)/2, edges u and v, M x M pixels."""
        return Rectangle(self.center - 0.5 * (self.u + self.v), self.u, self.v, self.pixels)

    def blocked(self, start: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Which segments ``start`` -> ``ends[i]`` cross or touch the hidden rectangle, ``(len(ends),)`` bool.

        A renderer that traces the laser's and the sensor's lines loses the light of those; the model
        counts only the third bounce, so a scene with any blocked line is refused (:meth:`_check_lines`).
        A segment in the rectangle's plane counts as clear (it meets it, at most, edge on).
        """
        rectangle = self.rectangle()
        normal = rectangle.normal
        start = np.asarray(start, dtype=np.float64)
        toward = np.asarray(ends, dtype=np.float64) - start
        along = toward @ normal
        crosses = along != 0
        with np.errstate(over="ignore", invalid="ignore"):      # a nearly parallel segment: t far outside (0, 1)
            t = (rectangle.corner - start) @ normal / np.where(crosses, along, 1.0)
            crossing = start + np.where(crosses & (t > 0) & (t < 1), t, 0.0)[:, None] * toward - rectangle.corner
            u = crossing @ rectangle.u / (rectangle.u @ rectangle.u)
            v = crossing @ rectangle.v / (rectangle.v @ rectangle.v)
        return crosses & (t > 0) & (t < 1) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)

    def _check_lines(self) -> None:
        """The laser's line to every lit point and the sensor's to every read point clear of the hidden rectangle.

        One rule for every entry point (the model, renders, exports, tal configurations): the model
        counts only the third bounce laser -> l -> x -> s, which a blocked line would cut (mitransient
        and tal trace both lines), so a capture where any pair would lose it is refused.
        """
        for who, origin, points in (("laser", self.laser_position, self.laser_points),
                                    ("sensor", self.sensor_position, self.read_points)):
            blocked = self.blocked(origin, points)
            if blocked.any():
                where = points[int(np.argmax(blocked))].tolist()
                raise SceneError("hidden.center", f"the hidden rectangle blocks the {who}'s line from "
                                                  f"{origin.tolist()} to the wall point {where} ({int(blocked.sum()):,} "
                                                  f"of {len(points):,} such lines; the model counts them clear); "
                                                  f"move the {who} or the rectangle so that it sees the wall")

    def laser_leg(self, lit: np.ndarray) -> np.ndarray:
        """I cos θ_l^las / |o_l - l|² (ρ_w / π)² for lit points ``(P, 3)``: each pair's constant factor."""
        toward = self.laser_position - lit
        distance = np.linalg.norm(toward, axis=1)
        cosine = toward @ WALL_NORMAL / distance
        return self.intensity * cosine / distance**2 * (self.wall_reflectance / math.pi) ** 2

    def geometry(self) -> tuple[Rectangle, PointPairs]:
        """The hidden rectangle and the pairs (l, s), the wall's cosines at both ends (analytic.geometry)."""
        lit, read = self.pair_points
        offsets = None
        if self.scan.account_first_and_last_bounces:
            offsets = (np.linalg.norm(self.laser_position - lit, axis=1)
                       + np.linalg.norm(read - self.sensor_position, axis=1))
        normals = np.broadcast_to(WALL_NORMAL, lit.shape)
        return self.rectangle(), PointPairs(lit, read, offsets=offsets, source_normals=normals,
                                            sensor_normals=normals, scales=self.laser_leg(lit))

    def replace(self, **changes) -> "RelayWallScene":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    # -- what files and reports need (analytic.scenes.kinds.SceneKind) --------------

    def describe(self) -> str:
        """The transient's rows in words: "64 pairs (confocal scan)"."""
        return f"{self.sensor_count} pairs ({self.scan.type} scan)"

    def darkness(self) -> tuple[str, str] | None:
        """(key, why) when the relay wall or the hidden rectangle is black everywhere, else None."""
        if self.wall_reflectance == 0:
            return "relay_wall.reflectance", "the relay wall is black"
        if not np.any(np.asarray(self.reflectance) > 0):
            return "hidden.reflectance", "the hidden rectangle is black (reflectance 0 everywhere)"
        return None

    def meta_fields(self) -> dict:
        """meta.json's ``geometry``, ``attenuation``, ``units`` and the tables of docs/design.md section 7.

        ``relay_wall``: {``size`` (metres along x and y), ``reflectance`` (ρ_w)};
        ``hidden``: {``center``, ``u``, ``v`` (metres), ``pixels`` (M),
        ``reflectance`` (ρ_h when uniform, else None: an image),
        ``reflectance_mean``}; ``laser``: {``position`` (o_l), ``intensity``
        (I, W/sr)}; ``sensor``: {``position`` (o_s)}; ``scan``: {``type``,
        ``grid`` ([W, H] read points), ``laser_point`` (single: l),
        ``laser_grid`` (exhaustive: the lit points' [W, H]),
        ``account_first_and_last_bounces``, ``pairs`` (P)}. A key of another
        scan type is None. The third bounce is Lambertian at every vertex.
        """
        scan = self.scan
        image = np.asarray(self.reflectance, dtype=np.float64)
        uniform = bool(np.all(image == image.flat[0]))
        laser_point = [float(v) for v in self.laser_points[0]] if scan.type == "single" else None
        laser_grid = [int(g) for g in (scan.laser_grid or scan.grid)] if scan.type == "exhaustive" else None

        def vector(value):
            return [float(v) for v in value]

        return {
            "geometry": self.kind, "attenuation": "lambertian", "units": self.units,
            "relay_wall": {"size": vector(self.wall_size), "reflectance": float(self.wall_reflectance)},
            "hidden": {"center": vector(self.center), "u": vector(self.u), "v": vector(self.v),
                       "pixels": int(self.pixels), "reflectance": float(image.flat[0]) if uniform else None,
                       "reflectance_mean": float(image.mean())},
            "laser": {"position": vector(self.laser_position), "intensity": float(self.intensity)},
            "sensor": {"position": vector(self.sensor_position)},
            "scan": {"type": scan.type, "grid": [int(g) for g in scan.grid], "laser_point": laser_point,
                     "laser_grid": laser_grid,
                     "account_first_and_last_bounces": bool(scan.account_first_and_last_bounces),
                     "pairs": int(self.sensor_count)},
        }

    def to_tables(self, shared: dict) -> dict:
        """``[relay_wall]``, ``[hidden]``, ``[laser]``, ``[sensor]``, ``[scan]``, ``[model]``, then ``shared``."""
        image = self.reflectance
        uniform = bool(np.all(image == image.flat[0]))
        scan = {"type": self.scan.type, "grid": list(self.scan.grid),
                "account_first_and_last_bounces": bool(self.scan.account_first_and_last_bounces)}
        if self.scan.laser_point is not None:
            scan["laser_point"] = np.asarray(self.scan.laser_point).tolist()
        if self.scan.laser_grid is not None:
            scan["laser_grid"] = list(self.scan.laser_grid)
        return {
            "relay_wall": {"size": list(self.wall_size), "reflectance": self.wall_reflectance},
            "hidden": {"center": self.center.tolist(), "u": self.u.tolist(), "v": self.v.tolist(),
                       "pixels": self.pixels, "reflectance": float(image.flat[0]) if uniform else np.array(image)},
            "laser": {"position": self.laser_position.tolist(), "intensity": self.intensity},
            "sensor": {"position": self.sensor_position.tolist()},
            "scan": scan,
            "model": {"tolerance": self.tolerance},
            **shared,
        }


def default_relay_wall_scene(**changes) -> RelayWallScene:
    """A small confocal capture of the built-in pattern on a 1 m hidden square 1 m in front of a 2 m wall.

    The laser and sensor sit at (-0.5, 0, 0.25) (tal's defaults), 8 x 8
    confocal points, bins of 1 cm from 1.9 m: the third bounce of every point
    arrives between 2.0 and 3.2 m of path.
    """
    from .reflectance import builtin_reflectance

    pixels = int(changes.pop("pixels", 32))
    scene = RelayWallScene(pixels=pixels, reflectance=builtin_reflectance(pixels),
                           scan=Scan(type="confocal", grid=(8, 8)),
                           sampling=Sampling(bin_width_opl=0.01, start_opl=1.9, count=140), name="relay-wall")
    return scene.replace(**changes) if changes else scene
