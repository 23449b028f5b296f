"""The ``transient_opl`` integrator: the single-plane scene of docs/design.md, one bounce, binned by path length.

The scene is one Lambertian rectangle, one point emitter above it and omni
point sensors. Every path is source -> plane point x -> sensor k: one
bounce, and nothing can occlude it (the plane is convex and both ends lie
above it), so no rays are traced. Each sample is a point x on the plane
that serves every sensor: it adds

    c_k = I ρ(x) a_k(x) / p(x)

to the bins its path length d_s + d_k reaches, each with the illumination's
kernel κ_n(d_s + d_k) (so any waveform renders directly), with either
attenuation of docs/design.md section 2 (the ``attenuation`` property):

    lambertian   a_k = cos θ_s cos θ_k / (π d_s² d_k²)   (physical transport, the default)
    paper        a_k = cos θ_s / (d_s² d_k²)             (eq. 1: π / cos θ_k more per sample)

Geometry, the intensity I and the sums are float64 from the scene to the
deposit: float32 coordinates 400 m away are off by tens of micrometres, and
float32 intensities round I = 1e30 by 1.5e-8 and flush I = 1e-300 to zero.
Only the reflectance texture is float32 (Mitsuba's bitmaps are), and so is
the (u, v) that looks it up: a point within a float32 rounding (~6e-8 of
the plane) of a pixel border may read the neighbouring pixel, either way.

How x is drawn (:func:`techniques` chooses, the
techniques themselves are :mod:`transient.plane_sampling`):

- **by solid angle from the source** (spherical-rectangle sampling):
  p(x) ∝ cos θ_s / d_s², so the weight I ρ Ω_s cos θ_k / (π d_k²) stays
  bounded however low the source;
- **multiple importance sampling with low sensors**: a sensor whose
  cos θ_k / d_k² peaks far above its mean (a sensor close to the plane)
  gets its own share of the samples drawn by the solid angle it sees, and
  every sample is weighted by the balance heuristic over all techniques, so
  no weight has a 1/d² spike;
- **jittered stratification** in a coherent order: each technique's share of
  a replica is a jittered grid of cells of equal probability, visited in
  Morton order. The error of a replica then falls as n^(-3/4) where the
  integrand has edges (isochrones, pixel borders), n^(-1) where it is smooth;
- **independent replicas** give the standard error (Student t, R - 1
  degrees of freedom): see :mod:`transient.chunks`.

Points from which the density varies by less than a factor
:data:`AREA_SAMPLING_RATIO` over the plane (a source high or far above
it) are sampled by area instead: as good there within a third, cheaper per
sample, and free of the solid angle's rounding at tiny Ω.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from analytic.attenuation import ATTENUATIONS, attenuation_code
from analytic.waveforms.builders import plugin_rows

from . import spherical_rectangle
from .chunks import ReplicaLayout, checked_chunk
from .intensity import emitter_intensity
from .common import attenuation, deposit, is_diffuse, jittered_point, opaque_f64, opaque_u32, reduce_mode, \
    replica_of, sample_stream, time_axis_and_waveform
from .plane_sampling import AREA, AREA_SAMPLING_RATIO, SOLID_ANGLE, Technique, block_bounds, mixture_density, \
    peak_ratio, sampling_kind, warp

__all__ = ["TransientPlaneIntegrator", "PLUGIN_NAME", "Technique", "techniques", "plane_frame",
           "AREA_SAMPLING_RATIO", "PEAK_RATIO_LIMIT", "STRATEGIES", "SAMPLERS",
           "ATTENUATIONS"]

PLUGIN_NAME = "transient_opl"

#: Sampling strategies: multiple importance sampling with low sensors, the
#: source's solid angle alone, uniform area (the plain estimator, kept to
#: measure the others against).
STRATEGIES = ("mis", "source", "area")

#: Point sets per technique: jittered-stratified, or independent uniform.
SAMPLERS = ("stratified", "independent")

#: A sensor gets a sampling technique of its own when, with points drawn by
#: the source alone, the largest weight cos θ_k / d_k² / p_s(x) exceeds its
#: mean by more than this factor (the relative variance it bounds).
PEAK_RATIO_LIMIT = 16.0

#: Share of each replica for the source's technique when sensors have
#: techniques too; the sensors share the rest equally.
SOURCE_SHARE = 0.5

# Agreement demanded between the double-precision geometry this plugin is
# given and the float32 copy Mitsuba built the scene from: its rounding, with room.
_FLOAT32_MATCH = 1e-6


def plane_frame(matrix: np.ndarray):
    """The rectangle's frame from Mitsuba's ``to_world`` of the local square [-1, 1]².

    Parameters
    ----------
    matrix : numpy.ndarray
        ``(4, 4)`` float64 transform.

    Returns
    -------
    corner, x_axis, y_axis, normal : numpy.ndarray
        World position of local (-1, -1), unit vectors along the local x and
        y edges, and the front normal (Mitsuba's: the transformed +z normal).
    width, height : float
        Side lengths a, b, metres.

    Raises
    ------
    ValueError
        The transform shears the square (its edges are not perpendicular).
    """
    corner = matrix[:3, :3] @ np.array([-1.0, -1.0, 0.0]) + matrix[:3, 3]
    edge_x, edge_y = 2.0 * matrix[:3, 0], 2.0 * matrix[:3, 1]
    width, height = float(np.linalg.norm(edge_x)), float(np.linalg.norm(edge_y))
    if not (width > 0.0 and height > 0.0) or abs(edge_x @ edge_y) > 1e-12 * width * height:
        raise ValueError("transient_opl: plane_to_world must map the square to a rectangle "
                         "(perpendicular, non-zero edges)")
    normal = np.linalg.inv(matrix[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
    return corner, edge_x / width, edge_y / height, normal / np.linalg.norm(normal), width, height


def techniques(source, sensors, width: float, height: float, strategy: str = "mis") -> list[Technique]:
    """The sampling techniques of a scene and their shares, source first.

    Parameters
    ----------
    source : array_like
        (x, y, h) of the point emitter in the plane's frame, metres, h > 0.
    sensors : array_like
        ``(K, 3)`` sensor positions in the plane's frame, metres.
    width, height : float
        The rectangle's sides, metres.
    strategy : {"mis", "source", "area"}
        See :data:`STRATEGIES`.

    Returns
    -------
    list of Technique
        Shares add up to 1.

    Notes
    -----
    ``mis``: the source's technique, plus one for each sensor above the
    plane whose peak ratio (:data:`PEAK_RATIO_LIMIT`) says the source's
    points would leave it a heavy-tailed weight; the source then keeps
    :data:`SOURCE_SHARE` and the sensors split the rest.
    """
    source = tuple(float(v) for v in source)
    if strategy == "area":
        return [Technique(AREA, source, 1.0, None)]
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
    kind = sampling_kind(source, width, height)
    rectangle = spherical_rectangle.setup(source, width, height) if kind == SOLID_ANGLE else None
    first = Technique(kind, source, 1.0, rectangle)
    if strategy == "source":
        return [first]
    peaked = [tuple(float(v) for v in sensor) for sensor in np.asarray(sensors, dtype=np.float64)
              if sensor[2] > 0.0 and peak_ratio(first, sensor, width, height) > PEAK_RATIO_LIMIT]
    if not peaked:
        return [first]
    share = (1.0 - SOURCE_SHARE) / len(peaked)
    return [first._replace(share=SOURCE_SHARE)] + [
        Technique(SOLID_ANGLE, sensor, share, spherical_rectangle.setup(sensor, width, height))
        for sensor in peaked]


class TransientPlaneIntegrator(mi.SamplingIntegrator):
    r"""
    .. _integrator-transient_opl:

    Single-plane path-length integrator (:monosp:`transient_opl`)
    -------------------------------------------------------------

    .. pluginparameters::

     * - bins
       - |int|
       - Number of time bins N. (Required)
     * - start_opl
       - |float|
       - Lower edge t0 of bin 0, metres of optical path length. (Default: 0)
     * - bin_width_opl
       - |float|
       - Bin width T, metres of optical path length. (Required)
WAVEFORM_ROWS
     * - plane_to_world
       - |transform|
       - The rectangle's ``to_world`` again, in double precision (Mitsuba
         keeps shapes in float32); checked against the shape. (Required)
     * - source_position
       - |point|
       - The point emitter's position in double precision; checked
         against the emitter. (Required)
     * - source_intensity
       - |float|
       - The point emitter's intensity I (W/sr) in double precision, the
         one rendered; the emitter must hold :func:`emitter_intensity` of
         it (float32(I), or the smallest normal float32 where I is below
         it). (Default: the emitter's own float32 intensity)
     * - attenuation
       - |string|
       - ``lambertian`` (physical: cos θ_s cos θ_k / (π d_s² d_k²)) or
         ``paper`` (eq. 1 of the paper: cos θ_s / (d_s² d_k²)), docs/design.md
         section 2 (Default: ``lambertian``).
     * - strategy
       - |string|
       - ``mis`` (the source's solid angle, plus low sensors' own, balance
         heuristic), ``source`` or ``area`` (Default: ``mis``).
     * - sampler
       - |string|
       - ``stratified`` (jittered, Morton order) or ``independent``
         (Default: ``stratified``).

    The scene must hold exactly one ``rectangle`` with a ``diffuse`` BSDF,
    one ``point`` emitter above its front side and ``omni_point`` sensors.
    Render with :meth:`render_chunk` (or :func:`transient.render.render`),
    not ``mi.render``.
    """

    def __init__(self, props):
        super().__init__(props)
        self.bins, self.start_opl, self.bin_width_opl, self.waveform = time_axis_and_waveform(
            props, "transient_opl")
        if "max_depth" in props:
            raise ValueError("transient_opl: paths on a single plane have exactly one bounce "
                             "(max_depth belongs to transient_opl_path)")
        if "plane_to_world" not in props or "source_position" not in props:
            raise ValueError("transient_opl: plane_to_world and source_position are required "
                             "(use transient_opl_path for other scenes)")
        self.plane_matrix = np.array(props.get("plane_to_world").matrix, dtype=np.float64).reshape(4, 4)
        self.corner, self.x_axis, self.y_axis, self.normal, self.width, self.height = \
            plane_frame(self.plane_matrix)
        self.source_world = np.array(props.get("source_position"), dtype=np.float64).reshape(3)
        self.source = self.to_plane(self.source_world)
        if not self.source[2] > 0.0:
            raise ValueError("transient_opl: source_position must lie above the rectangle's front side")
        self.source_intensity = None
        if "source_intensity" in props:
            self.source_intensity = float(props.get("source_intensity"))
            if not (math.isfinite(self.source_intensity) and self.source_intensity > 0.0):
                raise ValueError(f"transient_opl: source_intensity must be finite and > 0, "
                                 f"got {self.source_intensity}")
        self.attenuation = str(props.get("attenuation", "lambertian"))
        if self.attenuation not in ATTENUATIONS:
            raise ValueError(f"transient_opl: attenuation must be one of {ATTENUATIONS}, "
                             f"got {self.attenuation!r}")
        self.strategy = str(props.get("strategy", "mis"))
        self.sampler = str(props.get("sampler", "stratified"))
        if self.strategy not in STRATEGIES:
            raise ValueError(f"transient_opl: strategy must be one of {STRATEGIES}, got {self.strategy!r}")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"transient_opl: sampler must be one of {SAMPLERS}, got {self.sampler!r}")
        self._planned: dict[bytes, list[Technique]] = {}

    def to_plane(self, points) -> np.ndarray:
        """World points ``(..., 3)`` in the plane's frame: (x, y) along its edges from the corner, h along its normal."""
        offset = np.asarray(points, dtype=np.float64) - self.corner
        return np.stack([offset @ self.x_axis, offset @ self.y_axis, offset @ self.normal], axis=-1)

    def to_string(self):
        return (f"TransientPlaneIntegrator[bins={self.bins}, start_opl={self.start_opl}, "
                f"bin_width_opl={self.bin_width_opl}, waveform={self.waveform.description!r}, "
                f"attenuation={self.attenuation!r}, strategy={self.strategy!r}, sampler={self.sampler!r}]")

    # -- scene checks -------------------------------------------------------------

    def _scene_parts(self, scene):
        """(rectangle shape, source intensity (float64, W/sr), sensor positions in the plane's frame)."""
        shapes = scene.shapes()
        if len(shapes) != 1 or shapes[0].shape_type() != mi.ShapeType.Rectangle:
            raise ValueError("transient_opl: the scene must hold exactly one 'rectangle' shape")
        plane = shapes[0]
        if not is_diffuse(plane.bsdf()):
            raise ValueError("transient_opl: the rectangle needs a 'diffuse' BSDF")
        shape_matrix = np.array(mi.traverse(plane)["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        if not np.allclose(shape_matrix, self.plane_matrix, rtol=_FLOAT32_MATCH,
                           atol=_FLOAT32_MATCH * np.abs(self.plane_matrix).max()):
            raise ValueError("transient_opl: plane_to_world differs from the rectangle's to_world")
        emitters = scene.emitters()
        if len(emitters) != 1:
            raise ValueError("transient_opl: the scene must hold exactly one 'point' emitter")
        parameters = mi.traverse(emitters[0])
        if "position" not in parameters.keys() or "intensity.value" not in parameters.keys():
            raise ValueError("transient_opl: the emitter must be a 'point' emitter with a constant intensity")
        position = np.array(parameters["position"], dtype=np.float64).reshape(3)
        if not np.allclose(position, self.source_world, rtol=_FLOAT32_MATCH,
                           atol=_FLOAT32_MATCH * np.abs(self.source_world).max()):
            raise ValueError("transient_opl: source_position differs from the point emitter's position")
        intensity = self._intensity(float(np.array(parameters["intensity.value"]).ravel()[0]))
        sensors = scene.sensors()
        if not sensors or not all(hasattr(sensor, "position") for sensor in sensors):
            raise ValueError("transient_opl: every sensor must be an 'omni_point' sensor")
        positions = self.to_plane(np.array([sensor.position for sensor in sensors], dtype=np.float64))
        return plane, intensity, positions

    def _intensity(self, emitted: float) -> float:
        """The float64 intensity rendered, after checking the emitter's float32 one against it."""
        if self.source_intensity is None:
            return emitted
        expected = emitter_intensity(self.source_intensity)
        if not math.isclose(emitted, expected, rel_tol=_FLOAT32_MATCH):
            raise ValueError(f"transient_opl: source_intensity {self.source_intensity!r} differs from the point "
                             f"emitter's intensity {emitted!r} (expected {expected!r})")
        return self.source_intensity

    def intensity(self, scene) -> float:
        """The source intensity I this integrator renders in ``scene``, W/sr (float64).

        ``source_intensity`` when given (checked against the emitter), else
        the emitter's float32 value.
        """
        return self._scene_parts(scene)[1]

    def techniques(self, sensors: np.ndarray) -> list[Technique]:
        """The sampling techniques for these sensors (plane frame), planned once per sensor set."""
        key = np.ascontiguousarray(sensors).tobytes()
        if key not in self._planned:
            self._planned[key] = techniques(self.source, sensors, self.width, self.height, self.strategy)
        return self._planned[key]

    # -- the estimator ------------------------------------------------------------

    def render_chunk(self, scene, *, seed: int, layout: ReplicaLayout, first: int, count: int) -> np.ndarray:
        """Per-replica sums Σc over samples [first, first + count) of a render, in units of y.

        :meth:`render_chunk_per_unit_intensity` times the source intensity
        I (float64): one rounding per entry. A renderer that keeps
        accumulating per unit intensity and multiplies by I once at the end
        gets y(I) / I identical for every I (:func:`transient.render.render`
        does).

        Parameters and returns as :meth:`render_chunk_per_unit_intensity`,
        with c_k[n] = I ρ a_k κ_n / p (units of y).
        """
        sums = self.render_chunk_per_unit_intensity(scene, seed=seed, layout=layout, first=first, count=count)
        return sums * self.intensity(scene)

    def render_chunk_per_unit_intensity(self, scene, *, seed: int, layout: ReplicaLayout, first: int,
                                        count: int) -> np.ndarray:
        """Per-replica sums Σc over samples [first, first + count) of a render, per unit source intensity.

        Parameters
        ----------
        scene : mitsuba.Scene
            Scene loaded with this integrator.
        seed : int
            Render seed, 0 <= seed < 2^32.
        layout : ReplicaLayout
            The render's replicas; sample g is sample g mod n of replica
            ⌊g / n⌋.
        first, count : int
            The chunk's first global sample index and its size
            (1 <= count <= 2^31, first + count <= R n).

        Returns
        -------
        numpy.ndarray
            ``(replicas touched, K, N)`` float64: for each replica the chunk
            touches (in order), Σ c over its samples in the chunk, where
            c_k[n] = ρ a_k κ_n / p is one sample's contribution to y_k[n] / I
            (units of y per W/sr). A complete replica's sum over n is its
            estimate of y / I.

        Notes
        -----
        Every argument that changes between chunks (seed, offsets, replica
        size, technique blocks) reaches the kernel as an opaque value, so one
        compiled kernel serves every chunk of every render of the scene.
        """
        first, count = checked_chunk(layout, seed, first, count)
        plane, _, sensors = self._scene_parts(scene)
        plan = self.techniques(sensors)
        size = layout.size
        first_replica = first // size
        rows = (first + count - 1) // size - first_replica + 1
        K, N = len(sensors), self.bins

        # -- per-sample state: index, random stream, replica, technique block
        lane = dr.arange(mi.UInt32, count)                            # sample within the chunk
        index = mi.UInt64(lane) + dr.opaque(mi.UInt64, first)        # global sample index g
        rng = sample_stream(opaque_u32(seed), mi.UInt32(index), mi.UInt32(index >> 32))
        replica, in_replica = replica_of(mi.Float64(lane) + opaque_f64(first - first_replica * size),
                                         opaque_f64(size))
        bounds = block_bounds([t.share for t in plan], size)
        technique = mi.UInt32(0)                                      # which technique draws x
        block_start = opaque_u32(0)                                   # its block in the replica
        block_size = opaque_u32(bounds[1] - bounds[0])
        for t in range(1, len(plan)):
            later = in_replica >= opaque_u32(bounds[t])
            technique = dr.select(later, mi.UInt32(t), technique)
            block_start = dr.select(later, opaque_u32(bounds[t]), block_start)
            block_size = dr.select(later, opaque_u32(bounds[t + 1] - bounds[t]), block_size)
        jitter_u, jitter_v = rng.next_float64(), rng.next_float64()
        if self.sampler == "stratified":
            u, v = jittered_point(in_replica - block_start, block_size, jitter_u, jitter_v)
        else:
            u, v = jitter_u, jitter_v

        x, y = warp(plan, technique, u, v, self.width, self.height)
        reflectance = self._reflectance(plane, x, y)
        # The balance heuristic: every point is weighted by the density of all techniques together.
        shares = [opaque_f64((bounds[t + 1] - bounds[t]) / size) for t in range(len(plan))]
        weight_scale = reflectance / mixture_density(plan, shares, x, y, self.width, self.height)

        histogram = dr.zeros(mi.Float64, layout.histogram_rows * K * N)
        mode = reduce_mode()
        taps = self.waveform.bins_touched(self.bin_width_opl, self.bins)
        terms = self.waveform.terms
        source_distance = _distance(x, y, self.source)
        kind = attenuation_code(self.attenuation)
        for k in range(K):
            sensor = sensors[k]
            if not sensor[2] > 0.0:
                continue                        # below a one-sided plane: it sees no light
            weight = attenuation(x, y, self.source, sensor, kind)
            deposit(histogram, replica * K + k, weight_scale * weight, source_distance + _distance(x, y, sensor),
                    mi.Bool(True), bins=N, start_opl=self.start_opl, bin_width_opl=self.bin_width_opl,
                    terms=terms, taps=taps, mode=mode)
        dr.eval(histogram)
        return np.array(histogram, dtype=np.float64).reshape(-1, K, N)[:rows]

    def _reflectance(self, plane, x, y):
        """ρ(x) from the rectangle's own BSDF texture (as Mitsuba stores it: float32), Float64.

        The texture itself, not the BSDF's value ρ / π cos θ: Mitsuba forms that in float32, and
        its 1/π alone would bias every render by float32(1/π) π − 1 = −4.0e-8.
        """
        interaction = dr.zeros(mi.SurfaceInteraction3f)
        interaction.uv = mi.Point2f(mi.Float(x / self.width), mi.Float(y / self.height))
        interaction.n = mi.Normal3f(0.0, 0.0, 1.0)
        interaction.sh_frame = mi.Frame3f(interaction.n)
        interaction.wi = mi.Vector3f(0.0, 0.0, 1.0)
        value = plane.bsdf().eval_diffuse_reflectance(interaction)
        return mi.Float64(value[0])


def _distance(x, y, point):
    px, py, height = (float(v) for v in point)
    return dr.sqrt(dr.square(x - px) + dr.square(y - py) + height * height)


# the waveform rows from the waveform registry: each module's name and plugin properties
TransientPlaneIntegrator.__doc__ = TransientPlaneIntegrator.__doc__.replace("WAVEFORM_ROWS", plugin_rows())

mi.register_integrator(PLUGIN_NAME, lambda props: TransientPlaneIntegrator(props))
