"""Scene description: TOML file or code -> frozen, validated dataclass.

Every length is in metres and every time is an optical path length in metres
(c = 1), as DESIGN.md section 1 fixes. The TOML keys are those of DESIGN.md
section 5 plus the optional extras documented in the README; an unknown key
is an error, so a typo never falls back to a default.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .reflectance import ImageError, builtin_reflectance, read_reflectance

__all__ = [
    "SceneError",
    "Illumination",
    "Sampling",
    "Noise",
    "Scene",
    "default_scene",
    "load_scene",
    "read_toml",
    "scene_from_dict",
    "sensor_grid",
]

WAVEFORMS = ("impulse", "square", "butterworth")
ATTENUATIONS = ("lambertian", "paper")
NOISE_KINDS = ("gaussian", "poisson")


class SceneError(ValueError):
    """A bad scene value; ``key`` names the offending TOML key.

    Parameters
    ----------
    key : str
        Dotted TOML key, e.g. ``"sampling.period"``.
    problem : str
        What is wrong, in a few words.
    """

    def __init__(self, key: str, problem: str):
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}")


def _number(key: str, value: Any, *, positive: bool = False, nonnegative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SceneError(key, f"expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(key, f"must be finite, got {value}")
    if positive and value <= 0.0:
        raise SceneError(key, f"must be > 0, got {value}")
    if nonnegative and value < 0.0:
        raise SceneError(key, f"must be >= 0, got {value}")
    return value


def _integer(key: str, value: Any, *, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        else:
            raise SceneError(key, f"expected a whole number, got {value!r}")
    value = int(value)
    if value < minimum:
        raise SceneError(key, f"must be >= {minimum}, got {value}")
    return value


def _point(key: str, value: Any) -> np.ndarray:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise SceneError(key, f"expected [x, y, z] in metres, got {value!r}")
    point = np.array([_number(f"{key}[{i}]", v) for i, v in enumerate(value)])
    if point[2] <= 0.0:
        raise SceneError(key, f"z = {point[2]} must be > 0 (strictly above the plane)")
    return point


def _choice(key: str, value: Any, options: tuple[str, ...]) -> str:
    if value not in options:
        raise SceneError(key, f"must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


@dataclass(frozen=True, kw_only=True)
class Illumination:
    """The source's intensity waveform s(t).

    Parameters
    ----------
    waveform : {"impulse", "square", "butterworth"}
        Dirac impulse; unit-amplitude box of width ``width``; or the truncated
        impulse response of an analogue Butterworth low-pass scaled to unit
        peak amplitude.
    width : float, optional
        Square pulse width, metres of path length. Default: period / 5.
    cutoff : float, optional
        Butterworth -3 dB cutoff frequency, cycles per metre of path length.
        Default: 1 / (2 period), the sampler's Nyquist frequency.
    duration : float, optional
        Butterworth truncation: s(t) = 0 for t > duration, metres.
        Default: 3 / cutoff (the envelope has decayed below 1e-4 by then).
    order : int, optional
        Butterworth order. Default 3 (the paper's).
    """

    waveform: str = "impulse"
    width: float | None = None
    cutoff: float | None = None
    duration: float | None = None
    order: int | None = None

    def __post_init__(self):
        _choice("illumination.waveform", self.waveform, WAVEFORMS)
        own = {"square": ("width",), "butterworth": ("cutoff", "duration", "order")}
        for name in ("width", "cutoff", "duration", "order"):
            value = getattr(self, name)
            if value is None:
                continue
            if name not in own.get(self.waveform, ()):
                raise SceneError(f"illumination.{name}",
                                 f"does not apply to waveform = {self.waveform!r}")
            if name == "order":
                object.__setattr__(self, name, _integer("illumination.order", value))
            else:
                object.__setattr__(self, name,
                                   _number(f"illumination.{name}", value, positive=True))


@dataclass(frozen=True, kw_only=True)
class Sampling:
    """Box ("integrate and dump") sampling: bin n covers
    [start_opl + n bin_width_opl, start_opl + (n + 1) bin_width_opl).

    The scene file's keys are ``[sampling] period`` (T), ``start`` (t0) and
    ``count`` (N), as DESIGN.md section 5 fixes; in code and in every output
    file the first two are named as mitransient names them.

    Parameters
    ----------
    bin_width_opl : float
        Bin width T, metres of path length (TOML ``sampling.period``).
    start_opl : float
        Lower edge t0 of the first bin, metres of path length (TOML
        ``sampling.start``).
    count : int
        Number of bins N.
    """

    bin_width_opl: float = 0.1
    start_opl: float = 0.0
    count: int = 40

    def __post_init__(self):
        object.__setattr__(self, "bin_width_opl",
                           _number("sampling.period", self.bin_width_opl, positive=True))
        object.__setattr__(self, "start_opl", _number("sampling.start", self.start_opl))
        object.__setattr__(self, "count", _integer("sampling.count", self.count))

    @property
    def edges(self) -> np.ndarray:
        """Bin edges, ``(N + 1,)`` metres of path length."""
        return self.start_opl + self.bin_width_opl * np.arange(self.count + 1)


@dataclass(frozen=True, kw_only=True)
class Noise:
    """Measurement noise added to the model's samples.

    Parameters
    ----------
    kind : {"gaussian", "poisson"}
        Additive i.i.d. Gaussian of standard deviation ``sigma``, or photon
        counting: Poisson(photons * y) / photons.
    sigma : float
        Gaussian standard deviation, in units of y. Default 0.1 (the paper's).
    photons : float
        Poisson scale: expected photon count per unit of y. Default 1000.
    seed : int
        Seed of the noise generator.
    """

    kind: str = "gaussian"
    sigma: float = 0.1
    photons: float = 1000.0
    seed: int = 0

    def __post_init__(self):
        _choice("noise.kind", self.kind, NOISE_KINDS)
        object.__setattr__(self, "sigma", _number("noise.sigma", self.sigma, nonnegative=True))
        object.__setattr__(self, "photons", _number("noise.photons", self.photons, positive=True))
        object.__setattr__(self, "seed", _integer("noise.seed", self.seed, minimum=0))


@dataclass(frozen=True, kw_only=True, eq=False)
class Scene:
    """A Lambertian plane, one point source, K point sensors, sampling.

    Parameters
    ----------
    size : float
        Plane side L, metres; the plane is [0, L] x [0, L] at z = 0.
    pixels : int
        Image side M; pixel side is L / M.
    reflectance : float or numpy.ndarray
        A constant in [0, 1] or an ``(M, M)`` image (row 0 at the top).
    source : array_like
        Source position (x, y, z), metres, z > 0.
    sensors : array_like
        ``(K, 3)`` sensor positions, metres, every z > 0.
    illumination : Illumination
        Source waveform.
    sampling : Sampling
        Time bins.
    attenuation : {"lambertian", "paper"}
        Physical transport, or the paper's eq. (1).
    tolerance : float
        Relative accuracy of every system-matrix entry, relative to the
        largest entry of its row. Default 1e-6.
    noise : Noise or None
        Noise for ``transient_noisy.npy``; None means noiseless.
    name : str
        Label used in reports.
    """

    size: float = 1.0
    pixels: int = 50
    reflectance: Any = 0.5
    source: Any = (0.5, 0.5, 1.0)
    sensors: Any = ((0.2, 0.7, 1.0),)
    illumination: Illumination = field(default_factory=Illumination)
    sampling: Sampling = field(default_factory=Sampling)
    attenuation: str = "lambertian"
    tolerance: float = 1e-6
    noise: Noise | None = None
    name: str = "scene"

    def __post_init__(self):
        size = _number("plane.size", self.size, positive=True)
        pixels = _integer("plane.pixels", self.pixels)
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "pixels", pixels)
        if isinstance(self.reflectance, np.ndarray):
            image = np.array(self.reflectance, dtype=np.float64)
            if image.shape != (pixels, pixels):
                raise SceneError("plane.reflectance",
                                 f"image shape {image.shape} differs from ({pixels}, {pixels})")
            if not np.all(np.isfinite(image)) or image.min() < 0 or image.max() > 1:
                raise SceneError("plane.reflectance", "values must be finite and in [0, 1]")
        else:
            value = _number("plane.reflectance", self.reflectance)
            if not 0.0 <= value <= 1.0:
                raise SceneError("plane.reflectance", f"must lie in [0, 1], got {value}")
            image = np.full((pixels, pixels), value)
        image.setflags(write=False)
        object.__setattr__(self, "reflectance", image)
        object.__setattr__(self, "source", _point("source.position", self.source))
        self.source.setflags(write=False)
        sensors = np.asarray(self.sensors, dtype=object) if not isinstance(
            self.sensors, np.ndarray) else self.sensors
        if len(sensors) == 0:
            raise SceneError("sensors.positions", "at least one sensor is needed")
        points = np.array([_point(f"sensors.positions[{k}]", p) for k, p in enumerate(list(sensors))])
        points.setflags(write=False)
        object.__setattr__(self, "sensors", points)
        if not isinstance(self.illumination, Illumination):
            raise SceneError("illumination", "expected an Illumination")
        if not isinstance(self.sampling, Sampling):
            raise SceneError("sampling", "expected a Sampling")
        _choice("model.attenuation", self.attenuation, ATTENUATIONS)
        tolerance = _number("model.tolerance", self.tolerance, positive=True)
        if tolerance >= 0.1:
            raise SceneError("model.tolerance", f"must be < 0.1, got {tolerance}")
        object.__setattr__(self, "tolerance", tolerance)
        if self.noise is not None and not isinstance(self.noise, Noise):
            raise SceneError("noise", "expected a Noise or None")

    @property
    def pixel_size(self) -> float:
        """Pixel side Δ = L / M, metres."""
        return self.size / self.pixels

    @property
    def sensor_count(self) -> int:
        """Number of sensors K."""
        return len(self.sensors)

    def replace(self, **changes) -> "Scene":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)


def sensor_grid(shape: tuple[int, int], extent: float, center) -> np.ndarray:
    """Sensor positions of a regular grid array.

    Parameters
    ----------
    shape : (int, int)
        Sensors along x and along y.
    extent : float
        Array side W, metres: the outermost sensors are W apart.
    center : array_like
        Array centre (x, y, z), metres.

    Returns
    -------
    numpy.ndarray
        ``(nx * ny, 3)`` positions, x varying fastest.
    """
    nx, ny = shape
    center = np.asarray(center, dtype=np.float64)

    def offsets(n):
        return np.zeros(1) if n == 1 else extent * (np.arange(n) / (n - 1) - 0.5)

    gx, gy = np.meshgrid(center[0] + offsets(nx), center[1] + offsets(ny))
    return np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, center[2])])


def default_scene(**changes) -> Scene:
    """The built-in scene: the paper's Fig. 1 set-up.

    A 1 m x 1 m plane imaged at M = 50 with the built-in reflectance pattern;
    the source 1 m above the plane's centre; a 4 x 4 sensor array of extent
    W = 1 m centred on the source; impulse illumination, T = 0.1 m, 40 bins from
    t0 = 0; physical (Lambertian) attenuation; Gaussian noise σ = 0.1.

    Parameters
    ----------
    **changes
        Fields of :class:`Scene` to override.
    """
    scene = Scene(
        name="default",
        size=1.0,
        pixels=50,
        reflectance=builtin_reflectance(50),
        source=(0.5, 0.5, 1.0),
        sensors=sensor_grid((4, 4), 1.0, (0.5, 0.5, 1.0)),
        illumination=Illumination(waveform="impulse"),
        sampling=Sampling(bin_width_opl=0.1, start_opl=0.0, count=40),
        attenuation="lambertian",
        noise=Noise(kind="gaussian", sigma=0.1, seed=0),
    )
    if "pixels" in changes and "reflectance" not in changes:
        changes["reflectance"] = builtin_reflectance(int(changes["pixels"]))
    return scene.replace(**changes) if changes else scene


# TOML keys of [sampling] -> Sampling fields
_SAMPLING_FIELDS = {"period": "bin_width_opl", "start": "start_opl", "count": "count"}

_SCHEMA = {
    "name": None,
    "plane": {"size", "pixels", "reflectance"},
    "source": {"position"},
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


def scene_from_dict(data: dict, base_dir: str | Path = ".", *, name: str = "scene") -> Scene:
    """Build a scene from the TOML tables of DESIGN.md section 5.

    Parameters
    ----------
    data : dict
        Parsed TOML. Missing tables and keys take the defaults documented in
        the README; unknown ones are errors.
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
    sensors = _table(data, "sensors")
    sampling = _table(data, "sampling")
    model = _table(data, "model")
    pixels = _integer("plane.pixels", plane.get("pixels", 50))
    reflectance = plane.get("reflectance", 0.5)
    if isinstance(reflectance, str):
        try:
            reflectance = read_reflectance(Path(base_dir) / reflectance, pixels)
        except ImageError as error:
            raise SceneError("plane.reflectance", str(error)) from None
    if "positions" in sensors:
        extra = {"grid", "extent", "center"} & sensors.keys()
        if extra:
            raise SceneError(f"sensors.{sorted(extra)[0]}", "give either positions or grid, not both")
        positions = sensors["positions"]
        if not isinstance(positions, list) or not positions:
            raise SceneError("sensors.positions", "expected a non-empty list of [x, y, z]")
    elif "grid" in sensors:
        grid = sensors["grid"]
        if not isinstance(grid, list) or len(grid) != 2:
            raise SceneError("sensors.grid", f"expected [nx, ny], got {grid!r}")
        shape = tuple(_integer(f"sensors.grid[{i}]", g) for i, g in enumerate(grid))
        extent = _number("sensors.extent", sensors.get("extent", 1.0), positive=True)
        if "center" not in sensors:
            raise SceneError("sensors.center", "required with sensors.grid")
        center = _point("sensors.center", sensors["center"])
        positions = sensor_grid(shape, extent, center)
    else:
        raise SceneError("sensors", "give positions = [[x, y, z], ...] or grid = [nx, ny]")
    noise = None
    if "noise" in data:
        table = _table(data, "noise")
        noise = Noise(**table)
    return Scene(
        name=str(data.get("name", name)),
        size=plane.get("size", 1.0),
        pixels=pixels,
        reflectance=reflectance,
        source=source.get("position", (0.5, 0.5, 1.0)),
        sensors=positions,
        illumination=Illumination(**illumination),
        sampling=Sampling(**{_SAMPLING_FIELDS[key]: value for key, value in sampling.items()}),
        attenuation=model.get("attenuation", "lambertian"),
        tolerance=model.get("tolerance", 1e-6),
        noise=noise,
    )


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
    """Parse a TOML file; an unreadable file or bad TOML is a SceneError naming the file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise SceneError(str(path), f"cannot read {what} file ({error.strerror})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(str(path), f"invalid TOML ({error})") from None
