"""The scene: frozen, validated dataclasses (docs/design.md sections 1 and 5).

Every length is in metres and every time is an optical path length in metres
(c = 1), as docs/design.md section 1 fixes. A value is checked where the
dataclass is built, so a bad one fails with a :class:`SceneError` naming its
scene-file key before anything is computed or written; sizes that would not
fit in memory fail with a :class:`ResourceError` before anything is
allocated. Reading and writing scene files is :mod:`analytic.scenes.scene_file`.

Limits (each a clean error, not a silently wrong number):

- every length and coordinate within ±``MAX_LENGTH`` (1e12 m) and every
  positive length at least ``MIN_LENGTH`` (1e-9 m), the source and sensors
  at least ``MIN_HEIGHT_FRACTION`` (1e-9) of the scene's extent above the
  plane (:func:`check_heights`): beyond these, path lengths and their
  differences leave the range where float64 resolves the response;
- the model's tolerance in [1e-10, 0.1) (:func:`check_tolerance`);
- bins resolvable in float64: T ≥ 1e-12 × the largest |path length| of the
  window;
- at most ``MAX_SENSORS`` sensors (the renderer compiles one deposit per
  sensor) and images and transients that fit in half the memory available.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..measurement.detector import Detector
from ..errors import SceneError
from ..geometry import ATTENUATIONS, plane_geometry
from .kinds import register_scene_kind
from .limits import (MAX_INTENSITY, MAX_TOLERANCE, MIN_HEIGHT_FRACTION, MIN_INTENSITY, MIN_TOLERANCE,
                     check_intensity, check_tolerance, minimum_height, scene_extent)
from .reflectance import builtin_reflectance, reflectance_image
from ..resources import require_memory
from ..values import MAX_LENGTH, MIN_LENGTH, _integer, _number, exact
from ..waveforms import builders as _registry

__all__ = ["SceneError", "Illumination", "Sampling", "Noise", "Scene", "default_scene", "sensor_grid",
           "WAVEFORMS", "ATTENUATIONS", "NOISE_KINDS", "MAX_LENGTH", "MIN_LENGTH", "MIN_HEIGHT_FRACTION", "MAX_SENSORS", "MIN_TOLERANCE", "MAX_TOLERANCE",
           "illumination_keys", "check_heights", "check_tolerance", "scene_extent", "minimum_height",
           "DEFAULT_ARRAY"]

#: The waveforms a scene may name: the registry itself (:mod:`analytic.waveforms.builders`), so one
#: registered later is known too.
WAVEFORMS = _registry.WAVEFORMS
NOISE_KINDS = ("gaussian", "poisson")

#: Largest Gaussian noise σ: m σ² (the discrepancy rule's target) stays finite.
MAX_SIGMA = 1e150
#: Most sensors a scene may have.
MAX_SENSORS = 1024
#: Relative resolution a bin edge needs in float64 (T against |t|).
_BIN_RESOLUTION = 1e-12
#: Seeds are 32-bit, as the renderer's.
_SEED_LIMIT = 2**32


def _point(key: str, value: Any) -> np.ndarray:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise SceneError(key, f"expected [x, y, z] in metres, got {value!r}")
    point = np.array([_number(f"{key}[{i}]", v, length=True) for i, v in enumerate(value)])
    if not point[2] > 0.0:
        raise SceneError(key, f"z = {point[2]} must be > 0 (strictly above the plane)")
    return point


def check_heights(size: float, source, sensors) -> None:
    """Refuse a source or sensor too close to the plane for float64 to resolve its response.

    Parameters
    ----------
    size : float
        Plane side L, metres.
    source : array_like
        (x, y, z), metres.
    sensors : array_like
        ``(K, 3)``, metres.

    Raises
    ------
    SceneError
        Naming ``source.position`` or ``sensors.positions[k]`` and the
        smallest height supported.

    Notes
    -----
    Criterion: h >= MIN_HEIGHT_FRACTION x extent (:func:`scene_extent`). The
    attenuation's peak under a point at height h has width h; below the
    criterion it spans fewer than ~10⁶ roundings of the plane coordinates
    and path lengths, and the quadrature can no longer find it (at 1e-300
    it would silently return ~0 instead of the finite limit).
    """
    floor = minimum_height(size, source, sensors)
    checks = [("source.position", np.asarray(source, dtype=np.float64))]
    checks += [(f"sensors.positions[{k}]", p) for k, p in
               enumerate(np.reshape(np.asarray(sensors, dtype=np.float64), (-1, 3)))]
    for key, point in checks:
        if not point[2] >= floor:
            raise SceneError(key, f"height {exact(point[2])} m is below the smallest height supported, "
                             f"{exact(floor)} m ({MIN_HEIGHT_FRACTION:g} of the scene's extent "
                             f"{floor / MIN_HEIGHT_FRACTION:.6g} m): float64 cannot resolve the light "
                             f"under a point that low; raise it to at least {exact(floor)} m")


def _choice(key: str, value: Any, options: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in options:
        raise SceneError(key, f"must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


@dataclass(frozen=True, init=False, eq=False, repr=False)
class Illumination:
    """The source's intensity waveform s(t) (docs/design.md sections 2 and 8).

    Parameters
    ----------
    waveform : str
        A name in :data:`WAVEFORMS` (each module's ``SUMMARY`` says what it
        is): ``impulse``, ``square``, ``butterworth``, ``gaussian``, ``emg``,
        ``sech2``, ``sampled``. Each but the impulse is scaled to unit peak
        amplitude. The keys are the ones the registered waveforms declare
        (``PARAMETERS``; the project's are below), each applying only to the
        waveforms declaring it; a key not given reads as None.
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
    fwhm : float, optional
        Gaussian, EMG and sech² (required): the full width at half maximum
        (the EMG's Gaussian's), metres of path (1 ps = 2.99792458e-4 m).
    tail : float, optional
        EMG (required): the exponential's time constant, metres of path.
    samples : sequence of float, optional
        Sampled: the response's samples (>= 0, some > 0), or read from
        ``file``; stored as a tuple.
    file : str, optional
        Sampled: the .npy/.csv file the samples come from (the scene file
        reads it, relative to itself; given alone here, relative to the
        working folder). Recorded in the description only.
    sample_width, sample_width_ps : float, optional
        Sampled (exactly one of them): the samples' spacing, metres of path
        or picoseconds.
    start : float, optional
        Sampled: path length of the first sample, metres. Default 0.
    """

    waveform: str
    values: tuple      # ((key, value), ...): the keys given, checked, in the registry's order; read as attributes

    def __init__(self, *, waveform: str = "impulse", **keys):
        unknown = [key for key in keys if key not in _registry.keys()]
        if unknown:
            raise TypeError(f"Illumination.__init__() got an unexpected keyword argument {unknown[0]!r}")
        _choice("illumination.waveform", waveform, WAVEFORMS)
        object.__setattr__(self, "waveform", waveform)
        own = _registry.own_keys(waveform)
        given = {}
        for name in _registry.keys():          # the registry's order: the first bad key in it is named
            value = keys.get(name)
            if value is None:
                continue
            if name not in own:
                raise SceneError(f"illumination.{name}", f"does not apply to waveform = {waveform!r}")
            kind = _registry.parameter(name).kind
            if kind == "integer":
                value = _integer(f"illumination.{name}", value)
            elif kind in ("length", "coordinate"):
                value = _number(f"illumination.{name}", value, positive=kind == "length", length=True)
            elif kind == "positive":
                # the waveform's own bounds (analytic.waveforms.make_waveform) depend on the period
                value = _number(f"illumination.{name}", value, positive=True)
            given[name] = value
        if waveform == "sampled":
            self._check_sampled(given)
        object.__setattr__(self, "values", tuple((key, given[key]) for key in _registry.keys() if key in given))

    def __getattr__(self, name: str):
        # a registered key not given is None (``illumination.fwhm``); called only where no attribute is found
        if name.startswith("_") or name not in _registry.keys():
            raise AttributeError(f"'Illumination' object has no attribute {name!r}")
        return dict(self.values).get(name)

    def _compared(self) -> tuple:
        """What equality compares: a key of kind ``file`` (where the samples came from) is a label only."""
        return self.waveform, tuple(item for item in self.values if _registry.parameter(item[0]).kind != "file")

    def __eq__(self, other):
        return self._compared() == other._compared() if type(other) is type(self) else NotImplemented

    def __hash__(self):
        return hash(self._compared())

    def __repr__(self) -> str:
        shown = (("waveform", self.waveform), *self.values)
        return f"Illumination({', '.join(f'{key}={value!r}' for key, value in shown)})"

    def _check_sampled(self, given: dict):
        """Samples from ``samples`` or ``file`` (exactly one), a spacing from exactly one key, a resolvable span."""
        from ..waveforms.measured import check_samples, finite_span, read_samples, sample_width_metres

        file, samples = given.get("file"), given.get("samples")
        if file is not None and not isinstance(file, str):
            raise SceneError("illumination.file", f"expected a file name, got {file!r}")
        if samples is None and file is None:
            raise SceneError("illumination.file", "required with waveform = 'sampled' (a .npy or .csv of the "
                                                  "response's samples), or give samples = [...]")
        samples = read_samples(file) if samples is None else check_samples(samples)
        given["samples"] = tuple(float(v) for v in samples)
        stated = [name for name in ("sample_width", "sample_width_ps") if name in given]
        if len(stated) != 1:
            raise SceneError("illumination.sample_width", "give exactly one of sample_width (metres of path) and "
                             f"sample_width_ps (picoseconds); got {' and '.join(stated) or 'neither'}")
        width = sample_width_metres(given.get("sample_width"), given.get("sample_width_ps"))
        if not width >= MIN_LENGTH:
            raise SceneError(f"illumination.{stated[0]}", f"{exact(width)} m is below the smallest length supported, "
                                                         f"{MIN_LENGTH:g} m")
        finite_span(len(samples), width, given.get("start", 0.0), MAX_LENGTH, _BIN_RESOLUTION)


def illumination_keys() -> tuple:
    """Every optional key of ``[illumination]`` (the scene file's names): those the registered waveforms declare."""
    return _registry.keys()


@dataclass(frozen=True, kw_only=True)
class Sampling:
    """Box ("integrate and dump") sampling: bin n covers
    [start_opl + n bin_width_opl, start_opl + (n + 1) bin_width_opl).

    The scene file's keys are ``[sampling] period`` (T), ``start`` (t0) and
    ``count`` (N), as docs/design.md section 5 fixes; in code and in every output
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
        width = _number("sampling.period", self.bin_width_opl, positive=True, length=True)
        start = _number("sampling.start", self.start_opl, length=True)
        count = _integer("sampling.count", self.count)
        end = start + count * width
        if not abs(end) <= MAX_LENGTH:
            raise SceneError("sampling.count", f"the window ends at {exact(end)} m, beyond the "
                             f"±{MAX_LENGTH:g} m this tool resolves; use fewer or narrower bins")
        if width < _BIN_RESOLUTION * max(abs(start), abs(end)):
            raise SceneError("sampling.period", f"bins of {exact(width)} m cannot be told apart at path "
                             f"lengths of {exact(max(abs(start), abs(end)))} m in float64 (need period >= "
                             f"{_BIN_RESOLUTION:g} x the largest |path length|)")
        object.__setattr__(self, "bin_width_opl", width)
        object.__setattr__(self, "start_opl", start)
        object.__setattr__(self, "count", count)

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
    sigma : float, optional
        Gaussian only: standard deviation, in units of y. Default 0.1 (the
        paper's). None for ``poisson``.
    photons : float, optional
        Poisson only: expected photon count per unit of y. Default 1000.
        None for ``gaussian``.
    seed : int
        Seed of the noise generator, 0 <= seed < 2^32.
    """

    kind: str = "gaussian"
    sigma: float | None = None
    photons: float | None = None
    seed: int = 0

    def __post_init__(self):
        _choice("noise.kind", self.kind, NOISE_KINDS)
        own, other = ("sigma", "photons") if self.kind == "gaussian" else ("photons", "sigma")
        if getattr(self, other) is not None:
            raise SceneError(f"noise.{other}", f"does not apply to kind = {self.kind!r}")
        if self.kind == "gaussian":
            sigma = _number("noise.sigma", 0.1 if self.sigma is None else self.sigma, nonnegative=True)
            if sigma > MAX_SIGMA:
                raise SceneError("noise.sigma", f"{exact(sigma)} is beyond the {MAX_SIGMA:g} whose square "
                                                f"stays finite")
            object.__setattr__(self, "sigma", sigma)
        else:
            object.__setattr__(self, "photons", _number("noise.photons", 1000.0 if self.photons is None
                                                        else self.photons, positive=True))
        object.__setattr__(self, "seed", _integer("noise.seed", self.seed, minimum=0,
                                                  maximum=_SEED_LIMIT - 1))


@register_scene_kind
@dataclass(frozen=True, kw_only=True, eq=False)
class Scene:
    """A Lambertian plane, one point source, K point sensors, sampling (the scene kind ``plane``).

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
    intensity : float
        The source's peak radiant intensity I, W/sr (scene key
        ``[source] intensity``). The source emits I s(t): y and the noise's σ
        are in units of W/sr x m⁻² x m of path length (see the README). For
        the impulse, I scales the unit-area Dirac pulse the same way.
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
    detector : analytic.measurement.detector.Detector or None
        Photon counting for ``counts_expected.npy`` and ``counts.npy``
        (docs/design.md section 8); None: no counts.
    name : str
        Label used in reports.
    """

    size: float = 1.0
    pixels: int = 50
    reflectance: Any = 0.5
    source: Any = (0.5, 0.5, 1.0)
    intensity: float = 1.0
    sensors: Any = ((0.2, 0.7, 1.0),)
    illumination: Illumination = field(default_factory=Illumination)
    sampling: Sampling = field(default_factory=Sampling)
    attenuation: str = "lambertian"
    tolerance: float = 1e-6
    noise: Noise | None = None
    detector: Detector | None = None
    name: str = "scene"

    #: The scene kind's name, its rows and its image's key (:class:`analytic.scenes.kinds.SceneKind`).
    kind: ClassVar[str] = "plane"
    row_noun: ClassVar[str] = "sensor"
    image_key: ClassVar[str] = "plane.reflectance"
    #: How y's units follow from the source's intensity (docs/design.md section 1), as meta.json states them.
    units: ClassVar[str] = (
        "lengths in metres; time as optical path length in metres (c = 1); y in W/sr x m^-2 x m "
        "of path length: the source's peak radiant intensity I (W/sr) times the pulse's "
        "integral over the bin (m of path length) times the attenuation (m^-4) times area (m^2); "
        "noise sigma in the units of y")

    def __post_init__(self):
        size = _number("plane.size", self.size, positive=True, length=True)
        pixels = _integer("plane.pixels", self.pixels)
        # the image and a few copies of it (f, its DCT, a reconstruction): refuse before allocating
        require_memory(4 * 8 * pixels**2, f"plane.pixels = {pixels}",
                       "use fewer pixels")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "pixels", pixels)
        object.__setattr__(self, "reflectance", reflectance_image("plane.reflectance", self.reflectance, pixels))
        object.__setattr__(self, "source", _point("source.position", self.source))
        self.source.setflags(write=False)
        object.__setattr__(self, "intensity", check_intensity("source.intensity", self.intensity))
        if not isinstance(self.sensors, np.ndarray) and not isinstance(self.sensors, (list, tuple)):
            raise SceneError("sensors.positions", f"expected a list of [x, y, z], got {self.sensors!r}")
        sensors = list(self.sensors)
        if len(sensors) == 0:
            raise SceneError("sensors.positions", "at least one sensor is needed")
        if len(sensors) > MAX_SENSORS:
            raise SceneError("sensors.positions", f"{len(sensors)} sensors; at most {MAX_SENSORS} "
                             f"are supported (the renderer compiles one deposit per sensor)")
        points = np.array([_point(f"sensors.positions[{k}]", p) for k, p in enumerate(sensors)])
        points.setflags(write=False)
        object.__setattr__(self, "sensors", points)
        check_heights(size, self.source, points)
        if not isinstance(self.illumination, Illumination):
            raise SceneError("illumination", "expected an Illumination")
        if not isinstance(self.sampling, Sampling):
            raise SceneError("sampling", "expected a Sampling")
        # y, its noisy copy, the render's mean, error and moments: K N doubles each
        require_memory(8 * 8 * len(points) * self.sampling.count,
                       f"{len(points)} sensors x sampling.count = {self.sampling.count} bins",
                       "use fewer bins (sampling.count) or sensors")
        _choice("model.attenuation", self.attenuation, ATTENUATIONS)
        object.__setattr__(self, "tolerance", check_tolerance(self.tolerance))
        if self.noise is not None and not isinstance(self.noise, Noise):
            raise SceneError("noise", "expected a Noise or None")
        if self.detector is not None and not isinstance(self.detector, Detector):
            raise SceneError("detector", "expected an analytic.measurement.detector.Detector or None")
        if not isinstance(self.name, str):
            raise SceneError("name", f"expected a string, got {self.name!r}")
        # the name labels reports, figures and printed lines: one line of printable text
        unprintable = next((c for c in self.name if not c.isprintable()), None)
        if unprintable is not None:
            raise SceneError("name", f"holds the unprintable character U+{ord(unprintable):04X} (a control or "
                                     f"format character, or a separator other than the space); use printable text")

    @property
    def pixel_size(self) -> tuple[float, float]:
        """Pixel sides (Δ, Δ) along x and y, Δ = L / M, metres."""
        return self.size / self.pixels, self.size / self.pixels

    @property
    def sensor_count(self) -> int:
        """Number of sensors K."""
        return len(self.sensors)

    def replace(self, **changes) -> "Scene":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def geometry(self):
        """The plane as the model's rectangle and point pairs (:func:`analytic.geometry.plane_geometry`)."""
        return plane_geometry(self)

    def describe(self) -> str:
        """The transient's rows in words: "16 sensors"."""
        return f"{self.sensor_count} sensors"

    def darkness(self) -> tuple[str, str] | None:
        """("plane.reflectance", why) when the plane is black everywhere, else None."""
        if np.any(np.asarray(self.reflectance) > 0):
            return None
        return "plane.reflectance", "the plane is black (reflectance 0 everywhere)"

    def meta_fields(self) -> dict:
        """meta.json's ``geometry``, ``plane_size``, ``source``, ``sensor_positions``, ``attenuation``, ``units``."""
        return {"geometry": self.kind, "plane_size": float(self.size), "source": [float(v) for v in self.source],
                "sensor_positions": np.asarray(self.sensors, dtype=np.float64).tolist(),
                "attenuation": self.attenuation, "units": self.units}

    def to_tables(self, shared: dict) -> dict:
        """``[plane]``, ``[source]``, ``[sensors]``, ``shared``, ``[model]`` (the image inline, or its constant)."""
        image = self.reflectance
        uniform = bool(np.all(image == image.flat[0]))
        return {"plane": {"size": self.size, "pixels": self.pixels,
                          "reflectance": float(image.flat[0]) if uniform else np.array(image)},
                "source": {"position": self.source.tolist(), "intensity": self.intensity},
                "sensors": {"positions": self.sensors.tolist()},
                **shared,
                "model": {"attenuation": self.attenuation, "tolerance": self.tolerance}}


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


#: The built-in scene's sensor array: 4 x 4, W = 1 m, centred on the source at its height.
DEFAULT_ARRAY = {"grid": (4, 4), "extent": 1.0, "center": (0.5, 0.5, 1.0)}


def default_scene(**changes) -> Scene:
    """The built-in scene: the paper's Fig. 1 set-up, at a flux where σ = 0.1 leaves the image recoverable.

    A 1 m x 1 m plane imaged at M = 50 with the built-in reflectance pattern;
    the source 1 m above the plane's centre with peak intensity 10⁴ W/sr; a
    4 x 4 sensor array of extent W = 1 m centred on the source; impulse
    illumination; bins of T = 0.1 m from t0 = 1.9 m, 12 of them: the light
    arrives between 2.014 m and 2.957 m of path, so the window holds all of it
    with one empty bin at each end; physical (Lambertian) attenuation;
    Gaussian noise σ = 0.1 (the paper's).

    Why 10⁴ W/sr: at 1 W/sr (docs/design.md's unit) the signal peaks at 0.04 W/m
    against σ = 0.1 and no reconstruction beats a flat grey image; at 10⁴ W/sr
    it peaks at 409 W/m and a data-driven λ recovers the image about 5 dB better
    than the flat image (the README's table).

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
        intensity=1e4,
        sensors=sensor_grid(DEFAULT_ARRAY["grid"], DEFAULT_ARRAY["extent"], DEFAULT_ARRAY["center"]),
        illumination=Illumination(waveform="impulse"),
        sampling=Sampling(bin_width_opl=0.1, start_opl=1.9, count=12),
        attenuation="lambertian",
        noise=Noise(kind="gaussian", sigma=0.1, seed=0),
    )
    if "pixels" in changes and "reflectance" not in changes:
        changes["reflectance"] = builtin_reflectance(int(changes["pixels"]))
    return scene.replace(**changes) if changes else scene
