"""The ``transient_opl`` integrator: path-length-binned transport with any illumination waveform.

Each sample's paths are binned by optical length τ (source -> surfaces ->
sensor, c = 1) with the illumination's kernel κ_n(τ) = S(t_{n+1} - τ) -
S(t_n - τ), so any waveform renders directly, without a second convolution.
Per-bin sums of the contributions and of their squares are accumulated in
float64 for a standard error.

Two estimators:

* **Single plane** (``plane_to_world`` and ``source_position`` given: the
  scene of DESIGN.md, one Lambertian rectangle, one point emitter, omni
  point sensors). Every path is source -> plane point x -> sensor k: one
  bounce, and nothing can occlude it (the plane is convex and both ends lie
  above it), so no visibility rays are traced. Each sample draws x uniformly
  on the rectangle (pdf 1 / area) and serves every sensor:

      w_k(x) = area · I · [f(x)/π · cos θ_s] · cos θ_k / (d_s² d_k²),

  (the bracket is Mitsuba's ``diffuse`` BSDF evaluated at x; the rest is the
  point emitter's 1/d_s² and the change from the sensor's solid angle to
  area, cos θ_k / d_k²). The geometry is float64 throughout: float32
  coordinates 400 m away are off by tens of micrometres of path length.

* **General** (neither given): any shapes with ``diffuse`` BSDFs, point and
  area emitters, up to ``max_depth`` bounces, with shadow rays. x1 is drawn
  on all surfaces by area and connected to every sensor; the path continues
  by BSDF sampling with next-event estimation at each vertex. Its segment
  lengths come from float32 ray tracing (relative error about 1e-7).

Only physical (``lambertian``) transport is rendered; the paper's eq. (1)
attenuation is a model-side approximation with no renderer counterpart.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import functools

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from analytic.binning import bin_index
from analytic.scene import Illumination
from analytic.waveforms import EXPONENTIAL_SUM, IMPULSE, SQUARE, Waveform, make_waveform

__all__ = ["register", "integrator_class", "PLUGIN_NAME", "cumulative", "sample_index_key"]

PLUGIN_NAME = "transient_opl"


# Agreement demanded between the double-precision geometry this plugin is given
# and the float32 copy Mitsuba built the scene from: the float32 rounding, with room.
_FLOAT32_MATCH = 1e-6


def cumulative(waveform: Waveform, u):
    """S(u) = ∫_{-∞}^u s(t) dt in Dr.Jit Float64, the same closed form as ``Waveform.cumulative``.

    Parameters
    ----------
    waveform : Waveform
        The illumination's waveform.
    u : mi.Float64
        Time after the pulse's start, metres of path length.

    Returns
    -------
    mi.Float64
        S(u): dimensionless for the impulse (a step), metres for the others.
    """
    zero = mi.Float64(0.0)
    if waveform.kind == IMPULSE:
        return dr.select(u > 0.0, mi.Float64(1.0), zero)
    if waveform.kind == SQUARE:
        return dr.clip(u, 0.0, waveform.duration)
    if waveform.kind != EXPONENTIAL_SUM:
        raise ValueError(f"waveform {waveform.name!r}: unknown closed form {waveform.kind}")
    clipped = dr.clip(u, 0.0, waveform.duration)
    value = mi.Float64(float(waveform.constant))
    for a, w, b, c in _real_terms(waveform):
        term = float(b) * dr.cos(w * clipped) + float(c) * dr.sin(w * clipped) if w else float(b)
        value += dr.exp(a * clipped) * term
    # Near u = 0 the exponentials cancel to S ~ u^order: the Taylor series, as in NumPy.
    series = mi.Float64(0.0)
    for coefficient in waveform.series[::-1]:
        series = series * clipped + float(coefficient)
    value = dr.select(clipped < waveform.series_limit, series, value)
    return dr.select(u <= 0.0, zero, value)


def _real_terms(waveform: Waveform) -> list[tuple[float, float, float, float]]:
    """The exponential-sum terms (a, ω >= 0, b, c) with complex-conjugate pairs merged.

    A conjugate pole pair gives two terms with ±ω; since cos is even and sin
    odd they add up to one term, halving the transcendentals per kernel
    evaluation (they dominate the cost of a Butterworth render).
    """
    merged: dict[tuple[float, float], list[float]] = {}
    for a, w, b, c in zip(waveform.decay, waveform.frequency, waveform.cos_coefficient,
                          waveform.sin_coefficient):
        a, w, b, c = float(a), float(w), float(b), float(c)
        if w < 0.0:
            w, c = -w, -c
        key = next((k for k in merged if math.isclose(k[0], a, rel_tol=1e-12)
                    and math.isclose(k[1], w, rel_tol=1e-12, abs_tol=1e-300)), (a, w))
        entry = merged.setdefault(key, [0.0, 0.0])
        entry[0] += b
        entry[1] += c
    return [(a, w, b, c) for (a, w), (b, c) in merged.items()]


def sample_index_key(first_sample: int) -> tuple[int, int]:
    """(high, low) 32-bit halves of a global sample index.

    Sample i's PCG32 stream is seeded from ``sample_tea_32(seed, low)`` (a
    bijection of the 64-bit pair, so every (seed, low) differs) with ``high``
    added above bit 32 of the stream selector: every (seed, global index)
    triple gets its own stream, whatever the chunking, and for the first 2^32
    samples (high = 0) the streams are those of Mitsuba's ``independent``
    sampler.

    Parameters
    ----------
    first_sample : int
        Global index of a sample.
    """
    high, low = divmod(int(first_sample), 2**32)
    return high, low


def _is_diffuse(bsdf) -> bool:
    """A purely diffuse-reflecting BSDF: its value depends on wi only through its hemisphere."""
    if bsdf is None:
        return False
    flags = bsdf.flags()
    others = (mi.BSDFFlags.Glossy, mi.BSDFFlags.Delta, mi.BSDFFlags.Transmission)
    return (mi.has_flag(flags, mi.BSDFFlags.DiffuseReflection)
            and not any(mi.has_flag(flags, flag) for flag in others))


def _matrix(transform) -> np.ndarray:
    return np.array(transform.matrix, dtype=np.float64).reshape(4, 4)


def integrator_class() -> type:
    """The integrator class for the active variant (Mitsuba's base classes are per variant)."""
    return _integrator_class(mi.variant())


@functools.cache   # one class per variant: Mitsuba's base classes differ between variants
def _integrator_class(variant: str) -> type:

    class TransientPathLength(mi.SamplingIntegrator):
        r"""
        .. _integrator-transient_opl:

        Path-length-binned transient integrator (:monosp:`transient_opl`)
        ------------------------------------------------------------------

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
         * - waveform
           - |string|
           - Source intensity waveform s(t): ``impulse``, ``square`` or
             ``butterworth`` (Default: ``impulse``). Each bin receives
             κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) of its path length τ.
         * - pulse_width
           - |float|
           - ``square`` only: width in metres (Default: T / 5).
         * - cutoff, duration, order
           - |float|, |float|, |int|
           - ``butterworth`` only: cutoff (cycles per metre), truncation
             (metres), order (Defaults: 1/(2T), 3/cutoff, 3).
         * - plane_to_world
           - |transform|
           - Selects the single-plane estimator: the rectangle's
             ``to_world`` again, in double precision (Mitsuba keeps shapes
             in float32). Checked against the shape. Give it together with
             ``source_position``.
         * - source_position
           - |point|
           - Single-plane estimator: the point emitter's position in double
             precision. Checked against the emitter.
         * - max_depth
           - |int|
           - General estimator only: most surface bounces between emitter
             and sensor (Default: 1). Refused with the single-plane
             estimator, whose paths have exactly one bounce.

        Sensors must be ``omni_point``. Use :meth:`render_transient`, not
        ``mi.render``.
        """

        def __init__(self, props):
            super().__init__(props)
            self.bins = int(props.get("bins"))
            self.start_opl = float(props.get("start_opl", 0.0))
            self.bin_width_opl = float(props.get("bin_width_opl"))
            if self.bins < 1:
                raise ValueError(f"transient_opl: bins must be >= 1, got {self.bins}")
            if not (self.bin_width_opl > 0.0 and math.isfinite(self.bin_width_opl)):
                raise ValueError(f"transient_opl: bin_width_opl must be > 0, got {self.bin_width_opl}")
            name = props.get("waveform", "impulse")
            options = {"width": props.get("pulse_width") if "pulse_width" in props else None,
                       "cutoff": props.get("cutoff") if "cutoff" in props else None,
                       "duration": props.get("duration") if "duration" in props else None,
                       "order": props.get("order") if "order" in props else None}
            # Illumination validates names and values exactly as the scene file does.
            illumination = Illumination(waveform=name, **options)
            self.waveform = make_waveform(illumination, self.bin_width_opl)
            has_plane, has_source = "plane_to_world" in props, "source_position" in props
            if has_plane != has_source:
                raise ValueError("transient_opl: give both plane_to_world and source_position "
                                 "(single-plane scene) or neither (general scene)")
            if has_plane and "max_depth" in props:
                raise ValueError("transient_opl: max_depth applies to the general estimator only "
                                 "(single-plane paths have exactly one bounce)")
            self.max_depth = int(props.get("max_depth", 1))
            if self.max_depth < 1:
                raise ValueError(f"transient_opl: max_depth must be >= 1, got {self.max_depth}")
            self.plane_matrix = _matrix(props.get("plane_to_world")) if has_plane else None
            self.source_position = (np.array(props.get("source_position"), dtype=np.float64).reshape(3)
                                    if has_source else None)

        def to_string(self):
            return (f"TransientPathLength[bins={self.bins}, start_opl={self.start_opl}, "
                    f"bin_width_opl={self.bin_width_opl}, waveform={self.waveform.description!r}]")

        # -- scene checks -------------------------------------------------

        def _scene_parts(self, scene):
            """(rectangle shape, point intensity) after checking the single-plane scene fits."""
            shapes = scene.shapes()
            if len(shapes) != 1 or shapes[0].shape_type() != mi.ShapeType.Rectangle:
                raise ValueError("transient_opl: the scene must hold exactly one 'rectangle' shape")
            plane = shapes[0]
            if not _is_diffuse(plane.bsdf()):
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
                raise ValueError("transient_opl: the emitter must be a 'point' emitter "
                                 "with a constant intensity")
            position = np.array(parameters["position"], dtype=np.float64).reshape(3)
            if not np.allclose(position, self.source_position, rtol=_FLOAT32_MATCH,
                               atol=_FLOAT32_MATCH * np.abs(self.source_position).max()):
                raise ValueError("transient_opl: source_position differs from the point emitter's position")
            intensity = float(np.array(parameters["intensity.value"]).ravel()[0])
            return plane, intensity

        def _check_general_scene(self, scene):
            """Refuse what the general estimator does not model: non-diffuse BSDFs, no emitter."""
            if not scene.emitters():
                raise ValueError("transient_opl: the scene has no emitter")
            for shape in scene.shapes():
                if not _is_diffuse(shape.bsdf()):
                    raise ValueError(f"transient_opl: shape {shape.id()!r} needs a 'diffuse' BSDF")
            for emitter in scene.emitters():
                if not (mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)
                        or mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface)):
                    raise ValueError("transient_opl: only point and area emitters are supported")

        # -- the estimator ------------------------------------------------

        def render_transient(self, scene, *, seed: int, first_sample: int, sample_count: int):
            """Per-bin sums of w and w² over samples [first_sample, first_sample + sample_count).

            Parameters
            ----------
            scene : mitsuba.Scene
                Scene loaded with this integrator.
            seed : int
                Render seed, 0 <= seed < 2^32.
            first_sample : int
                Global index of the first sample. Sample i's random numbers
                depend only on (seed, i), so the sums over a range do not
                depend on how the range is split.
            sample_count : int
                Samples to draw, <= 2^32 - (first_sample mod 2^32).

            Returns
            -------
            sums, sums_of_squares : numpy.ndarray
                ``(K, N)`` float64: Σ_i c_i and Σ_i c_i² of the per-sample
                contributions c_i = w_k(x_i) κ_n(τ_i) to y_k[n], units of y
                (m⁻² · m per unit source intensity).

            Notes
            -----
            The Monte Carlo estimate of y_k[n] is sums / S over S samples.
            """
            if not 0 <= int(seed) < 2**32:
                raise ValueError(f"seed must be in [0, 2^32), got {seed}")
            high, low = sample_index_key(first_sample)
            if sample_count < 1 or low + sample_count > 2**32:
                raise ValueError(f"sample range [{first_sample}, {first_sample + sample_count}) "
                                 f"must be non-empty and not cross a multiple of 2^32")
            sensors = scene.sensors()
            if not sensors or not all(hasattr(sensor, "position") for sensor in sensors):
                raise ValueError("transient_opl: every sensor must be an 'omni_point' sensor")
            positions = np.array([sensor.position for sensor in sensors], dtype=np.float64)

            # Per-sample random stream from (seed, global index): chunk-invariant.
            # Opaque offsets keep one compiled kernel for every chunk.
            index = dr.arange(mi.UInt32, sample_count) + dr.opaque(mi.UInt32, low)
            v0, v1 = mi.sample_tea_32(dr.opaque(mi.UInt32, int(seed)), index)
            rng = mi.PCG32(sample_count)
            rng.seed(mi.UInt64(v0), mi.UInt64(v1) + dr.opaque(mi.UInt64, high << 32))

            sums = dr.zeros(mi.Float64, len(positions) * self.bins)
            squares = dr.zeros(mi.Float64, len(positions) * self.bins)
            if self.plane_matrix is not None:
                self._plane_samples(scene, rng, positions, sums, squares)
            else:
                self._general_samples(scene, rng, positions, sums, squares)
            dr.eval(sums, squares)  # one kernel for the whole chunk
            shape = (len(positions), self.bins)
            return (np.array(sums, dtype=np.float64).reshape(shape),
                    np.array(squares, dtype=np.float64).reshape(shape))

        def _plane_samples(self, scene, rng, sensors, sums, squares):
            """The single-plane estimator: x uniform on the rectangle, one bounce, no visibility."""
            plane, intensity = self._scene_parts(scene)
            bsdf = plane.bsdf()
            F64 = mi.Float64
            u32, v32 = rng.next_float32(), rng.next_float32()
            u, v = F64(u32), F64(v32)

            # Rectangle local [-1, 1]² -> world, in double: x = c + (2u-1) a + (2v-1) b.
            centre, axis_a, axis_b = (self.plane_matrix[:3, 3], self.plane_matrix[:3, 0],
                                      self.plane_matrix[:3, 1])
            normal = np.cross(axis_a, axis_b)
            area = 4.0 * float(np.linalg.norm(normal))
            normal = normal / np.linalg.norm(normal)
            point = [float(centre[i]) + (2.0 * u - 1.0) * float(axis_a[i])
                     + (2.0 * v - 1.0) * float(axis_b[i]) for i in range(3)]
            point = mi.Point3d(*point)
            normal_d = mi.Vector3d(*map(float, normal))

            to_source = mi.Point3d(*map(float, self.source_position)) - point
            source_distance = dr.norm(to_source)
            direction_source = to_source / source_distance

            # Mitsuba's diffuse BSDF at x: f(x)/π cos θ_s, zero unless the source
            # is above the surface. Seen from the surface normal (wi = +z): a
            # Lambertian BSDF's value does not depend on wi beyond its
            # hemisphere, which is checked per sensor below in float64.
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.uv = mi.Point2f(u32, v32)
            si.n = mi.Normal3f(*map(float, normal))
            si.sh_frame = mi.Frame3f(si.n)
            si.wi = mi.Vector3f(0.0, 0.0, 1.0)
            wo = si.to_local(mi.Vector3f(direction_source))
            reflected = F64(bsdf.eval(mi.BSDFContext(), si, wo)[0])
            # area / pdf, intensity, BSDF and the emitter's 1/d_s²: shared by every sensor.
            common = (area * intensity) * reflected / dr.square(source_distance)

            for k in range(len(sensors)):
                to_sensor = mi.Point3d(*map(float, sensors[k])) - point
                sensor_distance = dr.norm(to_sensor)
                cos_sensor = dr.dot(to_sensor, normal_d) / sensor_distance
                weight = common * cos_sensor / dr.square(sensor_distance)
                self._deposit(sums, squares, k, [(weight, source_distance + sensor_distance,
                                                  cos_sensor > 0.0)])

        def _general_samples(self, scene, rng, sensors, sums, squares):
            """Any diffuse shapes, point or area emitters, up to max_depth bounces, with visibility.

            Each sample picks x1 on the scene's surfaces by area and connects it
            to every sensor (shadow ray, cos θ_k / d_k²). From x1 a path
            continues by cosine-weighted BSDF sampling; at every vertex x_j
            (j <= max_depth) next-event estimation to an emitter closes a path
            sensor <- x1 <- ... <- x_j <- light, and emitted radiance at x1
            itself closes the zero-bounce path sensor <- x1. Emission hit by a
            BSDF-sampled ray is not counted: next-event estimation alone
            already samples every such path once. Distances come from
            float32 ray tracing (relative error ~1e-7 of each segment).
            """
            self._check_general_scene(scene)
            F64 = mi.Float64
            context = mi.BSDFContext()
            shapes = scene.shapes_dr()
            areas = np.array(shapes.surface_area(), dtype=np.float64).ravel()
            chooser = mi.DiscreteDistribution(mi.Float(areas.astype(np.float32)))

            # x1: a shape with probability ∝ area, then a uniform point on it.
            index, _ = chooser.sample_reuse(rng.next_float32())
            shape = dr.gather(mi.ShapePtr, shapes, index)
            position = shape.sample_position(0.0, mi.Point2f(rng.next_float32(), rng.next_float32()))
            density = position.pdf * chooser.eval_pmf_normalized(index)     # per m² of surface
            first = mi.SurfaceInteraction3f(position, dr.zeros(mi.Color0f))
            first.shape = shape
            first.sh_frame = mi.Frame3f(first.n)
            first.wi = mi.Vector3f(0.0, 0.0, 1.0)
            bsdf = first.bsdf()
            emitter = shape.emitter()
            alive = density > 0.0
            point = mi.Point3d(first.p)

            # Sensor connections: G_k / p(x1), with the shadow ray and the local wi_k.
            geometry, sensor_lengths, local_in = [], [], []
            for k in range(len(sensors)):
                target = mi.Point3d(*map(float, sensors[k]))
                to_sensor = target - point
                distance = dr.norm(to_sensor)
                direction = mi.Vector3f(to_sensor / distance)
                visible = ~scene.ray_test(first.spawn_ray_to(mi.Point3f(target)), alive)
                cosine = dr.abs(F64(dr.dot(direction, first.n)))
                geometry.append(dr.select(visible & alive, cosine / (dr.square(distance) * F64(density)),
                                          F64(0.0)))
                sensor_lengths.append(distance)
                local_in.append(first.to_local(direction))
            terms = [[] for _ in sensors]

            # Zero bounces: radiance emitted by x1 toward the sensor.
            for k in range(len(sensors)):
                first.wi = local_in[k]
                emitted = F64(emitter.eval(first, alive)[0])
                terms[k].append((geometry[k] * emitted, sensor_lengths[k], alive & (emitted > 0.0)))

            vertex, throughput, travelled = first, [F64(1.0)] * len(sensors), F64(0.0)
            for depth in range(1, self.max_depth + 1):
                # Next-event estimation at x_depth (visibility tested by Mitsuba).
                sample = mi.Point2f(rng.next_float32(), rng.next_float32())
                light, light_weight = scene.sample_emitter_direction(vertex, sample, True, alive)
                light_local = vertex.to_local(light.d)
                for k in range(len(sensors)):
                    if depth == 1:
                        vertex.wi = local_in[k]
                    value = F64(bsdf.eval(context, vertex, light_local, alive)[0]) * F64(light_weight[0])
                    active = alive & (light.pdf > 0.0)
                    terms[k].append((geometry[k] * throughput[k] * value,
                                     sensor_lengths[k] + travelled + F64(light.dist), active))
                if depth == self.max_depth:
                    break
                # Continue by sampling the BSDF; at x1 its weight depends on wi_k.
                if depth == 1:
                    vertex.wi = mi.Vector3f(0.0, 0.0, 1.0)
                bounce, bounce_weight = bsdf.sample(context, vertex, rng.next_float32(),
                                                    mi.Point2f(rng.next_float32(), rng.next_float32()),
                                                    alive)
                if depth == 1:
                    for k in range(len(sensors)):
                        vertex.wi = local_in[k]
                        value = bsdf.eval(context, vertex, bounce.wo, alive)[0]
                        throughput[k] = dr.select(bounce.pdf > 0.0, F64(value) / F64(bounce.pdf), F64(0.0))
                else:
                    throughput = [t * F64(bounce_weight[0]) for t in throughput]
                ray = vertex.spawn_ray(vertex.to_world(bounce.wo))
                following = scene.ray_intersect(ray, alive & (bounce.pdf > 0.0))
                alive = alive & (bounce.pdf > 0.0) & following.is_valid()
                travelled = travelled + F64(following.t)
                vertex, bsdf = following, following.bsdf()

            for k in range(len(sensors)):
                self._deposit(sums, squares, k, terms[k])

        def _deposit(self, sums, squares, sensor, terms):
            """Add one sample's contributions to sensor ``sensor``'s bins, and their squares.

            Parameters
            ----------
            sums, squares : mi.Float64
                ``K N`` accumulators (row-major: sensor, bin).
            sensor : int
                Sensor index k.
            terms : list of (mi.Float64, mi.Float64, mi.Bool)
                Per-sample (weight w, path length τ in metres, active) of
                each path the sample contributes; term j adds w_j κ_n(τ_j)
                to bin n.

            Notes
            -----
            The standard error needs the square of a sample's *total*
            contribution to a bin. When several terms of one sample reach the
            same bin, the first of them (in list order) deposits their sum and
            the others deposit nothing.
            """
            F64, U32 = mi.Float64, mi.UInt32
            bins, period = self.bins, self.bin_width_opl
            taps = self.waveform.bins_touched(period)
            firsts = [bin_index(length, self.start_opl, period, bins, floor=dr.floor)[0]
                      for _, length, _ in terms]

            def kernel(j, n):
                # κ_n(τ_j) = S(t_{n+1} - τ_j) - S(t_n - τ_j); exactly 0 or 1 for the impulse.
                if taps == 1:
                    return dr.select(firsts[j] == n, F64(1.0), F64(0.0))
                lower_edge = self.start_opl + n * period - terms[j][1]
                return (cumulative(self.waveform, lower_edge + period)
                        - cumulative(self.waveform, lower_edge))

            for j, (weight, length, active) in enumerate(terms):
                if taps > 1:
                    # Neighbouring taps share an edge: taps + 1 evaluations of S, not 2 taps.
                    edge = self.start_opl + firsts[j] * period - length
                    edges = [cumulative(self.waveform, edge + t * period) for t in range(taps + 1)]
                for tap in range(taps):
                    n = firsts[j] + tap
                    total = weight * (edges[tap + 1] - edges[tap]) if taps > 1 else weight
                    owner = active & (n >= 0) & (n < bins)
                    for other in range(len(terms)):
                        if other == j:
                            continue
                        reaches = terms[other][2] & (n >= firsts[other]) & (n < firsts[other] + taps)
                        if other < j:
                            owner &= ~reaches
                        else:
                            total += dr.select(reaches, terms[other][0] * kernel(other, n), F64(0.0))
                    slot = U32(dr.clip(n, 0, bins - 1)) + sensor * bins
                    dr.scatter_reduce(dr.ReduceOp.Add, sums, total, slot, active=owner)
                    dr.scatter_reduce(dr.ReduceOp.Add, squares, dr.square(total), slot, active=owner)

    return TransientPathLength


def register() -> None:
    """Register ``transient_opl`` with Mitsuba for the active variant."""
    cls = integrator_class()
    mi.register_integrator(PLUGIN_NAME, lambda props: cls(props))
